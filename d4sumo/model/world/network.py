"""Which road a campaign plays on, decided in one place: a shipped variant by its name, or a path (a network
file, a folder of node and edge files or of one network file); the files that identify it (their digest),
whether netconvert builds it; and the SUMO options a scenario may give as they are. Pure code, no SUMO.
"""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any, Mapping

from ...errors import ConfigError
from ...files import file_sha256

#: SUMO options given as they are (`EpisodeConfig.sumo_options`): they change what SUMO's traffic does, nothing
#: d4sumo decides
SUMO_OPTIONS_PASSED = ("time-to-teleport", "time-to-teleport.highways", "max-depart-delay", "ignore-route-errors",
                       "default.speeddev", "default.action-step-length", "ignore-junction-blocker",
                       "device.rerouting.probability", "device.rerouting.period", "routing-algorithm",
                       "lanechange.overtake-right", "time-to-impatience", "scale", "default.carfollowmodel",
                       "max-num-vehicles", "tls.all-off", "device.emissions.probability")
#: ... and the options of these SUMO devices (`device.rerouting.adaptation-steps`)
SUMO_OPTION_GROUPS_PASSED = ("device.rerouting.", "device.emissions.", "device.battery.")


def passed_option(name: str) -> bool:
    """Whether d4sumo gives SUMO option ``name`` as it is (`EpisodeConfig.sumo_options`)."""
    return name in SUMO_OPTIONS_PASSED or name.startswith(SUMO_OPTION_GROUPS_PASSED)


#: the names of SUMO's network files (netconvert's, netgenerate's, SUMO's own examples': compressed)
NETWORK_FILE_SUFFIXES = (".net.xml", ".net.xml.gz")


def _shipped_variants() -> Path:
    # Installed, the variants are data inside the package (pyproject.toml maps sumo_scenarios/ to
    # d4sumo/sumo_scenarios). Run from a checkout, or an editable install, they are the folder beside it.
    package = Path(__file__).resolve().parents[2]  # d4sumo/model/world/network.py -> d4sumo
    inside = package / "sumo_scenarios"
    return inside if inside.is_dir() else package.parent / "sumo_scenarios"


#: The variants shipped with d4sumo (a folder of data).
SCENARIOS_DIR = _shipped_variants()


def is_network_path(network: str) -> bool:
    """Whether a network is named by a path, not by a shipped variant's name (which is taken first, as
    `engine.networks.scenario_folder` does)."""
    return "/" in network or os.sep in network or not (SCENARIOS_DIR / network).is_dir()


def builds_network(network: str) -> bool:
    """Whether the road of ``network`` is built by netconvert from node and edge files: a shipped variant, or a folder
    of them. A network file, or a folder holding one and nothing else, may run as given (`EpisodeConfig.rebuild`)."""
    if not is_network_path(network):
        return True
    path = Path(network).expanduser()
    if path.name.endswith(NETWORK_FILE_SUFFIXES) or not path.is_dir():  # (a folder no longer there: as stored)
        return False
    nodes, edges, nets = folder_files(path)
    return not (not nodes and not edges and len(nets) == 1)


def network_files(network: str) -> list[Path]:
    """The files a network path names, those its road is built from: a network file, or a folder's node and
    edge files, else its one network file (none for a shipped variant's name, or a path with none there)."""
    if not is_network_path(network):
        return []
    path = Path(network).expanduser()
    if path.is_file():
        return [path]
    if not path.is_dir():
        return []
    nodes, edges, nets = folder_files(path)
    return sorted(nodes + edges) if len(nodes) == 1 and len(edges) == 1 else sorted(nodes + edges + nets)


def folder_files(folder: Path) -> tuple[list[Path], list[Path], list[Path]]:
    """A road folder's node, edge and network files, each sorted: a road is one node and one edge file, or one
    network file (`engine.networks` builds it from them)."""
    return tuple(sorted(f for pattern in patterns for f in folder.glob(pattern) if f.is_file())
                 for patterns in (("*.nod.xml",), ("*.edg.xml",), tuple(f"*{s}" for s in NETWORK_FILE_SUFFIXES)))


def files_digest(field: str, paths) -> str:
    """sha256 over files' bytes, in order; an unreadable file is a ConfigError naming ``field`` and it."""
    digest = hashlib.sha256()
    for path in paths:
        try:
            digest.update(Path(path).read_bytes())
        except OSError as exc:
            raise ConfigError(field, path, f"a readable file ({exc.strerror or exc})") from None
        digest.update(b"\0")
    return digest.hexdigest()


def sumo_options(options: Any) -> tuple[tuple[str, str], ...]:
    """SUMO options to give as they are, by name (`sumocfg.PASSED`), as sorted (name, value) pairs of strings."""
    pairs = options.items() if isinstance(options, Mapping) else options
    try:
        pairs = [(k, v) for k, v in pairs]
    except (TypeError, ValueError):
        raise ConfigError("scenario.sumo_options", options, "a table of SUMO options, e.g. {time-to-teleport = \"-1\"}") from None
    for name, value in pairs:
        if not passed_option(name):
            raise ConfigError(f"scenario.sumo_options.{name}", value, f"an option d4sumo can honour, one of "
                              f"{', '.join([*SUMO_OPTIONS_PASSED, *(g + '*' for g in SUMO_OPTION_GROUPS_PASSED)])}")
        if not isinstance(value, (str, int, float)) or isinstance(value, bool):
            raise ConfigError(f"scenario.sumo_options.{name}", value, "a value as SUMO takes it (a string or a number)")
    return tuple(sorted((k, str(v)) for k, v in pairs))


def network_digest(network: str) -> str:
    """sha256 over the files a network path names (a *.net.xml, or a folder's node, edge and network files, by
    name); "" for a shipped variant's name (a name without a "/": d4sumo's own roads, versioned with it) and a
    path with no such files."""
    files = network_files(network)
    try:
        if len(files) == 1:
            return file_sha256(files[0])
        return hashlib.sha256("".join(f"{f.name}\0{file_sha256(f)}\0" for f in files).encode()).hexdigest() if files else ""
    except OSError as exc:
        raise ConfigError("scenario.network", network, f"a road whose files can be read ({exc.strerror or exc}: "
                                                       f"{exc.filename})") from None
