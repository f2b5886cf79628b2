"""The SUMO world: the only module that talks to SUMO (libsumo, or traci for sumo-gui).

SUMO moves the cars (ballistic update). Python commands the speed of the attacker and of every
Python-commanded follower (SUMO's car-following, lane changing and speed checks are off for them:
speed mode 32, lane-change mode 0); followers driven by SUMO's own car-following models run with their
vehicle type, loaded from an additional file checked once per content, with SUMO's default speed mode.
`SumoWorld` is the seam the step loop (`engine.loop.play`) drives: insert, sense, apply speeds, step,
remove. Many platoons share one SUMO each on its own copy of the road (`scenarios.batch_road`).
"""

from __future__ import annotations

import hashlib
import os
import re
import subprocess
import tempfile
from pathlib import Path
from typing import Callable, Sequence
from xml.sax.saxutils import escape as xml_escape

import numpy as np

from ..errors import ConfigError, SumoError
from ..model.config import EpisodeConfig
from ..model.maneuvers import CAR_WIDTH_M, maneuver_of, occupied_lanes
from ..model.platoon import SumoFollower, followers_of
from ..model.vehicle import VehicleParams
from ..sumohome import sumo_binary
from .scenarios import Road, default_cache_dir

ROUTE_ID = "platoon"
VTYPE_ID = "d4car"
ATTACKER_VTYPE_ID = "d4attacker"
SPEED_MODE_PYTHON = 32  # all checks off: Python's speed is applied as given
LANE_CHANGE_MODE_OFF = 0  # no lane change of SUMO's own; a TraCI request is carried out without regard to others
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
    if text in _CHECKED and _CHECKED[text].is_file():
        return _CHECKED[text]
    sumo = sumo_binary("sumo")
    build = f"{sumo}:{os.stat(sumo).st_mtime_ns}"  # another SUMO checks again
    folder = Path(default_cache_dir()).parent / "vtypes"
    path = folder / f"{hashlib.sha256((build + text).encode()).hexdigest()[:16]}.add.xml"
    if not path.is_file():
        try:
            folder.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=folder, suffix=".add.xml")
        except OSError as exc:
            raise SumoError(f"cannot write SUMO's vehicle types under {folder}: {exc.strerror or exc}") from None
        try:
            with os.fdopen(fd, "w", encoding="utf-8") as f:
                f.write(text)
            _check_types(config, road, sumo, tmp)
            os.replace(tmp, path)
        except OSError as exc:
            raise SumoError(f"cannot write SUMO's vehicle types under {folder}: {exc.strerror or exc}") from None
        finally:
            if os.path.exists(tmp):
                os.unlink(tmp)
    _CHECKED[text] = path
    return path


def _check_types(config: EpisodeConfig, road: Road, sumo: str, types_file: str) -> None:
    cmd = [sumo, "--net-file", str(road.net_file), "--additional-files", types_file, "--step-length",
           repr(config.step_s), "--end", "0", "--no-step-log", "true", "--duration-log.disable", "true"]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    except subprocess.TimeoutExpired:
        raise SumoError("SUMO did not load the followers' vehicle types within 120 s") from None
    if done.returncode == 0:
        return
    errors = [ln.removeprefix("Error: ") for ln in done.stderr.splitlines() if ln.startswith("Error:")]
    message = errors[0] if errors else done.stderr.strip() or f"exit {done.returncode}"
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
                 types_file: Path | None = None) -> list[str]:
    """The SUMO command line, as one explicit list; ``types_file``: the followers' vehicle types, as
    `check_episode` returns them."""
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
        "--seed", "0",
        "--no-step-log", "true",
        "--no-warnings", "true",
        "--duration-log.disable", "true",
        # SUMO's output precision reaches its car-following: a Krauss follower answering a cut-in moved
        # 5 mm apart with the FCD's 6 decimals and without them. One precision for every run, so a replay
        # that writes FCD is the campaign's episode.
        "--precision", str(FCD_PRECISION),
    ]
    if types_file is not None:
        cmd += ["--additional-files", str(types_file)]
    if config.maneuver_class.lateral and config.lane_change_s > 0:  # the attacker moves across over this time
        cmd += ["--lanechange.duration", repr(config.lane_change_s)]
    if fcd_path is not None:
        cmd += ["--fcd-output", str(fcd_path), "--fcd-output.attributes", FCD_ATTRIBUTES,
                "--fcd-output.acceleration", "true"]
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
    for e, ids in enumerate(platoons):
        route = f"{ROUTE_ID}{e}" if episodes > 1 else ROUTE_ID
        api.route.add(route, list(road.route(e)))
        for vid, car, type_id in zip(ids, placed[id(configs[e])], type_ids):
            api.vehicle.add(vid, route, typeID=type_id, depart="0", departLane=str(road.platoon_lane + car.lane),
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
    """``api.vehicle.<name>``; for libsumo its C function itself, without the one-line Python wrapper
    around it (a third of the cost of a call, and these run for every car at every step)."""
    return getattr(getattr(api, "_libsumo", None), f"vehicle_{name}", None) or getattr(api.vehicle, name)


def simulation_step(api):
    """``api.simulationStep``; for libsumo its C function (d4sumo registers no step listeners)."""
    raw = getattr(getattr(api, "_libsumo", None), "simulation_step", None)
    return (lambda: raw(0.0)) if raw else api.simulationStep


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


class SumoWorld:
    """Platoons in one running SUMO, as the step loop sees them: each episode's vehicle ids (``platoons``),
    fast bound calls to sense and command them, a step, and the removal of an ended episode's cars.
    Open it with `open_world`, which starts SUMO, inserts the platoons and closes SUMO afterwards."""

    def __init__(self, api, config: EpisodeConfig, road: Road, platoons: list[tuple[str, ...]]):
        self.api = api
        self.platoons = platoons
        self.attacker_max_speed_mps = road.speed_limit_mps
        self.get_speed, self.set_speed = (vehicle_call(api, f) for f in ("getSpeed", "setSpeed"))
        self.get_position = route_position(api, road, [vid for ids in platoons for vid in ids])
        maneuver = maneuver_of(config)
        self.laterals = [_Lateral(api, maneuver, road, ids[0]) for ids in platoons] if maneuver.lateral else None
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

            cmd = sumo_command(config, road, fcd_path, binary=sumo_binary("sumo-gui"), types_file=types_file)
        else:
            import libsumo as api

            cmd = sumo_command(config, road, fcd_path, types_file=types_file)
        self.api, self.cmd, self.config, self.road, self.configs = api, cmd, config, road, list(configs)

    def __enter__(self) -> SumoWorld:
        try:
            self.api.start(self.cmd)
        except Exception as exc:  # libsumo/traci raise their own types, or FatalTraCIError
            raise SumoError(f"SUMO did not start: {exc}") from None
        try:
            platoons = load_platoon(self.api, self.config, self.road, len(self.configs), self.configs)
            return SumoWorld(self.api, self.config, self.road, platoons)
        except BaseException as exc:
            self.__exit__(type(exc), exc, None)
            raise

    def __exit__(self, kind, exc, tb):
        try:
            self.api.close()
        except Exception:  # already closed, or SUMO died: nothing left to close
            pass
        if kind is not None and issubclass(kind, self.api.TraCIException):
            raise SumoError(f"SUMO failed during the episode: {exc}") from None
        return False
