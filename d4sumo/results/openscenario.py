"""A stored counterexample out to other simulators: its road as OpenDRIVE and its episode as OpenSCENARIO 1.2.

``d4sumo export DB SAMPLE --openscenario DIR`` replays the sample through SUMO (its FCD: where each car
was, every step) and writes

- ``DIR/road.xodr``: the network the episode ran on, as netconvert's own ``--opendrive-output`` writes it: a
  network file run as given keeps its coordinates and its geo-reference (its ``<geoReference>`` and offset);
- ``DIR/scenario.xosc``: OpenSCENARIO 1.2, written with scenariogeneration, in the network's coordinates, its
  clock starting with the platoon. Each car is an entity whose reference point is its front bumper (SUMO's
  position; its bounding box lies behind it), and follows the trajectory it drove, a polyline of timed world
  positions, one a step:
  - the attacker (and a maneuver's other car) always;
  - the followers, the systems under test, while the parameter ``followers_as_played`` is true (the
    default). Each carries its controller: named by its class, its parameters (and the scenario's setpoint
    and target speed, its radar and channel) as properties. Set to false, they start where they were at
    their speed, for another simulator to put its own ACC in their place;
  - among traffic, every traffic car that came within `TRAFFIC_MEETS_M` of a car of the platoon, out of the
    scene until it entered the road and after it left (AddEntityAction, DeleteEntityAction).

  The storyboard stops at the collision that ended the episode (the pair that collided), or at its end.

The file header's properties say what d4sumo found: the outcome, the pair, the time of the collision, the
systems under test.
"""

from __future__ import annotations

import math
import os
import shutil
import tempfile
from pathlib import Path
from typing import Sequence
from xml.etree import ElementTree as ET

import numpy as np

from ..engine.netconvert import opendrive_output
from ..errors import ConfigError
from ..model.controllers.fmu import SIGNALS, is_fmu
from ..model.world.lanes import CAR_WIDTH_M
from ..model.stepping.trace import Collision
from ..model.world.traffic import is_traffic
from ..search.store import campaign_key
from .analysis import TRAFFIC_MEETS_M
from .records import Record
from .replays import evaluator_of

CAR_HEIGHT_M = 1.5
#: OpenSCENARIO's minor version the export writes (1.2)
OSC_MINOR = 2
ROAD_FILE, SCENARIO_FILE = "road.xodr", "scenario.xosc"


def read_fcd_xy(path: str | Path) -> dict[str, dict[str, list[float]]]:
    """SUMO's FCD as {vehicle: {time, x, y, angle, speed}}, every step it was there."""
    out: dict[str, dict[str, list[float]]] = {}
    for _, element in ET.iterparse(path, events=("end",)):
        if element.tag != "timestep":
            continue
        t = float(element.get("time"))
        for v in element.iter("vehicle"):
            d = out.setdefault(v.get("id"), {"time": [], "x": [], "y": [], "angle": [], "speed": [], "type": v.get("type", "")})
            d["time"].append(t)
            for key in ("x", "y", "angle", "speed"):
                d[key].append(float(v.get(key)))
        element.clear()
    return out


def heading_rad(sumo_angle_deg: float) -> float:
    """SUMO's angle (degrees, clockwise from north) as OpenSCENARIO's heading (radians, counterclockwise
    from the x axis), in [0, 2 pi)."""
    return math.radians(90.0 - sumo_angle_deg) % (2.0 * math.pi)


def read_motion(path: str | Path, vehicle: str, step_s: float, steps: int, sample: int | None = None,
                campaign: str | None = None, changes_lanes: bool = False, lanes=None) -> np.ndarray:
    """The speed at each step's end of ``vehicle`` as an exported scenario has it, what `AttackPlan.motion`
    replays: from its initial speed, and the distance along its lane between two of its trajectory's timed
    positions, which SUMO's ballistic update covers at the mean of the speeds at the step's ends (a car that
    stops within a step ends it at 0). Past the trajectory's end it holds its last speed. ``sample``: the
    sample it must be the export of, and ``campaign`` the key of its campaign (its header says so), where it
    says. ``changes_lanes``: its heading turns away from its lane's while it changes lanes (the more, the
    slower it drives: at a standstill it moves only across), so the distance along its lane is read along
    the heading it starts with, in its lane: the roads lane changes are played on are straight
    (`engine.simulation.check_road`: lanes as long as each other, no curve, no junction). ``lanes``: the route's
    lanes the car keeps to (`layout.route_lanes`), along which its positions are measured as SUMO counts them (on a
    curve a lane's shape is longer or shorter than SUMO's length of it, by a few centimetres in a hundred metres)."""
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ConfigError("--openscenario", str(path), f"an OpenSCENARIO file d4sumo exported ({exc})") from None
    trajectory = next((t for t in root.iter("Trajectory") if t.get("name") == f"{vehicle}_as_played"), None)
    vertices = trajectory.findall("./Shape/Polyline/Vertex") if trajectory is not None else []
    if len(vertices) < 2:
        raise ConfigError("--openscenario", str(path), f"an OpenSCENARIO file d4sumo exported, with {vehicle}'s trajectory "
                                                       "(a polyline of timed world positions)")
    start = next((p for p in root.iter("Private") if p.get("entityRef") == vehicle), None)
    target = start.find(".//AbsoluteTargetSpeed") if start is not None else None
    if target is None:
        raise ConfigError("--openscenario", str(path), f"an OpenSCENARIO file d4sumo exported, with {vehicle}'s initial speed")
    try:
        t = np.array([float(v.get("time")) for v in vertices])
        xy = np.array([[float(v.find("./Position/WorldPosition").get(k)) for k in ("x", "y")] for v in vertices])
        # the distance along the car's heading: a lane change, which SUMO makes within a step, moves it across
        heading = np.array([float(v_.find("./Position/WorldPosition").get("h", 0.0)) for v_ in vertices])
        v = float(target.get("value"))
    except (TypeError, ValueError, AttributeError):
        ok = False
    else:
        ok = bool(np.all(np.isfinite(t)) and np.all(np.isfinite(xy)) and np.all(np.isfinite(heading)) and math.isfinite(v))
    if not ok:  # a NaN played as a position replayed another motion
        raise ConfigError("--openscenario", str(path), f"an OpenSCENARIO file d4sumo exported, {vehicle}'s trajectory's times, "
                                                       "positions, headings and initial speed numbers")
    if sample is not None:  # the header says which sample it is: another's motion would replay another attack
        said = next((p.get("value") for p in root.iter("Property") if p.get("name") == "d4sumo.sample"), None)
        if said is not None and said != str(sample):
            raise ConfigError("--openscenario", str(path), f"the export of sample {sample} (this one is sample {said}'s)")
    if campaign is not None:  # the same sample number in another database is another campaign's attack
        of = next((p.get("value") for p in root.iter("Property") if p.get("name") == "d4sumo.campaign"), None)
        if of is not None and of != campaign:
            where = next((p.get("value") for p in root.iter("Property") if p.get("name") == "d4sumo.database"), "?")
            raise ConfigError("--openscenario", str(path), f"the export of this database's sample {sample} (this one is "
                                                           f"of another campaign, exported from {where})")
    if np.any(np.abs(np.diff(t) - step_s) > 1e-6):
        raise ConfigError("--openscenario", str(path), f"a trajectory with a position every step of the episode ({step_s:g} s)")
    if lanes is not None and not changes_lanes:
        along = np.maximum(np.diff(along_route(xy, lanes)), 0.0)  # cars never drive backwards
    else:
        lane = np.full_like(heading, heading[0]) if changes_lanes else heading  # the direction of its lane at each position
        step = np.diff(xy, axis=0)
        along = np.abs(step[:, 0] * np.cos(lane[:-1]) + step[:, 1] * np.sin(lane[:-1]))
    speeds = []
    for d, dt in zip(along, np.diff(t)):
        v = max(0.0, 2.0 * d / dt - v)
        speeds.append(v)
    speeds = np.array(speeds)
    return np.concatenate([speeds, np.full(max(0, steps - speeds.size), speeds[-1])])[:steps]


def along_route(xy: np.ndarray, lanes) -> np.ndarray:
    """Each point's position along the route as SUMO counts it (a car's: where it started plus its odometer), from the
    route's lanes (`layout.route_lanes`): the point projected onto the nearest of the lane it was on and the next few,
    its distance along that lane's shape scaled to SUMO's length of the lane."""
    from sumolib.geomhelper import polyLength, polygonOffsetWithMinimumDistanceToPoint, distancePointToPolygon

    starts, at = [], 0.0
    for _, length in lanes:
        starts.append(at)
        at += length
    factors = [length / polyLength(shape) if polyLength(shape) > 0 else 1.0 for shape, length in lanes]
    out, current = [], 0
    for point in map(tuple, xy):
        candidates = range(current, min(len(lanes), current + 4))
        current = min(candidates, key=lambda i: distancePointToPolygon(point, lanes[i][0], perpendicular=False))
        offset = polygonOffsetWithMinimumDistanceToPoint(point, lanes[current][0], perpendicular=False)
        out.append(starts[current] + offset * factors[current])
    return np.array(out)


class NotExported(ConfigError):
    """A sample this version does not export as OpenSCENARIO: the sample is the value refused, ``why`` says
    what its campaign has."""

    def __init__(self, sample_id: int, why: str, allowed: str):
        self.why = why
        super().__init__("sample", f"{sample_id} ({why})", allowed)


def export_openscenario(record: Record, out_dir: str | Path, fcd: str | Path | None = None) -> tuple[Path, Path]:
    """Write the sample's ``road.xodr`` and ``scenario.xosc`` into ``out_dir`` (created; files already there
    are replaced whole, never half-written). ``fcd``: its replay's FCD where one was written already (its
    verdict is then the stored one, which a replay reproduces); else it is replayed here."""
    out_dir = Path(out_dir)
    evaluator = evaluator_of(record)
    campaign = evaluator.campaign
    config = evaluator.config_for(record.params)  # in the situation the sample played
    if campaign.message:  # another simulator would see the attacker's motion, and none of its lies
        raise NotExported(record.sample_id, f"its campaign has a message attack, {campaign.message}", "a sample of a "
                          "campaign without a message attack (OpenSCENARIO carries the cars' motion, not what their V2V "
                          "beacons said)")
    with tempfile.TemporaryDirectory(prefix="d4sumo-xosc-") as tmp:
        if fcd is None:
            fcd = Path(tmp) / "fcd.xml"
            episode = evaluator.simulate(record.index, record.params, fcd_path=fcd)
            outcome, first = episode.outcome, episode.first_collision
        else:
            outcome = record.outcome
            first = Collision(*record.pair.split("-", 1), record.time_s, record.position_m, record.speed_diff_kmh) \
                if record.pair else None
        tracks = read_fcd_xy(fcd)
        opendrive_output(evaluator.road.net_file, Path(tmp) / ROAD_FILE, config.network)
        scenario = _scenario(record, campaign, config, tracks, outcome, first)
        scenario.write_xml(str(Path(tmp) / SCENARIO_FILE))
        out_dir.mkdir(parents=True, exist_ok=True)
        for name in (ROAD_FILE, SCENARIO_FILE):  # each replaced whole: a reader never sees half a file
            part = out_dir / f".{name}.part"
            shutil.copyfile(Path(tmp) / name, part)
            os.replace(part, out_dir / name)
    return out_dir / ROAD_FILE, out_dir / SCENARIO_FILE


def _vehicle(xosc, name: str, vehicle, max_speed_mps: float):
    category = {"truck": xosc.VehicleCategory.truck, "bus": xosc.VehicleCategory.bus,
                "motorcycle": xosc.VehicleCategory.motorbike}.get(vehicle.vclass, xosc.VehicleCategory.car)
    length = vehicle.length_m
    # the reference point is the front bumper, as SUMO's position: the box lies behind it
    box = xosc.BoundingBox(CAR_WIDTH_M, length, CAR_HEIGHT_M, -length / 2.0, 0.0, CAR_HEIGHT_M / 2.0)
    front = xosc.Axle(0.5, 0.6, 1.6, -0.2 * length, 0.3)
    rear = xosc.Axle(0.0, 0.6, 1.6, -0.8 * length, 0.3)
    return xosc.Vehicle(name, category, box, front, rear, max_speed_mps, vehicle.max_accel_mps2, vehicle.max_decel_mps2)


def _controller(xosc, follower: int, controller, config):
    """The follower's controller as the system under test: its class, its parameters as properties."""
    properties = xosc.Properties()
    properties.add_property("system_under_test", "true")
    properties.add_property("class", controller.cls)
    properties.add_property("setpoint_m", repr(config.setpoint_m))
    properties.add_property("target_speed_mps", repr(config.speed_mps))
    sensing = [*controller.params,  # what it senses and hears is part of the system under test too
               *((f"radar.{k}", v) for k, v in (config.radar.to_dict() if config.radar is not None else {}).items()),
               *((f"v2v.{k}", v) for k, v in (config.v2v.to_dict() if config.v2v is not None else {}).items())]
    fmu = is_fmu(controller.cls)
    for key, value in sensing:
        if fmu and key in SIGNALS:  # the FMU's variable a signal maps to: not the signal's value set above
            key = f"fmu.{key}"
        properties.add_property(str(key), repr(value) if isinstance(value, float) else str(value))
    return xosc.Controller(f"v{follower}_{controller.cls}", properties)


def _position(xosc, track: dict, i: int):
    return xosc.WorldPosition(track["x"][i], track["y"][i], 0.0, heading_rad(track["angle"][i]), 0.0, 0.0)


#: the parameter that plays the followers as they drove (true, the default) or leaves them to the simulator's own
#: controllers in their place (false), as the simulator that plays the file sets it
FOLLOWERS_AS_PLAYED = "followers_as_played"
#: SUMO's default passenger car, for a traffic car whose size the FCD does not say
TRAFFIC_LENGTH_M, TRAFFIC_WIDTH_M = 5.0, 1.8


def near_traffic(tracks: dict, platoon: Sequence[str], within_m: float) -> list[str]:
    """The traffic cars that came within ``within_m`` of a car of the platoon, front bumper to front bumper, at a
    step both were on the road (`read_fcd_xy` tracks), in the order they first appeared."""
    at: dict[float, list[tuple[float, float]]] = {}
    for vid in platoon:
        for t, x, y in zip(*(tracks[vid][k] for k in ("time", "x", "y"))) if vid in tracks else ():
            at.setdefault(round(t, 6), []).append((x, y))
    near = []
    for vid, d in tracks.items():
        if vid in platoon or not is_traffic(vid):
            continue
        if any(math.hypot(x - px, y - py) <= within_m for t, x, y in zip(d["time"], d["x"], d["y"])
               for px, py in at.get(round(t, 6), ())):
            near.append(vid)
    return sorted(near, key=lambda vid: tracks[vid]["time"][0])


def _trajectory_event(xosc, vid: str, track: dict, t0: float, first: int = 0):
    """An event that drives ``vid`` along its track from sample ``first`` on, its times relative to the event's start."""
    times = track["time"][first:]
    polyline = xosc.Polyline([t - times[0] for t in times], [_position(xosc, track, k) for k in range(first, len(track["time"]))])
    trajectory = xosc.Trajectory(f"{vid}_as_played", False)
    trajectory.add_shape(polyline)
    event = xosc.Event(f"{vid}_drives", xosc.Priority.override)
    event.add_action(f"{vid}_follows_its_trajectory", xosc.FollowTrajectoryAction(
        trajectory, xosc.FollowingMode.position, xosc.ReferenceContext.relative, 1.0, 0.0))
    event.add_trigger(xosc.ValueTrigger(f"{vid}_at_start", 0.0, xosc.ConditionEdge.none,
                                        xosc.SimulationTimeCondition(times[0] - t0, xosc.Rule.greaterOrEqual)))
    return event


def _group(xosc, vid: str, *events):
    maneuver = xosc.Maneuver(f"{vid}_maneuver")
    for event in events:
        maneuver.add_event(event)
    group = xosc.ManeuverGroup(f"{vid}_group")
    group.add_actor(vid)
    group.add_maneuver(maneuver)
    return group


def _at_start(xosc, name: str):
    return xosc.ValueTrigger(name, 0.0, xosc.ConditionEdge.none, xosc.SimulationTimeCondition(0.0, xosc.Rule.greaterOrEqual))


def _scenario(record: Record, campaign, config, tracks: dict, outcome: str, first):
    """``config``: the sample's (its campaign's, in the situation it played)."""
    from scenariogeneration import xosc

    ids = [vid for vid in config.vehicle_ids if vid in tracks]
    n = config.followers + 1
    # the scenario's clock starts with the platoon (among traffic SUMO's ran through the traffic's warm-up first)
    t0 = min(tracks[v]["time"][0] for v in ids)
    traffic = near_traffic(tracks, ids, TRAFFIC_MEETS_M)
    entities = xosc.Entities()
    init = xosc.Init()
    for i, vid in enumerate(ids):
        vehicle = _vehicle(xosc, vid, config.vehicle_of(config.vehicle_ids.index(vid)), max(config.speed_mps, 70.0))
        follower = 1 <= i < n
        controller = _controller(xosc, i, config.controllers[i - 1], config) if follower else None
        entities.add_scenario_object(vid, vehicle, controller=controller)
        _start_at(xosc, init, tracks[vid], vid)
    end = max(tracks[v]["time"][-1] for v in ids)
    traffic_act = _traffic_act(xosc, config, tracks, traffic, t0, end, entities, init)
    story = xosc.Story("attack")
    act = xosc.Act("as_played", _at_start(xosc, "at_start"))
    for i, vid in enumerate(ids):  # the cars d4sumo commands, not the systems under test: as they drove
        if not 1 <= i < n:
            act.add_maneuver_group(_group(xosc, vid, _trajectory_event(xosc, vid, tracks[vid], t0)))
    story.add_act(act)
    # the systems under test as they drove, unless the parameter hands them to the simulator's own controllers
    as_played = xosc.ConditionGroup()
    as_played.add_condition(_at_start(xosc, "followers_at_start"))
    as_played.add_condition(xosc.ValueTrigger("followers_as_played_set", 0.0, xosc.ConditionEdge.none,
                                              xosc.ParameterCondition(FOLLOWERS_AS_PLAYED, "true", xosc.Rule.equalTo)))
    played = xosc.Trigger()
    played.add_conditiongroup(as_played)
    followers = xosc.Act("systems_under_test_as_played", played)
    for i, vid in enumerate(ids):
        if 1 <= i < n:
            followers.add_maneuver_group(_group(xosc, vid, _trajectory_event(xosc, vid, tracks[vid], t0)))
    story.add_act(followers)
    stops = _stop_trigger(xosc, end - t0 + config.step_s, first)
    storyboard = xosc.StoryBoard(init, stops)
    storyboard.add_story(story)
    if traffic:
        traffic_story = xosc.Story("traffic")
        traffic_story.add_act(traffic_act)
        storyboard.add_story(traffic_story)
    parameters = xosc.ParameterDeclarations()
    parameters.add_parameter(xosc.Parameter(FOLLOWERS_AS_PLAYED, xosc.ParameterType.boolean, "true"))
    header = _header(xosc, record, campaign, outcome, ids[1:n], traffic, first)
    return xosc.Scenario(f"d4sumo sample {record.sample_id}", "d4sumo", parameters, entities, storyboard,
                         xosc.RoadNetwork(ROAD_FILE), xosc.Catalog(), osc_minor_version=OSC_MINOR,
                         header_properties=header)


def _traffic_act(xosc, config, tracks: dict, traffic, t0: float, end: float, entities, init):
    """The traffic that came near the platoon, each car as it drove, entering and leaving the scene where it
    entered and left the road."""
    traffic_act = xosc.Act("traffic_as_played", _at_start(xosc, "traffic_at_start"))
    for vid in traffic:
        track = tracks[vid]
        box = xosc.BoundingBox(TRAFFIC_WIDTH_M, TRAFFIC_LENGTH_M, CAR_HEIGHT_M, -TRAFFIC_LENGTH_M / 2.0, 0.0, CAR_HEIGHT_M / 2.0)
        vehicle = xosc.Vehicle(vid, xosc.VehicleCategory.car, box, xosc.Axle(0.5, 0.6, 1.6, -1.0, 0.3),
                               xosc.Axle(0.0, 0.6, 1.6, -4.0, 0.3), 70.0, 3.0, 9.0)
        vehicle.add_property("sumo.type", track["type"])  # its size: SUMO's default passenger car's
        entities.add_scenario_object(vid, vehicle)
        late = track["time"][0] > t0 + 1e-9
        events = []
        if late:  # it enters the road after the platoon: out of the scene until then, where it entered
            init.add_global_action(xosc.DeleteEntityAction(vid))
            enter = xosc.Event(f"{vid}_enters", xosc.Priority.parallel)
            enter.add_action(f"{vid}_added", xosc.AddEntityAction(vid, _position(xosc, track, 0)))
            enter.add_trigger(xosc.ValueTrigger(f"{vid}_entering", 0.0, xosc.ConditionEdge.none,
                                                xosc.SimulationTimeCondition(track["time"][0] - t0, xosc.Rule.greaterOrEqual)))
            events.append(enter)
        else:
            _start_at(xosc, init, track, vid, int(np.searchsorted(np.round(track["time"], 6), round(t0, 6))))
        first_k = 0 if late else int(np.searchsorted(np.round(track["time"], 6), round(t0, 6)))
        events.append(_trajectory_event(xosc, vid, track, t0, first_k))
        if track["time"][-1] < end - 1e-9:  # it left the road (or SUMO's network) before the episode's end
            leave = xosc.Event(f"{vid}_leaves", xosc.Priority.parallel)
            leave.add_action(f"{vid}_deleted", xosc.DeleteEntityAction(vid))
            leave.add_trigger(xosc.ValueTrigger(f"{vid}_leaving", 0.0, xosc.ConditionEdge.none, xosc.SimulationTimeCondition(
                track["time"][-1] - t0 + config.step_s, xosc.Rule.greaterOrEqual)))
            events.append(leave)
        traffic_act.add_maneuver_group(_group(xosc, vid, *events))
    return traffic_act


def _start_at(xosc, init, track: dict, vid: str, k: int = 0) -> None:
    """A car at the scenario's start where its track is at sample k, at its speed there."""
    init.add_init_action(vid, xosc.TeleportAction(_position(xosc, track, k)))
    init.add_init_action(vid, xosc.AbsoluteSpeedAction(track["speed"][k], xosc.TransitionDynamics(
        xosc.DynamicsShapes.step, xosc.DynamicsDimension.time, 0.0)))


def _stop_trigger(xosc, end_s: float, first):
    """The scenario ends after its last step, or at the collision d4sumo found."""
    stop = xosc.ConditionGroup("stop")
    stop.add_condition(xosc.ValueTrigger("episode_end", 0.0, xosc.ConditionEdge.rising,
                                         xosc.SimulationTimeCondition(end_s, xosc.Rule.greaterThan), "stop"))
    stops = xosc.Trigger("stop")
    stops.add_conditiongroup(stop)
    if first is not None:  # the expected end: the collision d4sumo found
        collided = xosc.ConditionGroup("stop")
        collided.add_condition(xosc.EntityTrigger("expected_collision", 0.0, xosc.ConditionEdge.rising,
                                                  xosc.CollisionCondition(first.follower), first.leader, triggeringpoint="stop"))
        stops.add_conditiongroup(collided)
    return stops


def _header(xosc, record: Record, campaign, outcome: str, systems: list[str], traffic, first):
    """What the scenario says of where it comes from: the database, the sample, its campaign and outcome."""
    header = xosc.Properties()
    header.add_property("d4sumo.database", str(Path(record.db).resolve()))
    header.add_property("d4sumo.sample", str(record.sample_id))
    header.add_property("d4sumo.campaign", campaign_key(campaign.definition()))  # which campaign's sample: a replay checks it
    header.add_property("d4sumo.outcome", outcome)
    header.add_property("d4sumo.systems_under_test", " ".join(systems))
    if traffic:
        header.add_property("d4sumo.traffic", f"{len(traffic)} cars that came within {TRAFFIC_MEETS_M:g} m of the platoon")
    if first is not None:
        header.add_property("d4sumo.collision_pair", f"{first.leader}-{first.follower}")
        header.add_property("d4sumo.collision_time_s", repr(round(first.time_s, 9)))  # a whole step: 3.4, not 3.4000000000000004
    return header
