"""A built network as the platoon drives it: the straight chain of edges from its one start, its length,
its lowest speed limit, and, for each lane of the first edge that leads on through every junction, the
platoon's corridor from it: the lane it is in on each edge (an on-ramp adds a lane on the right and an
exit or lane drop takes one away, so its index changes along the route as SUMO's connections say), the
lanes beside it that lead on with it, whether they are as long and as wide as each other, and which
vehicle classes each closes to. What no platoon can drive (branches, no lane that leads on, speed
limits that are no numbers) is refused naming scenario.network."""

from __future__ import annotations

import math
from pathlib import Path

from ..errors import ConfigError
from ..model.world.vehicle import VEHICLE_CLASSES

#: the version of a road's description: a cached one of another is described again
LAYOUT = 3
OR_ROUTE = ", or a scenario.route"  # the end of a refusal that a route settles (one given: it does not lead on)


def describe(net_file: Path, name: str, route: tuple[str, ...] = ()) -> dict:
    """The straight chain of edges from the road's start (or the ``route``'s edges through a network of
    many ways, kept whole for the traffic on them), its length, and the corridor from each lane of its
    first edge that leads on through it (refusals name the network ``name``)."""
    import sumolib

    net = sumolib.net.readNet(str(net_file))
    chain = _route_chain(net, route) if route else _one_chain(net, name)
    for lane in (lane for e in chain for lane in e.getLanes()):  # netconvert keeps "nan" and "inf"; SUMO refuses them
        if not 0 < lane.getSpeed() < math.inf:
            raise ConfigError("scenario.network", name,
                              f"speed limits that are positive numbers of m/s (lane {lane.getID()}: {lane.getSpeed()})")
    reach = _reach(chain)
    paths = [lane_path(chain, i, reach) for i in range(chain[0].getLaneNumber())]
    through = [path for path in paths if len(path) == len(chain)]
    if not through:
        furthest = max(range(len(paths)), key=lambda i: (len(paths[i]), -i))
        end = chain[len(paths[furthest]) - 1]
        raise ConfigError("scenario.network", name,
                          f"a road with a lane that leads on through every junction (none of {chain[0].getID()}'s does: the "
                          f"furthest, lane {furthest}, ends on {end.getID()} as lane {paths[furthest][-1]}); "
                          f"{_longest_piece(chain, reach)}")
    corridors = {str(path[0]): _corridor(net_file, chain, path) for path in through}
    return {
        "layout": LAYOUT,
        "route_edges": [e.getID() for e in chain],
        "length_m": sum(e.getLength() for e in chain),
        "first_edge_m": chain[0].getLength(),
        "platoon_lane": through[0][0],  # the rightmost lane that leads on: the platoon's unless scenario.lane says
        "corridors": corridors,
    }


def _one_chain(net, name: str) -> list:
    """The network's one straight chain of edges from its one start."""
    edges = [e for e in net.getEdges() if e.getFunction() != "internal"]
    starts = [e for e in edges if not e.getIncoming()]
    if len(starts) != 1:
        raise ConfigError("scenario.network", name,
                          f"a network with exactly one road start (a straight one-way chain of edges){OR_ROUTE}")
    chain = [starts[0]]
    while True:
        nxt = list(chain[-1].getOutgoing())
        if not nxt:
            break
        if len(nxt) > 1 or nxt[0] in chain:
            raise ConfigError("scenario.network", name,
                              f"a straight chain of edges without branches{OR_ROUTE}")
        chain.append(nxt[0])
    return chain


def _route_chain(net, route: tuple[str, ...]) -> list:
    """The route's edges in a network of many ways, each leading on to the next."""
    chain = []
    for edge_id in route:
        if not net.hasEdge(edge_id):
            raise ConfigError("scenario.route", list(route), f"edges of the network (it has no edge {edge_id!r})")
        edge = net.getEdge(edge_id)
        if chain and edge not in chain[-1].getOutgoing():
            raise ConfigError("scenario.route", list(route), f"edges that lead on one to the next ({chain[-1].getID()} "
                                                             f"does not lead on to {edge_id})")
        chain.append(edge)
    return chain


def _corridor(net_file: Path, chain, path: list[int]) -> dict:
    """The platoon's corridor from the first edge's lane ``path[0]``: its lane on each edge, the lanes
    (as offsets from it, 0 the platoon's, 1 the one to its left, ..) that lead on beside it, the route's
    lowest speed limit, whether the lanes are even, their widths, and the classes each closes to."""
    lanes = _lanes_beside(chain, path)
    in_corridor = [e.getLanes()[p + j] for e, p in zip(chain, path) for j in range(lanes)]
    return {
        "lane_path": path,
        "lanes": lanes,
        # a junction where the platoon's lane joins several of the next edge's: SUMO picks one looking ahead a
        # limited distance, which may not be the one that leads on (the episode then checks where it drives)
        "forks": any(len(_next_lanes(e, p, to)) > 1 for e, p, to in zip(chain, path, chain[1:])),
        "platoon_lane_width_m": min(e.getLanes()[p].getWidth() for e, p in zip(chain, path)),
        # each edge's limit as sumolib reads it (its last lane's, the leftmost), lowest along the route:
        # what the attacker is clamped to and the target speed is checked against, as for every stored campaign
        "speed_limit_mps": min(e.getSpeed() for e in chain),
        "even_lanes": _even_lanes(net_file, [e.getID() for e in chain], path, lanes),
        "lane_widths_m": sorted({lane.getWidth() for lane in in_corridor}),
        "closed_to": [_closed_to(chain, path, j) for j in range(lanes)],
    }


def lane_path(chain, first: int, reach: list[list[int]]) -> list[int]:
    """The lane a car in lane ``first`` of the chain's first edge is in on each edge, following SUMO's
    connections without a lane change; shorter than the chain where that lane ends (a lane drop, an exit).

    Where a lane connects to several lanes of the next edge (a lane added beside it), the one that leads
    on furthest is taken, the rightmost of those alike: SUMO's own choice (MSVehicle's best lanes) as far
    as SUMO looks ahead, checked against its FCD in the tests. SUMO looks ahead a limited distance: where
    it takes another lane, the episode says so (`sumo.SumoWorld`), never a verdict. ``reach``: `_reach`'s."""
    path = [first]
    for k, (edge, to) in enumerate(zip(chain, chain[1:])):
        onward = _next_lanes(edge, path[-1], to)
        if not onward:
            break
        path.append(max(onward, key=lambda i: (reach[k + 1][i], -i)))
    return path


def _reach(chain) -> list[list[int]]:
    """For each edge and each of its lanes, the index of the last edge a car in it reaches without a lane change."""
    reach = [[len(chain) - 1] * chain[-1].getLaneNumber()]
    for k in range(len(chain) - 2, -1, -1):
        edge, to = chain[k], chain[k + 1]
        reach.insert(0, [max((reach[0][i] for i in _next_lanes(edge, lane, to)), default=k)
                         for lane in range(edge.getLaneNumber())])
    return reach


def _next_lanes(edge, lane: int, to) -> list[int]:
    """The lanes of the next edge ``to`` that lane ``lane`` of ``edge`` connects to."""
    return sorted({c.getToLane().getIndex() for c in edge.getLanes()[lane].getOutgoing() if c.getTo() == to})


def _lanes_beside(chain, path: list[int]) -> int:
    """How many lanes, from the platoon's up (to its left), lead on along the whole chain beside it, each
    keeping its offset from the platoon's lane.

    Only these can hold a platoon (and a lane change between them): a car in a lane that ends at a
    junction (a lane drop) stops there, which is no collision of the followers' doing."""
    lanes = min(e.getLaneNumber() - p for e, p in zip(chain, path))
    for k, (edge, to) in enumerate(zip(chain, chain[1:])):
        lanes = next((j for j in range(lanes) if path[k + 1] + j not in _next_lanes(edge, path[k] + j, to)), lanes)
    return lanes


def _closed_to(chain, path: list[int], offset: int) -> list[tuple[str, str]]:
    """The vehicle classes some edge of the chain closes the corridor's lane ``offset`` to, each with the
    first such edge."""
    closed: dict[str, str] = {}
    for edge, p in zip(chain, path):
        for vclass in VEHICLE_CLASSES:
            if vclass not in closed and not edge.getLanes()[p + offset].allows(vclass):
                closed[vclass] = edge.getID()
    return sorted(closed.items())


def _even_lanes(net_file: Path, route: list[str], path: list[int], lanes: int) -> bool:
    """Whether the corridor's lanes, and the junction lanes joining them, are as long as each other
    (within 1 mm) edge by edge: a car's odometer then reads the same distance in any of them."""
    import sumolib

    net = sumolib.net.readNet(str(net_file), withInternal=True)
    for k, (edge_id, to_id) in enumerate(zip(route, [*route[1:], None])):
        edge = net.getEdge(edge_id)
        lengths = [edge.getLanes()[path[k] + j].getLength() for j in range(lanes)]
        if to_id is not None:  # the junction lanes from each lane to its lane of the next edge
            junction = [sum(net.getLane(c.getViaLaneID()).getLength() for c in edge.getLanes()[path[k] + j].getOutgoing()
                            if c.getTo().getID() == to_id and c.getToLane().getIndex() == path[k + 1] + j and c.getViaLaneID())
                        for j in range(lanes)]
            lengths = [a + b for a, b in zip(lengths, junction)]
        if max(lengths) - min(lengths) > 1e-3:
            return False
    return True


def _longest_piece(chain, reach: list[list[int]]) -> str:
    """The longest run of the chain's edges along which some lane leads on (``reach``: `_reach`'s), as a route to take."""
    best = max(range(len(chain)), key=lambda s: sum(e.getLength() for e in chain[s:max(reach[s]) + 1]))
    piece = chain[best:max(reach[best]) + 1]
    route = ", ".join(f'"{e.getID()}"' for e in piece)
    return (f"the longest piece along which a lane leads on is {len(piece)} edge{'s' if len(piece) > 1 else ''} "
            f"({sum(e.getLength() for e in piece):.0f} m, speed limit {min(e.getSpeed() for e in piece):g} m/s): "
            f"scenario.route = [{route}]")


def route_lanes(net_file: Path, route: tuple[str, ...], path: tuple[int, ...]) -> list[tuple[tuple[tuple[float, float], ...], float]]:
    """The lanes the platoon drives along the route, in order, its junctions' internal lanes included: each one's
    shape (x, y) and its length as SUMO counts positions on it. SUMO lays a car at lane position p at the point p *
    (shape's length / length) along the shape: on a curve the lanes of an edge share its length, not their shapes'."""
    import sumolib

    net = sumolib.net.readNet(str(net_file), withInternal=True)
    lanes = []
    for k, edge in enumerate(route):
        lane = net.getLane(f"{edge}_{path[k]}")
        lanes.append(lane)
        if k + 1 == len(route):
            break
        to = net.getLane(f"{route[k + 1]}_{path[k + 1]}")
        for _ in range(8):  # through the junction: one internal lane, or two through an internal junction
            via = next((c.getViaLaneID() for c in lane.getOutgoing() if c.getToLane() is to), "")
            if not via:
                break
            lane = net.getLane(via)
            lanes.append(lane)
    return [(tuple(map(tuple, lane.getShape())), lane.getLength()) for lane in lanes]
