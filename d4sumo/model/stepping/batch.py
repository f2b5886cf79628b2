"""Many episodes advanced together, one numpy operation per law: pure code, no SUMO.

An optimiser that proposes several attacks at once (a cross-entropy generation, a CMA-ES population,
a batch of random points), or several campaigns of a sweep stepped together, have them played side
by side (their configurations may differ in setpoint, target speed and start: `batch_key`): `simulation.simulate_batch` moves the
platoons in one SUMO instance, each on its own copy of the road, and `PlatoonBatch.advance` commands
every car of every episode in one step. The laws run over arrays (`control.ARRAY_KERNELS`), each
element with exactly the arithmetic of the scalar controller, so an episode played in a batch is bit
for bit the episode played alone (`Platoon`). A follower whose controller has no array form (a user's
class) runs its own scalar controller, one per episode.

Shapes: M episodes, n cars (config.vehicle_ids), C commanded cars (`Platoon.commanded`).
"""

from __future__ import annotations

import json
from typing import Sequence

import numpy as np

from ...errors import is_number
from ..config import EpisodeConfig
from ..world.network import is_network_path
from ..controllers.arrays import ARRAY_KERNELS, ActuatorArray, CommandArray, CruiseArray, per_row
from ..controllers.control import CruiseControl
from ..attacks.maneuvers import Pair, maneuver_of
from ..world.lanes import FREE_ROAD_GAP_M
from ..controllers.commands import checked_command
from .platoon import Platoon, PythonFollower, cruise_params, followers_of
from .recording import assemble_trace
from .trace import Collision, Episode

#: episodes of a campaign played side by side at most, by default (the results never depend on it, only the speed)
DEFAULT_BATCH = 64


def batch_key(config: EpisodeConfig) -> str:
    """`_batch_key`, kept for the last configurations asked for (a batch checks its configurations' keys, and a
    campaign that searches its situation makes one a sample)."""
    try:
        return _KEYS[config]
    except KeyError:
        pass
    except TypeError:  # a configuration holding something unhashable
        return _batch_key(config)
    if len(_KEYS) >= 1024:
        _KEYS.clear()
    key = _KEYS[config] = _batch_key(config)
    return key


_KEYS: dict[EpisodeConfig, str] = {}


def known_key(config: EpisodeConfig, key: str) -> None:
    """Keep ``key`` as ``config``'s `batch_key`, known by its maker (a sample's configuration in a situation whose every
    corner has its campaign's key: `evaluator.Evaluator.config_for`), so that a batch's check costs nothing."""
    if len(_KEYS) >= 1024:
        _KEYS.clear()
    _KEYS[config] = key


def _batch_key(config: EpisodeConfig) -> str:
    """Configurations whose episodes may play in one batch have the same key: they differ at most in what the
    batch carries per episode, so several campaigns of a sweep (or the samples of a campaign that searches its
    situation) can share one SUMO:

    - the setpoint, the target speed and the start from rest or steady (`PER_EPISODE`); followers driven by SUMO's
      models read the target speed from their vehicle type, so theirs must be the same too;
    - the numbers of one Python controller for every follower (its gains: the arrays and each platoon take them per
      episode), its radar's and its V2V channel's numbers (each platoon senses and beacons on its own), and the
      actuator's lag (none of SUMO's; a road of one's own keeps it, its traffic lights' drivers plan with it).

    Whether the arrays command them (`EpisodeConfig.batch_arrays`) is one for the batch."""
    doc = dict(config.to_dict())
    doc["scenario"] = {k: v for k, v in doc["scenario"].items() if k not in PER_EPISODE}
    if config.start == "warmup":  # the warm-up's length decides the attack's start
        doc["scenario"]["start"] = "warmup"
    if config.sumo_driven:
        doc["scenario"]["speed_mps"] = config.speed_mps
    if isinstance(doc.get("controller"), dict) and not config.controllers[0].sumo_model:
        doc["controller"] = {k: v for k, v in doc["controller"].items() if not is_number(v)}
    doc.pop("radar", None)
    if isinstance(doc.get("v2v"), dict):
        doc["v2v"] = {k: v for k, v in doc["v2v"].items() if not is_number(v)}
    if not is_network_path(config.network):
        doc["vehicle"] = {k: v for k, v in doc["vehicle"].items() if k != "actuator_lag_s"}
    doc["arrays"] = config.batch_arrays
    return json.dumps(doc, sort_keys=True, default=str)


#: what may differ between the episodes of one batch's [scenario] (`batch_key`)
PER_EPISODE = ("setpoint_m", "speed_mps", "start")


def episode_configs(config: EpisodeConfig | Sequence[EpisodeConfig], count: int) -> list[EpisodeConfig]:
    """One configuration per episode of a batch of ``count``: ``config`` for all, or the sequence
    given, checked to be one per episode and to share one `batch_key`."""
    configs = [config] * count if isinstance(config, EpisodeConfig) else list(config)
    if len(configs) != count:
        raise ValueError(f"{len(configs)} configurations for {count} episodes")
    distinct = {id(c): c for c in configs}
    if len(distinct) > 1 and len({batch_key(c) for c in distinct.values()}) > 1:
        raise ValueError("a batch's configurations differ in more than a batch carries per episode (`batch_key`)")
    return configs


class PlatoonBatch:
    """M platoons, each playing its own attack signal (row of ``attacks_u``): of one configuration, or
    of one per episode (``config`` a sequence, all with one `batch_key`)."""

    def __init__(self, config: EpisodeConfig | Sequence[EpisodeConfig], attacks_u: np.ndarray, attacker_max_speed_mps: float):
        attacks_u = np.asarray(attacks_u, dtype=float)
        configs = episode_configs(config, attacks_u.shape[0])
        config = configs[0]
        if attacks_u.ndim != 2 or attacks_u.shape[1] != config.steps:
            raise ValueError(f"attack signals have shape {attacks_u.shape}, expected (episodes, {config.steps})")
        if not config.batch_arrays:
            raise ValueError("these platoons are commanded one by one (EpisodeConfig.batch_arrays), not by the arrays")
        distinct = {id(c): c for c in configs}
        self.config = config  # what every episode shares
        self.configs = configs
        self.maneuver = maneuver_of(config)
        self.ids = config.vehicle_ids
        self.size = m = attacks_u.shape[0]
        self.attacks_u = attacks_u
        vehicle, dt, n = config.vehicle, config.step_s, config.followers + 1  # one vehicle for all (`batch_arrays`)
        self.followers = followers_of(config)  # the kinds, for the trace: the same in every episode
        # each distinct configuration's followers: their controllers carry its setpoint and target speed
        rows_followers = {k: (self.followers if c is config else followers_of(c)) for k, c in distinct.items()}
        episode_followers = [rows_followers[id(c)] for c in configs]
        row_gains = {k: cruise_params(c) for k, c in distinct.items()}  # (a situation searched may set each episode's gains)
        gains = [row_gains[id(c)] for c in configs]
        speeds = [c.speed_mps for c in configs]  # the target speed of each episode
        self.attacker_cruise = CruiseArray(gains, per_row([c.attacker_cruise_mps for c in configs], (m,)), dt, (m,))
        self._command = CommandArray(vehicle)
        self._attacking = np.zeros(m, dtype=bool)
        others = list(range(n, len(self.ids)))
        self._others = np.array(others, dtype=int)
        self._lead = (CruiseArray(gains, per_row(speeds, (m, len(others))), dt, (m, len(others)))
                      if self.maneuver.other_cruises else None)
        python = [i for i, f in enumerate(self.followers, start=1) if not f.sumo_driven]
        self.commanded = (0, *python, *others)
        self._commanded = _index(list(self.commanded))
        self._with_mode = [i for i, f in enumerate(self.followers, start=1) if f.has_mode]
        # Followers with one controller table share an array kernel over (episodes x those followers).
        self._kernels: list[tuple] = []  # (its cars, the cars before them, their columns in `commanded` and in the modes, the kernel)
        self._scalar: list[tuple[int, int, list[PythonFollower]]] = []  # (car, column, one follower per episode)
        groups: dict = {}
        for column, i in enumerate(python, start=1):
            groups.setdefault(self.followers[i - 1].config, []).append((i, column))
        for controller, members in groups.items():
            cars = np.array([i for i, _ in members])
            prototype = self.followers[cars[0] - 1].controller
            kernel = ARRAY_KERNELS.get(type(prototype))
            if kernel is None:  # one object per episode, of its own controller table (its own parameters)
                for i, column in members:
                    self._scalar.append((i, column, [PythonFollower(c.controllers[i - 1], c, i) for c in configs]))
                continue
            columns = [c for _, c in members]
            modes = [self._with_mode.index(i) for i, _ in members]
            rows = [f[cars[0] - 1].controller for f in episode_followers]  # one prototype per episode
            self._kernels.append((_index(cars.tolist()), _index([i - 1 for i in cars.tolist()]), _index(columns),
                                  _index(modes), kernel(rows, (m, len(cars)), dt)))
        max_speeds = [attacker_max_speed_mps] + [np.inf] * len(python) + [attacker_max_speed_mps] * len(others)
        self.actuator = ActuatorArray(vehicle, dt, (m, len(self.commanded)), np.array(max_speeds),
                                      [c.vehicle.actuator_lag_s for c in configs])
        self.commands = np.zeros((config.steps, m, len(self.commanded)))  # each step's commands, as played
        self.modes = np.zeros((config.steps, m, len(self._with_mode))) if self._with_mode else None
        self._scalar.sort(key=lambda entry: entry[0])  # car order: the first follower to fail is the one named alone
        self.failed: dict[int, Exception] = {}  # episode -> the error of a user's controller, which ended it
        #: episode -> a user's controller's mode that is not a number: alone, its trace cannot be made, so
        #: the episode ends with this error unless the controller fails first
        self.bad_modes: dict[int, Exception] = {}
        self._rows = np.arange(m)[:, None]
        #: the paper's column: each car's leader is the car before it (the attacker leads itself)
        self._column = np.broadcast_to(np.maximum(np.arange(len(self.ids)) - 1, 0), (m, len(self.ids)))

    def leaders(self, positions: np.ndarray, pairs: list[list[Pair]] | None) -> tuple[np.ndarray, np.ndarray]:
        """Each car's leader and bumper gap to it (M x n); a car with nobody ahead in its lane leads
        itself at the free road's gap. ``pairs``: each episode's pairs, for a lane-changing maneuver
        (None: the paper's column, vectorised with the arithmetic of `Maneuver.pairs`)."""
        m, n = positions.shape
        gap = np.full((m, n), FREE_ROAD_GAP_M)
        if pairs is None:
            gap[:, 1:] = positions[:, :-1] - self.config.vehicle.length_m - positions[:, 1:]
            return self._column, gap
        lead = np.broadcast_to(np.arange(n), (m, n)).copy()
        for e, episode_pairs in enumerate(pairs):
            if episode_pairs is None:
                continue
            for a, b, g in episode_pairs:  # a car covering two lanes may have two: the nearer counts
                if lead[e, b] == b or g < gap[e, b]:
                    lead[e, b], gap[e, b] = a, g
        return lead, gap

    def advance(self, k: int, positions: np.ndarray, speeds: np.ndarray, lead: np.ndarray, gap: np.ndarray,
                active: np.ndarray) -> np.ndarray:
        """Commands for step k of every episode from the sensed state (M x n) and each car's leader and
        gap; returns the speed at the step's end of each commanded car (M x C). Episodes not
        ``active`` (ended) are computed along and ignored; a user's controller runs only for active ones."""
        u = self.commands[k]
        attack = self.attacks_u[:, k]
        cruising = attack != attack  # NaN: no attack here, the attacker cruises like everyone else
        if np.count_nonzero(cruising):
            self.attacker_cruise.reset(cruising & self._attacking)  # a new cruise window: the PID starts afresh
            a = self.attacker_cruise.acceleration(speeds[:, 0], cruising)
            u[:, 0] = np.where(cruising, self._command(a), attack)
        else:
            u[:, 0] = attack
        self._attacking = ~cruising
        column = lead is self._column
        for cars, before, columns, _, kernel in self._kernels:
            ahead = speeds[:, before] if column else speeds[self._rows, lead[:, cars]]
            u[:, columns] = kernel.command(gap[:, cars], speeds[:, cars], ahead)
        for i, column_index, followers in self._scalar:  # a user's controllers, v1 first as alone
            for e in np.flatnonzero(active).tolist():
                if e in self.failed:
                    continue
                try:
                    u[e, column_index] = checked_command(
                        followers[e].command(float(gap[e, i]), float(speeds[e, i]), float(speeds[e, lead[e, i]])), i, k)
                except Exception as exc:  # as alone: this episode ends with the error, the others go on
                    self.failed[e] = exc
        others = self._others
        if others.size and self._lead is not None:
            u[:, -others.size:] = self._command(self._lead.acceleration(speeds[:, others]))
        new_speeds = self.actuator.apply(u, speeds[:, self._commanded])
        if others.size and self._lead is None:  # the obstacle holds its speed (command 0)
            new_speeds[:, -others.size:] = self.config.obstacle_speed_mps
        if self.modes is not None:
            modes = self.modes[k]
            for _, _, _, mode_columns, kernel in self._kernels:
                modes[:, mode_columns] = kernel.mode
            for i, _, followers in self._scalar:
                if followers[0].has_mode:
                    column = self._with_mode.index(i)
                    for e, f in enumerate(followers):
                        try:
                            modes[e, column] = f.controller.mode
                        except Exception as exc:  # not a number: as alone, the trace will not be made
                            self.bad_modes.setdefault(e, exc)
        return new_speeds

    def detach(self, e: int, k: int) -> Platoon:
        """Episode ``e`` before its step ``k`` as a `Platoon` of its own, in exactly the state it has here
        (controllers, actuators, the commands and modes it recorded), to go on one car at a time: a batch
        whose few episodes left cost less that way than the arrays' fixed cost per step. (A lane-changing
        maneuver's pairs are the caller's: it records them for every episode.)"""
        config = self.configs[e]
        own = config.controllers  # its own tables: a situation searched may set each episode's gains
        followers = [f if f.sumo_driven else PythonFollower(own[i - 1], config, i) for i, f in enumerate(self.followers, start=1)]
        for i, _, scalar in self._scalar:  # a user's controller: its own object goes on
            followers[i - 1] = scalar[e]
        platoon = Platoon(config, self.attacks_u[e], float(self.actuator.max_speed_mps[e, 0]), followers)
        _carry(self.attacker_cruise, e, platoon.attacker_cruise)
        platoon._attacking = bool(self._attacking[e])
        accel = self.actuator.accel_mps2[e].tolist()
        column = dict(zip(self.commanded, range(len(self.commanded))))
        platoon.attacker_actuator.accel_mps2 = accel[0]
        for cars, _, _, _, kernel in self._kernels:
            for j, i in enumerate(_positions(cars)):
                controller = followers[i - 1].controller
                controller.mode = float(kernel.mode[e, j])
                controller._mode_known = kernel._mode_known
                _carry(kernel.cruise, (e, j), controller.cruise)
        for i, f in enumerate(followers, start=1):
            if not f.sumo_driven:
                f.actuator.accel_mps2 = accel[column[i]]
        for j, (i, cruise, actuator, _) in enumerate(platoon._others):
            actuator.accel_mps2 = accel[column[i]]
            if cruise is not None:
                _carry(self._lead, (e, j), cruise)
        platoon.commands = self.commands[:k, e].tolist()
        if self.modes is not None:
            platoon.modes = self.modes[:k, e].tolist()
        platoon.compile()  # in C from here on, where it may be: in the state the arrays left
        return platoon

    def episode(self, e: int, steps: int, positions: np.ndarray, speeds: np.ndarray, collisions: tuple[Collision, ...],
                pairs: list[list[Pair]] | None = None, lateral_m: np.ndarray | None = None) -> Episode:
        """Episode ``e`` after ``steps`` steps, from its sensed rows (steps + 1 samples x n)."""
        times = np.arange(steps + 1) * self.config.step_s
        modes = self.modes[:steps, e] if self.modes is not None else None
        trace, min_gaps, warmup_min_gaps = assemble_trace(self.configs[e], self.followers, self.commanded, times, positions,
                                                          speeds, self.commands[:steps, e], modes, pairs or [], lateral_m)
        return Episode(trace, collisions, min_gaps, warmup_min_gaps)


def _carry(cruise: CruiseArray, at, to: CruiseControl) -> None:
    """One car's PID state, from the arrays to its own controller."""
    to.integral = float(cruise.integral[at])
    to.prev_error = float(cruise.prev_error[at]) if cruise.engaged[at] else None


def _positions(index: slice | np.ndarray) -> list[int]:
    return list(range(index.start, index.stop)) if isinstance(index, slice) else index.tolist()


def _index(positions: list[int]) -> slice | np.ndarray:
    """Columns to index with: a slice where they are contiguous (a view, and cheaper), else an array."""
    if positions == list(range(positions[0], positions[0] + len(positions))):
        return slice(positions[0], positions[0] + len(positions))
    return np.array(positions, dtype=int)


def collided(gap: np.ndarray, collision_gap_m: float = 0.0) -> np.ndarray:
    """Which episodes (rows of the M x n gaps of `PlatoonBatch.leaders`) have a collision: a bumper gap
    below ``collision_gap_m`` (`platoon.collisions_at`)."""
    return (gap < collision_gap_m).any(axis=1)
