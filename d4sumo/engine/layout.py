"""A built network as the platoon drives it: the straight chain of edges from its one start, its length,
its lowest speed limit, the lanes that lead on through every junction, whether they are as long and as
wide as each other, and which vehicle classes each closes to. What no platoon can drive (branches, a
lane 0 that ends, speed limits that are no numbers) is refused naming scenario.network."""

from __future__ import annotations

import math
from pathlib import Path

from ..errors import ConfigError
from ..model.vehicle import VEHICLE_CLASSES

OR_ROUTE = ", or a scenario.route"  # the end of a refusal that a route settles (one given: it does not lead on)


def describe(net_file: Path, name: str) -> dict:
    """The straight chain of edges from the road's start, its length and its lowest speed limit (refusals
    name the network ``name``)."""
    import sumolib

    net = sumolib.net.readNet(str(net_file))
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
    for lane in (lane for e in chain for lane in e.getLanes()):  # netconvert keeps "nan" and "inf"; SUMO refuses them
        if not 0 < lane.getSpeed() < math.inf:
            raise ConfigError("scenario.network", name,
                              f"speed limits that are positive numbers of m/s (lane {lane.getID()}: {lane.getSpeed()})")
    lanes = _through_lanes(chain)
    if lanes == 0:
        raise ConfigError("scenario.network", name,
                          f"a road whose rightmost lane (the platoon's, lane 0) leads on through every junction; "
                          f"lane 0 of {_lane_end(chain)} ends there; {_longest_piece(chain)}")
    return {
        "route_edges": [e.getID() for e in chain],
        "length_m": sum(e.getLength() for e in chain),
        "speed_limit_mps": min(e.getSpeed() for e in chain),
        "lanes": lanes,
        "first_edge_m": chain[0].getLength(),
        "even_lanes": _even_lanes(net_file, [e.getID() for e in chain], lanes),
        "lane_widths_m": sorted({e.getLanes()[i].getWidth() for e in chain for i in range(lanes)}),
        "lane_width_m": min(e.getLanes()[0].getWidth() for e in chain),  # what d4sumo 0.10, sharing the cache, reads
        "closed_to": [_closed_to(chain, i) for i in range(lanes)],
    }


def _closed_to(chain, lane: int) -> list[tuple[str, str]]:
    """The vehicle classes some edge of the chain closes its lane ``lane`` to, each with the first such edge."""
    closed: dict[str, str] = {}
    for edge in chain:
        for vclass in VEHICLE_CLASSES:
            if vclass not in closed and not edge.getLanes()[lane].allows(vclass):
                closed[vclass] = edge.getID()
    return sorted(closed.items())


def _even_lanes(net_file: Path, route: list[str], lanes: int) -> bool:
    """Whether the route's lanes 0 .. lanes - 1, and the junction lanes joining them, are as long as each
    other (within 1 mm) edge by edge: a car's odometer then reads the same distance in any of them."""
    import sumolib

    net = sumolib.net.readNet(str(net_file), withInternal=True)
    for edge_id, to_id in zip(route, [*route[1:], None]):
        edge = net.getEdge(edge_id)
        lengths = [edge.getLanes()[i].getLength() for i in range(lanes)]
        if to_id is not None:  # the junction lanes from each lane to the next edge's
            junction = [sum(net.getLane(c.getViaLaneID()).getLength() for c in edge.getLanes()[i].getOutgoing()
                            if c.getTo().getID() == to_id and c.getToLane().getIndex() == i and c.getViaLaneID())
                        for i in range(lanes)]
            lengths = [a + b for a, b in zip(lengths, junction)]
        if max(lengths) - min(lengths) > 1e-3:
            return False
    return True


def _leads_on(edge, lane: int, to) -> bool:
    """Whether lane ``lane`` of ``edge`` connects to the lane of the same index of the next edge ``to``."""
    return any(c.getTo() == to and c.getToLane().getIndex() == lane for c in edge.getLanes()[lane].getOutgoing())


def _through_lanes(chain) -> int:
    """How many lanes, from the rightmost (0) up, lead on along the whole chain with the same index.

    Only these can hold a platoon (and a lane change between them): a car in a lane that ends at a
    junction (a lane drop) stops there, which is no collision of the followers' doing."""
    lanes = min(e.getLaneNumber() for e in chain)
    for edge, to in zip(chain, chain[1:]):
        lanes = next((i for i in range(lanes) if not _leads_on(edge, i, to)), lanes)
    return lanes


def _longest_piece(chain) -> str:
    """The longest run of the chain's edges whose lane 0 leads on from each to the next, as a route to take."""
    pieces = [[chain[0]]]
    for edge, to in zip(chain, chain[1:]):
        if _leads_on(edge, 0, to):
            pieces[-1].append(to)
        else:
            pieces.append([to])
    piece = max(pieces, key=lambda p: sum(e.getLength() for e in p))
    route = ", ".join(f'"{e.getID()}"' for e in piece)
    return (f"the longest piece whose lane 0 leads on is {len(piece)} edge{'s' if len(piece) > 1 else ''} "
            f"({sum(e.getLength() for e in piece):.0f} m, speed limit {min(e.getSpeed() for e in piece):g} m/s): "
            f"scenario.route = [{route}]")


def _lane_end(chain) -> str:
    """The first edge whose lane 0 does not lead on."""
    return next(edge.getID() for edge, to in zip(chain, chain[1:]) if not _leads_on(edge, 0, to))
