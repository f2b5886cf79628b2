"""SUMO's command line for an episode, and the files it reads beside the network: the followers' vehicle types
(checked by loading them in SUMO once, cached by their content), the traffic's demand (merged and checked as
SUMO plays it), a scenario's additional files (their outputs sent nowhere) and its options. Each is checked
once, before anything runs, and a file SUMO refuses is one line naming its key. Nothing here runs an episode:
`sumo` does, with this command line.
"""

from __future__ import annotations

import hashlib
import os
import re
import subprocess
import tempfile
from pathlib import Path
from typing import Callable
from xml.sax.saxutils import escape as xml_escape

from ..cache import default_cache_dir
from ..errors import ConfigError, SumoError
from ..model.config import EpisodeConfig
from ..model.world.network import files_digest
from ..model.stepping.platoon import SumoFollower, followers_of
from ..model.world.traffic import demand_files_xml, type_elements
from ..sumohome import sumo_binary, sumo_home
from .scenarios import Road


ROUTE_ID = "platoon"
VTYPE_ID = "d4car"
ATTACKER_VTYPE_ID = "d4attacker"
SPEED_MODE_PYTHON = 32  # all checks off: Python's speed is applied as given
LANE_CHANGE_MODE_OFF = 0  # no lane change of SUMO's own; a TraCI request is carried out without regard to others
LANE_CHANGE_MODE_SUMO = 1621  # SUMO's default: its model changes lanes, respecting others
FCD_PRECISION = 6  # decimals in FCD: gaps recomputed from it agree with the trace to far below 1 cm
#: SUMO's default FCD attributes, the odometer, from which a position along a route of many edges comes
#: (a lane position starts again at 0 on each edge), and the lateral position in the lane, from which a
#: car's place across the lanes comes on a curved road (its y does not tell it there)
FCD_ATTRIBUTES = "x,y,angle,type,speed,pos,lane,slope,acceleration,odometer,posLat"


# --- followers driven by SUMO's car-following models ---------------------------------------------

_CHECKED: dict[str, Path] = {}  # vehicle-type XML -> its checked file, in this process


def follower_types(config: EpisodeConfig) -> dict[tuple, tuple[str, SumoFollower]]:
    """The SUMO-driven followers' distinct (controller, vehicle) -> their vehicle-type id and one such follower."""
    types: dict = {}
    if not config.sumo_driven:  # the common case: nothing to build
        return types
    for follower in followers_of(config):
        if follower.sumo_driven and follower.vtype_key not in types:
            types[follower.vtype_key] = (f"d4{follower.model}{len(types)}", follower)
    return types


def followers_xml(config: EpisodeConfig, road: Road) -> str | None:
    """The vehicle types of the SUMO-driven followers, as SUMO reads them, or None when there are none."""
    types = follower_types(config)
    if not types:
        return None
    lines = ["<additional>"]
    for type_id, follower in types.values():
        attrs = " ".join(f'{k}="{xml_escape(str(v), {chr(34): "&quot;"})}"' for k, v in follower.vtype(road.lanes).items())
        lines.append(f'    <vType id="{type_id}" {attrs}/>')
    lines.append("</additional>")
    return "\n".join(lines) + "\n"


def followers_file(config: EpisodeConfig, road: Road) -> Path | None:
    """The followers' vehicle-type file, checked by loading it in SUMO once (cached by its content and
    SUMO's build).

    SUMO refuses a value its model cannot take (a zero tau, say) only when it loads the type: this turns
    that into a ConfigError before any episode runs. Only a checked file gets its final name.
    """
    text = followers_xml(config, road)
    if text is None:
        return None
    return _checked_file(text, "vtypes", "vehicle types", ".add.xml", lambda sumo, tmp: _check_types(config, road, sumo, tmp))


_DEMANDS: dict[tuple, str] = {}  # the traffic's demand text, by what makes it (its files by path, time and size)
#: the version of the demand's check: a demand an earlier one passed is checked again (2: its vehicle types
#: against SUMO's schema, and errors SUMO goes on after)
DEMAND_CHECK = 2


def traffic_files(config: EpisodeConfig, road: Road) -> list[Path] | None:
    """The traffic's demand as SUMO's route files (`traffic.demand_files_xml`: one for each demand file and
    one for d4sumo's flow, which SUMO merges by departure), checked by loading them together in SUMO once
    (cached like the followers' types): a vehicle type SUMO refuses is a ConfigError naming its table, a
    demand file SUMO refuses (routes over edges the network lacks, say) one naming the file. None without
    traffic."""
    if config.traffic is None:
        return None
    # the user's demand files are read and parsed once a version of them, not at every episode
    files = tuple((p, os.stat(p).st_mtime_ns, os.stat(p).st_size) for p in config.traffic.demand if os.path.isfile(p))
    key = (config.traffic, road.route(0), road.through_lanes, config.traffic.warmup_s + config.total_s + 1.0, files)
    if key not in _DEMANDS:
        _DEMANDS[key] = demand_files_xml(*key[:4])
    texts = _DEMANDS[key]
    check = lambda paths: lambda sumo, tmp: _check_demand(config, road, sumo, paths or [tmp])  # noqa: E731
    if len(texts) == 1:  # (named as before: a campaign's warm-up, named after it, stays where it is cached)
        return [_checked_file(texts[0], "traffic", "traffic demand", ".rou.xml", check(None), version=DEMAND_CHECK)]
    parts = [_checked_file(text, "traffic", "traffic demand", ".rou.xml", lambda sumo, tmp: None) for text in texts]
    # checked together, as SUMO plays them: a file of their names says they passed
    _checked_file("\n".join(p.name for p in parts), "traffic", "traffic demand", ".together", check(parts), version=DEMAND_CHECK)
    return parts


def _checked_file(text: str, kind: str, what: str, suffix: str, check: Callable[[str, str], None], version: int = 1) -> Path:
    """A file SUMO reads, written under d4sumo's cache and named by its content and SUMO's build once
    ``check(sumo, path)`` passed on it; later calls with the same text return it at once. A check of a later
    ``version`` than the one a cached file passed runs again (its name stays: what is named after it, a
    traffic's warm-up, stays too)."""
    if text in _CHECKED and _CHECKED[text].is_file():
        return _CHECKED[text]
    sumo = sumo_binary("sumo")
    build = f"{sumo}:{os.stat(sumo).st_mtime_ns}"  # another SUMO checks again
    folder = Path(default_cache_dir()).parent / kind
    path = folder / f"{hashlib.sha256((build + text).encode()).hexdigest()[:16]}{suffix}"
    passed = path.with_name(f"{path.name}.check{version}") if version > 1 else path  # what says the check passed
    if not path.is_file() or not passed.is_file():
        try:
            folder.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=folder, suffix=suffix)
        except OSError as exc:
            raise SumoError(f"cannot write SUMO's {what} under {folder}: {exc.strerror or exc}") from None
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
            check(sumo, tmp)
            os.replace(tmp, path)
            passed.touch()
        except OSError as exc:
            raise SumoError(f"cannot write SUMO's {what} under {folder}: {exc.strerror or exc}") from None
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    _CHECKED[text] = path
    return path


#: the outputs an additional file's elements write, by element: (the attribute naming the file)
_OUTPUTS = {"edgeData": "file", "laneData": "file", "timedEvent": "dest", "e1Detector": "file", "inductionLoop": "file",
            "e2Detector": "file", "laneAreaDetector": "file", "e3Detector": "file", "entryExitDetector": "file",
            "instantInductionLoop": "file", "routeProbe": "file", "calibrator": "output", "edgeRelations": "file",
            "tazRelations": "file", "vTypeProbe": "file"}
#: the attributes by which an additional file's element reads another file (a VSS's or a rerouter's definitions)
_INPUTS = ("file", "href", "files")
_ADDITIONAL: dict[tuple[str, ...], list[str]] = {}


def additional_files(config: EpisodeConfig) -> list[str]:
    """The scenario's additional files as every episode loads them: where a file writes outputs (a detector's
    file, an edgeData dump, a saved switch state), a copy kept by its content in d4sumo's cache whose outputs go
    nowhere, and whose other files are named from the original's folder; else the file itself. Many episodes
    run side by side, each of which would write them anew, into the folder the file is in; a replay's FCD is
    d4sumo's output."""
    if not config.additional:
        return []
    key = (config.additional_sha256, *config.additional)
    if key not in _ADDITIONAL:
        import xml.etree.ElementTree as ET

        folder = Path(default_cache_dir()).parent / "additional"
        out = []
        for path in config.additional:
            try:
                tree = ET.parse(path)
            except (ET.ParseError, OSError) as exc:
                raise ConfigError("scenario.additional", path, f"a SUMO additional file that parses ({exc})") from None
            outputs = [e for e in tree.getroot().iter() if _OUTPUTS.get(e.tag) in e.attrib]
            if not outputs:  # loaded where it is: the files it names are found as SUMO finds them
                out.append(path)
                continue
            for element in outputs:
                element.set(_OUTPUTS[element.tag], os.devnull)
            here = os.path.dirname(os.path.abspath(path))
            for element in tree.getroot().iter():  # the copy elsewhere: what it reads, named from its own folder
                for name in _INPUTS:
                    given = element.get(name)
                    if given and element not in outputs and not os.path.isabs(given):
                        element.set(name, ",".join(os.path.join(here, p) for p in given.split(",")))
            text = ET.tostring(tree.getroot(), encoding="unicode")
            copy = folder / f"{hashlib.sha256(text.encode()).hexdigest()[:16]}-{Path(path).name}"
            if not copy.is_file():
                try:
                    folder.mkdir(parents=True, exist_ok=True)
                    fd, tmp = tempfile.mkstemp(dir=folder, suffix=".partial")
                    with os.fdopen(fd, "w", encoding="utf-8") as f:
                        f.write(text)
                    os.replace(tmp, copy)
                except OSError as exc:
                    raise SumoError(f"cannot write SUMO's additional files under {folder}: {exc.strerror or exc}") from None
            out.append(str(copy))
        _ADDITIONAL[key] = out
    return _ADDITIONAL[key]


def option_args(config: EpisodeConfig) -> list[str]:
    """The scenario's SUMO options (`EpisodeConfig.sumo_options`) on SUMO's command line."""
    return [arg for name, value in config.sumo_options for arg in (f"--{name}", value)]


def check_options(config: EpisodeConfig, road: Road) -> None:
    """The scenario's SUMO options (`EpisodeConfig.sumo_options`), loaded once by SUMO on the road (cached like the
    followers' types): a value SUMO refuses, or an option it does not know, is a ConfigError naming them in one line."""
    if not config.sumo_options:
        return

    def check(sumo: str, _: str) -> None:
        cmd = [sumo, "--net-file", str(road.net_file), "--end", "0", "--no-step-log", "true",
               *option_args(config)]
        try:
            done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
        except subprocess.TimeoutExpired:
            raise SumoError("SUMO did not load the scenario's options within 120 s") from None
        said = " ".join(ln.strip().removeprefix("Error: ") for ln in done.stderr.splitlines()
                        if ln.strip() and not ln.startswith(("Warning", "Quitting")))
        if done.returncode != 0 or "Error" in done.stderr:
            raise ConfigError("scenario.sumo_options", dict(config.sumo_options), f"options SUMO takes (SUMO: {said})")
    _checked_file("\n".join(f"{k}={v}" for k, v in config.sumo_options), "options", "options", ".checked", check)


def check_additional(config: EpisodeConfig, road: Road) -> None:
    """The scenario's additional files (`EpisodeConfig.additional`), loaded once in SUMO on the road with its options
    (cached like the followers' types): one it refuses, or whose content has changed since the campaign took it, is
    a ConfigError naming them."""
    if not config.additional:
        return
    if files_digest("scenario.additional", config.additional) != config.additional_sha256:
        raise ConfigError("scenario.additional", list(config.additional), "the additional files this campaign was run "
                                                                           "with (their content has changed since)")
    text = "\n".join([str(road.net_file), config.additional_sha256, *config.additional,
                      *(f"{k}={v}" for k, v in config.sumo_options)])

    def check(sumo: str, _: str) -> None:
        horizon = (config.traffic.warmup_s if config.traffic is not None else 0.0) + config.total_s + 1.0  # meandata ends with it
        cmd = [sumo, "--net-file", str(road.net_file), "--additional-files", ",".join(additional_files(config)),
               "--end", repr(horizon), "--no-step-log", "true", "--duration-log.disable", "true", "--no-warnings", "true",
               *option_args(config)]
        message = _sumo_errors(cmd, "the additional files")
        if message is not None:
            raise ConfigError("scenario.additional", list(config.additional), f"additional files SUMO loads on {road.name} "
                                                                               f"(SUMO: {message})")
    _checked_file(text, "additional", "additional files", ".checked", check)


def _sumo_errors(cmd: list[str], what: str, env: dict | None = None) -> str | None:
    """SUMO's first error loading ``cmd`` (None: it loaded)."""
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=120, env=env)
    except subprocess.TimeoutExpired:
        raise SumoError(f"SUMO did not load {what} within 120 s") from None
    # an error SUMO goes on after (an unknown vehicle class: it takes the default) is one too
    errors = [ln.removeprefix("Error: ") for ln in done.stderr.splitlines() if ln.startswith("Error:")]
    if done.returncode == 0 and not errors:
        return None
    return errors[0] if errors else done.stderr.strip() or f"exit {done.returncode}"


#: the root of a file of SUMO's routes that SUMO checks against its schema (an unknown attribute is refused)
_VALIDATED_ROUTES = ('<routes xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" '
                     'xsi:noNamespaceSchemaLocation="http://sumo.dlr.de/xsd/routes_file.xsd">')


def _sumo_home_known() -> bool:
    """Whether SUMO's installation folder is known (not only its programs, on the PATH)."""
    try:
        sumo_home()
    except SumoError:
        return False
    return True


def _check_demand(config: EpisodeConfig, road: Road, sumo: str, demand: list) -> None:
    # played as far as the episodes play it: a flow without an end ends with the simulation, and one that
    # begins after an earlier end is refused ("ends before its begin time"), which SUMO plays without one
    horizon = config.traffic.warmup_s + config.total_s + 1.0
    cmd = [sumo, "--net-file", str(road.net_file), "--step-length", repr(config.step_s),
           "--end", repr(horizon), "--no-step-log", "true", "--duration-log.disable", "true", "--no-warnings", "true",
           *(["--additional-files", ",".join(additional_files(config))] if config.additional else []),
           *option_args(config)]
    message = None
    xsd = Path(sumo_home(), "data", "xsd") if _sumo_home_known() else None
    if config.traffic.types and config.traffic.vehicles_per_hour is not None and xsd is not None and xsd.is_dir():
        # the types first, alone, against SUMO's schema (found in SUMO_HOME): a misspelt attribute
        # ("speedfactor") is otherwise taken without a word
        types = f"{demand[-1]}.types.rou.xml"
        try:
            Path(types).write_text("\n".join([_VALIDATED_ROUTES, *type_elements(config.traffic), "</routes>"]) + "\n")
            message = _sumo_errors(cmd + ["--route-files", types], "the traffic's vehicle types",
                                   env={**os.environ, "SUMO_HOME": sumo_home()})
        finally:
            Path(types).unlink(missing_ok=True)
    message = message or _sumo_errors(cmd + ["--route-files", ",".join(str(p) for p in demand)], "the traffic's demand")
    if message is None:
        return
    named = re.search(r"[Aa]ttribute '?(\w+)'?", message)
    attribute = (named.group(1) if named else "carFollowModel" if "car following model" in message
                 else "laneChangeModel" if "lane change model" in message else "vClass" if "vehicle class" in message
                 else None)
    for name, attributes in config.traffic.types:
        if attribute in dict(attributes):
            field = f"traffic.types.{name}.{attribute}"
            what = "an attribute of SUMO's <vType>" if "is not declared" in message else "a value SUMO's <vType> accepts"
            raise ConfigError(field, dict(attributes)[attribute], f"{what} (SUMO: {message})")
    if config.traffic.demand:
        raise ConfigError("traffic.demand", list(config.traffic.demand), f"demand SUMO plays on {road.name} (SUMO: {message})")
    raise ConfigError("traffic", config.traffic.label, f"traffic SUMO can insert on {road.name} (SUMO: {message})")


def _check_types(config: EpisodeConfig, road: Road, sumo: str, types_file: str) -> None:
    cmd = [sumo, "--net-file", str(road.net_file), "--additional-files", types_file, "--step-length",
           repr(config.step_s), "--end", "0", "--no-step-log", "true", "--duration-log.disable", "true"]
    message = _sumo_errors(cmd, "the followers' vehicle types")
    if message is None:
        return
    # Name the attribute SUMO refused, in the table of the first follower that sets it.
    named = re.search(r"Attribute '?(\w+)'?", message)
    field = "controller"
    if named:
        for c in config.controllers:
            if named.group(1) in dict(c.params):
                field, given = f"{c.where}.{named.group(1)}", dict(c.params)[named.group(1)]
                raise ConfigError(field, given, f"a value SUMO's {c.sumo_model} model accepts (SUMO: {message})")
    raise ConfigError(field, config.system_label, f"parameters SUMO accepts (SUMO: {message})")


def sumo_command(config: EpisodeConfig, road: Road, fcd_path: str | Path | None = None, binary: str = "sumo", *,
                 types_file: Path | None = None, demand_files: list[Path] | None = None,
                 state_file: Path | None = None) -> list[str]:
    """The SUMO command line, as one explicit list; ``types_file``: the followers' vehicle types, as
    `check_episode` returns them; ``demand_files``: the traffic's (`traffic_files`), to warm it up;
    ``state_file``: the warmed-up traffic (`traffic_state`), to play an episode in it."""
    cmd = [
        binary,
        "--net-file", str(road.net_file),
        "--begin", "0",
        "--step-length", repr(config.step_s),
        "--step-method.ballistic", "true",
        "--collision.action", "warn",
        "--collision.mingap-factor", "0",
        "--collision.check-junctions", "false",
        "--insertion-checks", "none",
        "--seed", str(config.traffic.seed if config.traffic else 0),
        "--no-step-log", "true",
        "--no-warnings", "true",
        "--duration-log.disable", "true",
        # SUMO's output precision reaches its car-following: a Krauss follower answering a cut-in moved
        # 5 mm apart with the FCD's 6 decimals and without them. One precision for every run, so a replay
        # that writes FCD is the campaign's episode.
        "--precision", str(FCD_PRECISION),
    ]
    additional = [*([str(types_file)] if types_file is not None else []), *additional_files(config)]
    if additional:  # the followers' vehicle types, and the scenario's own files (a .sumocfg's)
        cmd += ["--additional-files", ",".join(additional)]
    cmd += option_args(config)  # a .sumocfg's options that change nothing d4sumo decides
    if demand_files:  # SUMO merges them by departure
        cmd += ["--route-files", ",".join(str(p) for p in demand_files)]
    if state_file is not None:  # the traffic's vehicles, flows and random streams at the end of its warm-up
        cmd += ["--load-state", str(state_file)]
    if config.traffic is not None:  # a traffic car queued to enter must not hold the platoon back in the queue
        cmd += ["--eager-insert", "true"]
    if config.maneuver_class.lateral and config.lane_change_s > 0:  # the attacker moves across over this time
        cmd += ["--lanechange.duration", repr(config.lane_change_s)]
    if fcd_path is not None:
        cmd += ["--fcd-output", str(fcd_path), "--fcd-output.attributes", FCD_ATTRIBUTES,
                "--fcd-output.acceleration", "true"]
        if config.traffic is not None:  # from the platoon's insertion on, not the traffic's warm-up
            cmd += ["--device.fcd.begin", repr(config.traffic.warmup_s)]
    if binary != "sumo":  # sumo-gui: start at once and leave the window open at the end
        cmd += ["--start", "true", "--quit-on-end", "false", "--delay", "50"]
    return cmd
