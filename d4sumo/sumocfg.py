"""A SUMO configuration file (``*.sumocfg``) as the scenario: what ``--network scenario.sumocfg`` means.

A user's SUMO scenario *is* a ``.sumocfg``: its network, its demand, its additional files and its options.
`expand` lays them over an input document, as the keys d4sumo has for each, before anything is checked:

- ``net-file``: ``scenario.network`` (run as given);
- ``route-files``: ``traffic.demand``, merged by departure as SUMO merges them;
- ``additional-files``: ``scenario.additional`` (detectors, variable speed signs, rerouters, signal programmes
  of one's own, vehicle types), loaded by every episode and its traffic's warm-up;
- options that change nothing d4sumo decides (`model.network.passed_option`): ``scenario.sumo_options``, given to SUMO as they are.

Paths are taken relative to the ``.sumocfg``'s folder, as SUMO takes them. What d4sumo sets itself
(`OWN`: the clock, the step, the collisions, the random seed, insertion) is overridden, each named in one
note; outputs and what only the GUI or the log reads are left out, likewise. Any other option, one that
would change what d4sumo's episodes mean (a sublane model, another time step's semantics), is refused in one
line naming it, as are a file that does not parse and one that names a missing file.
"""

from __future__ import annotations

import copy
import logging
import os
from pathlib import Path
from typing import Any, Mapping
from xml.etree import ElementTree as ET

from .errors import ConfigError
from .model.world.network import SUMO_OPTION_GROUPS_PASSED as GROUPS, SUMO_OPTIONS_PASSED as PASSED, passed_option

log = logging.getLogger(__name__)

SUFFIX = ".sumocfg"
#: options d4sumo sets itself for every episode: the file's value is overridden
OWN = {
    "begin": "the platoon's clock starts at 0, after its traffic's warm-up",
    "end": "scenario.duration_s",
    "step-length": "scenario.step_s",
    "step-method.ballistic": "the ballistic update",
    "collision.action": "warn, every collision d4sumo's to see",
    "collision.mingap-factor": "0, bumper overlaps",
    "collision.check-junctions": "d4sumo sees collisions inside junctions, in 2D",
    "seed": "traffic.seed",
    "random": "traffic.seed",
    "insertion-checks": "traffic.insertion_checks for the traffic, none for the platoon",
    "eager-insert": "on among traffic",
    "lanechange.duration": "scenario.lane_change_s",
    "precision": "6 decimals",
    "load-state": "the traffic's warm-up",
}
#: options left out: what only a window, a log or an output file reads (d4sumo writes FCD itself, on replay)
_LEFT_OUT_PARTS = ("output", "log", "verbose", "gui", "window", "delay", "start", "quit-on-end", "statistic", "summary",
                   "tripinfo", "vehroute", "duration", "xml-validation", "no-warnings", "save-", "configuration",
                   "print-options", "help", "version", "write-license")
#: the file options, and where they go
_FILES = {"net-file": "scenario.network", "route-files": "traffic.demand", "additional-files": "scenario.additional"}
_ALIASES = {"n": "net-file", "r": "route-files", "a": "additional-files", "b": "begin", "e": "end", "s": "route-steps"}


def is_sumocfg(network: Any) -> bool:
    return isinstance(network, str) and network.endswith(SUFFIX)


def read(path: str) -> dict[str, str]:
    """The options a ``.sumocfg`` sets, by their long names, as written."""
    try:
        root = ET.parse(path).getroot()
    except ET.ParseError as exc:
        raise ConfigError("scenario.network", path, f"a SUMO configuration file that parses (XML: {exc})") from None
    except OSError as exc:
        raise ConfigError("scenario.network", path, f"a readable SUMO configuration file ({exc.strerror or exc})") from None
    if root.tag not in ("configuration", "sumoConfiguration"):
        raise ConfigError("scenario.network", path, f"a SUMO configuration file, its root <configuration> (this one's is <{root.tag}>)")
    options: dict[str, str] = {}
    for element in root.iter():
        if element is root or "value" not in element.attrib:
            continue  # a section (<input>, <time>, ...)
        options[_ALIASES.get(element.tag, element.tag)] = element.get("value", "")
    return options


def expand(doc: Mapping[str, Any]) -> dict:
    """The document with its ``scenario.network``'s ``.sumocfg`` laid over it (see the module); as it is
    where the network is no ``.sumocfg``. What it overrides and leaves out is said (`expanded`)."""
    out, note = expanded(doc)
    if note:
        log.warning("%s", note)
    return out


def expanded(doc: Mapping[str, Any]) -> tuple[dict, str]:
    """`expand`'s document, and the note that says what of the ``.sumocfg`` d4sumo overrides and leaves out
    ("": nothing), for the caller to say once the document is sound."""
    network = doc.get("scenario", {}).get("network") if isinstance(doc.get("scenario"), Mapping) else None
    if not is_sumocfg(network):
        return dict(doc), ""
    options = read(network)
    folder = os.path.dirname(network)
    out = copy.deepcopy(dict(doc))
    scenario = out["scenario"]
    files = {key: [os.path.join(folder, p) for p in options.pop(key, "").replace(",", " ").split()] for key in _FILES}
    if len(files["net-file"]) != 1:
        raise ConfigError(f"{network}: net-file", options.get("net-file", ""), "one network file")
    for key, paths in files.items():
        for p in paths:
            if not Path(p).is_file():
                raise ConfigError(f"{network}: {key}", p, "a file that exists (paths are taken from the .sumocfg's folder)")
    scenario["network"] = files["net-file"][0]
    if files["route-files"]:
        traffic = out.setdefault("traffic", {})
        if not isinstance(traffic, dict) or traffic.get("demand"):
            raise ConfigError("traffic.demand", traffic.get("demand") if isinstance(traffic, dict) else traffic,
                              f"none beside {network}, whose route files are the demand")
        traffic["demand"] = files["route-files"]
    if files["additional-files"]:
        given = scenario.get("additional", [])
        if not isinstance(given, list) or not all(isinstance(p, str) for p in given):
            raise ConfigError("scenario.additional", given, f"a list of SUMO additional files beside {network}'s")
        scenario["additional"] = [*given, *files["additional-files"]]
    passed, overridden, left_out = {}, [], []
    for name, value in options.items():
        if name in OWN:
            overridden.append(f"{name} = {value} ({OWN[name]})")
        elif passed_option(name):
            passed[name] = value
        elif any(part in name for part in _LEFT_OUT_PARTS) or name == "route-steps":
            left_out.append(name)
        else:
            raise ConfigError(f"{network}: {name}", value, f"an option d4sumo can honour, one of {', '.join(PASSED)}, "
                                                           f"{', '.join(p + '*' for p in GROUPS)} (or leave "
                                                           "it out: d4sumo sets the clock, the step, collisions, seeds and "
                                                           "insertion itself, and reads no sublane model)")
    if passed:
        given = scenario.get("sumo_options", {})
        if not isinstance(given, Mapping):
            raise ConfigError("scenario.sumo_options", given, "a table of SUMO options, e.g. {time-to-teleport = \"-1\"}")
        scenario["sumo_options"] = {**passed, **given}
    said = ([f"overridden by d4sumo's own: {', '.join(overridden)}"] if overridden else []) + (
        [f"left out: {', '.join(left_out)} (outputs, and what only the GUI or the log reads)"] if left_out else [])
    return out, f"{network}: {'; '.join(said)}" if said else ""
