"""Road network variants: plain SUMO node/edge XML in ``sumo_scenarios/<name>/``, built with netconvert.

A variant is a folder holding one ``*.nod.xml`` and one ``*.edg.xml`` that describe a straight one-way
road (one edge, or a chain of edges). The shipped variants live in ``sumo_scenarios/``, installed with
d4sumo inside its package; a user's own folder works the same way. The ``.net.xml`` is built on first use
and cached under the user's cache folder, keyed by a hash of the inputs, so editing a variant rebuilds
it. A `NetworkSource` carries a variant's XML itself, so a worker on another machine builds the same
road without seeing the client's disk.
"""

from __future__ import annotations

import dataclasses
import functools
import hashlib
import json
import logging
import math
import os
import shlex
import subprocess
import tempfile
from dataclasses import dataclass
from pathlib import Path

from ..errors import ConfigError, SumoError
from ..sumohome import sumo_binary

log = logging.getLogger(__name__)

def _shipped_variants() -> Path:
    # Installed, the variants are data inside the package (pyproject.toml maps sumo_scenarios/ to
    # d4sumo/sumo_scenarios). Run from a checkout, or an editable install, they are the folder beside it.
    package = Path(__file__).resolve().parent.parent
    inside = package / "sumo_scenarios"
    return inside if inside.is_dir() else package.parent / "sumo_scenarios"


#: The variants shipped with d4sumo (a folder of data).
SCENARIOS_DIR = _shipped_variants()


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
    #: change reads lanes of one width (`maneuvers.occupied_lanes`)
    lane_widths_m: tuple[float, ...] = (3.2,)  # SUMO's default
    #: lane index -> {vehicle class: the first edge of the route whose lane of that index it may not use}
    closed_to: tuple[tuple[tuple[str, str], ...], ...] = ()

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


def copy_prefix(copy: int) -> str:
    return f"c{copy}_"


def default_cache_dir() -> Path:
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "d4sumo" / "nets"


def list_scenarios(root: Path | None = None) -> list[str]:
    root = root or SCENARIOS_DIR
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if p.is_dir() and _inputs(p, strict=False))


def scenario_folder(name: str, root: Path | None = None) -> Path:
    """The folder of a named variant, or the folder or ``.net.xml`` file given directly."""
    root = root or SCENARIOS_DIR
    candidates = [root / name] if "/" not in name and os.sep not in name else []
    candidates.append(Path(name))
    for folder in candidates:
        if folder.is_file() and folder.name.endswith(".net.xml"):
            return folder.resolve()
        if folder.is_dir() and _inputs(folder, strict=False):
            return folder.resolve()
    raise ConfigError("scenario.network", name, _not_a_network(Path(name), root))


def _not_a_network(path: Path, root: Path) -> str:
    """What ``--network`` takes, said for the path given that is none of it: a file that is not there, an
    OpenStreetMap file (netconvert imports it first), a node or edge file (its folder is the road), a
    folder without one road's files."""
    if any(s.lower() == ".osm" for s in path.suffixes):
        if not path.is_file():
            return f"an OpenStreetMap file that exists, imported with netconvert first (there is no {path.absolute()})"
        net = path.name[:path.name.lower().index(".osm")] + ".net.xml"
        return (f"a network file (*.net.xml): import an OpenStreetMap file with netconvert first: "
                f"netconvert --osm-files {shlex.quote(str(path))} -o {shlex.quote(net)}")
    if path.name.endswith(".net.xml") and not path.exists():
        return f"a *.net.xml that exists (there is no {path.absolute()})"
    if path.name.endswith((".nod.xml", ".edg.xml")) and path.is_file():
        return f"the folder that holds the node and edge files ({path.absolute().parent}), not one of them"
    if path.is_dir():
        found = ", ".join(f"{len(list(path.glob(g)))} {g}" for g in ("*.nod.xml", "*.edg.xml", "*.net.xml"))
        return f"a folder with exactly one *.nod.xml and one *.edg.xml, or one *.net.xml (it holds {found})"
    names = list_scenarios(root)
    allowed = (f"one of {', '.join(names) or '(none found in ' + str(root) + ')'}, a folder with *.nod.xml and *.edg.xml, "
               "or a *.net.xml")
    if path.is_file():
        return f"{allowed} ({path.name} is not one: a network file's name ends in .net.xml)"
    return allowed + (f" (there is no {path.absolute()})" if len(path.parts) > 1 or path.suffix else "")


def _inputs(folder: Path, strict: bool = True) -> tuple[Path, Path] | Path | None:
    """A variant's node and edge files, or its lone network file."""
    nodes = sorted(folder.glob("*.nod.xml"))
    edges = sorted(folder.glob("*.edg.xml"))
    if len(nodes) == 1 and len(edges) == 1:
        return nodes[0], edges[0]
    nets = sorted(folder.glob("*.net.xml"))
    if not nodes and not edges and len(nets) == 1:
        return nets[0]
    if strict:
        raise ConfigError("scenario.network", str(folder), "a folder with exactly one *.nod.xml and one *.edg.xml, or one *.net.xml")
    return None


@dataclass(frozen=True)
class NetworkSource:
    """A variant's plain XML (nodes, edges, and the connections and types a network file had), by value:
    what a road is built from, anywhere."""

    name: str  # as the user named it (a variant, or the path given): what messages say
    stem: str  # the folder's or the network file's own name: its built files' names in the cache
    nodes_xml: bytes
    edges_xml: bytes
    connections_xml: bytes = b""
    types_xml: bytes = b""

    @property
    def digest(self) -> str:
        parts = [self.nodes_xml, self.edges_xml] + ([self.connections_xml, self.types_xml]
                                                   if self.connections_xml or self.types_xml else [])
        return hashlib.sha256(b"\0".join(parts)).hexdigest()[:16]


def network_source(name: str, root: Path | None = None, route: tuple[str, ...] = ()) -> NetworkSource:
    """The XML of a named variant, of a folder given directly, or of a lone network file (netgenerate's,
    an OSM import's, netconvert's), taken back to plain XML by netconvert; with a ``route``, only its
    edges (the road the platoon drives, and each copy of it in a batch)."""
    source = _network_source(name, root)
    return _restrict(source, tuple(route)) if route else source


def _parsed(source: NetworkSource):
    """A source's node, edge and connection XML as element trees (no connections: None)."""
    from xml.etree import ElementTree as ET

    try:
        return (ET.fromstring(source.nodes_xml), ET.fromstring(source.edges_xml),
                ET.fromstring(source.connections_xml) if source.connections_xml else None)
    except ET.ParseError as exc:
        raise ConfigError("scenario.network", source.name, f"node and edge XML that parses ({exc})") from None


def _restrict(source: NetworkSource, route: tuple[str, ...]) -> NetworkSource:
    """The route's edges alone, with their nodes and the connections from each to the next."""
    from xml.etree import ElementTree as ET

    nodes, edges, connections = _parsed(source)
    by_id = {e.get("id"): e for e in edges.iter("edge")}
    for edge in route:
        if edge not in by_id:
            raise ConfigError("scenario.route", list(route), f"edges of {source.name} (it has no edge {edge!r})")
    if len(set(route)) != len(route):
        raise ConfigError("scenario.route", list(route), "each edge once")
    used = {by_id[e].get(k) for e in route for k in ("from", "to")}
    out_nodes, out_edges = ET.Element(nodes.tag, nodes.attrib), ET.Element(edges.tag, edges.attrib)
    for node in nodes.iter("node"):
        if node.get("id") in used:
            out_nodes.append(node)
    for edge in route:
        out_edges.append(by_id[edge])
    out_connections = b""
    if connections is not None:
        follows = set(zip(route, route[1:]))
        kept = ET.Element(connections.tag, connections.attrib)
        for c in connections.iter("connection"):
            if (c.get("from"), c.get("to")) in follows:
                kept.append(c)
        out_connections = ET.tostring(kept)
    return NetworkSource(source.name, source.stem, ET.tostring(out_nodes), ET.tostring(out_edges), out_connections,
                         source.types_xml)


def _network_source(name: str, root: Path | None = None) -> NetworkSource:
    folder = scenario_folder(name, root)
    found = folder if folder.is_file() else _inputs(folder)
    try:
        if isinstance(found, Path):
            return _plain_source(found, name, folder.name.removesuffix(".net.xml") if folder.is_file() else folder.name)
        nodes, edges = found
        return NetworkSource(name, folder.name, nodes.read_bytes(), edges.read_bytes())
    except OSError as exc:
        raise ConfigError("scenario.network", name, f"a readable folder ({exc.strerror}: {exc.filename})") from None


_PLAIN: dict[tuple[str, int, int], NetworkSource] = {}  # a network file, by path, size and time -> its plain XML


def _plain_source(net_file: Path, name: str, stem: str) -> NetworkSource:
    """A network file as plain node, edge, connection and type XML (netconvert --plain-output-prefix)."""
    stat = net_file.stat()
    key = (str(net_file), stat.st_size, stat.st_mtime_ns)
    if key in _PLAIN:
        return dataclasses.replace(_PLAIN[key], name=name, stem=stem)
    binary = sumo_binary("netconvert")
    with tempfile.TemporaryDirectory() as tmp:
        prefix = Path(tmp) / "plain"
        cmd = [binary, "--sumo-net-file", str(net_file), "--plain-output-prefix", str(prefix)]
        try:
            result = subprocess.run(cmd, capture_output=True, text=True, timeout=300)
        except OSError as exc:
            raise SumoError(f"netconvert could not run ({binary}): {exc}") from None
        if result.returncode != 0:
            raise ConfigError("scenario.network", name, "a network file SUMO loads (netconvert: "
                              f"{_netconvert_errors(result.stderr or result.stdout, {str(net_file): net_file.name})})")
        read = lambda ext: prefix.with_suffix(ext).read_bytes() if prefix.with_suffix(ext).is_file() else b""  # noqa: E731
        source = NetworkSource(name, stem, read(".nod.xml"), read(".edg.xml"), read(".con.xml"), read(".typ.xml"))
    _PLAIN[key] = source
    return source


def build_road(name: str | NetworkSource, *, root: Path | None = None, cache_dir: Path | None = None,
               netconvert: str | None = None, route: tuple[str, ...] = ()) -> Road:
    """Build (or take from the cache) the network of a variant and describe its road (with a ``route``:
    the road of those edges, which must lead on one to the next)."""
    source = name if isinstance(name, NetworkSource) else network_source(name, root, route)
    cache = Path(cache_dir) if cache_dir else default_cache_dir()
    net_file = cache / f"{source.stem}-{source.digest}.net.xml"
    info_file = net_file.with_suffix(".json")
    info = _read_info(info_file) if net_file.is_file() else None
    if info is None:
        _build_net(source, net_file, netconvert)
        try:
            info = _describe(net_file, source.name)
        except ConfigError as exc:
            if not route or not exc.allowed.endswith(_OR_ROUTE):  # a road's own fault (a lane 0 that ends): said as is
                raise
            raise ConfigError("scenario.route", list(route), "edges that lead on one to the next, "
                              "never back to a junction passed before") from None
        if route and info["route_edges"] != list(route):
            raise ConfigError("scenario.route", list(route), f"edges that lead on one to the next (they drive as {info['route_edges']})")
        _write_atomic(info_file, json.dumps(info))
    return Road(
        name=source.name,
        net_file=net_file,
        route_edges=tuple(info["route_edges"]),
        length_m=info["length_m"],
        speed_limit_mps=info["speed_limit_mps"],
        lanes=info["lanes"],
        first_edge_m=info["first_edge_m"],
        even_lanes=info["even_lanes"],
        lane_widths_m=tuple(info["lane_widths_m"]),
        closed_to=tuple(tuple(tuple(pair) for pair in lane) for lane in info["closed_to"]),
    )


def _build_net(source: NetworkSource, net_file: Path, netconvert: str | None = None) -> None:
    try:
        net_file.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SumoError(f"cannot create the network cache {net_file.parent} ({exc.strerror})") from None
    with tempfile.TemporaryDirectory(dir=net_file.parent) as tmp:
        nodes, edges = Path(tmp) / "road.nod.xml", Path(tmp) / "road.edg.xml"
        nodes.write_bytes(source.nodes_xml)
        edges.write_bytes(source.edges_xml)
        extra = []
        for data, ext, option in ((source.connections_xml, ".con.xml", "--connection-files"), (source.types_xml, ".typ.xml", "--type-files")):
            if data:
                path = Path(tmp) / f"road{ext}"
                path.write_bytes(data)
                extra += [option, str(path)]
        _netconvert(sumo_binary("netconvert", netconvert), nodes, edges, net_file, source.name, extra)


#: the largest batch of episodes one SUMO instance plays side by side
MAX_COPIES = 64


def batch_road(name: str | NetworkSource, copies: int, *, root: Path | None = None, cache_dir: Path | None = None,
               route: tuple[str, ...] = ()) -> Road:
    """The road of a variant ``copies`` times side by side, apart and unconnected, each copy's edges
    named with `copy_prefix`: the platoons of a batch share one SUMO instance and never meet. Copies are
    rounded up to a power of two (fewer networks to build and cache). Each copy is the variant's road
    with its y coordinates shifted, so a car drives exactly as on the road alone; where netconvert builds
    a copy otherwise (`_copies_alike`), the road alone is returned, marked ``copies_unlike``: its episodes
    play one at a time."""
    if not 1 <= copies <= MAX_COPIES:
        raise ValueError(f"copies: got {copies}; allowed: 1 .. {MAX_COPIES}")
    source = name if isinstance(name, NetworkSource) else network_source(name, root, route)
    road = build_road(source, cache_dir=cache_dir, route=route)
    if copies == 1:
        return road
    copies = 1 << (copies - 1).bit_length()
    nodes, edges, connections = _side_by_side(source, copies)
    copied = NetworkSource(source.name, f"{source.stem}-x{copies}", nodes, edges, connections, source.types_xml)
    net_file = road.net_file.parent / f"{copied.stem}-{copied.digest}.net.xml"
    if not net_file.is_file():
        _build_net(copied, net_file)
    if not _copies_alike(road.net_file, net_file, copies):
        return dataclasses.replace(road, copies_unlike=True)
    return dataclasses.replace(road, net_file=net_file, copies=copies)


@functools.lru_cache(maxsize=32)
def _copies_alike(alone: Path, copied: Path, copies: int) -> bool:
    """Whether every copy's lanes (edges' and junctions') are the road's alone, attribute for attribute
    but their shapes. netconvert computes a junction's geometry anew at each copy's coordinates, and a
    curved one can come out of another length or speed limit (1.22 m against 1.26 m), which SUMO's
    car-following models obey: the episodes played on that copy would not be the episodes alone."""
    from xml.etree import ElementTree as ET

    def lanes(path: Path) -> dict[str, dict]:
        return {lane.get("id"): {k: v for k, v in lane.attrib.items() if k not in ("id", "shape")}
                for lane in ET.parse(path).getroot().iter("lane")}

    road, batch = lanes(alone), lanes(copied)
    if len(batch) != copies * len(road):
        return False
    for j in range(copies):
        prefix = copy_prefix(j)
        for lane_id, attributes in road.items():
            internal = lane_id.startswith(":")  # a junction's lane: ':' then the junction's id
            copy_id = f":{prefix}{lane_id[1:]}" if internal else prefix + lane_id
            if batch.get(copy_id) != attributes:
                return False
    return True


def _side_by_side(source: NetworkSource, copies: int) -> tuple[bytes, bytes, bytes]:
    """Node, edge and connection XML of ``copies`` copies of a variant, each shifted in y past the one before."""
    from xml.etree import ElementTree as ET

    nodes, edges, connections = _parsed(source)
    ys = [float(n.get("y", 0.0)) for n in nodes.iter("node")]
    spacing = (max(ys) - min(ys) if ys else 0.0) + 100.0  # wider than any road of a few lanes

    def shifted(shape: str, dy: float) -> str:
        points = [p.split(",") for p in shape.split()]
        return " ".join(",".join([p[0], repr(float(p[1]) + dy), *p[2:]]) for p in points)

    out_nodes, out_edges = ET.Element(nodes.tag, nodes.attrib), ET.Element(edges.tag, edges.attrib)
    out_connections = ET.Element(connections.tag, connections.attrib) if connections is not None else None
    for j in range(copies):
        prefix, dy = copy_prefix(j), j * spacing
        for node in nodes.iter("node"):
            copy = ET.SubElement(out_nodes, "node", dict(node.attrib))
            copy.set("id", prefix + node.get("id"))
            copy.set("y", repr(float(node.get("y", 0.0)) + dy))
            if node.get("shape"):
                copy.set("shape", shifted(node.get("shape"), dy))
        for edge in edges.iter("edge"):
            copy = ET.SubElement(out_edges, "edge", dict(edge.attrib))
            for key in ("id", "from", "to"):
                copy.set(key, prefix + edge.get(key))
            if edge.get("shape"):
                copy.set("shape", shifted(edge.get("shape"), dy))
            copy.extend(list(edge))
        for connection in (connections.iter("connection") if connections is not None else ()):
            copy = ET.SubElement(out_connections, "connection", dict(connection.attrib))
            for key in ("from", "to"):
                copy.set(key, prefix + connection.get(key))
    return (ET.tostring(out_nodes), ET.tostring(out_edges),
            ET.tostring(out_connections) if out_connections is not None else b"")


def _read_info(path: Path) -> dict | None:
    """A built road's description, or None when missing or written by an older d4sumo (then rebuilt)."""
    try:
        info = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return info if isinstance(info, dict) and "lane_widths_m" in info else None


def _netconvert(binary: str, nodes: Path, edges: Path, out: Path, name: str, extra: list[str] | None = None) -> None:
    # Build into a temporary file and rename, so parallel workers never read a half-written net.
    fd, tmp = tempfile.mkstemp(dir=out.parent, suffix=".net.xml")
    os.close(fd)
    cmd = [binary, "--node-files", str(nodes), "--edge-files", str(edges), "--output-file", tmp, "--no-turnarounds", "true",
           *(extra or [])]
    log.info("building %s with netconvert", out.name)
    try:
        result = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    except OSError as exc:
        os.unlink(tmp)
        raise SumoError(f"netconvert could not run ({binary}): {exc}") from None
    if result.returncode != 0:
        os.unlink(tmp)
        names = {str(nodes): "the node file", str(edges): "the edge file"}
        said = _netconvert_errors(result.stderr or result.stdout, names)
        if result.returncode < 0:  # it crashed on them (numLanes="-2": SIGSEGV), with no error of its own
            said = (f"it crashed (signal {-result.returncode}) on these files: check their numbers "
                    "(numLanes, speed, coordinates)")
        raise ConfigError("scenario.network", name, f"node and edge XML that netconvert builds into a road "
                                                    f"(netconvert: {said})")
    os.replace(tmp, out)


def _netconvert_errors(text: str, files: dict[str, str]) -> str:
    """netconvert's errors in one line: each error with where it is ("In file ..., At line/column a/b"),
    its temporary files named as the user knows them, without "Quitting (on error)"."""
    errors: list[str] = []
    for line in text.splitlines():
        line = line.strip()
        if line.startswith("Error:"):
            errors.append(line.removeprefix("Error:").strip().rstrip("."))
        elif line.startswith("In file") and errors:
            path = line.removeprefix("In file").strip().strip("'")
            errors[-1] += f" in {files.get(path, Path(path).name)}"
        elif line.startswith("At line/column") and errors:
            at = line.removeprefix("At line/column").strip().rstrip(".").split("/")
            errors[-1] += f", line {at[0]}, column {at[1]}" if len(at) == 2 else f", at {'/'.join(at)}"
    return "; ".join(errors) or text.strip().splitlines()[-1] if text.strip() else "no message"


_OR_ROUTE = ", or a scenario.route"  # the end of a refusal that a route settles (one given: it does not lead on)


def _describe(net_file: Path, name: str) -> dict:
    """The straight chain of edges from the road's start, its length and its lowest speed limit (refusals
    name the network ``name``)."""
    import sumolib

    net = sumolib.net.readNet(str(net_file))
    edges = [e for e in net.getEdges() if e.getFunction() != "internal"]
    starts = [e for e in edges if not e.getIncoming()]
    if len(starts) != 1:
        raise ConfigError("scenario.network", name,
                          f"a network with exactly one road start (a straight one-way chain of edges){_OR_ROUTE}")
    chain = [starts[0]]
    while True:
        nxt = list(chain[-1].getOutgoing())
        if not nxt:
            break
        if len(nxt) > 1 or nxt[0] in chain:
            raise ConfigError("scenario.network", name,
                              f"a straight chain of edges without branches{_OR_ROUTE}")
        chain.append(nxt[0])
    for lane in (lane for e in chain for lane in e.getLanes()):  # netconvert keeps "nan" and "inf"; SUMO refuses them
        if not 0 < lane.getSpeed() < math.inf:
            raise ConfigError("scenario.network", name,
                              f"speed limits that are positive numbers of m/s (lane {lane.getID()}: {lane.getSpeed()})")
    lanes = _through_lanes(chain)
    if lanes == 0:
        raise ConfigError("scenario.network", name,
                          f"a road whose rightmost lane (the platoon's, lane 0) leads on through every junction; "
                          f"lane 0 of {_lane_end(chain)} ends there")
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
    from ..model.vehicle import VEHICLE_CLASSES

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


def _lane_end(chain) -> str:
    """The first edge whose lane 0 does not lead on."""
    return next(edge.getID() for edge, to in zip(chain, chain[1:]) if not _leads_on(edge, 0, to))


def _write_atomic(path: Path, text: str) -> None:
    fd, tmp = tempfile.mkstemp(dir=path.parent, suffix=".tmp")
    with os.fdopen(fd, "w") as fh:
        fh.write(text)
    os.replace(tmp, path)
