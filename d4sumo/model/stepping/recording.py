"""What an episode recorded, as its trace: from the rows the step loop kept (each car's position, speed and
command, the followers' modes, who followed whom), every signal the specification and the figures read, and
the minimum gaps of each pair that followed each other, from the attack's start and in the warm-up before it.
Under a message attack, what the liar's beacons said too (`sent_signals`). Pure code, no SUMO."""

from __future__ import annotations

import numpy as np

from ..config import EpisodeConfig
from ..attacks.maneuvers import Pair
from ..world.lanes import FREE_ROAD_GAP_M
from .trace import Trace
from ..world.traffic import TRAFFIC_ID


def sent_signals(sent: list, n_samples: int, liar: int = 0) -> dict[str, np.ndarray]:
    """Under a message attack, what the liar's beacons (car ``liar``: 0 the attacker) said at each sample,
    beside the truth (``pos_vK``, ``speed_vK``, ``accel_vK``): the newest beacon it sent at or before it (NaN
    before the first; a beacon it did not send leaves the one before), ``sent_pos_vK``, ``sent_speed_vK``,
    ``sent_accel_vK``."""
    names = [f"sent_{field}_v{liar}" for field in ("pos", "speed", "accel")]
    out = {name: np.full(n_samples, np.nan) for name in names}
    pos, speed, accel = (out[name] for name in names)
    for k, message in sent:
        if message is None or k >= n_samples:
            continue
        pos[k:] = message.position_m
        speed[k:] = message.speed_mps
        accel[k:] = message.accel_mps2
    return out


def assemble_trace(config: EpisodeConfig, followers: list, commanded: tuple[int, ...], times_s: np.ndarray,
                   positions: np.ndarray, speeds: np.ndarray, commands: np.ndarray, modes: np.ndarray | None,
                   pairs: list[list[Pair]], lateral_m: np.ndarray | None
                   ) -> tuple[Trace, dict[str, float], dict[str, float] | None]:
    """The Trace of an episode from its sensed rows (samples x cars), the commands recorded per step
    (steps x ``commanded`` cars) and the modes of the followers that have one (steps x those); for a
    lane-changing maneuver also the pairs of each sample and each car's lateral position. With it the
    minimum gap of every pair of cars that followed each other from the attack's start, the window the
    specification scores and the outcome counts (a collision in a warm-up is an error), and after a
    warm-up the minimum gaps during it (None without one). One function for an episode played alone or
    in a batch, so both give the same trace."""
    n_samples = times_s.size
    ids = config.vehicle_ids
    accel = np.zeros_like(speeds)
    accel[1:] = np.diff(speeds, axis=0) / config.step_s
    cmds = np.empty((n_samples, len(ids)))
    cmds[:, list(commanded)] = _hold_last(commands, n_samples)
    for i, follower in enumerate(followers, start=1):
        if follower.sumo_driven:  # no throttle/brake in SUMO: the command its next step's acceleration asks for
            vehicle = follower.vehicle
            ahead = np.append(accel[1:, i], accel[-1, i])
            u = np.where(ahead >= 0.0, ahead / vehicle.max_accel_mps2, ahead / vehicle.max_decel_mps2)
            cmds[:, i] = np.clip(u, -1.0, 1.0)  # acceleration_to_command, over the whole column
    signals: dict[str, np.ndarray] = {}
    for i, vid in enumerate(ids):
        signals[f"pos_{vid}"] = positions[:, i]
        signals[f"speed_{vid}"] = speeds[:, i]
        signals[f"accel_{vid}"] = accel[:, i]
        signals[f"cmd_{vid}"] = cmds[:, i]
    if config.traffic is not None:  # who followed whom is what the step sensed (a traffic car is index N + 1)
        rows = _lane_gaps((*ids, TRAFFIC_ID), signals, pairs, lateral_m, traffic=True)
        if not config.maneuver_class.lateral:  # the paper's column names: gap_I is v(I+1)'s gap to whatever is ahead
            for i in range(config.followers):
                signals[f"gap_{i}"] = signals[f"gap_v{i + 1}"]
    elif config.maneuver_class.lateral:
        rows = _lane_gaps(ids, signals, pairs, lateral_m)
    else:
        rows = _column_gaps([v.length_m for v in config.car_vehicles], signals, positions)
    start = min(config.attack_start_step, n_samples - 1)
    min_gaps = _window_minima(rows, start, n_samples)
    warmup_min_gaps = _window_minima(rows, 0, start) if start > 0 else None
    if modes is not None and modes.size:
        modes = _hold_last(modes, n_samples)
        with_mode = [i for i, f in enumerate(followers, start=1) if f.has_mode]
        for column, i in enumerate(with_mode):
            signals[f"mode_v{i}"] = modes[:, column]
    return Trace(times_s=times_s, signals=signals, followers=config.followers), min_gaps, warmup_min_gaps


def _window_minima(rows: dict[str, tuple[np.ndarray, np.ndarray] | np.ndarray], start: int, stop: int) -> dict[str, float]:
    """Each pair's minimum gap over samples [start, stop): ``rows`` is a pair's gap at every sample (an
    array) or at the samples where it followed ((samples, gaps)); a pair that never did is left out."""
    minima = {}
    for name, gaps in rows.items():
        if isinstance(gaps, np.ndarray):
            minima[name] = float(gaps[start:stop].min())
        else:
            samples, gaps = gaps
            inside = gaps[(samples >= start) & (samples < stop)].tolist()
            if inside:
                minima[name] = min(inside)  # min(): the first of equal gaps, a NaN first or never
    return minima


def _column_gaps(lengths_m: list[float], signals: dict, positions: np.ndarray) -> dict[str, np.ndarray]:
    """The paper's column v0, v1, .., vN: gap_I between vI and vI+1 (vI's length behind its front bumper),
    vectorised (the same arithmetic as the maneuver's pairs), and the named gaps every maneuver's trace has;
    each pair's gap at every sample."""
    n = positions.shape[1]
    for i in range(n - 1):
        signals[f"gap_{i}"] = positions[:, i] - lengths_m[i] - positions[:, i + 1]
    free = np.full(positions.shape[0], FREE_ROAD_GAP_M)
    signals["gap_v0"] = free
    for i in range(1, n):
        signals[f"gap_v{i}"] = signals[f"gap_{i - 1}"]
    signals["attacker_gap"] = signals["gap_0"]
    signals["victim_gap"] = np.min([signals[f"gap_{i}"] for i in range(1, n - 1)], axis=0) if n > 2 else free
    return {f"v{i}-v{i + 1}": signals[f"gap_{i}"] for i in range(n - 1)}


def _lane_gaps(ids: tuple[str, ...], signals: dict, pairs: list[list[Pair]], lateral_m: np.ndarray | None,
               traffic: bool = False) -> dict[str, tuple[np.ndarray, np.ndarray]]:
    """From the recorded pairs: each car's gap to the car ahead in its lane(s), the nearest gap of a
    pair without the attacker (victim_gap) and with it (attacker_gap), and lateral positions (when
    given); each pair's gaps at the samples where it followed, as (samples, gaps). With ``traffic`` the last of
    ``ids`` is every traffic car (`traffic.TRAFFIC_ID`; the pairs index each as sensed, past the platoon's): its gaps
    are not a signal, its pairs' are (``traffic-v3``). Over arrays (`_min_at`)."""
    n_samples = len(pairs)
    gaps = np.full((n_samples, len(ids)), FREE_ROAD_GAP_M)
    victim = np.full(n_samples, FREE_ROAD_GAP_M)
    attacker = np.full(n_samples, FREE_ROAD_GAP_M)
    rows: dict[str, tuple[np.ndarray, np.ndarray]] = {}
    flat = [pair for sample in pairs for pair in sample]
    if flat:
        k = np.repeat(np.arange(n_samples), [len(sample) for sample in pairs])
        a = np.fromiter((pair[0] for pair in flat), dtype=np.intp, count=len(flat))
        b = np.fromiter((pair[1] for pair in flat), dtype=np.intp, count=len(flat))
        if traffic:  # as sensed, each traffic car its own index past the platoon's: here one, TRAFFIC_ID's
            np.minimum(a, len(ids) - 1, out=a)
            np.minimum(b, len(ids) - 1, out=b)
        gap = np.fromiter((pair[2] for pair in flat), dtype=float, count=len(flat))
        _min_at(gaps.reshape(-1), k * len(ids) + b, gap)
        with_attacker = (a == 0) | (b == 0)
        _min_at(attacker, k[with_attacker], gap[with_attacker])
        _min_at(victim, k[~with_attacker], gap[~with_attacker])
        code = a * len(ids) + b
        codes, first = np.unique(code, return_index=True)
        for c in codes[np.argsort(first)]:  # each pair in the order it first followed
            mine = code == c
            rows[f"{ids[c // len(ids)]}-{ids[c % len(ids)]}"] = (k[mine], gap[mine])
    for i, vid in enumerate(ids[:-1] if traffic else ids):
        signals[f"gap_{vid}"] = gaps[:, i]
        if lateral_m is not None:
            signals[f"y_{vid}"] = lateral_m[:, i]
    signals["victim_gap"] = victim
    signals["attacker_gap"] = attacker
    return rows


def _min_at(out: np.ndarray, slots: np.ndarray, values: np.ndarray) -> None:
    """out[slot] = min(out[slot], value) for each slot and value in the order given, as Python's min() does it: a value
    replaces only a greater one (never a NaN, and of 0.0 and -0.0 the first stays), over arrays."""
    if not len(values):
        return
    order = np.lexsort((values, slots))  # by slot, then value (NaN last); equal values in the order given
    ordered = slots[order]
    first = np.ones(len(order), dtype=bool)
    first[1:] = ordered[1:] != ordered[:-1]
    slot, best = ordered[first], values[order][first]  # each slot's least value, the first of equal ones
    smaller = best < out[slot]
    out[slot[smaller]] = best[smaller]


def _hold_last(rows: np.ndarray, n_samples: int) -> np.ndarray:
    """Rows recorded per step, one per sample: the last sample has no step after it, so it holds the last row."""
    if rows.shape[0] < n_samples:
        rows = np.vstack([rows, np.repeat(rows[-1:], n_samples - rows.shape[0], axis=0)])
    return rows[:n_samples]
