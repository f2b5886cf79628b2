"""SUMO's netconvert, run on a road's files: plain XML built into SUMO's network, and a network file
taken back to plain XML. What netconvert refuses is one line naming scenario.network: its errors, each
with where it is, the temporary files named as the user knows them."""

from __future__ import annotations

import logging
import os
import subprocess
import tempfile
from pathlib import Path

from ..errors import ConfigError, SumoError
from ..sumohome import sumo_binary

log = logging.getLogger(__name__)


def build_net(net_file: Path, name: str, nodes_xml: bytes, edges_xml: bytes, connections_xml: bytes = b"",
              types_xml: bytes = b"", *, binary: str | None = None) -> None:
    """Build ``net_file`` from a road's plain XML (the network ``name``, for messages), into a temporary
    file renamed at the end, so parallel workers never read a half-written network."""
    try:
        net_file.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise SumoError(f"cannot create the network cache {net_file.parent} ({exc.strerror})") from None
    binary = sumo_binary("netconvert", binary)
    with tempfile.TemporaryDirectory(dir=net_file.parent) as tmp:
        nodes, edges = Path(tmp) / "road.nod.xml", Path(tmp) / "road.edg.xml"
        nodes.write_bytes(nodes_xml)
        edges.write_bytes(edges_xml)
        extra = []
        for data, ext, option in ((connections_xml, ".con.xml", "--connection-files"), (types_xml, ".typ.xml", "--type-files")):
            if data:
                path = Path(tmp) / f"road{ext}"
                path.write_bytes(data)
                extra += [option, str(path)]
        out = Path(tmp) / "road.net.xml"
        cmd = [binary, "--node-files", str(nodes), "--edge-files", str(edges), "--output-file", str(out),
               "--no-turnarounds", "true", *extra]
        log.info("building %s with netconvert", net_file.name)
        result = _run(binary, cmd, timeout_s=120)
        if result.returncode != 0:
            said = _errors(result.stderr or result.stdout, {str(nodes): "the node file", str(edges): "the edge file"})
            if result.returncode < 0:  # it crashed on them (numLanes="-2": SIGSEGV), with no error of its own
                said = (f"it crashed (signal {-result.returncode}) on these files: check their numbers "
                        "(numLanes, speed, coordinates)")
            raise ConfigError("scenario.network", name, f"node and edge XML that netconvert builds into a road "
                                                        f"(netconvert: {said})")
        os.replace(out, net_file)


def plain_xml(net_file: Path, name: str) -> tuple[bytes, bytes, bytes, bytes]:
    """A network file (netconvert's, netgenerate's, an OSM import's) as plain node, edge, connection and
    type XML (netconvert --plain-output-prefix; a file it lacks is empty)."""
    binary = sumo_binary("netconvert")
    with tempfile.TemporaryDirectory() as tmp:
        prefix = Path(tmp) / "plain"
        result = _run(binary, [binary, "--sumo-net-file", str(net_file), "--plain-output-prefix", str(prefix)], timeout_s=300)
        if result.returncode != 0:
            raise ConfigError("scenario.network", name, "a network file SUMO loads (netconvert: "
                              f"{_errors(result.stderr or result.stdout, {str(net_file): net_file.name})})")
        read = lambda ext: prefix.with_suffix(ext).read_bytes() if prefix.with_suffix(ext).is_file() else b""  # noqa: E731
        return read(".nod.xml"), read(".edg.xml"), read(".con.xml"), read(".typ.xml")


def opendrive_output(net_file: Path, out: Path, name: str) -> None:
    """The network as OpenDRIVE, written by netconvert itself (``--opendrive-output``)."""
    binary = sumo_binary("netconvert")
    result = _run(binary, [binary, "--sumo-net-file", str(net_file), "--opendrive-output", str(out)], timeout_s=300)
    if result.returncode != 0:
        raise ConfigError("scenario.network", name, "a network netconvert writes as OpenDRIVE (netconvert: "
                          f"{_errors(result.stderr or result.stdout, {str(net_file): net_file.name})})")


def opendrive_input(xodr: Path, out: Path) -> None:
    """An OpenDRIVE road as SUMO's network (``--opendrive-files``): the way back of `opendrive_output`."""
    binary = sumo_binary("netconvert")
    result = _run(binary, [binary, "--opendrive-files", str(xodr), "--output-file", str(out)], timeout_s=300)
    if result.returncode != 0:
        raise ConfigError("--network", str(xodr), "an OpenDRIVE file netconvert imports (netconvert: "
                          f"{_errors(result.stderr or result.stdout, {str(xodr): xodr.name})})")


def _run(binary: str, cmd: list[str], timeout_s: float) -> subprocess.CompletedProcess:
    try:
        return subprocess.run(cmd, capture_output=True, text=True, timeout=timeout_s)
    except OSError as exc:
        raise SumoError(f"netconvert could not run ({binary}): {exc}") from None


def _errors(text: str, files: dict[str, str]) -> str:
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
