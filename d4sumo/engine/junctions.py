"""Collisions inside junctions, in 2D: a car of the platoon and a vehicle crossing, merging or turning
across its way meet on lanes that are not each other's, where no leader or follower SUMO names sees them.

Along a route of several edges, each junction between two of its edges covers a stretch of the route
(the platoon's lanes' junction lanes). While a platoon car's body is within `NEAR_M` of that stretch, the
vehicles in the junction (on its internal lanes, and on the lanes into and out of it next to it) are its
foes: each one's body (`bodies.Body`: SUMO's position, heading, length and width, as the FCD writes them)
against the car's. A foe whose clearance is below the collision gap is a pair of the step (the one that
ran into the other as the follower, `bodies.struck_by`), its gap that clearance: the collision check,
the minimum gaps and the specification read it as any other pair, so the verdict counts it as on a lane.
Only such a pair is added: an episode ends at its first collision, so no controller ever acts on one, and
an episode without one is what it was without this check, bit for bit.
"""

from __future__ import annotations

import math

from ..model.world.bodies import Body, body_gap_m, struck_by
from ..model.attacks.maneuvers import Pair
from .calls import api_call, route_junctions

#: how far before and after a junction's stretch of the route a car's body is looked at [m]
NEAR_M = 5.0
#: a vehicle on a lane out of a junction with its rear this near the lane's start may still reach into it [m]
#: (one on a lane into it has its whole body behind the stop line)
EDGE_M = 2.0


class JunctionCrossings:
    """The 2D collisions of one platoon's cars inside the junctions of its route (see the module)."""

    def __init__(self, api, route: tuple[str, ...], path: tuple[int, ...], ids: tuple[str, ...], collision_gap_m: float):
        self.api, self.ids, self.crash_m = api, ids, collision_gap_m
        self.platoon = set(ids)
        self.lengths = [api.vehicle.getLength(vid) for vid in ids]
        #: (start, end, internal lanes, lanes out of it) of each junction along the route
        self.spans: list[tuple[float, float, list[str], list[str]]] = []
        for edge, _, _, along, length in route_junctions(api, route, path):
            junction = api.edge.getToJunction(edge)
            edges_in, edges_out = api.junction.getIncomingEdges(junction), api.junction.getOutgoingEdges(junction)
            internal = sorted({e for e in (*edges_in, *edges_out) if e.startswith(":")})
            lanes = lambda edges: [f"{e}_{i}" for e in edges for i in range(api.edge.getLaneNumber(e))]  # noqa: E731
            self.spans.append((along - NEAR_M, along + length + NEAR_M, lanes(internal),
                               lanes([e for e in edges_out if not e.startswith(":")])))
        self.next = [0] * len(ids)  # each car's next junction: cars never drive backwards
        self.started = False
        vehicle = lambda name: api_call(api, "vehicle", name)  # noqa: E731
        self.get_position, self.get_angle, self.get_width = vehicle("getPosition"), vehicle("getAngle"), vehicle("getWidth")
        self.get_length, self.get_lane_position, self.get_speed = vehicle("getLength"), vehicle("getLanePosition"), vehicle("getSpeed")
        self.on_lane = api_call(api, "lane", "getLastStepVehicleIDs")
        self.sizes: dict[str, tuple[float, float]] = {}

    def __call__(self, x: list[float], pairs: list[Pair], names: list[str], xs: list[float], vs: list[float]) -> list[Pair]:
        """The step's 2D collisions of the platoon's cars at positions ``x`` along the route; a foe not yet
        among ``names`` (the step's ids, positions and speeds that pairs index) is added to them. None at the
        platoon's insertion (t = 0): its pairs reach the controllers before any collision check, and a car
        placed onto another is seen a step later, before anyone acts on it."""
        if not self.started:
            self.started = True
            return []
        spans, found = self.spans, []
        foes_of: dict[int, list[str]] = {}
        for b, front in enumerate(x):
            j, rear = self.next[b], front - self.lengths[b]
            while j < len(spans) and rear >= spans[j][1]:
                j += 1
            self.next[b] = j
            if j == len(spans) or front <= spans[j][0]:
                continue
            if j not in foes_of:
                foes_of[j] = self._foes(spans[j])
            if foes_of[j]:
                found.extend(self._collisions(b, foes_of[j], x, pairs, names, xs, vs))
        return found

    def _foes(self, span) -> list[tuple[str, tuple[float, float]]]:
        """The vehicles, none of the platoon's, in a junction or reaching into it, each with its front bumper's position."""
        _, _, internal, lanes_out = span
        on_lane, position, length = self.on_lane, self.get_lane_position, self.get_length
        foes = [v for lane in internal for v in on_lane(lane)]
        for lane in lanes_out:
            foes += [v for v in on_lane(lane) if position(v) - length(v) < EDGE_M]
        return [(v, self.get_position(v)) for v in sorted(set(foes) - self.platoon)]

    def _size(self, vid: str) -> tuple[float, float]:
        """A vehicle's length and width [m] (read once: nothing changes them during an episode)."""
        if vid not in self.sizes:
            self.sizes[vid] = (self.get_length(vid), self.get_width(vid))
        return self.sizes[vid]

    def _body(self, vid: str, front: tuple[float, float] | None = None) -> Body:
        x, y = front or self.get_position(vid)
        return Body(x, y, self.get_angle(vid), *self._size(vid))

    def _collisions(self, b: int, foes: list[str], x: list[float], pairs: list[Pair], names: list[str],
                    xs: list[float], vs: list[float]) -> list[Pair]:
        paired = {names[a] for a, c, _ in pairs if c == b} | {names[c] for a, c, _ in pairs if a == b}  # on a lane: its gap counts
        mine, found = self._body(self.ids[b]), []
        for foe, (fx, fy) in foes:
            if foe in paired:
                continue
            # front bumpers farther apart than both bodies' length and width: the bodies cannot touch
            if math.hypot(fx - mine.x_m, fy - mine.y_m) > mine.length_m + mine.width_m + sum(self._size(foe)) + self.crash_m:
                continue
            theirs = self._body(foe, (fx, fy))
            gap = body_gap_m(mine, theirs)
            if gap >= self.crash_m:
                continue
            if foe not in names:  # at the platoon car's place along the route: where the collision is recorded
                names.append(foe)
                xs.append(x[b])
                vs.append(self.get_speed(foe))
            t = names.index(foe)
            found.append((b, t, gap) if struck_by(mine, theirs) == 1 else (t, b, gap))
        return found
