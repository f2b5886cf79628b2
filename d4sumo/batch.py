"""Many episodes of one configuration advanced together, one numpy operation per law: pure code, no SUMO.

An optimiser that proposes several attacks at once (a cross-entropy generation, a CMA-ES population,
a batch of random points) has them played side by side: `simulation.simulate_batch` moves the
platoons in one SUMO instance, each on its own copy of the road, and `PlatoonBatch.advance` commands
every car of every episode in one step. The laws run over arrays (`control.ARRAY_KERNELS`), each
element with exactly the arithmetic of the scalar controller, so an episode played in a batch is bit
for bit the episode played alone (`Platoon`). A follower whose controller has no array form (a user's
class) runs its own scalar controller, one per episode.

Shapes: M episodes, n cars (config.vehicle_ids), C commanded cars (`Platoon.commanded`).
"""

from __future__ import annotations

import numpy as np

from .config import EpisodeConfig
from .control import ARRAY_KERNELS, ActuatorArray, CruiseArray, acceleration_to_command_array
from .maneuvers import FREE_ROAD_GAP_M, Pair, maneuver_of
from .platoon import ControllerError, PythonFollower, assemble_trace, collisions_at, cruise_params, followers_of
from .trace import Collision, Episode


#: episodes of a campaign played side by side at most, by default (the results never depend on it, only the speed)
DEFAULT_BATCH = 32


class PlatoonBatch:
    """M platoons of one configuration, each playing its own attack signal (row of ``attacks_u``)."""

    def __init__(self, config: EpisodeConfig, attacks_u: np.ndarray, attacker_max_speed_mps: float):
        attacks_u = np.asarray(attacks_u, dtype=float)
        if attacks_u.ndim != 2 or attacks_u.shape[1] != config.steps:
            raise ValueError(f"attack signals have shape {attacks_u.shape}, expected (episodes, {config.steps})")
        self.config = config
        self.maneuver = maneuver_of(config)
        self.ids = config.vehicle_ids
        self.size = m = attacks_u.shape[0]
        self.attacks_u = attacks_u
        vehicle, dt, n = config.vehicle, config.step_s, config.followers + 1
        self.followers = followers_of(config)  # the kinds, for the trace: the same in every episode
        gains = cruise_params(config)
        self.attacker_cruise = CruiseArray(gains, config.speed_mps, dt, (m,))
        self._attacking = np.zeros(m, dtype=bool)
        others = list(range(n, len(self.ids)))
        self._others = np.array(others, dtype=int)
        self._lead = CruiseArray(gains, config.speed_mps, dt, (m, len(others))) if self.maneuver.other_cruises else None
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
            if kernel is None:
                for i, column in members:
                    self._scalar.append((i, column, [PythonFollower(controller, config) for _ in range(m)]))
                continue
            columns = [c for _, c in members]
            modes = [self._with_mode.index(i) for i, _ in members]
            self._kernels.append((_index(cars.tolist()), _index([i - 1 for i in cars.tolist()]), _index(columns),
                                  _index(modes), kernel(prototype, (m, len(cars)), dt)))
        max_speeds = [attacker_max_speed_mps] + [np.inf] * len(python) + [attacker_max_speed_mps] * len(others)
        self.actuator = ActuatorArray(vehicle, dt, (m, len(self.commanded)), np.array(max_speeds))
        self.commands = np.zeros((config.steps, m, len(self.commanded)))  # each step's commands, as played
        self.modes = np.zeros((config.steps, m, len(self._with_mode))) if self._with_mode else None
        self.failed: dict[int, ControllerError] = {}  # episode -> the error of a user's controller
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
            u[:, 0] = np.where(cruising, acceleration_to_command_array(a, self.config.vehicle), attack)
        else:
            u[:, 0] = attack
        self._attacking = ~cruising
        column = lead is self._column
        for cars, before, columns, _, kernel in self._kernels:
            ahead = speeds[:, before] if column else speeds[self._rows, lead[:, cars]]
            u[:, columns] = kernel.command(gap[:, cars], speeds[:, cars], ahead)
        for i, column_index, followers in self._scalar:
            for e in np.flatnonzero(active).tolist():
                if e in self.failed:
                    continue
                c = followers[e].command(float(gap[e, i]), float(speeds[e, i]), float(speeds[e, lead[e, i]]))
                if not -1.0 <= c <= 1.0:  # NaN fails too
                    self.failed[e] = ControllerError(
                        f"the controller of v{i} returned {c!r} at step {k}; allowed: a command in [-1, 1]")
                    c = 0.0
                u[e, column_index] = c
        others = self._others
        if others.size and self._lead is not None:
            u[:, -others.size:] = acceleration_to_command_array(self._lead.acceleration(speeds[:, others]),
                                                                self.config.vehicle)
        new_speeds = self.actuator.apply(u, speeds[:, self._commanded])
        if others.size and self._lead is None:  # the obstacle holds its speed (command 0)
            new_speeds[:, -others.size:] = self.config.obstacle_speed_mps
        if self.modes is not None:
            modes = self.modes[k]
            for _, _, _, mode_columns, kernel in self._kernels:
                modes[:, mode_columns] = kernel.mode
            for i, _, followers in self._scalar:
                if followers[0].has_mode:
                    modes[:, self._with_mode.index(i)] = [f.controller.mode for f in followers]
        return new_speeds

    def episode(self, e: int, steps: int, positions: np.ndarray, speeds: np.ndarray, collisions: tuple[Collision, ...],
                pairs: list[list[Pair]] | None = None, lateral_m: np.ndarray | None = None) -> Episode:
        """Episode ``e`` after ``steps`` steps, from its sensed rows (steps + 1 samples x n)."""
        times = np.arange(steps + 1) * self.config.step_s
        modes = self.modes[:steps, e] if self.modes is not None else None
        trace, min_gaps = assemble_trace(self.config, self.followers, self.commanded, times, positions, speeds,
                                         self.commands[:steps, e], modes, pairs or [], lateral_m)
        return Episode(trace, collisions, min_gaps)


def _index(positions: list[int]) -> slice | np.ndarray:
    """Columns to index with: a slice where they are contiguous (a view, and cheaper), else an array."""
    if positions == list(range(positions[0], positions[0] + len(positions))):
        return slice(positions[0], positions[0] + len(positions))
    return np.array(positions, dtype=int)


def collided(gap: np.ndarray) -> np.ndarray:
    """Which episodes (rows of the M x n gaps of `PlatoonBatch.leaders`) have a bumper overlap."""
    return (gap < 0.0).any(axis=1)


def integrate_batch(config: EpisodeConfig, attacks_u: np.ndarray, attacker_max_speed_mps: float = float("inf")) -> list[Episode | ControllerError]:
    """`platoon.integrate` for many attacks at once: ballistic positions, no SUMO, the paper's maneuver.
    For physics tests of the array laws against the scalar ones."""
    from .maneuvers import initial_state

    batch = PlatoonBatch(config, attacks_u, attacker_max_speed_mps)
    m, dt, ids = batch.size, config.step_s, config.vehicle_ids
    x0, v0 = initial_state(config)
    rows_x = np.empty((config.steps + 1, m, len(ids)))
    rows_v = np.empty_like(rows_x)
    rows_x[0], rows_v[0] = x0, v0
    positions, speeds = rows_x[0].copy(), rows_v[0].copy()
    active = np.ones(m, dtype=bool)
    ended: dict[int, Episode | ControllerError] = {}
    lead, gap = batch.leaders(positions, None)
    for k in range(config.steps):
        new_speeds = batch.advance(k, positions, speeds, lead, gap, active)
        positions = positions + 0.5 * (speeds + new_speeds) * dt
        speeds = new_speeds
        rows_x[k + 1], rows_v[k + 1] = positions, speeds
        lead, gap = batch.leaders(positions, None)
        hit = collided(gap) | np.isin(np.arange(m), list(batch.failed))
        for e in np.flatnonzero(hit & active).tolist():
            active[e] = False
            if e in batch.failed:
                ended[e] = batch.failed[e]
                continue
            x, v = rows_x[k + 1, e].tolist(), rows_v[k + 1, e].tolist()
            record = collisions_at((k + 1) * dt, batch.maneuver.pairs(x), x, v, ids)
            ended[e] = batch.episode(e, k + 1, rows_x[:k + 2, e], rows_v[:k + 2, e], record)
        if not active.any():
            break
    for e in np.flatnonzero(active).tolist():
        ended[e] = batch.episode(e, config.steps, rows_x[:, e], rows_v[:, e], ())
    return [ended[e] for e in range(m)]


