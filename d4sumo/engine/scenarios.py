"""Roads: a network the user names (`networks`), built by netconvert into SUMO's network (`netconvert`),
cached, and described as the platoon drives it (`layout`): the `Road` an episode plays on; and its
copies side by side for a batch (`copies`).

The ``.net.xml`` is built on first use and cached under the user's cache folder, keyed by a hash of the
road's XML, so editing a variant rebuilds it; its description is cached beside it.
"""

from __future__ import annotations

import dataclasses
import hashlib
import json
import os
import tempfile
from dataclasses import dataclass
from pathlib import Path

from ..cache import default_cache_dir  # noqa: F401 (where it was: callers import it from here)
from ..errors import ConfigError
from .copies import copies_alike, copy_prefix, one_lane_alike, side_by_side
from .layout import LAYOUT, OR_ROUTE, describe
from .netconvert import build_net
from .networks import NetworkSource, network_source


@dataclass(frozen=True)
class Road:
    """A built network variant: what an episode needs to know about the road."""

    name: str
    net_file: Path
    route_edges: tuple[str, ...]  # the straight chain of edges the platoon drives
    length_m: float
    speed_limit_mps: float  # the lowest limit along the chain
    lanes: int
    copies: int = 1  # side by side, for a batch of episodes (`batch_road`)
    #: netconvert builds this road's copies otherwise than the road: its batches play one at a time (`batch_road`)
    copies_unlike: bool = False
    first_edge_m: float = float("inf")  # the first edge's length: every car starts on it
    #: whether every edge of the route, and every junction lane between two of them, is as long in each of
    #: its lanes: positions along the route in different lanes are then comparable (lane changes need it)
    even_lanes: bool = True
    #: the widths of the lanes the platoon may use (0 .. lanes - 1) along the route, narrowest first: a lane
    #: change reads lanes of one width (`lanes.occupied_lanes`)
    lane_widths_m: tuple[float, ...] = (3.2,)  # SUMO's default
    #: lane index -> {vehicle class: the first edge of the route whose lane of that index it may not use}
    closed_to: tuple[tuple[tuple[str, str], ...], ...] = ()
    #: the platoon's lane on each edge of the route, as SUMO counts them (0 the rightmost): an on-ramp adds
    #: a lane on its right and an exit takes one away. A maneuver's lanes, and the fields above, count from
    #: it (0 the platoon's lane, 1 the one to its left); none: lane 0 all along
    lane_path: tuple[int, ...] = ()
    #: whether the platoon's lane joins several lanes of the next edge at some junction: SUMO's cars may
    #: then take another than the lane path, and each episode checks that they do not
    forks: bool = False
    #: the lanes of the first edge that lead on through the route without a lane change (SUMO's indices):
    #: where traffic enters
    through_lanes: tuple[int, ...] = (0,)
    #: a network file SUMO runs as it is (`EpisodeConfig.network_given`), not rebuilt from plain XML
    given: bool = False
    #: each copy is the platoon's lane alone, as SUMO's lane 0 (`batch_road`'s one_lane)
    lane_copies: bool = False

    @property
    def platoon_lane(self) -> int:
        """The platoon's lane on the route's first edge, where every car starts (SUMO's index)."""
        return self.lane_path[0] if self.lane_path else 0

    @property
    def platoon_path(self) -> tuple[int, ...]:
        """The platoon's lane on every edge of the route (SUMO's index), whether or not it changes."""
        return self.lane_path or (self.platoon_lane,) * len(self.route_edges)

    @property
    def platoon_lanes(self) -> dict[str, int] | None:
        """The platoon's lane on each edge of the route, by edge, where its index changes along it, else None."""
        return dict(zip(self.route(), self.lane_path)) if self.lane_shifts else None

    @property
    def lane_shifts(self) -> bool:
        """Whether the platoon's lane changes its index along the route."""
        return len(set(self.lane_path)) > 1

    @property
    def lane_width_m(self) -> float:
        """The narrowest lane's width: the one width of them all wherever a lane change plays."""
        return self.lane_widths_m[0]

    def closed(self, lane: int, vclass: str) -> str | None:
        """The first edge of the route whose lane ``lane`` ``vclass`` may not use, or None."""
        return dict(self.closed_to[lane]).get(vclass) if lane < len(self.closed_to) else None

    @property
    def one_edge(self) -> bool:
        """Whether the route is one edge: a car's lane position is then its position along the route."""
        return len(self.route_edges) == 1

    def route(self, copy: int = 0) -> tuple[str, ...]:
        """The edges of one copy of the road."""
        return self.route_edges if self.copies == 1 else tuple(f"{copy_prefix(copy)}{e}" for e in self.route_edges)


def build_road(name: str | NetworkSource, *, root: Path | None = None, cache_dir: Path | None = None,
               netconvert: str | None = None, route: tuple[str, ...] = (), lane: int | None = None,
               whole: bool = False, given: bool = False) -> Road:
    """Build (or take from the cache) the network of a variant and describe its road (with a ``route``:
    the road of those edges, which must lead on one to the next) as the platoon drives it from ``lane``
    of the first edge (none: the rightmost lane that leads on through the route). ``whole``: the network
    is built whole, every way of it, the route's edges the road through it (traffic of a user's demand
    drives the other ways too); else it is the route's edges alone. ``given``: a network file SUMO runs as it
    is (`EpisodeConfig.rebuild`), whole."""
    given = given or isinstance(name, NetworkSource) and name.given
    whole = (whole or given) and bool(route)
    source = name if isinstance(name, NetworkSource) else network_source(name, root, () if whole else route, given=given)
    cache = Path(cache_dir) if cache_dir else default_cache_dir()
    net_file = cache / f"{source.stem}-{source.digest}.net.xml"
    info_file = (net_file.with_suffix(f".{hashlib.sha256(' '.join(route).encode()).hexdigest()[:12]}.json") if whole
                 else net_file.with_suffix(".json"))
    info = _read_info(info_file) if net_file.is_file() else None
    if info is None:
        if not net_file.is_file() or not whole:
            _build(source, net_file, netconvert)
        try:
            info = describe(net_file, source.name, route if whole else ())
        except ConfigError as exc:
            if not route or not exc.allowed.endswith(OR_ROUTE):  # a road's own fault (a lane 0 that ends): said as is
                raise
            raise ConfigError("scenario.route", list(route), "edges that lead on one to the next, "
                              "never back to a junction passed before") from None
        if route and info["route_edges"] != list(route):
            raise ConfigError("scenario.route", list(route), f"edges that lead on one to the next (they drive as {info['route_edges']})")
        _write_atomic(info_file, json.dumps(_with_earlier_keys(info)))
    corridor = _corridor(info, source.name, lane)
    path = tuple(corridor["lane_path"])
    return Road(
        name=source.name,
        net_file=net_file,
        route_edges=tuple(info["route_edges"]),
        length_m=info["length_m"],
        speed_limit_mps=corridor["speed_limit_mps"],
        lanes=corridor["lanes"],
        first_edge_m=info["first_edge_m"],
        even_lanes=corridor["even_lanes"],
        lane_widths_m=tuple(corridor["lane_widths_m"]),
        closed_to=tuple(tuple(tuple(pair) for pair in lane) for lane in corridor["closed_to"]),
        lane_path=path if any(path) else (),
        forks=corridor["forks"],
        through_lanes=tuple(sorted(int(lane) for lane in info["corridors"])),
        given=given,
    )


def _corridor(info: dict, name: str, lane: int | None) -> dict:
    """The platoon's corridor from ``lane`` of the first edge (none: the rightmost that leads on)."""
    corridors = info["corridors"]
    if lane is None:
        return corridors[str(info["platoon_lane"])]
    if str(lane) not in corridors:
        through = ", ".join(corridors)
        raise ConfigError("scenario.lane", lane, f"a lane of {name}'s first edge {info['route_edges'][0]} that leads on "
                                                 f"through every junction of the route without a lane change: {through} "
                                                 "(0 the rightmost)")
    return corridors[str(lane)]


def _with_earlier_keys(info: dict) -> dict:
    """The description with the keys earlier d4sumo versions read (sharing this cache), where they mean
    what those versions think: a road whose platoon drives lane 0 all along. Of any other road they find
    none, and describe it again themselves (and refuse it)."""
    corridor = info["corridors"][str(info["platoon_lane"])]
    if any(corridor["lane_path"]):
        return info
    earlier = {key: corridor[key] for key in ("speed_limit_mps", "lanes", "even_lanes", "lane_widths_m", "closed_to")}
    return {**info, **earlier, "lane_width_m": corridor["platoon_lane_width_m"]}


def _build(source: NetworkSource, net_file: Path, netconvert: str | None = None) -> None:
    if source.given:  # the network file itself, kept in the cache by its content
        net_file.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=net_file.parent, suffix=".partial")
        with os.fdopen(fd, "wb") as fh:
            fh.write(source.net_xml)
        os.replace(tmp, net_file)
        return
    build_net(net_file, source.name, source.nodes_xml, source.edges_xml, source.connections_xml, source.types_xml,
              binary=netconvert)


#: the largest batch of episodes one SUMO instance plays side by side
MAX_COPIES = 64


def config_road(config) -> Road:
    """The road an episode of ``config`` (`EpisodeConfig`) plays on alone: its network as it says (a network
    file as given or rebuilt, a route's edges alone or the network whole around them), from its lane."""
    return build_road(config.network, route=config.route, lane=config.lane, whole=config.whole_network,
                      given=config.network_given)


def batch_road(name: str | NetworkSource, copies: int, *, root: Path | None = None, cache_dir: Path | None = None,
               route: tuple[str, ...] = (), lane: int | None = None, given: bool = False, one_lane: bool = False) -> Road:
    """The road of a variant ``copies`` times side by side, apart and unconnected, each copy's edges
    named with `copy_prefix`: the platoons of a batch share one SUMO instance and never meet. Copies are
    rounded up to a power of two (fewer networks to build and cache). Each copy is the variant's road
    with its y coordinates shifted, so a car drives exactly as on the road alone; where netconvert builds
    a copy otherwise (`copies.copies_alike`), the road alone is returned, marked ``copies_unlike``: its episodes
    play one at a time. ``one_lane``: the episodes drive the platoon's lane alone (in the paper's column, among no
    traffic); on a road of one edge each copy is then that lane alone, where netconvert builds it as the road's
    (`copies.one_lane_alike`): the same episodes, SUMO's steps at less than half the cost of a road of four lanes."""
    if not 1 <= copies <= MAX_COPIES:
        raise ValueError(f"copies: got {copies}; allowed: 1 .. {MAX_COPIES}")
    if given or isinstance(name, NetworkSource) and name.given:  # the network as it is has no copies: one at a time
        road = build_road(name, root=root, cache_dir=cache_dir, route=route, lane=lane, given=True)
        return road if copies == 1 else dataclasses.replace(road, copies_unlike=True)
    source = name if isinstance(name, NetworkSource) else network_source(name, root, route)
    road = build_road(source, cache_dir=cache_dir, route=route, lane=lane)
    if copies == 1:
        return road
    copies = 1 << (copies - 1).bit_length()
    if one_lane and road.one_edge and road.lanes > 1:
        narrow = _one_lane_copies(source, road, copies)
        if narrow is not None:
            return narrow
    net_file = _copies_built(source, road, copies)
    if not copies_alike(road.net_file, net_file, copies):
        return dataclasses.replace(road, copies_unlike=True)
    return dataclasses.replace(road, net_file=net_file, copies=copies)


def _copies_built(source: NetworkSource, road: Road, copies: int, lane: int | None = None) -> Path:
    """The network file of the road's copies side by side (`copies.side_by_side`), built once beside the road's."""
    copied = side_by_side(source, copies, lane)
    net_file = road.net_file.parent / f"{copied.stem}-{copied.digest}.net.xml"
    if not net_file.is_file():
        _build(copied, net_file)
    return net_file


def _one_lane_copies(source: NetworkSource, road: Road, copies: int) -> Road | None:
    """``copies`` copies of the platoon's lane of a road of one edge, as a road; None where netconvert builds the lane
    otherwise alone than on the road (a curve's lanes differ in length)."""
    lane, (edge,) = road.platoon_lane, road.route_edges
    net_file = _copies_built(source, road, copies, lane)
    if not one_lane_alike(road.net_file, net_file, copies, edge, lane):
        return None
    # closed_to counts from the platoon's lane; lanes stays the road's (SUMO's Plexe models are told it)
    return dataclasses.replace(road, net_file=net_file, copies=copies, lane_path=(), through_lanes=(0,),
                               closed_to=road.closed_to[:1], lane_copies=True)


def _read_info(path: Path) -> dict | None:
    """A built road's description, or None when missing or written by an older d4sumo (then rebuilt)."""
    try:
        info = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return info if isinstance(info, dict) and info.get("layout") == LAYOUT else None


def _write_atomic(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        fh.write(text)
    os.replace(tmp, path)
