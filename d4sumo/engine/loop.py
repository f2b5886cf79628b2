"""The one step loop: every episode d4sumo plays, alone or side by side, in SUMO or in the SUMO-free
ballistic world, is played by `play`.

Each step: command (from the sensed state and who follows whom) -> apply the speeds -> step the world
-> sense -> pairs -> collide -> end. The world is the seam (`engine.sumo.SumoWorld`,
`engine.ballistic.BallisticWorld`): each episode's vehicle ids, ``get_position``, ``get_speed``,
``set_speed``, ``step``, ``remove`` (and ``lanes``, ``change_lane``, ``lateral_rows`` for maneuvers
that change lanes). Its modes are classes behind two seams:
- who commands: many episodes are commanded by the batch's arrays (`_Arrays`, over `batch.PlatoonBatch`)
  while more than `DETACH_AT` are left; fewer, each by its own `platoon.Platoon` (`_Alone`), over plain
  lists. That is the only place where batched and alone differ, and each episode is bit for bit the same
  either way;
- how an episode alone senses who follows whom: in the paper's column (`_Column`), across lanes where its
  maneuver changes them (`_Lanes`), or among SUMO's traffic (`_Traffic`).
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from ..errors import WarmupCollision
from . import calls as sumo_calls
from ..model.stepping.batch import PlatoonBatch, collided
from ..model.config import EpisodeConfig
from ..model.controllers import compiled
from ..model.attacks.maneuvers import AttackPlan, lane_changes, maneuver_of
from ..model.stepping.platoon import Platoon, collisions_at
from ..model.stepping.trace import Episode, rows_array

#: episodes go on one at a time once this few are left: the arrays' fixed cost per step then exceeds
#: what they save (measured with tools/bench_batch.py). Episodes the column's loop in C plays (`_Episodes.in_c`)
#: never take the arrays: at 10, 30 and 60 episodes in one SUMO the loop costs 1.0-1.4 times less than they do
DETACH_AT = 4


class _Column:
    """Who follows whom in the paper's column: car i the car i - 1 ahead of it, at the pair's gap."""

    def __init__(self, world, maneuver, names: tuple[str, ...], crash_m: float, recorded: list[list]):
        self.pairs_at, self.names, self.crash_m = maneuver.pairs, names, crash_m

    def sense(self, e: int, x: list, v: list) -> tuple[list, tuple | None]:
        """The pairs an episode's cars form, and what else it sensed (None: nothing)."""
        return self.pairs_at(x), None

    def speeds(self, alone: "_Alone") -> list:
        """The speeds its platoon is commanded from: its own cars'."""
        return alone.v

    def collisions(self, time_s: float, pairs: list, x: list, v: list, sensed) -> tuple:
        return collisions_at(time_s, pairs, x, v, self.names, self.crash_m)


class _Lanes(_Column):
    """Who follows whom where the attacker changes lanes: the pairs of each lane, recorded for the trace."""

    def __init__(self, world, maneuver, names: tuple[str, ...], crash_m: float, recorded: list[list]):
        super().__init__(world, maneuver, names, crash_m, recorded)
        self.lanes, self.recorded = world.lanes, recorded

    def sense(self, e: int, x: list, v: list) -> tuple[list, tuple | None]:
        pairs = self.pairs_at(x, self.lanes(e))
        self.recorded[e].append(pairs)
        return pairs, None


class _Traffic(_Column):
    """Who follows whom among SUMO's traffic: SUMO's leader, a traffic car included (any traffic car recorded
    as one, index n); the pairs index the sensed ids, positions and speeds, the traffic's among them."""

    def __init__(self, world, maneuver, names: tuple[str, ...], crash_m: float, recorded: list[list]):
        super().__init__(world, maneuver, names, crash_m, recorded)
        self.world_sense, self.recorded = world.sense, recorded

    def sense(self, e: int, x: list, v: list) -> tuple[list, tuple | None]:
        pairs, ids_, x_, v_ = self.world_sense(e, x, v)
        self.recorded[e].append(pairs)  # a traffic car's index past the platoon's, made one when the trace is assembled
        return pairs, (ids_, x_, v_)

    def speeds(self, alone: "_Alone") -> list:
        return alone.sensed[2]

    def collisions(self, time_s: float, pairs: list, x: list, v: list, sensed) -> tuple:
        ids_, x_, v_ = sensed
        return collisions_at(time_s, pairs, x_, v_, ids_, self.crash_m)


class _Alone:
    """An episode commanded on its own: its platoon, and its samples as lists from ``start`` on."""

    __slots__ = ("e", "platoon", "ids", "commanded", "start", "xs", "vs", "x", "v", "pairs", "sensed", "rows")

    def __init__(self, e: int, platoon: Platoon, ids: tuple[str, ...], start: int, x: list, v: list, pairs: list,
                 sensed: tuple | None = None):
        self.e, self.platoon, self.ids, self.start = e, platoon, ids, start
        self.commanded = [ids[i] for i in platoon.commanded]  # SUMO moves its own followers
        self.xs, self.vs = [x], [v]
        self.x, self.v, self.pairs = x, v, pairs
        #: with traffic: the ids, positions and speeds the pairs index, the traffic cars in them included
        self.sensed = sensed
        #: played by the column's loop in C (`_Episodes.play_in_c`): its positions and speeds by step, in place of xs and vs
        self.rows: tuple[np.ndarray, np.ndarray] | None = None


class _Episodes:
    """What every mode shares: the world, each episode's configuration and result, and how an episode ends."""

    def __init__(self, world, configs: Sequence[EpisodeConfig], on_episode):
        self.world, self.configs, self.on_episode = world, configs, on_episode
        config = configs[0]
        self.names, self.dt, self.steps = config.vehicle_ids, config.step_s, config.steps
        self.maneuver = maneuver_of(config)
        self.crash_m = config.collision_gap_m  # the same in every episode of a batch (`batch.batch_key`)
        self.end_m = config.end_distance_m  # an episode also ends once its attacker is this far from its start
        m = len(configs)
        self.results: list = [None] * m
        self.recorded: list[list] = [[] for _ in range(m)]  # lane changes and traffic: each sample's pairs
        self.live = set(range(m))
        self.solo: list[_Alone] = []  # the episodes commanded one at a time
        self.arrays: _Arrays | None = None
        self.traffic = getattr(world, "traffic", None) is not None  # who is ahead is SUMO's leader
        self.lights = getattr(world, "lights", None) is not None  # the route's traffic lights, which the platoon obeys
        kind = _Traffic if self.traffic else _Lanes if self.maneuver.lateral else _Column
        self.sensing = kind(world, self.maneuver, self.names, self.crash_m, self.recorded)

    def alone(self, e: int, platoon: Platoon, start: int, x: list, v: list) -> _Alone:
        """Episode e, from sample ``start`` on commanded by its own platoon, from its cars' state (x, v)."""
        pairs, sensed = self.sensing.sense(e, x, v)
        return _Alone(e, platoon, self.world.platoons[e], start, x, v, pairs, sensed)

    def end(self, e: int, steps_done: int, collisions: tuple, error: Exception | None = None) -> None:
        """Episode e ends after ``steps_done`` steps, with its collisions or an error: its result, heard of."""
        self.live.discard(e)
        world = self.world
        if self.live:  # its cars cost the world nothing more
            world.remove(e)
        alone = next((a for a in self.solo if a.e == e), None)
        if alone is not None:
            self.solo = [a for a in self.solo if a.e != e]
        elif self.arrays is not None:
            self.arrays.drop(e)
        if self.arrays is not None:  # as alone: a failure, else an untraceable mode
            error = error or self.arrays.error(e)
        if error is None and collisions and steps_done <= self.configs[e].attack_start_step:
            error = _warmup_collision(self.configs[e], collisions[0])
        lateral_m = world.lateral_rows(e)
        if error is not None:
            self.results[e] = error
        elif alone is not None:
            self.results[e] = self._alone_result(alone, steps_done, collisions, lateral_m)
        else:
            self.results[e] = self.arrays.episode(e, steps_done, collisions, self.recorded[e], lateral_m)
        if self.on_episode:
            self.on_episode(e, self.results[e])

    def _alone_result(self, alone: _Alone, steps_done: int, collisions: tuple, lateral_m) -> "Episode | Exception":
        e, n = alone.e, len(self.names)
        alone.platoon.pairs = self.recorded[e]
        if alone.rows is not None:
            x, v = (rows[alone.start:steps_done + 1] for rows in alone.rows)
        else:
            x, v = rows_array(alone.xs, n), rows_array(alone.vs, n)
        if alone.start:  # carried on from the arrays: the samples before are theirs
            x, v = self.arrays.before(e, alone.start, x, v)
        try:
            trace, min_gaps, warmup_min_gaps = alone.platoon.trace(np.arange(steps_done + 1) * self.dt, x, v, lateral_m)
            among = self.world.traffic_collisions(e) if self.traffic else ()
            return Episode(trace, collisions, min_gaps, warmup_min_gaps, among,
                           self.world.signal_tracks(e) if self.lights else ())
        except Exception as exc:  # a user's controller's mode that is not a number
            return exc

    def in_c(self) -> bool:
        """Whether every episode left goes on in the column's step loop in C (`compiled.play_column`): each alone, in
        the paper's column (no lane change, no traffic lights), its platoon stepped in C, its attacker too."""
        return (compiled.play_column is not None and compiled.ENABLED and type(self.sensing) is _Column
                and not self.lights and bool(self.solo) and all(alone.platoon._attacker_in_c for alone in self.solo))

    def play_in_c(self, k: int) -> None:
        """Steps k to the last of every episode left, in C: as command_alone and sense_alone play them, bit for bit
        (tests/engine/test_loop.py), at a fraction of their cost."""
        steps, n, world = self.steps, len(self.names), self.world
        own_calls = getattr(world, "own_calls", None)  # SUMO's own calls in C (`SumoWorld.own_calls`)
        calls = own_calls() if sumo_calls.NATIVE and own_calls is not None else None
        played = []
        for alone in self.solo:
            platoon = alone.platoon
            alone.rows = np.empty((steps + 1, n)), np.empty((steps + 1, n))
            alone.rows[0][k], alone.rows[1][k] = alone.x, alone.v
            commands = np.empty((steps, len(platoon.commanded)))
            modes = np.empty((steps, len(platoon._with_mode))) if platoon._with_mode else None
            platoon.played_in_c(k, commands, modes)
            played.append((alone.e, platoon._compiled.__self__, alone.ids, tuple(self.maneuver.lengths_m[:-1]),
                           *alone.rows, commands, modes, alone.xs[0][0], calls and world.offsets(alone.e)))
        compiled.play_column(k, steps, world.step, world.set_speed, world.get_position, world.get_speed, played,
                             self._ended_in_c, self.crash_m, float(self.end_m or 0.0), calls)

    def _ended_in_c(self, e: int, steps_done: int, error: Exception | None, collided: bool) -> None:
        """Episode e, played in C, ends after ``steps_done`` steps: at a collision, its end distance or its error."""
        collisions = ()
        if collided:
            alone = next(a for a in self.solo if a.e == e)
            x, v = (rows[steps_done].tolist() for rows in alone.rows)
            collisions = collisions_at(steps_done * self.dt, self.maneuver.pairs(x), x, v, self.names, self.crash_m)
        self.end(e, steps_done, collisions, error)

    def command_alone(self, k: int) -> None:
        """Step k's commands of every episode commanded on its own, applied."""
        world, sensing = self.world, self.sensing
        for alone in self.solo:
            try:
                if self.lights:  # what its drivers see of the lights ahead
                    alone.platoon.stops = world.stops(alone.e, alone.x)
                out = alone.platoon.advance(k, alone.x, sensing.speeds(alone), alone.pairs)
            except Exception as exc:  # a user's controller: as alone, the episode ends with its error
                self.end(alone.e, k, (), exc)
                continue
            for _ in map(world.set_speed, alone.commanded, out):  # map: no Python frame per car
                pass
            if alone.platoon.beacons_for_sumo:  # SUMO's cooperative followers read the channel's beacons too
                world.feed_beacons(alone.ids, alone.platoon.beacons_for_sumo)

    def sense_alone(self, k: int) -> None:
        """After step k, each episode on its own senses its cars, and ends at a collision or its end distance."""
        get_position, get_speed, sensing = self.world.get_position, self.world.get_speed, self.sensing
        time_s = (k + 1) * self.dt
        for alone in self.solo:
            ids = alone.ids
            x, v = list(map(get_position, ids)), list(map(get_speed, ids))
            alone.xs.append(x)
            alone.vs.append(v)
            alone.x, alone.v = x, v
            alone.pairs, alone.sensed = sensing.sense(alone.e, x, v)
            collisions = sensing.collisions(time_s, alone.pairs, x, v, alone.sensed)
            if collisions:
                self.end(alone.e, k + 1, collisions)
            elif self.end_m and x[0] - alone.xs[0][0] >= self.end_m:
                self.end(alone.e, k + 1, ())


class _Arrays:
    """The episodes the batch's arrays command (`batch.PlatoonBatch`): their samples as rows (steps x episodes x
    cars), who follows whom in each, and the ids of the cars they sense and command."""

    def __init__(self, episodes: _Episodes, plans: Sequence[AttackPlan]):
        self.episodes = episodes
        world, configs = episodes.world, episodes.configs
        m, n, steps = len(plans), len(episodes.names), episodes.steps
        self.m = m
        self.batch = PlatoonBatch(configs, np.array([p.u for p in plans]), attacker_max_speed_mps=world.attacker_max_speed_mps)
        self.arrayed = list(range(m))  # still commanded by the batch's arrays
        self.active = np.ones(m, dtype=bool)
        self.commanded_ids = [[ids[i] for i in self.batch.commanded] for ids in world.platoons]
        self.rows_x = np.zeros((steps + 1, m, n))  # an ended episode's rows stay 0: computed along, never used
        self.rows_v = np.zeros_like(self.rows_x)
        self._ids()
        self.rows_x[0] = _read(world.get_position, self.sensed).reshape(m, n)
        self.rows_v[0] = _read(world.get_speed, self.sensed).reshape(m, n)
        self.lateral = episodes.maneuver.lateral
        self.pairs = ([episodes.sensing.sense(e, self.rows_x[0, e].tolist(), None)[0] for e in range(m)]
                      if self.lateral else None)
        self.lead, self.gap = self.batch.leaders(self.rows_x[0], self.pairs)

    def _ids(self) -> None:
        platoons = self.episodes.world.platoons
        self.sensed = [vid for i in self.arrayed for vid in platoons[i]]
        self.commanding = [vid for i in self.arrayed for vid in self.commanded_ids[i]]  # the cars Python commands

    def drop(self, e: int) -> None:
        """Episode e ended: the arrays command it no more."""
        if e in self.arrayed:
            self.arrayed.remove(e)
            self.active[e] = False
            self._ids()

    def error(self, e: int) -> Exception | None:
        return self.batch.failed.get(e) or self.batch.bad_modes.get(e)

    def episode(self, e: int, steps_done: int, collisions: tuple, recorded: list, lateral_m) -> Episode:
        return self.batch.episode(e, steps_done, self.rows_x[:steps_done + 1, e], self.rows_v[:steps_done + 1, e],
                                  collisions, recorded if self.lateral else None, lateral_m)

    def before(self, e: int, start: int, x: np.ndarray, v: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Episode e's samples before ``start`` (the arrays'), then ``x`` and ``v`` (its own, alone)."""
        return np.concatenate([self.rows_x[:start, e], x]), np.concatenate([self.rows_v[:start, e], v])

    def detach(self, k: int) -> list[_Alone]:
        """Every episode the arrays command goes on alone from sample k, in the state it has."""
        episodes, pairs_at = self.episodes, self.episodes.maneuver.pairs
        out = []
        for e in self.arrayed:
            x, v = self.rows_x[k, e].tolist(), self.rows_v[k, e].tolist()
            out.append(_Alone(e, self.batch.detach(e, k), episodes.world.platoons[e], k, x, v,
                              self.pairs[e] if self.lateral else pairs_at(x)))
            self.active[e] = False
        self.arrayed = []
        self._ids()
        return out

    def command(self, k: int) -> None:
        """Step k's commands of every episode the arrays command, applied (a user's controller that failed ends its episode)."""
        speeds = self.batch.advance(k, self.rows_x[k], self.rows_v[k], self.lead, self.gap, self.active)
        for e in sorted(self.batch.failed.keys() & set(self.arrayed)):  # it ends with its error
            self.episodes.end(e, k, ())
        arrayed = self.arrayed
        for _ in map(self.episodes.world.set_speed, self.commanding,
                     (speeds if len(arrayed) == self.m else speeds[arrayed]).ravel().tolist()):
            pass

    def sense(self, k: int) -> None:
        """After step k: the rows, who follows whom, and the episodes that collided end."""
        episodes, arrayed = self.episodes, self.arrayed
        world, n = episodes.world, len(episodes.names)
        if len(arrayed) == self.m:
            self.rows_x[k + 1] = _read(world.get_position, self.sensed).reshape(self.m, n)
            self.rows_v[k + 1] = _read(world.get_speed, self.sensed).reshape(self.m, n)
        else:
            self.rows_x[k + 1, arrayed] = _read(world.get_position, self.sensed).reshape(len(arrayed), n)
            self.rows_v[k + 1, arrayed] = _read(world.get_speed, self.sensed).reshape(len(arrayed), n)
        if self.lateral:
            self.pairs = [episodes.sensing.sense(e, self.rows_x[k + 1, e].tolist(), None)[0] if e in arrayed else None
                          for e in range(self.m)]
        self.lead, self.gap = self.batch.leaders(self.rows_x[k + 1], self.pairs)
        hit = collided(self.gap, episodes.crash_m)
        if np.count_nonzero(hit):
            time_s, names, pairs_at = (k + 1) * episodes.dt, episodes.names, episodes.maneuver.pairs
            for e in [e for e in arrayed if hit[e]]:
                x, v = self.rows_x[k + 1, e].tolist(), self.rows_v[k + 1, e].tolist()
                episodes.end(e, k + 1, collisions_at(time_s, self.pairs[e] if self.lateral else pairs_at(x), x, v, names,
                                                     episodes.crash_m))


def play(world, configs: Sequence[EpisodeConfig], plans: Sequence[AttackPlan], *,
         on_episode: Callable[[int, "Episode | Exception"], None] | None = None,
         detach_at: int | None = None, detach_at_step: int | None = None) -> list["Episode | Exception"]:
    """Play one episode per plan in ``world`` (its platoons inserted, t = 0), each with its own
    configuration (all of one `batch.batch_key`); every result is the episode, or the exception a
    user's follower controller raised in it. ``on_episode(e, result)`` hears of each as it ends.
    ``detach_at``: the arrays command while more than this many are left (0: to the end; None: `DETACH_AT`, or
    never where the episodes would go on in the column's loop in C);
    ``detach_at_step``: from this step on, every episode goes on alone (tests of the array laws)."""
    episodes = _Episodes(world, configs, on_episode)
    config, m = configs[0], len(plans)
    if detach_at is None:
        detach_at = DETACH_AT
        if (m > DETACH_AT and config.batch_arrays and all(p.motion is None for p in plans) and not episodes.lights
                and type(episodes.sensing) is _Column and compiled.play_column is not None  # would they go on in C? (asked
                and all(c.cls in ("switching", "timegap", "idm") or c.sumo_model for c in config.controllers)):  # of d4sumo's laws)
            if Platoon(config, plans[0].u, world.attacker_max_speed_mps, beacons=plans[0].beacons)._attacker_in_c:
                detach_at = m
    changes: dict[int, list[tuple[int, int]]] = {}  # step -> (episode, the lane its attacker changes to)
    for e, plan in enumerate(plans):
        for k, lane in lane_changes(plan, episodes.maneuver):
            changes.setdefault(k, []).append((e, lane))
    if (m > detach_at and detach_at_step != 0 and config.batch_arrays and not episodes.lights  # the arrays play the model
            and all(p.motion is None for p in plans)):  # as printed, with the attacker's pedals
        arrays = episodes.arrays = _Arrays(episodes, plans)
    else:
        arrays = None
        for e, (c, plan, ids) in enumerate(zip(configs, plans, world.platoons)):
            x, v = [world.get_position(vid) for vid in ids], [world.get_speed(vid) for vid in ids]
            platoon = Platoon(c, plan.u, world.attacker_max_speed_mps, beacons=plan.beacons, motion=plan.motion,
                              lights=episodes.lights)
            episodes.solo.append(episodes.alone(e, platoon, 0, x, v))
    live = episodes.live
    in_c = not changes  # the episodes left may go on in C, once none is the arrays' (`_Episodes.in_c`)
    for k in range(config.steps):
        if arrays is not None and arrays.arrayed and (len(arrays.arrayed) <= detach_at or k == detach_at_step):
            episodes.solo = sorted(episodes.solo + arrays.detach(k), key=lambda a: a.e)
        if in_c and (arrays is None or not arrays.arrayed):
            in_c = episodes.in_c()
            if in_c:
                episodes.play_in_c(k)
                break
        for e, lane in changes.get(k, ()):
            if e in live:
                world.change_lane(e, lane)
        if arrays is not None and arrays.arrayed:
            arrays.command(k)
        episodes.command_alone(k)
        if not live:
            break
        world.step()
        episodes.sense_alone(k)
        if arrays is not None and arrays.arrayed:
            arrays.sense(k)
        if not live:
            break
    for e in sorted(live):
        episodes.end(e, config.steps, ())
    # The arrays and the episodes hold each other: left so, a batch's traces would wait for Python's cycle
    # collector, and a sweep worker would hold 15 MiB more a batch until it ran (tests/engine/test_simulation.py)
    episodes.arrays = None
    return episodes.results


def _read(getter: Callable[[str], float], ids: list[str]) -> np.ndarray:
    """Each car's value, as np.array([getter(vid) for vid in ids]) does, without a Python frame per car."""
    return np.fromiter(map(getter, ids), dtype=float, count=len(ids))


def _warmup_collision(config: EpisodeConfig, collision) -> WarmupCollision:
    """A collision before the attack's first command acted (the step counts say, not the clock): the
    platoon's own, on this road and from rest, which no attack caused."""
    return WarmupCollision(
        f"{collision.pair} collided at {collision.time_s:.2f} s, in the warm-up before the attack (from "
        f"{config.attack_start_s:g} s): the platoon crashes on {config.network} with no attack at all")
