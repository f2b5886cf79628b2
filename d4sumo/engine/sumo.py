"""The SUMO world: with `command` (SUMO's command line and the files it reads, checked once) and `warmup` (the
traffic's warm-up), the only modules that talk to SUMO (libsumo, or traci for sumo-gui).

SUMO moves the cars (ballistic update). Python commands the speed of the attacker and of every
Python-commanded follower (SUMO's car-following, lane changing and speed checks are off for them:
speed mode 32, lane-change mode 0); followers driven by SUMO's own car-following models run with their
vehicle type, loaded from an additional file checked once per content, with SUMO's default speed mode.
`SumoWorld` is the seam the step loop (`engine.loop.play`) drives: insert, sense, apply speeds, step,
remove. Many platoons share one SUMO each on its own copy of the road (`scenarios.batch_road`).
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Callable, Sequence

import numpy as np

from ..errors import SumoError
from ..model.config import EpisodeConfig
from ..model.attacks.maneuvers import maneuver_of
from ..model.world.lanes import CAR_WIDTH_M, occupied_lanes
from ..model.controllers.carfollowing import beacon_parameters, vehicle_data
from ..model.stepping.platoon import followers_of
from ..model.world.vehicle import VehicleParams
from ..sumohome import sumo_binary
from .calls import native_calls, simulation_step, vehicle_call
from .command import (
    ATTACKER_VTYPE_ID, LANE_CHANGE_MODE_OFF, LANE_CHANGE_MODE_SUMO, ROUTE_ID, SPEED_MODE_PYTHON, VTYPE_ID,
    follower_types, sumo_command)
from .junctions import JunctionCrossings
from .lights import RouteLights, route_signals, signal_tracks
from .neighbours import RouteLanes, _LateralTrafficSense, _TrafficSense
from .scenarios import Road
from .warmup import traffic_state

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


def route_position(api, road: Road, vehicle_ids: Sequence[str]) -> tuple[Callable[[str], float], dict[str, float] | None]:
    """A reader of each car's position along its route [m], its front bumper, and where it was inserted (None: the
    reader is SUMO's lane position).

    On a road of one edge that is SUMO's lane position. On a route of many edges the lane position
    starts again at 0 on each edge (and on each junction's internal lane), so the position is where the
    car was inserted plus SUMO's odometer, the distance it has driven since, across edges and
    junctions. Call it right after the cars are inserted (t = 0, odometer 0).
    """
    get_position = vehicle_call(api, "getLanePosition")
    if road.one_edge:
        return get_position, None
    departed = {vid: get_position(vid) for vid in vehicle_ids}  # every car starts on the route's first edge
    get_distance = vehicle_call(api, "getDistance")
    return (lambda vid: departed[vid] + get_distance(vid)), departed



class _Lateral:
    """The attacker's lane change, and where it is across the road at each step: the lanes it covers.

    A maneuver counts lanes from the platoon's, which an on-ramp or an exit moves to another of SUMO's
    indices from one edge to the next (`RouteLanes`): a change is asked for by the index of the attacker's
    own edge. SUMO keeps the request's lane as the car passes onto the next edge (it shifts the requested
    index with the car's own)."""

    def __init__(self, api, maneuver, road: Road, attacker: str = "v0", copy: int = 0):
        self.api = api
        self.attacker = attacker
        self.width = road.lane_width_m
        self.route_lanes = RouteLanes(api, road.route(copy), road.platoon_path)
        lanes = maneuver.start_lanes()
        self.fixed = [(lane,) for lane in lanes[1:]]  # only the attacker changes lanes
        self.fixed_y = [(lane + 0.5) * self.width for lane in lanes[1:]]
        self.y: list[float] = []
        self.get_lane = api.vehicle.getLaneID
        self.get_lateral = api.vehicle.getLateralLanePosition

    def change_lane(self, lane: int) -> None:
        # SUMO carries it out (over scenario.lane_change_s, or in one step); the request holds until the next
        self.api.vehicle.changeLane(self.attacker, self.route_lanes.index(self.get_lane(self.attacker), lane), 1e6)

    def sense(self) -> list[tuple[int, ...]]:
        y = (self.route_lanes.place(self.get_lane(self.attacker)) + 0.5) * self.width + self.get_lateral(self.attacker)
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
        self.get_position, self._departed = route_position(api, road, [vid for ids in platoons for vid in ids])
        maneuver = maneuver_of(config)
        self.laterals = [_Lateral(api, maneuver, road, ids[0], e) for e, ids in enumerate(platoons)] if maneuver.lateral else None
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
        self._calls = None  # SUMO's own calls in C (`native_calls`), where its step is SUMO's alone
        if road.forks:  # SUMO may take another lane than the path at a fork: each step checks it did not
            check = _LanePathCheck(api, config, road, platoons, maneuver)
            self.removed = check.removed
            self.step = lambda: (step(), check())
        else:
            self.removed = set()
            self.step = step
            self._calls = native_calls(api)
        self._own = (self.step, self.set_speed, self.get_speed, self.get_position)

    def own_calls(self):
        """SUMO's own calls in C for the step loop in C (`calls.native_calls`), the same as this world's step, set_speed,
        get_speed and get_position; None where there are none, or where those were replaced (a test's or a tool's
        wrapper: the loop in C then calls those)."""
        own = (self.step, self.set_speed, self.get_speed, self.get_position)
        return self._calls if all(a is b for a, b in zip(own, self._own)) else None

    def offsets(self, e: int) -> tuple[float, ...] | None:
        """Where episode e's cars were inserted along the route, which their odometers add to (`route_position`); None:
        their positions are SUMO's lane positions."""
        return None if self._departed is None else tuple(self._departed[vid] for vid in self.platoons[e])

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
