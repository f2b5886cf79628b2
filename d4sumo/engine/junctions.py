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

from ..model.bodies import Body, body_gap_m, struck_by
from ..model.maneuvers import Pair

#: how far before and after a junction's stretch of the route a car's body is looked at [m]
NEAR_M = 5.0
#: a vehicle on a lane into a junction this near its end, or on a lane out of it with its rear this near
#: its start, may reach into the junction [m]
EDGE_M = 2.0


def _via_length(api, lane: str, to_lane: str) -> float:
    """The length of the junction lanes from ``lane`` to ``to_lane`` [m] (0: no junction lane between them)."""
    length, seen = 0.0, 0
    while seen < 8:  # a junction lane may lead through an internal junction to a second one
        seen += 1
        link = next((ln for ln in api.lane.getLinks(lane) if ln[0] == to_lane), None)
        if link is None or not link[4]:
            return length
        lane = link[4]
        length += api.lane.getLength(lane)
    return length


class JunctionCrossings:
    """The 2D collisions of one platoon's cars inside the junctions of its route (see the module)."""

    def __init__(self, api, route: tuple[str, ...], path: tuple[int, ...], ids: tuple[str, ...], collision_gap_m: float):
        self.api, self.ids, self.crash_m = api, ids, collision_gap_m
        self.platoon = set(ids)
        self.lengths = [api.vehicle.getLength(vid) for vid in ids]
        #: (start, end, internal lanes, lanes into it, lanes out of it) of each junction along the route
        self.spans: list[tuple[float, float, list[str], list[str], list[str]]] = []
        along = 0.0
        for k, (edge, to) in enumerate(zip(route, route[1:])):
            lane, to_lane = f"{edge}_{path[k]}", f"{to}_{path[k + 1]}"
            along += api.lane.getLength(lane)
            length = _via_length(api, lane, to_lane)
            junction = api.edge.getToJunction(edge)
            edges_in, edges_out = api.junction.getIncomingEdges(junction), api.junction.getOutgoingEdges(junction)
            internal = sorted({e for e in (*edges_in, *edges_out) if e.startswith(":")})
            lanes = lambda edges: [f"{e}_{i}" for e in edges for i in range(api.edge.getLaneNumber(e))]  # noqa: E731
            self.spans.append((along - NEAR_M, along + length + NEAR_M, lanes(internal),
                               lanes([e for e in edges_in if not e.startswith(":")]),
                               lanes([e for e in edges_out if not e.startswith(":")])))
            along += length
        self.next = [0] * len(ids)  # each car's next junction: cars never drive backwards
        self.get_position, self.get_angle = api.vehicle.getPosition, api.vehicle.getAngle
        self.get_width, self.get_length = api.vehicle.getWidth, api.vehicle.getLength

    def __call__(self, x: list[float], pairs: list[Pair], names: list[str], xs: list[float], vs: list[float]) -> list[Pair]:
        """The step's 2D collisions of the platoon's cars at positions ``x`` along the route; a foe not yet
        among ``names`` (the step's ids, positions and speeds that pairs index) is added to them."""
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

    def _foes(self, span) -> list[str]:
        """The vehicles, none of the platoon's, in a junction or reaching into it."""
        api = self.api
        _, _, internal, lanes_in, lanes_out = span
        foes = [v for lane in internal for v in api.lane.getLastStepVehicleIDs(lane)]
        for lane in lanes_in:
            end = api.lane.getLength(lane) - EDGE_M
            foes += [v for v in api.lane.getLastStepVehicleIDs(lane) if api.vehicle.getLanePosition(v) > end]
        for lane in lanes_out:
            foes += [v for v in api.lane.getLastStepVehicleIDs(lane)
                     if api.vehicle.getLanePosition(v) - api.vehicle.getLength(v) < EDGE_M]
        return sorted(set(foes) - self.platoon)

    def _body(self, vid: str) -> Body:
        x, y = self.get_position(vid)
        return Body(x, y, self.get_angle(vid), self.get_length(vid), self.get_width(vid))

    def _collisions(self, b: int, foes: list[str], x: list[float], pairs: list[Pair], names: list[str],
                    xs: list[float], vs: list[float]) -> list[Pair]:
        paired = {names[a] for a, c, _ in pairs if c == b} | {names[c] for a, c, _ in pairs if a == b}  # on a lane: its gap counts
        mine, found = None, []
        for foe in foes:
            if foe in paired:
                continue
            theirs = self._body(foe)
            mine = mine or self._body(self.ids[b])
            reach = mine.length_m + mine.width_m + theirs.length_m + theirs.width_m + self.crash_m
            if math.hypot(theirs.x_m - mine.x_m, theirs.y_m - mine.y_m) > reach:
                continue  # too far apart to touch: no need to measure
            gap = body_gap_m(mine, theirs)
            if gap >= self.crash_m:
                continue
            if foe not in names:  # at the platoon car's place along the route: where the collision is recorded
                names.append(foe)
                xs.append(x[b])
                vs.append(self.api.vehicle.getSpeed(foe))
            t = names.index(foe)
            found.append((b, t, gap) if struck_by(mine, theirs) == 1 else (t, b, gap))
        return found
