"""What ``--network`` names, and the road's plain XML by value (`NetworkSource`).

A network is a shipped variant (a folder of ``sumo_scenarios/``, installed with d4sumo inside its
package), a folder of the user's own holding one ``*.nod.xml`` and one ``*.edg.xml`` (SUMO's plain node
and edge files) or one ``*.net.xml``, or the path of a ``*.net.xml`` (netconvert's, netgenerate's, an OSM
import's), which netconvert takes back to plain XML, its lane connections kept. A name that is none of
these is refused saying what is wrong with it. With ``scenario.route``, the source is the route's edges
alone. A `NetworkSource` carries the XML itself, so a worker on another machine builds the same road
without seeing the client's disk.
"""

from __future__ import annotations

import dataclasses
import hashlib
import logging
import os
import shlex
import shutil
import tempfile
from dataclasses import dataclass
from pathlib import Path

from ..cache import default_cache_dir
from ..errors import ConfigError
from ..model.world.network import NETWORK_FILE_SUFFIXES, SCENARIOS_DIR, folder_files, network_digest, network_files
from .netconvert import plain_xml

log = logging.getLogger(__name__)
_SAID: set[tuple[str, tuple[str, ...]]] = set()  # networks (and routes) whose dropped signal plans were said



def list_scenarios(root: Path | None = None) -> list[str]:
    root = root or SCENARIOS_DIR
    if not root.is_dir():
        return []
    return sorted(p.name for p in root.iterdir() if p.is_dir() and _inputs(p, strict=False))


#: network paths stored campaigns name that are not where this process runs: this machine's copy of their files
_KEPT: dict[str, Path] = {}


def kept_road(sha256: str) -> Path:
    """Where this machine keeps the files of the road of content ``sha256`` (`keep_road`)."""
    return default_cache_dir().parent / "roads" / sha256


def keep_road(network: str, sha256: str) -> None:
    """Keep the files of a campaign's road of one's own by their content (once, whoever is first), so that its
    samples replay from any folder of this machine, and after the files were moved: `use_kept_road`."""
    kept = kept_road(sha256)
    files = network_files(network)
    if kept.is_dir() or not files or network_digest(network) != sha256:
        return
    path = Path(network).expanduser()
    work = None
    try:
        kept.parent.mkdir(parents=True, exist_ok=True)
        work = Path(tempfile.mkdtemp(prefix=".keep-", dir=kept.parent))
        inside = work if path.is_file() else work / path.name
        inside.mkdir(exist_ok=True)
        for f in files:
            shutil.copyfile(f, inside / f.name)
        work.rename(kept)
    except OSError:  # another process was first (its copy is the same), or a cache that cannot be written:
        if work is not None:  # the road is still where it is
            shutil.rmtree(work, ignore_errors=True)


def use_kept_road(network: str, sha256: str) -> Path | None:
    """Where a stored campaign's road ``network`` is not (a relative path from another folder, files moved),
    its files as this machine kept them, from now on in this process (None: none kept)."""
    kept = kept_road(sha256)
    found = sorted(kept.iterdir()) if kept.is_dir() else []
    if not found:
        return None
    _KEPT[network] = found[0] if found[0].is_dir() or len(found) == 1 else kept
    return _KEPT[network]


def scenario_folder(name: str, root: Path | None = None) -> Path:
    """The folder of a named variant, or the folder or ``.net.xml`` file given directly."""
    if name in _KEPT:
        return _KEPT[name]
    root = root or SCENARIOS_DIR
    candidates = [root / name] if "/" not in name and os.sep not in name else []
    candidates.append(Path(name))
    for folder in candidates:
        if folder.is_file() and folder.name.endswith(NETWORK_FILE_SUFFIXES):
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
    if path.name.endswith(NETWORK_FILE_SUFFIXES) and not path.exists():
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
        return f"{allowed} ({path.name} is not one: a network file's name ends in .net.xml, or .net.xml.gz)"
    return allowed + (f" (there is no {path.absolute()})" if len(path.parts) > 1 or path.suffix else "")


def _inputs(folder: Path, strict: bool = True) -> tuple[Path, Path] | Path | None:
    """A variant's node and edge files, or its lone network file."""
    nodes, edges, nets = folder_files(folder)
    if len(nodes) == 1 and len(edges) == 1:
        return nodes[0], edges[0]
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
    #: a network file run as given (`EpisodeConfig.rebuild` false): its content, uncompressed; then nothing above
    net_xml: bytes = b""

    @property
    def given(self) -> bool:
        return bool(self.net_xml)

    @property
    def digest(self) -> str:
        if self.net_xml:
            return hashlib.sha256(self.net_xml).hexdigest()[:16]
        parts = [self.nodes_xml, self.edges_xml] + ([self.connections_xml, self.types_xml]
                                                   if self.connections_xml or self.types_xml else [])
        return hashlib.sha256(b"\0".join(parts)).hexdigest()[:16]

    def parsed(self):
        """The node, edge and connection XML as element trees (no connections: None)."""
        from xml.etree import ElementTree as ET

        try:
            return (ET.fromstring(self.nodes_xml), ET.fromstring(self.edges_xml),
                    ET.fromstring(self.connections_xml) if self.connections_xml else None)
        except ET.ParseError as exc:
            raise ConfigError("scenario.network", self.name, f"node and edge XML that parses ({exc})") from None


def network_source(name: str, root: Path | None = None, route: tuple[str, ...] = (), given: bool = False) -> NetworkSource:
    """The XML of a named variant, of a folder given directly, or of a lone network file (netgenerate's,
    an OSM import's, netconvert's), taken back to plain XML by netconvert; with a ``route``, only its
    edges (the road the platoon drives, and each copy of it in a batch). ``given``: a network file as it
    is, for SUMO to run (its route is a way through it)."""
    if given:
        return _given_source(name, root)
    source = _network_source(name, root)
    source = _restrict(source, tuple(route)) if route else source
    folder = scenario_folder(name, root)
    if folder.is_file() or isinstance(_inputs(folder, strict=False), Path):  # a network file's, alone or in its folder
        _note_signals(source, tuple(route))
    return source


def _note_signals(source: NetworkSource, route: tuple[str, ...]) -> None:
    """Say once that a network file's own signal plans do not reach the road built from it: its plain
    nodes and edges keep which junctions are traffic lights, and netconvert gives each its default
    program (the programs themselves, in netconvert's plain .tll.xml, are not loaded). Only lights the
    road drives through are named."""
    from xml.etree import ElementTree as ET

    if (source.name, route) in _SAID:
        return
    _SAID.add((source.name, route))
    edges = list(ET.fromstring(source.edges_xml).iter("edge"))
    passed = {e.get("to") for e in edges} & {e.get("from") for e in edges}  # junctions a car drives through
    lights = sorted({n.get("tl") or n.get("id") for n in ET.fromstring(source.nodes_xml).iter("node")
                     if "traffic_light" in (n.get("type") or "") and n.get("id") in passed})
    if lights:
        several = len(lights) > 1
        log.warning("%s: the road d4sumo builds from it gives its %d traffic light%s %s(%s) netconvert's default "
                    "program%s, not the network's own: it is rebuilt from the network's plain nodes, edges and connections, "
                    "without the programs netconvert writes beside them", source.name, len(lights), "s" if several else "",
                    "on the route " if route else "", ", ".join(lights[:5]) + (", ..." if len(lights) > 5 else ""),
                    "s" if several else "")


def _network_source(name: str, root: Path | None = None) -> NetworkSource:
    folder = scenario_folder(name, root)
    found = folder if folder.is_file() else _inputs(folder)
    try:
        if isinstance(found, Path):
            return _plain_source(found, name, _stem(folder.name) if folder.is_file() else folder.name)
        nodes, edges = found
        return NetworkSource(name, folder.name, nodes.read_bytes(), edges.read_bytes())
    except OSError as exc:
        raise ConfigError("scenario.network", name, f"a readable folder ({exc.strerror}: {exc.filename})") from None


def _given_source(name: str, root: Path | None = None) -> NetworkSource:
    """A network file as SUMO runs it, its content read once a file version (uncompressed)."""
    import gzip

    net_file = scenario_folder(name, root)
    if net_file.is_dir() and isinstance(found := _inputs(net_file, strict=False), Path):  # a folder holding one network file
        net_file = found
    if not net_file.is_file():
        raise ConfigError("scenario.network", name, "a network file (*.net.xml or *.net.xml.gz), or a folder holding one, "
                                                    "to run as given")
    stat = net_file.stat()
    key = (str(net_file), stat.st_size, stat.st_mtime_ns, "given")
    if key not in _PLAIN:
        try:
            data = net_file.read_bytes()
            if data[:2] == b"\x1f\x8b":
                data = gzip.decompress(data)
        except (OSError, EOFError) as exc:
            raise ConfigError("scenario.network", name, f"a readable network file ({exc})") from None
        _PLAIN[key] = NetworkSource(name, _stem(net_file.name), b"", b"", net_xml=data)
    return dataclasses.replace(_PLAIN[key], name=name)


def _restrict(source: NetworkSource, route: tuple[str, ...]) -> NetworkSource:
    """The route's edges alone, with their nodes and the connections from each to the next."""
    from xml.etree import ElementTree as ET

    nodes, edges, connections = source.parsed()
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


_PLAIN: dict[tuple, NetworkSource] = {}  # a network file, by path, size and time -> its plain XML (or itself, given)


def _stem(file_name: str) -> str:
    """A network file's name without its suffix (``.net.xml``, or compressed ``.net.xml.gz``)."""
    return next(file_name[:-len(s)] for s in sorted(NETWORK_FILE_SUFFIXES, key=len, reverse=True) if file_name.endswith(s))


def _plain_source(net_file: Path, name: str, stem: str) -> NetworkSource:
    """A network file as plain node, edge, connection and type XML, taken back once a file version."""
    stat = net_file.stat()
    key = (str(net_file), stat.st_size, stat.st_mtime_ns)
    if key not in _PLAIN:
        _PLAIN[key] = NetworkSource(name, stem, *plain_xml(net_file, name))
    return dataclasses.replace(_PLAIN[key], name=name, stem=stem)


def opendrive_network(xodr: Path) -> Path:
    """An OpenDRIVE road (an exported scenario's road.xodr) as SUMO's network, imported by netconvert once
    (kept in the network cache by its content)."""
    from .netconvert import opendrive_input

    xodr = Path(xodr)
    if not xodr.is_file():
        raise ConfigError("--network", str(xodr), "an OpenDRIVE file (no file there)")
    net = default_cache_dir() / f"opendrive-{hashlib.sha256(xodr.read_bytes()).hexdigest()[:16]}.net.xml"
    if not net.is_file():
        net.parent.mkdir(parents=True, exist_ok=True)
        partial = net.with_name(f"{net.name}.{os.getpid()}.partial")
        opendrive_input(xodr, partial)
        os.replace(partial, net)
    return net
