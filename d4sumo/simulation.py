"""The SUMO co-simulation: the only module that talks to SUMO (libsumo, or traci for sumo-gui).

Each step Python commands the speed of the attacker and of every Python-commanded follower (SUMO's
car-following, lane changing and speed checks are off for them: speed mode 32, lane-change mode 0);
followers driven by SUMO's own car-following models run with their vehicle type, loaded from an
additional file checked once per content, with SUMO's default speed mode. SUMO moves the cars
(ballistic update). A collision is any bumper overlap at the end of a step, measured on SUMO's positions (`platoon.collisions_at`): SUMO's own
reports miss overlaps of 1 mm or less. The episode ends at the first one: SUMO lets the cars drive
through each other afterwards, so later data are not physical.
"""

from __future__ import annotations

import hashlib
import logging
import os
import re
import subprocess
import tempfile
from pathlib import Path
from typing import Callable, Sequence
from xml.sax.saxutils import escape as xml_escape

import numpy as np

from .config import ControllerConfig, EpisodeConfig
from .errors import ConfigError, SumoError
from .maneuvers import CAR_WIDTH_M, AttackPlan, check_road_lanes, maneuver_of, occupied_lanes
from .batch import PlatoonBatch, collided, episode_configs
from .platoon import Platoon, SumoFollower, collisions_at, followers_of, road_needed_m
from .scenarios import MAX_COPIES, Road, batch_road, build_road, default_cache_dir, sumo_binary
from .trace import Episode

log = logging.getLogger(__name__)

ROUTE_ID = "platoon"
VTYPE_ID = "d4car"
ATTACKER_VTYPE_ID = "d4attacker"
SPEED_MODE_PYTHON = 32  # all checks off: Python's speed is applied as given
LANE_CHANGE_MODE_OFF = 0  # no lane change of SUMO's own; a TraCI request is carried out without regard to others
FCD_PRECISION = 6  # decimals in FCD: gaps recomputed from it agree with the trace to far below 1 cm
#: SUMO's default FCD attributes and the odometer, from which a position along a route of many edges
#: comes (a lane position starts again at 0 on each edge)
FCD_ATTRIBUTES = "x,y,angle,type,speed,pos,lane,slope,acceleration,odometer"


def check_road(config: EpisodeConfig, road: Road) -> None:
    """Refuse episodes the road cannot hold: a target speed above the limit, or a road too short."""
    check_road_lanes(config, road.name, road.lanes)
    if config.speed_mps > road.speed_limit_mps + 1e-9:
        raise ConfigError("scenario.speed_mps", config.speed_mps, f"at most the speed limit of {road.name}: {road.speed_limit_mps:g} m/s")
    start = max(car.position_m for car in maneuver_of(config).cars())
    if start > road.first_edge_m:
        raise ConfigError(
            "scenario.network",
            road.name,
            f"a road whose first edge holds the platoon's start ({start:.1f} m; the first edge is {road.first_edge_m:g} m)",
        )
    needed = road_needed_m(config, road.speed_limit_mps)
    if needed > road.length_m:
        raise ConfigError(
            "scenario.duration_s",
            config.duration_s,
            f"an episode that fits on {road.name} ({road.length_m:g} m; this one may need {needed:.0f} m)",
        )


def check_episode(config: EpisodeConfig, road: Road) -> Path | None:
    """Everything an episode needs checked before it runs: the road, and SUMO's models' parameters.
    Returns the followers' checked vehicle-type file (None when no follower is SUMO-driven)."""
    check_road(config, road)
    return followers_file(config, road)


# --- followers driven by SUMO's car-following models ---------------------------------------------

_CHECKED: dict[str, Path] = {}  # vehicle-type XML -> its checked file, in this process


def follower_types(config: EpisodeConfig) -> dict[ControllerConfig, tuple[str, SumoFollower]]:
    """The SUMO-driven followers' distinct controllers -> their vehicle-type id and one such follower."""
    types: dict = {}
    if not config.sumo_driven:  # the common case: nothing to build
        return types
    for follower in followers_of(config):
        if follower.sumo_driven and follower.config not in types:
            types[follower.config] = (f"d4{follower.model}{len(types)}", follower)
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
    ]
    if types_file is not None:
        cmd += ["--additional-files", str(types_file)]
    if config.maneuver_class.lateral and config.lane_change_s > 0:  # the attacker moves across over this time
        cmd += ["--lanechange.duration", repr(config.lane_change_s)]
    if fcd_path is not None:
        cmd += ["--fcd-output", str(fcd_path), "--fcd-output.attributes", FCD_ATTRIBUTES,
                "--fcd-output.acceleration", "true", "--precision", str(FCD_PRECISION)]
    if binary != "sumo":  # sumo-gui: start at once and leave the window open at the end
        cmd += ["--start", "true", "--quit-on-end", "false", "--delay", "50"]
    return cmd


def load_platoon(api, config: EpisodeConfig, road: Road, episodes: int = 1,
                 configs: Sequence[EpisodeConfig] | None = None) -> list[tuple[str, ...]]:
    """Insert every car of the maneuver, each in its lane, and hand Python the ones it commands; with
    ``episodes`` > 1, one platoon on each copy of the road (`scenarios.batch_road`), each placed as
    its own entry of ``configs`` says (default: ``config``). Returns each platoon's SUMO vehicle ids,
    in the order of ``config.vehicle_ids`` (the same ids for one platoon)."""
    v = config.vehicle
    api.vehicletype.copy("DEFAULT_VEHTYPE", VTYPE_ID)
    api.vehicletype.setLength(VTYPE_ID, v.length_m)
    api.vehicletype.setWidth(VTYPE_ID, CAR_WIDTH_M)
    api.vehicletype.setMinGap(VTYPE_ID, 0.0)
    api.vehicletype.setMaxSpeed(VTYPE_ID, 100.0)  # Python clamps speeds itself
    api.vehicletype.setAccel(VTYPE_ID, v.max_accel_mps2)
    api.vehicletype.setDecel(VTYPE_ID, v.max_decel_mps2)
    api.vehicletype.setEmergencyDecel(VTYPE_ID, v.max_decel_mps2)
    api.vehicletype.setImperfection(VTYPE_ID, 0.0)
    api.vehicletype.setSpeedDeviation(VTYPE_ID, 0.0)
    types = follower_types(config)
    attacker_type = VTYPE_ID
    if types:  # the attacker's own type: what SUMO's models believe of its brakes
        attacker_type = ATTACKER_VTYPE_ID
        api.vehicletype.copy(VTYPE_ID, attacker_type)
        api.vehicletype.setApparentDecel(attacker_type, config.attacker_declared_decel_mps2)
    n = config.followers + 1
    type_ids = [attacker_type] + [types[c][0] if c in types else VTYPE_ID for c in config.controllers]
    type_ids += [VTYPE_ID] * (len(config.vehicle_ids) - n)  # the benign lead or the obstacle
    configs = configs or [config] * episodes
    placed = {id(c): maneuver_of(c).cars() for c in configs}
    platoons = [config.vehicle_ids if episodes == 1 else tuple(f"{e}.{vid}" for vid in config.vehicle_ids)
                for e in range(episodes)]
    for e, ids in enumerate(platoons):
        route = f"{ROUTE_ID}{e}" if episodes > 1 else ROUTE_ID
        api.route.add(route, list(road.route(e)))
        for vid, car, type_id in zip(ids, placed[id(configs[e])], type_ids):
            api.vehicle.add(vid, route, typeID=type_id, depart="0", departLane=str(car.lane),
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
        for vid, controller in zip(ids[1:n], config.controllers):
            if controller not in types:
                api.vehicle.setSpeedMode(vid, SPEED_MODE_PYTHON)
                continue
            for key, value in types[controller][1].parameters().items():
                api.vehicle.setParameter(vid, key, value)
    return platoons


def simulate(
    config: EpisodeConfig,
    attack: AttackPlan | np.ndarray,
    *,
    road: Road | None = None,
    fcd_path: str | Path | None = None,
    gui: bool = False,
) -> Episode:
    """Play one episode in SUMO. ``attack``: the attacker's plan (`maneuvers.attack_plan`), or only its
    command at each step's start (``config.steps`` values in [-1, 1], NaN where the attacker cruises)."""
    road = road or build_road(config.network)
    types_file = check_episode(config, road)
    plan = attack if isinstance(attack, AttackPlan) else AttackPlan(np.asarray(attack, dtype=float))
    platoon = Platoon(config, plan.u, attacker_max_speed_mps=road.speed_limit_mps)
    if gui:
        import traci as api  # libsumo has no window; traci drives sumo-gui with the same API

        cmd = sumo_command(config, road, fcd_path, binary=sumo_binary("sumo-gui"), types_file=types_file)
    else:
        import libsumo as api

        cmd = sumo_command(config, road, fcd_path, types_file=types_file)
    try:
        api.start(cmd)
    except Exception as exc:  # libsumo/traci raise their own types, or FatalTraCIError
        raise SumoError(f"SUMO did not start: {exc}") from None
    try:
        load_platoon(api, config, road)
        return _run(api, config, platoon, road, plan.lane_change_step)
    except api.TraCIException as exc:
        raise SumoError(f"SUMO failed during the episode: {exc}") from None
    finally:
        api.close()


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


def _run(api, config: EpisodeConfig, platoon: Platoon, road: Road, lane_change_step: int | None) -> Episode:
    ids = config.vehicle_ids
    commanded = [ids[i] for i in platoon.commanded]  # SUMO moves its own followers
    get_speed, set_speed = (vehicle_call(api, f) for f in ("getSpeed", "setSpeed"))
    get_position = route_position(api, road, ids)
    step = simulation_step(api)
    advance = platoon.advance
    maneuver = platoon.maneuver
    pairs_at = maneuver.pairs
    dt = config.step_s
    lateral = _Lateral(api, maneuver, road) if maneuver.lateral else None
    positions = [get_position(v) for v in ids]
    speeds = [get_speed(v) for v in ids]
    lanes = lateral.sense() if lateral else None
    pairs = pairs_at(positions, lanes)
    rows_x, rows_v = [positions], [speeds]
    collisions: tuple = ()
    for k in range(config.steps):
        if k == lane_change_step:
            lateral.change_lane()
        speeds_out = advance(k, positions, speeds, pairs)
        for vid, v in zip(commanded, speeds_out):
            set_speed(vid, v)
        step()
        positions = [get_position(v) for v in ids]
        speeds = [get_speed(v) for v in ids]
        rows_x.append(positions)
        rows_v.append(speeds)
        if lateral:
            platoon.pairs.append(pairs)  # the pairs of the sample before
            lanes = lateral.sense()
        pairs = pairs_at(positions, lanes)
        collisions = collisions_at((k + 1) * dt, pairs, positions, speeds, ids)
        if collisions:
            break
    if lateral:
        platoon.pairs.append(pairs)
    times = np.arange(len(rows_x)) * config.step_s
    trace, min_gaps = platoon.trace(times, np.array(rows_x), np.array(rows_v), lateral.rows() if lateral else None)
    return Episode(trace, collisions, min_gaps)


class _Lateral:
    """The attacker's lane change, and where it is across the road at each step: the lanes it covers."""

    def __init__(self, api, maneuver, road: Road, attacker: str = "v0"):
        self.api = api
        self.attacker = attacker
        self.width = road.lane_width_m
        self.target = maneuver.target_lane()
        lanes = maneuver.start_lanes()
        self.fixed = [(lane,) for lane in lanes[1:]]  # only the attacker changes lanes
        self.fixed_y = [(lane + 0.5) * self.width for lane in lanes[1:]]
        self.y: list[float] = []
        self.get_lane = api.vehicle.getLaneIndex
        self.get_lateral = api.vehicle.getLateralLanePosition

    def change_lane(self) -> None:
        # SUMO carries it out (over scenario.lane_change_s, or in one step); the request holds for the episode
        self.api.vehicle.changeLane(self.attacker, self.target, 1e6)

    def sense(self) -> list[tuple[int, ...]]:
        y = (self.get_lane(self.attacker) + 0.5) * self.width + self.get_lateral(self.attacker)
        self.y.append(y)
        return [occupied_lanes(y, self.width), *self.fixed]

    def rows(self) -> np.ndarray:
        return np.column_stack([self.y, *(np.full(len(self.y), y) for y in self.fixed_y)])


# --- a batch: many episodes side by side in one SUMO ---------------------------------------------

def shares_sumo(config: EpisodeConfig) -> bool:
    """Whether the configuration's platoons may share one SUMO (see `simulate_batch`)."""
    return all(f.shares_sumo for f in followers_of(config))


def _one_at_a_time(config: EpisodeConfig, plans: Sequence[AttackPlan], road: Road | None, on_episode) -> list:
    """`simulate_batch`'s results, each episode played alone."""
    road = road or build_road(config.network)
    check_episode(config, road)
    results: list = []
    for i, plan in enumerate(plans):
        try:
            result = simulate(config, plan, road=road)
        except (SumoError, ConfigError):
            raise  # as in a batch: SUMO's failure, or a configuration it cannot play, ends them all
        except Exception as exc:  # a user's controller: this episode's error, as alone
            result = exc
        results.append(result)
        if on_episode:
            on_episode(i, result)
    return results


def simulate_batch(config: EpisodeConfig | Sequence[EpisodeConfig], plans: Sequence[AttackPlan], *,
                   road: Road | None = None,
                   on_episode: Callable[[int, "Episode | Exception"], None] | None = None) -> list["Episode | Exception"]:
    """Play many episodes side by side in one SUMO instance, each platoon on its own copy of the road
    (`scenarios.batch_road`), commanded together (`batch.PlatoonBatch`). ``config``: one for every
    episode, or one per plan, differing at most in setpoint, target speed and start from rest or
    steady (`batch.batch_key`: several campaigns' episodes in one SUMO).

    Each result is bit for bit what `simulate` gives for the same plan alone: the episode, or the
    exception a user's follower controller raised in it (alone it would end that episode). An episode
    that ends (its first collision) leaves SUMO at once and costs nothing more; ``on_episode(i, result)``
    hears of it then. Followers whose SUMO model draws from SUMO's random streams (`carfollowing.shares_sumo`)
    would draw differently beside other platoons: their episodes play one at a time, in turn.
    """
    if not plans:
        return []
    if len(plans) > MAX_COPIES:
        raise ValueError(f"a batch of {len(plans)} episodes; allowed: at most {MAX_COPIES}")
    configs = episode_configs(config, len(plans))
    config = configs[0]
    distinct = list({id(c): c for c in configs}.values())
    if not shares_sumo(config):
        alone = road if road is not None and road.copies == 1 else None
        if len(distinct) == 1:
            return _one_at_a_time(config, plans, alone, on_episode)
        results = []
        for i, (c, plan) in enumerate(zip(configs, plans)):  # each with its own configuration, in turn
            results += _one_at_a_time(c, [plan], alone, on_episode and (lambda _, r, i=i: on_episode(i, r)))
        return results
    if road is None or road.copies < len(plans):
        road = batch_road(config.network, len(plans))
    types_file = check_episode(config, road)
    for c in distinct[1:]:
        check_episode(c, road)
    batch = PlatoonBatch(configs, np.array([p.u for p in plans]), attacker_max_speed_mps=road.speed_limit_mps)
    import libsumo as api

    try:
        api.start(sumo_command(config, road, types_file=types_file))
    except Exception as exc:  # libsumo raises its own types
        raise SumoError(f"SUMO did not start: {exc}") from None
    try:
        platoons = load_platoon(api, config, road, len(plans), configs)
        return _run_batch(api, config, batch, road, platoons, [p.lane_change_step for p in plans], on_episode)
    except api.TraCIException as exc:
        raise SumoError(f"SUMO failed during the episode: {exc}") from None
    finally:
        api.close()


#: a batch carries on one episode at a time once this few are left: the arrays' fixed cost per step
#: then exceeds what they save (measured with tools/bench_batch.py)
DETACH_AT = 4


def _run_batch(api, config: EpisodeConfig, batch: PlatoonBatch, road: Road, platoons: list[tuple[str, ...]],
               lane_change_steps: list[int | None], on_episode) -> list:
    m, n, dt = batch.size, len(config.vehicle_ids), config.step_s
    vehicle = api.vehicle
    get_speed, set_speed = (vehicle_call(api, f) for f in ("getSpeed", "setSpeed"))
    get_position = route_position(api, road, [vid for ids in platoons for vid in ids])
    sumo_step = simulation_step(api)
    commanded_ids = [[ids[i] for i in batch.commanded] for ids in platoons]
    maneuver = batch.maneuver
    laterals = [_Lateral(api, maneuver, road, ids[0]) for ids in platoons] if maneuver.lateral else None
    recorded: list[list] = [[] for _ in range(m)]  # lane-changing maneuvers: each sample's pairs
    rows_x = np.zeros((config.steps + 1, m, n))  # an ended episode's rows stay 0: computed along, never used
    rows_v = np.zeros_like(rows_x)
    active = np.ones(m, dtype=bool)  # still commanded by the batch's arrays
    live = list(range(m))  # still in SUMO
    detached: dict[int, Platoon] = {}  # carried on one at a time
    sensed = [vid for ids in platoons for vid in ids]
    results: list = [None] * m

    def sense(k: int) -> None:
        if len(live) == m:
            rows_x[k] = np.array([get_position(v) for v in sensed]).reshape(m, n)
            rows_v[k] = np.array([get_speed(v) for v in sensed]).reshape(m, n)
        else:
            rows_x[k, live] = np.array([get_position(v) for v in sensed]).reshape(len(live), n)
            rows_v[k, live] = np.array([get_speed(v) for v in sensed]).reshape(len(live), n)

    def episode_pairs(k: int) -> list | None:
        if laterals is None:
            return None
        pairs: list = [None] * m
        for e in live:
            pairs[e] = maneuver.pairs(rows_x[k, e].tolist(), laterals[e].sense())
            recorded[e].append(pairs[e])
        return pairs

    def end(e: int, steps: int, collisions: tuple, error: Exception | None = None) -> None:
        nonlocal sensed
        active[e] = False
        live.remove(e)
        sensed = [vid for i in live for vid in platoons[i]]
        for vid in platoons[e]:  # it costs SUMO nothing more
            vehicle.remove(vid)
        error = error or batch.failed.get(e) or batch.bad_modes.get(e)  # as alone: a failure, else an untraceable mode
        lateral_m = laterals[e].rows() if laterals else None
        platoon = detached.pop(e, None)
        if error is not None:
            results[e] = error
        elif platoon is not None:
            platoon.pairs = recorded[e]
            try:
                trace, min_gaps = platoon.trace(np.arange(steps + 1) * dt, rows_x[:steps + 1, e], rows_v[:steps + 1, e],
                                                lateral_m)
                results[e] = Episode(trace, collisions, min_gaps)
            except Exception as exc:  # a user's controller's mode that is not a number, as alone
                results[e] = exc
        else:
            results[e] = batch.episode(e, steps, rows_x[:steps + 1, e], rows_v[:steps + 1, e], collisions,
                                       recorded[e] if laterals else None, lateral_m)
        if on_episode:
            on_episode(e, results[e])

    changes: dict[int, list[int]] = {}
    for e, step in enumerate(lane_change_steps):
        if step is not None:
            changes.setdefault(step, []).append(e)
    sense(0)
    pairs = episode_pairs(0)
    lead, gap = batch.leaders(rows_x[0], pairs)
    for k in range(config.steps):
        arrayed = len(live) - len(detached)  # episodes the arrays command
        if 0 < arrayed <= DETACH_AT:  # few left: each goes on alone
            for e in live:
                if e not in detached:
                    detached[e] = batch.detach(e, k)
                    active[e] = False
            arrayed = 0
        for e in changes.get(k, ()):
            if e in live:
                laterals[e].change_lane()
        if arrayed:
            speeds = batch.advance(k, rows_x[k], rows_v[k], lead, gap, active)
            for e in batch.failed.keys() & live:  # a user's controller failed: the episode ends with its error
                end(e, k, ())
            rows = speeds.tolist()
            for e in live:  # none is detached while the arrays command any
                for vid, v in zip(commanded_ids[e], rows[e]):
                    set_speed(vid, v)
        for e, platoon in list(detached.items()):
            x = rows_x[k, e].tolist()
            try:
                out = platoon.advance(k, x, rows_v[k, e].tolist(), pairs[e] if pairs else maneuver.pairs(x))
            except Exception as exc:  # a user's controller: as alone, the episode ends with its error
                end(e, k, (), exc)
                continue
            for vid, v in zip(commanded_ids[e], out):
                set_speed(vid, v)
        if not live:
            break
        sumo_step()
        sense(k + 1)
        pairs = episode_pairs(k + 1)
        lead, gap = batch.leaders(rows_x[k + 1], pairs)
        hit = collided(gap)
        if np.count_nonzero(hit):
            for e in [e for e in live if hit[e]]:
                x, v = rows_x[k + 1, e].tolist(), rows_v[k + 1, e].tolist()
                end(e, k + 1, collisions_at((k + 1) * dt, pairs[e] if pairs else maneuver.pairs(x), x, v, config.vehicle_ids))
            if not live:
                break
    for e in list(live):
        end(e, config.steps, ())
    return results
