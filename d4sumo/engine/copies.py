"""A road's copies side by side, for a batch of episodes in one SUMO: each copy the road shifted in y, its
edges and nodes named with `copy_prefix`, apart and unconnected, so the platoons never meet; and whether
netconvert built every copy as it builds the road alone. Where the episodes drive the platoon's lane alone (in
the paper's column, among no traffic) on a road of one edge, each copy may be that lane alone: SUMO steps a
lane in less than half the time of four, and moves a car on it as on its lane of the road."""

from __future__ import annotations

import functools
from pathlib import Path

from .networks import NetworkSource

def copy_prefix(copy: int) -> str:
    return f"c{copy}_"


def side_by_side(source: NetworkSource, copies: int, lane: int | None = None) -> NetworkSource:
    """``copies`` copies of a road, each shifted in y past the one before (its built files named
    ``STEM-xCOPIES``); with ``lane``, each copy's edges of that lane alone, as their lane 0 (``STEM-xCOPIES-laneK``)."""
    from xml.etree import ElementTree as ET

    nodes, edges, connections = source.parsed()
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
            if lane is None:
                copy.extend(list(edge))
                continue
            copy.set("numLanes", "1")
            for child in edge:
                if child.tag != "lane" or int(child.get("index", -1)) == lane:
                    child = ET.fromstring(ET.tostring(child))
                    if child.tag == "lane":
                        child.set("index", "0")
                    copy.append(child)
        for connection in (connections.iter("connection") if connections is not None else ()):
            copy = ET.SubElement(out_connections, "connection", dict(connection.attrib))
            for key in ("from", "to"):
                copy.set(key, prefix + connection.get(key))
    stem = f"{source.stem}-x{copies}" + (f"-lane{lane}" if lane is not None else "")
    return NetworkSource(source.name, stem, ET.tostring(out_nodes), ET.tostring(out_edges),
                         ET.tostring(out_connections) if out_connections is not None else b"", source.types_xml)


@functools.lru_cache(maxsize=32)
def one_lane_alike(alone: Path, copied: Path, copies: int, edge: str, lane: int) -> bool:
    """Whether every copy's one lane (`side_by_side` with ``lane``) is the road's lane ``lane`` of its one edge,
    attribute for attribute but its shape and index: as long (a curve's lanes are not), as fast, open to the same cars."""
    from xml.etree import ElementTree as ET

    def lanes(path: Path) -> dict[str, dict]:
        return {lane.get("id"): {k: v for k, v in lane.attrib.items() if k not in ("id", "shape", "index")}
                for lane in ET.parse(path).getroot().iter("lane")}

    road, batch = lanes(alone), lanes(copied)
    own = road.get(f"{edge}_{lane}")
    return own is not None and len(batch) == copies and all(batch.get(f"{copy_prefix(j)}{edge}_0") == own
                                                             for j in range(copies))


@functools.lru_cache(maxsize=32)
def copies_alike(alone: Path, copied: Path, copies: int) -> bool:
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
