"""The one step loop: every episode d4sumo plays, alone or side by side, in SUMO or in the SUMO-free
ballistic world, is played by `play`.

Each step: command (from the sensed state and who follows whom) -> apply the speeds -> step the world
-> sense -> pairs -> collide -> end. The world is the seam (`engine.sumo.SumoWorld`,
`engine.ballistic.BallisticWorld`): each episode's vehicle ids, ``get_position``, ``get_speed``,
``set_speed``, ``step``, ``remove`` (and ``lanes``, ``change_lane``, ``lateral_rows`` for maneuvers
that change lanes). Many episodes are commanded by the batch's arrays (`batch.PlatoonBatch`) while
more than `DETACH_AT` are left; fewer, each by its own `platoon.Platoon`, over plain lists. That is
the only place where batched and alone differ, and each episode is bit for bit the same either way.
"""

from __future__ import annotations

from typing import Callable, Sequence

import numpy as np

from ..errors import WarmupCollision
from ..model.batch import PlatoonBatch, collided
from ..model.config import EpisodeConfig
from ..model.maneuvers import AttackPlan, lane_changes, maneuver_of
from ..model.platoon import Platoon, collisions_at
from ..model.trace import Episode, rows_array

#: episodes go on one at a time once this few are left: the arrays' fixed cost per step then exceeds
#: what they save (measured with tools/bench_batch.py)
DETACH_AT = 4


class _Alone:
    """An episode commanded on its own: its platoon, and its samples as lists from ``start`` on."""

    __slots__ = ("e", "platoon", "ids", "commanded", "start", "xs", "vs", "x", "v", "pairs", "sensed")

    def __init__(self, e: int, platoon: Platoon, ids: tuple[str, ...], start: int, x: list, v: list, pairs: list,
                 sensed: tuple | None = None):
        self.e, self.platoon, self.ids, self.start = e, platoon, ids, start
        self.commanded = [ids[i] for i in platoon.commanded]  # SUMO moves its own followers
        self.xs, self.vs = [x], [v]
        self.x, self.v, self.pairs = x, v, pairs
        #: with traffic: the ids, positions and speeds the pairs index, the traffic cars in them included
        self.sensed = sensed


def play(world, configs: Sequence[EpisodeConfig], plans: Sequence[AttackPlan], *,
         on_episode: Callable[[int, "Episode | Exception"], None] | None = None,
         detach_at: int = DETACH_AT, detach_at_step: int | None = None) -> list["Episode | Exception"]:
    """Play one episode per plan in ``world`` (its platoons inserted, t = 0), each with its own
    configuration (all of one `batch.batch_key`); every result is the episode, or the exception a
    user's follower controller raised in it. ``on_episode(e, result)`` hears of each as it ends.
    ``detach_at``: the arrays command while more than this many are left (0: to the end);
    ``detach_at_step``: from this step on, every episode goes on alone (tests of the array laws)."""
    m = len(plans)
    config = configs[0]
    names, dt, steps = config.vehicle_ids, config.step_s, config.steps
    n = len(names)
    maneuver = maneuver_of(config)
    pairs_at = maneuver.pairs
    lateral = maneuver.lateral
    get_position, get_speed, set_speed, world_step = world.get_position, world.get_speed, world.set_speed, world.step
    platoons = world.platoons
    max_speed = world.attacker_max_speed_mps
    results: list = [None] * m
    recorded: list[list] = [[] for _ in range(m)]  # lane-changing maneuvers: each sample's pairs
    changes: dict[int, list[tuple[int, int]]] = {}  # step -> (episode, the lane its attacker changes to)
    for e, plan in enumerate(plans):
        for k, lane in lane_changes(plan, maneuver):
            changes.setdefault(k, []).append((e, lane))
    live = set(range(m))
    solo: list[_Alone] = []  # the episodes commanded one at a time

    def sense_pairs(e: int, x: list):
        pairs = pairs_at(x, world.lanes(e)) if lateral else pairs_at(x)
        if lateral:
            recorded[e].append(pairs)
        return pairs

    traffic = getattr(world, "traffic", None) is not None  # who is ahead is SUMO's leader, a traffic car included

    def sense_traffic(e: int, x: list, v: list) -> tuple[list, tuple]:
        pairs, ids_, x_, v_ = world.sense(e, x, v)
        recorded[e].append([(min(a, n), min(b, n), gap) for a, b, gap in pairs])  # any traffic car as one: index n
        return pairs, (ids_, x_, v_)

    lights = getattr(world, "lights", None) is not None  # the route's traffic lights, which the platoon obeys
    batch = None
    end_m = config.end_distance_m  # an episode also ends once its attacker is this far from its start
    crash_m = config.collision_gap_m  # the same in every episode of a batch (`batch.batch_key`)
    if (m > detach_at and detach_at_step != 0 and config.batch_arrays and not lights  # the arrays play the model as printed ...
            and all(p.motion is None for p in plans)):  # ... with the attacker's pedals
        batch = PlatoonBatch(configs, np.array([p.u for p in plans]), attacker_max_speed_mps=max_speed)
        arrayed = list(range(m))  # still commanded by the batch's arrays
        active = np.ones(m, dtype=bool)
        commanded_ids = [[ids[i] for i in batch.commanded] for ids in platoons]
        rows_x = np.zeros((steps + 1, m, n))  # an ended episode's rows stay 0: computed along, never used
        rows_v = np.zeros_like(rows_x)
        sensed = [vid for ids in platoons for vid in ids]
        commanding = [vid for ids in commanded_ids for vid in ids]  # the arrayed episodes' cars Python commands
        rows_x[0] = _read(get_position, sensed).reshape(m, n)
        rows_v[0] = _read(get_speed, sensed).reshape(m, n)
        pairs = [sense_pairs(e, rows_x[0, e].tolist()) for e in range(m)] if lateral else None
        lead, gap = batch.leaders(rows_x[0], pairs)
    else:
        arrayed = []
        for e, (c, plan, ids) in enumerate(zip(configs, plans, platoons)):
            x, v = [get_position(vid) for vid in ids], [get_speed(vid) for vid in ids]
            pairs, sensed = sense_traffic(e, x, v) if traffic else (sense_pairs(e, x), None)
            solo.append(_Alone(e, Platoon(c, plan.u, max_speed, beacons=plan.beacons, motion=plan.motion, lights=lights),
                               ids, 0, x, v, pairs, sensed))

    def end(e: int, steps_done: int, collisions: tuple, error: Exception | None = None) -> None:
        nonlocal solo, sensed, commanding
        live.discard(e)
        if live:  # its cars cost the world nothing more
            world.remove(e)
        alone = next((a for a in solo if a.e == e), None)
        if alone is not None:
            solo = [a for a in solo if a.e != e]
        elif e in arrayed:
            arrayed.remove(e)
            active[e] = False
            sensed = [vid for i in arrayed for vid in platoons[i]]
            commanding = [vid for i in arrayed for vid in commanded_ids[i]]
        if batch is not None:  # as alone: a failure, else an untraceable mode
            error = error or batch.failed.get(e) or batch.bad_modes.get(e)
        if error is None and collisions and steps_done <= configs[e].attack_start_step:
            error = _warmup_collision(configs[e], collisions[0])
        lateral_m = world.lateral_rows(e)
        if error is not None:
            results[e] = error
        elif alone is not None:
            alone.platoon.pairs = recorded[e]
            x, v = rows_array(alone.xs, n), rows_array(alone.vs, n)
            if alone.start:  # carried on from the arrays: the samples before are theirs
                x = np.concatenate([rows_x[:alone.start, e], x])
                v = np.concatenate([rows_v[:alone.start, e], v])
            try:
                trace, min_gaps, warmup_min_gaps = alone.platoon.trace(np.arange(steps_done + 1) * dt, x, v, lateral_m)
                among = world.traffic_collisions(e) if traffic else ()
                results[e] = Episode(trace, collisions, min_gaps, warmup_min_gaps, among,
                                     world.signal_tracks(e) if lights else ())
            except Exception as exc:  # a user's controller's mode that is not a number
                results[e] = exc
        else:
            results[e] = batch.episode(e, steps_done, rows_x[:steps_done + 1, e], rows_v[:steps_done + 1, e],
                                       collisions, recorded[e] if lateral else None, lateral_m)
        if on_episode:
            on_episode(e, results[e])

    def detach(k: int) -> None:
        """Every episode the arrays command goes on alone from sample k, in the state it has."""
        nonlocal arrayed, sensed, commanding
        for e in arrayed:
            x, v = rows_x[k, e].tolist(), rows_v[k, e].tolist()
            solo.append(_Alone(e, batch.detach(e, k), platoons[e], k, x, v, pairs[e] if lateral else pairs_at(x)))
            active[e] = False
        solo.sort(key=lambda a: a.e)
        arrayed, sensed, commanding = [], [], []

    for k in range(steps):
        if arrayed and (len(arrayed) <= detach_at or k == detach_at_step):
            detach(k)
        for e, lane in changes.get(k, ()):
            if e in live:
                world.change_lane(e, lane)
        if arrayed:
            speeds = batch.advance(k, rows_x[k], rows_v[k], lead, gap, active)
            for e in sorted(batch.failed.keys() & set(arrayed)):  # a user's controller failed: it ends with its error
                end(e, k, ())
            for _ in map(set_speed, commanding, (speeds if len(arrayed) == m else speeds[arrayed]).ravel().tolist()):
                pass
        for alone in solo:
            try:
                if lights:  # what its drivers see of the lights ahead
                    alone.platoon.stops = world.stops(alone.e, alone.x)
                out = alone.platoon.advance(k, alone.x, alone.sensed[2] if traffic else alone.v, alone.pairs)
            except Exception as exc:  # a user's controller: as alone, the episode ends with its error
                end(alone.e, k, (), exc)
                continue
            for _ in map(set_speed, alone.commanded, out):  # map: no Python frame per car
                pass
            if alone.platoon.beacons_for_sumo:  # SUMO's cooperative followers read the channel's beacons too
                world.feed_beacons(alone.ids, alone.platoon.beacons_for_sumo)
        if not live:
            break
        world_step()
        time_s = (k + 1) * dt
        for alone in solo:
            ids = alone.ids
            x, v = list(map(get_position, ids)), list(map(get_speed, ids))
            alone.xs.append(x)
            alone.vs.append(v)
            alone.x, alone.v = x, v
            if traffic:
                alone.pairs, alone.sensed = pairs, (ids_, x_, v_) = sense_traffic(alone.e, x, v)
                collisions = collisions_at(time_s, pairs, x_, v_, ids_, crash_m)
            else:
                alone.pairs = pairs = sense_pairs(alone.e, x) if lateral else pairs_at(x)
                collisions = collisions_at(time_s, pairs, x, v, names, crash_m)
            if collisions:
                end(alone.e, k + 1, collisions)
            elif end_m and x[0] - alone.xs[0][0] >= end_m:
                end(alone.e, k + 1, ())
        if arrayed:
            if len(arrayed) == m:
                rows_x[k + 1] = _read(get_position, sensed).reshape(m, n)
                rows_v[k + 1] = _read(get_speed, sensed).reshape(m, n)
            else:
                rows_x[k + 1, arrayed] = _read(get_position, sensed).reshape(len(arrayed), n)
                rows_v[k + 1, arrayed] = _read(get_speed, sensed).reshape(len(arrayed), n)
            if lateral:
                pairs = [sense_pairs(e, rows_x[k + 1, e].tolist()) if e in arrayed else None for e in range(m)]
            lead, gap = batch.leaders(rows_x[k + 1], pairs)
            hit = collided(gap, crash_m)
            if np.count_nonzero(hit):
                for e in [e for e in arrayed if hit[e]]:
                    x, v = rows_x[k + 1, e].tolist(), rows_v[k + 1, e].tolist()
                    end(e, k + 1, collisions_at(time_s, pairs[e] if lateral else pairs_at(x), x, v, names, crash_m))
        if not live:
            break
    for e in sorted(live):
        end(e, steps, ())
    return results


def _read(getter: Callable[[str], float], ids: list[str]) -> np.ndarray:
    """Each car's value, as np.array([getter(vid) for vid in ids]) does, without a Python frame per car."""
    return np.fromiter(map(getter, ids), dtype=float, count=len(ids))


def _warmup_collision(config: EpisodeConfig, collision) -> WarmupCollision:
    """A collision before the attack's first command acted (the step counts say, not the clock): the
    platoon's own, on this road and from rest, which no attack caused."""
    return WarmupCollision(
        f"{collision.pair} collided at {collision.time_s:.2f} s, in the warm-up before the attack (from "
        f"{config.attack_start_s:g} s): the platoon crashes on {config.network} with no attack at all")
