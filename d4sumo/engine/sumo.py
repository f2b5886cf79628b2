"""The SUMO world: the only module that talks to SUMO (libsumo, or traci for sumo-gui).

SUMO moves the cars (ballistic update). Python commands the speed of the attacker and of every
Python-commanded follower (SUMO's car-following, lane changing and speed checks are off for them:
speed mode 32, lane-change mode 0); followers driven by SUMO's own car-following models run with their
vehicle type, loaded from an additional file checked once per content, with SUMO's default speed mode.
`SumoWorld` is the seam the step loop (`engine.loop.play`) drives: insert, sense, apply speeds, step,
remove. Many platoons share one SUMO each on its own copy of the road (`scenarios.batch_road`).
"""

from __future__ import annotations

import functools
import gzip
import hashlib
import math
import os
import re
import subprocess
import tempfile
import time
from pathlib import Path
from typing import Callable, Sequence
from xml.sax.saxutils import escape as xml_escape, unescape as xml_unescape

import numpy as np

from ..errors import ConfigError, SumoError
from ..model.config import EpisodeConfig
from ..model.maneuvers import CAR_WIDTH_M, FREE_ROAD_GAP_M, Pair, lane_pairs, maneuver_of, occupied_lanes
from ..model.carfollowing import beacon_parameters, vehicle_data
from ..model.platoon import SumoFollower, followers_of
from ..model.traffic import demand_files_xml, type_elements
from ..model.vehicle import VehicleParams
from ..sumohome import sumo_binary, sumo_home
from .calls import api_call
from .junctions import JunctionCrossings
from .lights import RouteLights, route_signals, signal_tracks
from ..cache import default_cache_dir
from .scenarios import Road

ROUTE_ID = "platoon"
VTYPE_ID = "d4car"
ATTACKER_VTYPE_ID = "d4attacker"
SPEED_MODE_PYTHON = 32  # all checks off: Python's speed is applied as given
LANE_CHANGE_MODE_OFF = 0  # no lane change of SUMO's own; a TraCI request is carried out without regard to others
LANE_CHANGE_MODE_SUMO = 1621  # SUMO's default: its model changes lanes, respecting others
FCD_PRECISION = 6  # decimals in FCD: gaps recomputed from it agree with the trace to far below 1 cm
#: SUMO's default FCD attributes and the odometer, from which a position along a route of many edges
#: comes (a lane position starts again at 0 on each edge)
FCD_ATTRIBUTES = "x,y,angle,type,speed,pos,lane,slope,acceleration,odometer"


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
    from ..model.config import files_digest

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


def load_platoon(api, config: EpisodeConfig, road: Road, episodes: int = 1,
                 configs: Sequence[EpisodeConfig] | None = None) -> list[tuple[str, ...]]:
    """Insert every car of the maneuver, each in its lane, and hand Python the ones it commands; with
    ``episodes`` > 1, one platoon on each copy of the road (`scenarios.batch_road`), each placed as
    its own entry of ``configs`` says (default: ``config``). Returns each platoon's SUMO vehicle ids,
    in the order of ``config.vehicle_ids`` (the same ids for one platoon)."""
    own_types = {config.vehicle: VTYPE_ID}  # the vehicle types of the cars Python commands, by vehicle

    def type_of(v: VehicleParams) -> str:
        if v not in own_types:
            own_types[v] = f"{VTYPE_ID}{len(own_types)}"
            _define_type(api, own_types[v], v)
        return own_types[v]

    _define_type(api, VTYPE_ID, config.vehicle)
    types = follower_types(config)
    followers = followers_of(config) if types else []
    attacker_type = type_of(config.vehicle_of(0))
    if types:  # the attacker's own type: what SUMO's models believe of its brakes
        api.vehicletype.copy(attacker_type, ATTACKER_VTYPE_ID)
        api.vehicletype.setApparentDecel(ATTACKER_VTYPE_ID, config.attacker_declared_decel_mps2)
        attacker_type = ATTACKER_VTYPE_ID
    n = config.followers + 1
    type_ids = [attacker_type] + [types[followers[i - 1].vtype_key][0] if types and followers[i - 1].sumo_driven
                                  else type_of(config.vehicle_of(i)) for i in range(1, n)]
    type_ids += [type_of(config.vehicle_of(i)) for i in range(n, len(config.vehicle_ids))]  # the benign lead or the obstacle
    configs = configs or [config] * episodes
    placed = {id(c): maneuver_of(c).cars() for c in configs}
    platoons = [config.vehicle_ids if episodes == 1 else tuple(f"{e}.{vid}" for vid in config.vehicle_ids)
                for e in range(episodes)]
    depart = "now" if config.traffic is not None else "0"  # after the traffic's warm-up, else at SUMO's start
    for e, ids in enumerate(platoons):
        route = f"{ROUTE_ID}{e}" if episodes > 1 else ROUTE_ID
        api.route.add(route, list(road.route(e)))
        for vid, car, type_id in zip(ids, placed[id(configs[e])], type_ids):
            api.vehicle.add(vid, route, typeID=type_id, depart=depart, departLane=str(road.platoon_lane + car.lane),
                            departPos=repr(car.position_m), departSpeed=repr(car.speed_mps))
    api.simulationStep()  # inserts the cars: this state is t = 0
    present = set(api.vehicle.getIDList())
    missing = [vid for ids in platoons for vid in ids if vid not in present]
    if missing:
        raise SumoError(f"SUMO did not insert {', '.join(missing[:5])} on {road.name}")
    for ids in platoons:
        for vid in ids:
            api.vehicle.setLaneChangeMode(vid, LANE_CHANGE_MODE_OFF)
        for vid in (ids[0], *ids[n:]):
            api.vehicle.setSpeedMode(vid, SPEED_MODE_PYTHON)
        for i, vid in enumerate(ids[1:n], start=1):
            if not (types and followers[i - 1].sumo_driven):
                api.vehicle.setSpeedMode(vid, SPEED_MODE_PYTHON)
                continue
            for key, value in followers[i - 1].parameters().items():
                api.vehicle.setParameter(vid, key, value)
    return platoons


def _define_type(api, type_id: str, v: VehicleParams) -> None:
    """A vehicle type of a car Python commands: its body and limits, no checks of SUMO's own."""
    api.vehicletype.copy("DEFAULT_VEHTYPE", type_id)
    if v.vclass != "passenger":
        api.vehicletype.setVehicleClass(type_id, v.vclass)
    if v.shape:
        api.vehicletype.setShapeClass(type_id, v.shape)
    api.vehicletype.setLength(type_id, v.length_m)
    api.vehicletype.setWidth(type_id, CAR_WIDTH_M)
    api.vehicletype.setMinGap(type_id, 0.0)
    api.vehicletype.setMaxSpeed(type_id, 100.0)  # Python clamps speeds itself
    api.vehicletype.setAccel(type_id, v.max_accel_mps2)
    api.vehicletype.setDecel(type_id, v.max_decel_mps2)
    api.vehicletype.setEmergencyDecel(type_id, v.max_decel_mps2)
    api.vehicletype.setImperfection(type_id, 0.0)
    api.vehicletype.setSpeedDeviation(type_id, 0.0)


def vehicle_call(api, name: str):
    """``api.vehicle.<name>``, bound (`calls.api_call`)."""
    return api_call(api, "vehicle", name)


def simulation_step(api):
    """``api.simulationStep``; for libsumo its C function (d4sumo registers no step listeners)."""
    raw = getattr(getattr(api, "_libsumo", None), "simulation_step", None)
    return functools.partial(raw, 0.0) if raw else api.simulationStep  # a partial: no Python frame a step


def route_position(api, road: Road, vehicle_ids: Sequence[str]) -> Callable[[str], float]:
    """A reader of each car's position along its route [m], its front bumper.

    On a road of one edge that is SUMO's lane position. On a route of many edges the lane position
    starts again at 0 on each edge (and on each junction's internal lane), so the position is where the
    car was inserted plus SUMO's odometer, the distance it has driven since, across edges and
    junctions. Call it right after the cars are inserted (t = 0, odometer 0).
    """
    get_position = vehicle_call(api, "getLanePosition")
    if road.one_edge:
        return get_position
    departed = {vid: get_position(vid) for vid in vehicle_ids}  # every car starts on the route's first edge
    get_distance = vehicle_call(api, "getDistance")
    return lambda vid: departed[vid] + get_distance(vid)



class _Lateral:
    """The attacker's lane change, and where it is across the road at each step: the lanes it covers."""

    def __init__(self, api, maneuver, road: Road, attacker: str = "v0"):
        self.api = api
        self.attacker = attacker
        self.width = road.lane_width_m
        self.base = road.platoon_lane  # a maneuver counts lanes from the platoon's (it keeps its index: `check_road`)
        lanes = maneuver.start_lanes()
        self.fixed = [(lane,) for lane in lanes[1:]]  # only the attacker changes lanes
        self.fixed_y = [(lane + 0.5) * self.width for lane in lanes[1:]]
        self.y: list[float] = []
        self.get_lane = api.vehicle.getLaneIndex
        self.get_lateral = api.vehicle.getLateralLanePosition

    def change_lane(self, lane: int) -> None:
        # SUMO carries it out (over scenario.lane_change_s, or in one step); the request holds until the next
        self.api.vehicle.changeLane(self.attacker, self.base + lane, 1e6)

    def sense(self) -> list[tuple[int, ...]]:
        y = (self.get_lane(self.attacker) - self.base + 0.5) * self.width + self.get_lateral(self.attacker)
        self.y.append(y)
        return [occupied_lanes(y, self.width), *self.fixed]

    def rows(self) -> np.ndarray:
        return np.column_stack([self.y, *(np.full(len(self.y), y) for y in self.fixed_y)])


class _LanePathCheck:
    """That every car that keeps its lane drives the road's lane path (`Road.lane_path`), edge by edge.

    Where the platoon's lane joins several lanes of the next edge, d4sumo takes the one that leads on
    through the route; SUMO takes the one that leads on furthest within the distance it looks ahead, which
    on a long enough route may be a lane that ends later on. A car there would stop at its end: a
    collision of SUMO's doing, no verdict. The episode ends with a SumoError naming the car and the lanes."""

    def __init__(self, api, config: EpisodeConfig, road: Road, platoons: list[tuple[str, ...]], maneuver):
        path = road.platoon_path
        offsets = [car.lane for car in maneuver.cars()]
        keeping = [i for i in range(len(config.vehicle_ids)) if not (maneuver.lateral and i == 0)]  # the attacker changes
        self.cars = [(vid, {edge: lane + offsets[i] for edge, lane in zip(road.route(e), path)}, e)
                     for e, ids in enumerate(platoons) for i, vid in enumerate(ids) if i in keeping]
        self.get_lane = vehicle_call(api, "getLaneID")
        self.removed: set[int] = set()
        self.name = road.name

    def __call__(self) -> None:
        for vid, expected, e in self.cars:
            if e in self.removed:
                continue
            lane = self.get_lane(vid)
            if lane.startswith(":"):  # a junction's lane
                continue
            edge, _, index = lane.rpartition("_")
            if expected.get(edge, int(index)) != int(index):
                raise SumoError(
                    f"SUMO drove {vid.rpartition('.')[2]} into lane {lane} of {self.name}, not lane {expected[edge]} that "
                    f"leads on through the route: where its lane joins several lanes of the next edge, SUMO looks ahead "
                    f"a limited distance; name a shorter scenario.route, or a scenario.lane without such a junction")


#: the version of the warm-up d4sumo saves: a cached state of another is warmed up again
TRAFFIC_STATE = 1
#: a flow's or a vehicle's element in SUMO's saved state that does not say its insertion checks: its id
_UNCHECKED = re.compile(rb'<(?:flowState|vehicle) id="([^"]*)"(?![^>]*\binsertionChecks=)')


def traffic_state(config: EpisodeConfig, road: Road) -> Path | None:
    """The traffic at the end of its warm-up (`traffic.TrafficParams`), as SUMO's saved state (its
    vehicles, flows and random streams), or None without traffic. Every episode of the configuration loads
    it and so meets the same traffic; it is warmed up once per SUMO build, road, demand, seed, step and
    warm-up, and kept in d4sumo's cache (a warm-up of 300 s costs as much as five 60 s episodes).

    The warm-up plays the traffic alone. A density SUMO cannot insert (more than two vehicles per lane, and
    a tenth of the demand, still waiting to enter at its end) and a collision among the traffic are refused:
    neither is the platoon's doing."""
    if config.traffic is None:
        return None
    demands = traffic_files(config, road)
    sumo = sumo_binary("sumo")
    key = "\0".join([f"{sumo}:{os.stat(sumo).st_mtime_ns}", str(TRAFFIC_STATE), road.net_file.name, ",".join(d.name for d in demands),
                     str(config.traffic.seed), repr(config.step_s), repr(config.traffic.warmup_s),
                     # what else its SUMO loads: a .sumocfg's additional files and options change the traffic
                     *([config.additional_sha256] if config.additional else []), *(f"{k}={v}" for k, v in config.sumo_options),
                     *(["insertion-checks", "a process of its own"] if config.traffic.insertion_checks else [])])
    folder = Path(default_cache_dir()).parent / "traffic-states"
    path = folder / f"{hashlib.sha256(key.encode()).hexdigest()[:16]}.xml.gz"
    if path.is_file():
        try:  # used now: the last a full cache lets go (`_prune`)
            os.utime(path)
        except OSError:  # a cache one may read, not write
            pass
        return path
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".xml.gz")
        os.close(fd)
    except OSError as exc:
        raise SumoError(f"cannot write the traffic's warm-up under {folder}: {exc.strerror or exc}") from None
    cmd = sumo_command(config, road, demand_files=demands) + ["--save-state.rng", "true", "--save-state.precision", "17"]
    try:
        _warm_up_alone(cmd, config, road, tmp)
        if config.traffic.insertion_checks:
            _keep_insertion_checks(Path(tmp), demands)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    _prune(folder, TRAFFIC_STATES_KEPT)
    return path


#: the traffic warm-ups the cache keeps, the most recently used (a few kB each): a campaign whose samples each meet
#: traffic of their own warms up one a sample
TRAFFIC_STATES_KEPT = 4096
#: a cached file used this recently is never let go [s]: another process may be about to load it
IN_USE_S = 3600.0


def _prune(folder: Path, kept: int) -> None:
    """The cache ``folder`` down to its ``kept`` most recently used files, none used within `IN_USE_S`."""
    try:
        files = [(f.stat().st_mtime, f) for f in folder.iterdir() if f.is_file()]
    except OSError:
        return
    if len(files) <= kept:
        return
    now = time.time()
    for used, f in sorted(files)[:len(files) - kept]:
        if now - used > IN_USE_S:
            try:
                f.unlink()
            except OSError:  # another process let it go first
                pass


def _warm_up_alone(cmd: list[str], config: EpisodeConfig, road: Road, state: str) -> None:
    """The warm-up, its state saved to ``state``, in a process of its own: SUMO's stream of random numbers for
    the demand it reads (a flow's random headways) counts its draws across the simulations of a process, and
    the saved state holds that count, which its loading replays; a state saved in a process that ran other
    simulations before met other traffic once loaded (the gap to the car ahead of the attacker 38.9 m, not
    55.4 m). A fresh process saves the same state on every machine."""
    import pickle
    import sys

    with tempfile.TemporaryDirectory() as work:
        given, said = Path(work, "given.pickle"), Path(work, "said.pickle")
        given.write_bytes(pickle.dumps((os.getpid(), cmd, config, road, state)))
        code = "import sys; from d4sumo.engine.sumo import _warm_up_here; _warm_up_here(sys.argv[1], sys.argv[2])"
        done = subprocess.run([sys.executable, "-c", code, str(given), str(said)], capture_output=True, text=True)
        if not said.is_file():
            last = (done.stderr.strip().splitlines() or [f"exit {done.returncode}"])[-1]
            raise SumoError(f"the traffic's warm-up failed: {last}")
        outcome = pickle.loads(said.read_bytes())
    if outcome is not None:
        kind, what = outcome
        raise ConfigError(*what) if kind == "config" else SumoError(what)


def _warm_up_here(given: str, said: str) -> None:
    """`_warm_up_alone`'s process: plays the warm-up, saves its state, and says how it ended (None: saved)."""
    import pickle

    import libsumo

    from ..processes import die_with_parent

    parent, cmd, config, road, state = pickle.loads(Path(given).read_bytes())
    die_with_parent(parent)
    outcome = None
    try:
        libsumo.start(cmd)
        try:
            _warm_up(libsumo, config, road)
            libsumo.simulation.saveState(state)
        finally:
            libsumo.close()
    except ConfigError as exc:
        outcome = ("config", (exc.field, exc.given, exc.allowed))
    except libsumo.TraCIException as exc:
        outcome = ("sumo", f"SUMO failed in the traffic's warm-up: {exc}")
    Path(said).write_bytes(pickle.dumps(outcome))


def _keep_insertion_checks(state: Path, demands: list[Path]) -> None:
    """SUMO's saved state drops what the demand says of its flows' and vehicles' insertion checks (1.28), and
    the episode inserts with none (the platoon's cars are placed where they are put): each flow and vehicle
    in the state is given back its demand's (`traffic.demand_xml`: all of them where a user's sets none; a
    flow's vehicle, its flow's), so that a car entering after the warm-up does not land on the one before it."""
    import xml.etree.ElementTree as ET

    checks = {e.get("id"): e.get("insertionChecks", "all") for demand in demands for e in ET.parse(demand).getroot() if e.get("id")}

    def given(match: re.Match) -> bytes:
        vid = xml_unescape(match.group(1).decode())
        value = checks.get(vid) or checks.get(vid.rpartition(".")[0]) or "all"
        return match.group(0) + f' insertionChecks="{xml_escape(value)}"'.encode()

    with gzip.open(state, "rb") as f:
        text = f.read()
    with gzip.open(state, "wb") as f:
        f.write(_UNCHECKED.sub(given, text))


def _warm_up(api, config: EpisodeConfig, road: Road) -> None:
    traffic = config.traffic
    step = simulation_step(api)
    departed = 0
    for _ in range(int(round(traffic.warmup_s / config.step_s))):
        step()
        departed += api.simulation.getDepartedNumber()
        if api.simulation.getCollidingVehiclesNumber():
            crashed = api.simulation.getCollidingVehiclesIDList()
            raise ConfigError("traffic", traffic.label, f"traffic that does not crash on its own on {road.name} ({', '.join(crashed[:2])} "
                                                        f"collided at {api.simulation.getTime():g} s of its warm-up, before the platoon joined)")
    # Poisson arrivals queue for a moment now and then; a density beyond what the road takes queues for good
    waiting = len(api.simulation.getPendingVehicles())
    if waiting > 2 * len(road.through_lanes) and waiting > 0.1 * (departed + waiting):
        raise ConfigError("traffic.vehicles_per_hour", traffic.vehicles_per_hour,
                          f"a density SUMO can insert on {road.name}: {waiting} of {departed + waiting} vehicles still waited "
                          f"to enter after the {traffic.warmup_s:g} s warm-up")


def clear_platoon_places(api, config: EpisodeConfig, road: Road) -> int:
    """Make room for the platoon in the warmed-up traffic: every traffic car whose body is in a lane of the
    platoon's on the first edge, from ``clear_m`` behind its rear bumper to ``clear_m`` ahead of its front
    car, leaves, and so do the cars queued to enter the road (they would enter before the platoon, into
    its places). Returns how many left."""
    removed = 0
    for vid in api.simulation.getPendingVehicles():
        api.vehicle.remove(vid)
        removed += 1
    zone = _platoon_zone(config, road)
    for lane in sorted(zone[0]):
        for vid in api.lane.getLastStepVehicleIDs(lane):
            if _in_zone(api, vid, zone):
                api.vehicle.remove(vid)
                removed += 1
    return removed


#: how many steps after the traffic's warm-up the platoon may try to join it (`join_traffic`)
MAX_JOINS = 50


def join_traffic(api, config: EpisodeConfig, road: Road, later: int) -> list[tuple[str, ...]] | None:
    """The platoon joins the warmed-up traffic (SUMO started in `traffic_state`) ``later`` steps after its
    warm-up: its places cleared (`clear_platoon_places`), its cars inserted (`load_platoon`). A traffic car
    that enters the road, or changes lanes, in the same step does not see the platoon and may land within
    ``clear_m`` of one of its cars: then None, and the caller starts again a step later (the same steps in every episode of the configuration:
    the traffic is the same). Else the platoon's vehicle ids, as `load_platoon` returns them."""
    step = simulation_step(api)
    for _ in range(later):
        step()
    clear_platoon_places(api, config, road)
    # the traffic beside the platoon's places keeps its lane in the step the platoon joins: it would not see
    # the platoon yet, and change into its places
    beside = _beside_platoon(api, config, road)
    for vid in beside:
        api.vehicle.setLaneChangeMode(vid, LANE_CHANGE_MODE_OFF)
    platoons = load_platoon(api, config, road)
    for vid in beside:
        if vid in api.vehicle.getIDList():
            api.vehicle.setLaneChangeMode(vid, LANE_CHANGE_MODE_SUMO)
    ours = set(platoons[0])
    first = road.route_edges[0]
    lengths = dict(zip(config.vehicle_ids, config.car_vehicles))
    near: dict[str, list[tuple[float, float]]] = {}  # each lane's stretches within clear_m of a car of the platoon
    for car in maneuver_of(config).cars():
        lane = f"{first}_{road.platoon_lane + car.lane}"
        near.setdefault(lane, []).append((car.position_m - lengths[car.id].length_m - config.traffic.clear_m,
                                          car.position_m + config.traffic.clear_m))
    for lane, stretches in sorted(near.items()):  # a car that entered the road, or changed lanes, in that step
        for vid in api.lane.getLastStepVehicleIDs(lane):
            if vid in ours:
                continue
            front = api.vehicle.getLanePosition(vid)
            back = front - api.vehicle.getLength(vid)
            if any(front > low and back < high for low, high in stretches):
                return None
    return platoons


def _beside_platoon(api, config: EpisodeConfig, road: Road) -> list[str]:
    """The traffic cars in the lanes next to the platoon's, along its places (`_platoon_zone`)."""
    lanes, rear, front = _platoon_zone(config, road)
    first = road.route_edges[0]
    indices = {int(lane.rpartition("_")[2]) for lane in lanes}
    beside = sorted({f"{first}_{i + d}" for i in indices for d in (-1, 1) if 0 <= i + d < api.edge.getLaneNumber(first)} - lanes)
    return [vid for lane in beside for vid in api.lane.getLastStepVehicleIDs(lane)
            if _in_zone(api, vid, ({lane}, rear, front))]


def _platoon_zone(config: EpisodeConfig, road: Road) -> tuple[set[str], float, float]:
    """The platoon's places on the first edge: its lanes (SUMO's ids), and from ``clear_m`` behind its rear
    bumper to ``clear_m`` ahead of its front car [m]."""
    cars = maneuver_of(config).cars()
    lanes = {f"{road.route_edges[0]}_{road.platoon_lane + car.lane}" for car in cars}
    lengths = dict(zip(config.vehicle_ids, config.car_vehicles))
    rear = min(car.position_m - lengths[car.id].length_m for car in cars) - config.traffic.clear_m
    front = max(car.position_m for car in cars) + config.traffic.clear_m
    return lanes, rear, front


def _in_zone(api, vid: str, zone: tuple[set[str], float, float]) -> bool:
    lanes, rear, front = zone
    if api.vehicle.getLaneID(vid) not in lanes:
        return False
    position = api.vehicle.getLanePosition(vid)
    return position > rear and position - api.vehicle.getLength(vid) < front


class _TrafficSense:
    """Who is ahead of each car of one platoon in its lane, a traffic car included, as SUMO's leader says,
    and who follows its rear car: the pairs of the step (`maneuvers.Pair`), with the traffic cars in them.

    Between two platoon cars next to each other it is their pair, its gap from their positions (the
    arithmetic of the platoon alone, bit for bit); where a traffic car is between them, or ahead of the
    attacker, or behind the rear car, the pair is with it, its gap SUMO's (bumper to bumper: SUMO's leader
    gap leaves out the follower's minGap, which is added back). A traffic car is index ``n + j`` of the
    step's extended ids, positions and speeds (j in order of appearance); pairs of two traffic cars are
    not the platoon's and are left out."""

    def __init__(self, api, config: EpisodeConfig, ids: tuple[str, ...]):
        self.ids = ids
        self.index = {vid: i for i, vid in enumerate(ids)}
        self.names = config.vehicle_ids
        self.lengths = [v.length_m for v in config.car_vehicles]
        self.min_gaps = [api.vehicle.getMinGap(vid) for vid in ids]
        self.get_leader, self.get_follower = vehicle_call(api, "getLeader"), vehicle_call(api, "getFollower")
        self.get_speed, self.get_length = vehicle_call(api, "getSpeed"), vehicle_call(api, "getLength")
        self.get_min_gap = vehicle_call(api, "getMinGap")

    def __call__(self, x: list[float], v: list[float]) -> tuple[list[Pair], list[str], list[float], list[float]]:
        """The step's pairs, and the extended ids (each traffic car by its SUMO id), positions (a traffic
        car's front bumper, from its gap) and speeds they index."""
        ids, n, look = self.ids, len(self.ids), FREE_ROAD_GAP_M
        names, xs, vs = list(self.names), list(x), list(v)
        traffic: dict[str, int] = {}
        pairs: list[Pair] = []

        def other(vid: str, front_m: float) -> int:
            if vid not in traffic:
                traffic[vid] = len(names)
                names.append(vid)
                xs.append(front_m)
                vs.append(self.get_speed(vid))
            return traffic[vid]

        for b in range(n):
            hit = self.get_leader(ids[b], look)
            if b and (not hit or hit[0] == ids[b - 1]):  # the car ahead in the column
                pairs.append((b - 1, b, x[b - 1] - self.lengths[b - 1] - x[b]))
                continue
            if not hit or not hit[0]:
                continue  # nobody ahead of the attacker
            if hit[0] in self.index:  # another car of the platoon (a car ahead of it left the lane): their pair
                a = self.index[hit[0]]
                pairs.append((a, b, x[a] - self.lengths[a] - x[b]))
                continue
            gap = hit[1] + self.min_gaps[b]
            if gap >= look:
                continue
            t = other(hit[0], x[b] + gap + self.get_length(hit[0]))
            pairs.append((t, b, gap))
            for _ in range(64) if b else ():  # traffic between two platoon cars: the first of it follows the car ahead
                ahead = self.get_leader(names[t], look)
                if not ahead or not ahead[0] or (ahead[0] in ids and ahead[0] != ids[b - 1]):
                    break
                gap = ahead[1] + self.get_min_gap(names[t])
                if ahead[0] == ids[b - 1]:
                    pairs.append((b - 1, t, gap))
                    break
                t = other(ahead[0], xs[t] + gap + self.get_length(ahead[0]))
        behind = self.get_follower(ids[-1], look)
        if behind and behind[0] and behind[0] not in ids:
            gap = behind[1] + self.get_min_gap(behind[0])
            if gap < look:
                pairs.append((n - 1, other(behind[0], x[-1] - self.lengths[-1] - gap), gap))
        return pairs, names, xs, vs


class _LateralTrafficSense:
    """Who follows whom among traffic when the attacker changes lanes (`maneuvers.LaneChange`, a road of
    one edge): in every lane each car covers (from its lateral position, a car changing lanes covering
    both), the nearest cars, a traffic car included (`maneuvers.lane_pairs`: the arithmetic of the
    maneuver alone, bit for bit, between cars of the platoon). The traffic cars that may be next to a car
    of the platoon are SUMO's: its leader and follower, and its leaders and followers in the lanes beside
    it. Returns what `_TrafficSense` returns."""

    def __init__(self, api, config: EpisodeConfig, ids: tuple[str, ...], lateral: _Lateral, road: Road):
        self.ids, self.index, self.lateral = ids, {vid: i for i, vid in enumerate(ids)}, lateral
        self.names = list(config.vehicle_ids)
        self.lengths = [v.length_m for v in config.car_vehicles]
        self.width, self.base = road.lane_width_m, road.platoon_lane
        call = lambda name: vehicle_call(api, name)  # noqa: E731
        self.get_leader, self.get_follower, self.get_neighbors = call("getLeader"), call("getFollower"), call("getNeighbors")
        self.get_position, self.get_speed, self.get_length = call("getLanePosition"), call("getSpeed"), call("getLength")
        self.get_lane, self.get_lateral = call("getLaneIndex"), call("getLateralLanePosition")

    def __call__(self, x: list[float], v: list[float]) -> tuple[list[Pair], list[str], list[float], list[float]]:
        lanes = self.lateral.sense()  # the platoon's cars' lanes (and the attacker's lateral position, recorded)
        near: set[str] = set()
        for vid in self.ids:
            for hit in (self.get_leader(vid, FREE_ROAD_GAP_M), self.get_follower(vid, FREE_ROAD_GAP_M)):
                if hit and hit[0]:
                    near.add(hit[0])
            for mode in range(4):  # the lanes to its right and left, followers and leaders
                near.update(other for other, _ in self.get_neighbors(vid, mode))
        traffic = sorted(near - self.index.keys())
        xs = list(x) + [self.get_position(t) for t in traffic]  # a road of one edge: the lane position is along it
        vs = list(v) + [self.get_speed(t) for t in traffic]
        lengths = self.lengths + [self.get_length(t) for t in traffic]
        covered = list(lanes) + [occupied_lanes((self.get_lane(t) - self.base + 0.5) * self.width + self.get_lateral(t), self.width)
                                 for t in traffic]
        pairs = [p for p in lane_pairs(xs, covered, lengths, apart=len(self.ids)) if p[2] < FREE_ROAD_GAP_M or max(p[:2]) < len(self.ids)]
        return pairs, self.names + traffic, xs, vs


class SumoWorld:
    """Platoons in one running SUMO, as the step loop sees them: each episode's vehicle ids (``platoons``),
    fast bound calls to sense and command them, a step, and the removal of an ended episode's cars.
    Open it with `open_world`, which starts SUMO, inserts the platoons and closes SUMO afterwards."""

    def __init__(self, api, config: EpisodeConfig, road: Road, platoons: list[tuple[str, ...]], record: bool = False):
        """``record``: the episode writes its FCD (a replay): what its figures draw is recorded too (`signal_tracks`)."""
        self.api = api
        self.platoons = platoons
        self.attacker_max_speed_mps = road.speed_limit_mps
        self.get_speed, self.set_speed = (vehicle_call(api, f) for f in ("getSpeed", "setSpeed"))
        self.get_position = route_position(api, road, [vid for ids in platoons for vid in ids])
        maneuver = maneuver_of(config)
        self.laterals = [_Lateral(api, maneuver, road, ids[0]) for ids in platoons] if maneuver.lateral else None
        #: with traffic, each platoon's sensing of who is ahead (`_TrafficSense`, `_LateralTrafficSense`); None:
        #: the maneuver's pairs
        self.traffic = None
        self._platoon = {vid for ids in platoons for vid in ids}
        self._traffic_collisions: list[tuple[float, str, str]] = []
        self._seen: set[tuple[str, str]] = set()
        self._k, self._step_s = -1, config.step_s  # the samples sensed (the first at t = 0)
        #: on a route through traffic lights the platoon obeys, what each platoon's cars see of them (`lights`); else None
        self.lights = None
        if config.signals != "ignore" and not road.one_edge:
            signals = [route_signals(api, road.route(e), road.platoon_path) for e in range(len(platoons))]
            if any(signals):
                self.lights = [RouteLights(api, found, len(ids), record) for found, ids in zip(signals, platoons)]
        #: with traffic on a route of several edges, each platoon's collisions inside its junctions (`junctions`)
        self.crossings = None
        if config.traffic is not None and config.traffic.junction_collisions and not road.one_edge:
            self.crossings = [JunctionCrossings(api, road.route(e), road.platoon_path, ids, config.collision_gap_m)
                              for e, ids in enumerate(platoons)]
        if config.traffic is not None:
            self.traffic = [_LateralTrafficSense(api, config, ids, self.laterals[e], road) if self.laterals
                            else _TrafficSense(api, config, ids) for e, ids in enumerate(platoons)]
        step = simulation_step(api)
        if road.forks:  # SUMO may take another lane than the path at a fork: each step checks it did not
            check = _LanePathCheck(api, config, road, platoons, maneuver)
            self.removed = check.removed
            self.step = lambda: (step(), check())
        else:
            self.removed = set()
            self.step = step

    def lanes(self, e: int) -> list[tuple[int, ...]]:
        """The lanes each car of episode ``e`` covers now (lane-changing maneuvers)."""
        return self.laterals[e].sense()

    def change_lane(self, e: int, lane: int) -> None:
        """The attacker of episode ``e`` begins its change to ``lane`` (counted from the platoon's)."""
        self.laterals[e].change_lane(lane)

    def sense(self, e: int, x: list[float], v: list[float]) -> tuple[list, list[str], list[float], list[float]]:
        """With traffic: the pairs of episode ``e`` at this step and the ids, positions and speeds they index
        (`_TrafficSense`), a collision inside a junction in 2D among them (`junctions.JunctionCrossings`); and
        the collisions among the traffic SUMO reported in the step, kept."""
        self._k += 1  # traffic plays one episode to a SUMO: each call is the next sample
        for c in self.api.simulation.getCollisions():
            pair = (c.collider, c.victim)
            if self._platoon.isdisjoint(pair) and pair not in self._seen:  # SUMO reports an overlap every step it lasts
                self._seen.add(pair)
                self._traffic_collisions.append((self._k * self._step_s, *pair))
        pairs, names, xs, vs = self.traffic[e](x, v)
        if self.crossings is not None:
            pairs += self.crossings[e](x, pairs, names, xs, vs)
        return pairs, names, xs, vs

    def signal_tracks(self, e: int) -> tuple[tuple[float, str, str], ...]:
        """Episode ``e``'s signals and their states at each step, where they were recorded (`lights.signal_tracks`)."""
        return signal_tracks(self.lights[e]) if self.lights is not None else ()

    def stops(self, e: int, x: list[float]):
        """What each car of episode ``e``, at positions ``x`` along its route, sees of the next traffic light
        (`signals.Stop`, or None), where the platoon obeys them (`lights`)."""
        return self.lights[e](x)

    def feed_beacons(self, ids: tuple[str, ...], beacons) -> None:
        """Give SUMO's cooperative followers (Plexe's CC model) the newest beacons they read, as Plexe's own
        application does: (follower, whether it reads every car ahead's, the beacons). Its CACC, Ploeg's
        and FLATBED read the leader's and the car ahead's; CONSENSUS every car ahead's, as GPS positions,
        laid out along the follower's heading from where it is."""
        set_parameter = self.api.vehicle.setParameter
        for i, every, newest in beacons:
            vid = ids[i]
            if not every:
                leader, front = newest
                set_parameter(vid, "carFollowModel.cclsa", beacon_parameters(leader))
                set_parameter(vid, "carFollowModel.ccpsa", beacon_parameters(front))
                continue
            x, y = self.api.vehicle.getPosition(vid)
            angle = math.radians(self.api.vehicle.getAngle(vid))  # SUMO's: clockwise from north
            heading = (math.sin(angle), math.cos(angle))
            along = self.get_position(vid)
            for m in newest:
                ahead = m.position_m - along
                set_parameter(vid, "carFollowModel.ccvd", vehicle_data(m, x + heading[0] * ahead, y + heading[1] * ahead, heading))

    def traffic_collisions(self, e: int) -> tuple[tuple[float, str, str], ...]:
        """The collisions of two traffic cars so far (time from the platoon's insertion [s], the car that ran
        into the other, that car)."""
        return tuple(self._traffic_collisions)

    def lateral_rows(self, e: int) -> np.ndarray | None:
        """Each car's lateral position at every sample of episode ``e`` (lane-changing maneuvers), else None."""
        return self.laterals[e].rows() if self.laterals else None

    def remove(self, e: int) -> None:
        """An ended episode's cars leave: they cost SUMO nothing more."""
        self.removed.add(e)
        for vid in self.platoons[e]:
            self.api.vehicle.remove(vid)


class open_world:
    """``with open_world(config, road, ...) as world``: SUMO started with the episode's command line, the
    platoons inserted (``configs``: one per episode), closed on the way out; SUMO's own errors as
    `SumoError`."""

    def __init__(self, config: EpisodeConfig, road: Road, configs: Sequence[EpisodeConfig], *,
                 fcd_path: str | Path | None = None, gui: bool = False, types_file: Path | None = None):
        if gui:
            import traci as api  # libsumo has no window; traci drives sumo-gui with the same API

            binary = sumo_binary("sumo-gui")
        else:
            import libsumo as api

            binary = "sumo"
        cmd = sumo_command(config, road, fcd_path, binary=binary, types_file=types_file, state_file=traffic_state(config, road))
        self.api, self.cmd, self.config, self.road, self.configs = api, cmd, config, road, list(configs)
        self.record = fcd_path is not None

    def __enter__(self) -> SumoWorld:
        for later in range(MAX_JOINS if self.config.traffic is not None else 1):
            try:
                self.api.start(self.cmd)
            except Exception as exc:  # libsumo/traci raise their own types, or FatalTraCIError
                raise SumoError(f"SUMO did not start: {exc}") from None
            try:
                if self.config.traffic is None:
                    return SumoWorld(self.api, self.config, self.road, load_platoon(self.api, self.config, self.road,
                                                                                   len(self.configs), self.configs), self.record)
                platoons = join_traffic(self.api, self.config, self.road, later)
                if platoons is not None:
                    return SumoWorld(self.api, self.config, self.road, platoons, self.record)
                self.api.close()  # a traffic car entered its places with it: again, a step later
            except BaseException as exc:
                self.__exit__(type(exc), exc, None)
                raise
        raise SumoError(f"the platoon found no room to join the traffic on {self.road.name} in {MAX_JOINS} steps of trying: "
                        "every step a traffic car entered the road in its places (a lower traffic.clear_m leaves more room)")

    def __exit__(self, kind, exc, tb):
        try:
            self.api.close()
        except Exception:  # already closed, or SUMO died: nothing left to close
            pass
        if kind is not None and issubclass(kind, self.api.TraCIException):
            gone = " (it reached the end of the road: a car faster than its speed limit for long enough leaves it)" \
                if "is not known" in str(exc) else ""
            raise SumoError(f"SUMO failed during the episode: {exc}{gone}") from None
        return False
