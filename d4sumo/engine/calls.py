"""Bound calls into SUMO's API for the step loop's hot paths."""

from __future__ import annotations

import functools


def api_call(api, domain: str, name: str):
    """``api.<domain>.<name>``; for libsumo its C function itself, without the one-line Python wrapper around it
    (a third of the cost of a call, and these run for every car at every step)."""
    return getattr(getattr(api, "_libsumo", None), f"{domain}_{name}", None) or getattr(getattr(api, domain), name)


def via_lanes(api, lane: str, to_lane: str) -> list[str]:
    """The junction lanes from ``lane`` to ``to_lane`` of the next edge, in order (none: they touch): one, or two
    through an internal junction."""
    found: list[str] = []
    while len(found) < 8:
        via = next((link[4] for link in api.lane.getLinks(lane) if link[0] == to_lane), "")
        if not via:
            break
        found.append(via)
        lane = via
    return found


def route_junctions(api, route: tuple[str, ...], path: tuple[int, ...]):
    """Each junction between two edges of the route, along the platoon's lane path: (the edge before it, the
    platoon's lane there, its lane on the next edge, where that lane ends along the route [m], how long the
    junction lanes between them are [m])."""
    along = 0.0
    for k, (edge, to) in enumerate(zip(route, route[1:])):
        lane, to_lane = f"{edge}_{path[k]}", f"{to}_{path[k + 1]}"
        along += api.lane.getLength(lane)
        length = sum(api.lane.getLength(via) for via in via_lanes(api, lane, to_lane))
        yield edge, lane, to_lane, along, length
        along += length


def vehicle_call(api, name: str):
    """``api.vehicle.<name>``, bound (`calls.api_call`)."""
    return api_call(api, "vehicle", name)


_NATIVE: dict = {}  # SUMO's calls in C, bound once a process (None: not to be had)
#: whether the step loop in C and the sensing among traffic take libsumo's own C++ functions where they can be had (tests
#: and the profile turn it off: the same episodes, through libsumo's Python)
NATIVE = True


def native_calls(api):
    """libsumo's own C++ functions (step, each car's position, odometer and speed, its commanded speed) for the step
    loop in C, as a capsule (`_sumo_calls`, `model/controllers/csrc/world_calls.h`); None where they cannot be had: TraCI,
    an install without the extension, a libsumo that names them otherwise. The same functions libsumo's Python calls."""
    raw = getattr(api, "_libsumo", None)
    if raw is None:
        return None
    if "calls" not in _NATIVE:
        try:
            from ._sumo_calls import bind
        except ImportError:  # built without a C++ compiler: the loop calls libsumo as the Python does
            _NATIVE["calls"] = None
        else:
            _NATIVE["calls"] = bind(raw.__file__, api.TraCIException, api.FatalTraCIError)
    return _NATIVE["calls"]


def native_traffic_pairs(api):
    """`neighbours._TrafficSense`'s step with libsumo's own C++ functions (`_sumo_calls.traffic_pairs`: the same pairs,
    ids, positions and speeds), or None where they cannot be had (`native_calls`) or are turned off (`NATIVE`)."""
    if not NATIVE or native_calls(api) is None:
        return None
    from ._sumo_calls import traffic_pairs

    return traffic_pairs


def native_lateral_pairs(api):
    """`neighbours._LateralTrafficSense`'s step with libsumo's own C++ functions: (``lateral_sense``, which makes what one
    platoon's sensing holds, ``lateral_pairs``, its step; `_sumo_calls`: the same pairs, ids, positions and speeds), or
    None where they cannot be had (`native_calls`) or are turned off (`NATIVE`)."""
    if not NATIVE or native_calls(api) is None:
        return None
    from ._sumo_calls import lateral_pairs, lateral_sense

    return lateral_sense, lateral_pairs


def fast_paths() -> str:
    """Which of its optional speed-ups this install has (each built at install where a compiler was found; without
    one, the same episodes, slower): said by ``d4sumo --version``."""
    import libsumo

    from ..model.controllers import compiled

    in_c = "yes" if compiled.play_column is not None else "no (install with a C compiler to have it)"
    native = "yes" if native_calls(libsumo) is not None else "no (on Linux, install with a C++ compiler to have it)"
    return f"followers and the paper's column stepped in C: {in_c}; libsumo's own C++ calls: {native}"


def simulation_step(api):
    """``api.simulationStep``; for libsumo its C function (d4sumo registers no step listeners)."""
    raw = getattr(getattr(api, "_libsumo", None), "simulation_step", None)
    return functools.partial(raw, 0.0) if raw else api.simulationStep  # a partial: no Python frame a step
