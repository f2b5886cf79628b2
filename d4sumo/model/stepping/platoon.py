"""The platoon's longitudinal control, one step at a time: pure code, no SUMO.

The system under test is a platoon of followers of two kinds: a `PythonFollower` runs a Python
controller whose command goes through the car's actuator; a `SumoFollower` is driven by one of SUMO's
car-following models, which the co-simulation only senses. `Platoon.advance` takes the sensed state
(positions and speeds, front to back) and returns the speed at the end of the step of each car Python
commands: the attacker plays its attack signal (or cruises where the signal is NaN) and each Python
follower runs its controller. The step loop (`engine.loop.play`) calls it each step, in SUMO or in the
SUMO-free ballistic world (`engine.ballistic.integrate`, for physics tests). A cooperative platoon's
followers (with their radars and channel) may be stepped in C instead (`compiled`), bit for bit.
"""

from __future__ import annotations

import math
from types import MappingProxyType

import numpy as np

from ...errors import D4sumoError
from ..controllers import carfollowing
from ..controllers.commands import ControllerError, checked_command
from ..config import ControllerConfig, EpisodeConfig
from ..controllers.compiled import compiled_followers
from ..controllers.control import CautiousDriver, CruiseControl, SwitchingController, SwitchingParams, user_code
from ..controllers.plugins import observer
from ..world.signals import SignalDriver, light_code
from ..world.vehicle import Actuator, acceleration_to_command
from ..world.sensing import sensed_command
from ..attacks.maneuvers import Pair, maneuver_of
from ..world.lanes import CAR_WIDTH_M, FREE_ROAD_GAP_M
from .recording import _hold_last, assemble_trace, sent_signals
from .trace import Collision, Trace, rows_array
from ..world.v2v import Channel


def _named_errors(command, car: int, name: str):
    """A user's controller's observe(), its errors a ControllerError naming the car and the class."""
    def checked(*args):
        try:
            return command(*args)
        except Exception as exc:
            raise ControllerError(f"the controller of v{car} ({name}) raised {type(exc).__name__}: {exc}") from exc
    return checked


def reach_m(speed_mps: float, accel_mps2: float, limit_mps: float, duration_s: float) -> float:
    """How far a car that starts at ``speed_mps`` can drive in ``duration_s``, accelerating at most at
    ``accel_mps2`` up to ``limit_mps`` [m]."""
    if speed_mps >= limit_mps or accel_mps2 <= 0.0:  # at its speed (held to the limit) all along
        return min(speed_mps, limit_mps) * duration_s
    t_limit = (limit_mps - speed_mps) / accel_mps2
    if duration_s <= t_limit:
        return speed_mps * duration_s + 0.5 * accel_mps2 * duration_s ** 2
    return speed_mps * t_limit + 0.5 * accel_mps2 * t_limit ** 2 + limit_mps * (duration_s - t_limit)


def reach_s(speed_mps: float, accel_mps2: float, limit_mps: float, distance_m: float) -> float:
    """The inverse of `reach_m`: the longest time in which such a car drives at most ``distance_m``."""
    if distance_m <= 0.0:
        return 0.0
    if speed_mps >= limit_mps or accel_mps2 <= 0.0:
        fastest = min(speed_mps, limit_mps)
        return distance_m / fastest if fastest > 0.0 else math.inf
    t_limit = (limit_mps - speed_mps) / accel_mps2
    to_limit = speed_mps * t_limit + 0.5 * accel_mps2 * t_limit ** 2
    if distance_m <= to_limit:
        return (math.sqrt(speed_mps ** 2 + 2.0 * accel_mps2 * distance_m) - speed_mps) / accel_mps2
    return t_limit + (distance_m - to_limit) / limit_mps


def _frontmost(config: EpisodeConfig) -> tuple[float, float, float]:
    """The frontmost start [m], the fastest start [m/s] and the strongest full throttle [m/s^2] of the cars."""
    cars = maneuver_of(config).cars()
    return (max(car.position_m for car in cars), max(car.speed_mps for car in cars),
            max(v.max_accel_mps2 for v in config.car_vehicles))


def road_needed_m(config: EpisodeConfig, speed_limit_mps: float) -> float:
    """Road length an episode may use: what the frontmost car's start leaves to a car that starts as fast as
    the fastest, accelerates as hard as the strongest, up to the limit, for the whole episode (its warm-up
    included): no car passes it."""
    start, speed, accel = _frontmost(config)
    return start + reach_m(speed, accel, speed_limit_mps, config.total_s)


def longest_duration_s(config: EpisodeConfig, length_m: float, speed_limit_mps: float) -> float:
    """The longest scenario.duration_s (on the step grid, after the warm-up) a road of ``length_m`` holds
    (`road_needed_m`); 0 or less: none."""
    start, speed, accel = _frontmost(config)
    total = reach_s(speed, accel, speed_limit_mps, length_m - start)
    return math.floor(round((total - config.attack_start_s) / config.step_s, 9)) * config.step_s


def collisions_at(time_s: float, pairs: list[Pair], positions: list[float], speeds: list[float],
                  ids: tuple[str, ...], collision_gap_m: float = 0.0) -> tuple[Collision, ...]:
    """Every collision at the end of a step, frontmost pair first: a pair whose bumper gap is below
    ``collision_gap_m`` (`EpisodeConfig.collision_gap_m`; 0: an overlap).

    This is the definition of a collision, whether SUMO reports it or not (SUMO ignores overlaps up to
    1 mm). The gaps are the maneuver's pairs, from which the trace's gaps come too, so the outcome, the
    collision record and the trace's minimum gaps always agree. The position is the follower's front
    bumper, where it hit.
    """
    for _, _, gap in pairs:  # none, at nearly every step: said without building anything
        if gap < collision_gap_m:
            break
    else:
        return ()
    return tuple(Collision(ids[a], ids[b], time_s, positions[b], (speeds[b] - speeds[a]) * 3.6)
                 for a, b, gap in pairs if gap < collision_gap_m)


class PythonFollower:
    """A follower commanded each step by a Python controller, through its actuator."""

    sumo_driven = False
    shares_sumo = True  # its platoon may share one SUMO with others (a batch)

    def __init__(self, config: ControllerConfig, episode: EpisodeConfig, car: int):
        self.config = config
        self.vehicle = episode.vehicle_of(car)
        users = user_code(config.cls) is not None
        try:
            self.controller = config.controller_class()(config.build_params(), setpoint_m=episode.setpoint_m,
                                                        target_speed_mps=episode.speed_mps, vehicle=self.vehicle,
                                                        step_s=episode.step_s)
        except Exception as exc:
            if not users or isinstance(exc, D4sumoError):
                raise
            raise ControllerError(f"the controller of v{car} ({config.cls}) could not be made: {type(exc).__name__}: {exc}") from exc
        self.actuator = Actuator(self.vehicle, episode.step_s, float("inf"))
        observe = observer(self.controller)
        if users:
            observe = _named_errors(observe, car, config.cls)
        #: what it does with the truth (gap, own speed, speed ahead): the observation, through its radar, to its controller
        self.command = sensed_command(observe, episode.radar, episode.step_s, car, beacons=episode.v2v is not None)
        self.has_mode = hasattr(self.controller, "mode")
        self.hears_all = bool(getattr(self.controller, "hears_all", False))


#: the time gap the attacker keeps to traffic ahead of it where it does not attack [s]: a careful driver's
ATTACKER_TIME_GAP_S = 1.5

#: SUMO's default comfortable deceleration of a passenger car, which its models plan with
PASSENGER_DECEL_MPS2 = 4.5


class SumoFollower:
    """A follower driven by one of SUMO's car-following models: d4sumo senses it and commands nothing.

    Its car is its vehicle (length, full-throttle acceleration, full-brake deceleration, class and shape
    from [vehicle] or its own [vehicle.vI]) whose desired speed is the target speed; the model and its
    attributes come from its controller table. `vtype` and `parameters` say it in SUMO's terms; the
    simulation loads them.
    """

    sumo_driven = True
    has_mode = False  # SUMO does not expose its models' internal modes to TraCI

    def __init__(self, config: ControllerConfig, episode: EpisodeConfig, car: int):
        self.config = config
        self.vehicle = episode.vehicle_of(car)
        self.model = config.sumo_model
        self.params = dict(config.params)
        self.episode = episode
        #: whether it reads V2V beacons (Plexe's cooperative controllers): the world feeds them to SUMO
        self.listens = carfollowing.listens(self.model, self.params)
        self.hears_all = carfollowing.hears_all(self.model, self.params)
        self.car = car
        #: whether its platoon may share one SUMO with others: not when its model draws random numbers
        self.shares_sumo = carfollowing.shares_sumo(self.model, self.params)

    def vtype(self, lanes: int) -> dict[str, str]:
        """Its <vType> attributes."""
        v = self.vehicle
        attributes = carfollowing.vtype_attributes(self.model, self.params, lanes=lanes)
        attributes.update(length=repr(v.length_m), accel=repr(v.max_accel_mps2), emergencyDecel=repr(v.max_decel_mps2),
                          maxSpeed=repr(self.episode.speed_mps), speedFactor="1", speedDev="0")
        if v.vclass != "passenger" or v.shape:
            attributes.update(vClass=v.vclass, width=repr(CAR_WIDTH_M), **({"guiShape": v.shape} if v.shape else {}))
        if v.vclass != "passenger" or v.max_decel_mps2 < PASSENGER_DECEL_MPS2:
            # a class brings its own defaults (a truck brakes at 4 m/s^2 by choice, a motorcycle at 10): the
            # model's comfortable deceleration stays the passenger car's unless its table sets one, and never
            # above what the car can brake
            attributes.setdefault("decel", repr(min(PASSENGER_DECEL_MPS2, v.max_decel_mps2)))
        return attributes

    @property
    def vtype_key(self) -> tuple:
        """What decides its <vType>: followers alike in it share one."""
        return self.config, self.vehicle

    def parameters(self) -> dict[str, str]:
        """Per-vehicle parameters its model reads after insertion."""
        return carfollowing.runtime_parameters(self.model, self.params, self.episode.speed_mps, self.car)


def make_follower(controller: ControllerConfig, config: EpisodeConfig, car: int) -> PythonFollower | SumoFollower:
    """The one place that tells the kinds of follower apart (``car``: its index, 1 for v1)."""
    return (SumoFollower if controller.sumo_model else PythonFollower)(controller, config, car)


def followers_of(config: EpisodeConfig) -> list[PythonFollower | SumoFollower]:
    """Each follower of the platoon, v1 first."""
    return [make_follower(c, config, i) for i, c in enumerate(config.controllers, start=1)]


class Platoon:
    """Every car Python knows of: the attacker, the followers and the maneuver's other car (a benign
    lead that cruises at the target speed, or an obstacle at its constant speed)."""

    def __init__(self, config: EpisodeConfig, attack_u: np.ndarray, attacker_max_speed_mps: float,
                 followers: list[PythonFollower | SumoFollower] | None = None, beacons=None, motion=None,
                 lights: bool = False):
        attack_u = np.asarray(attack_u, dtype=float)
        if attack_u.shape != (config.steps,):
            raise ValueError(f"attack signal has shape {attack_u.shape}, expected ({config.steps},)")
        self.config = config
        self.maneuver = maneuver_of(config)
        self.ids = config.vehicle_ids
        self.attack_u = attack_u.tolist()  # plain floats: fast in the step loop
        #: the attacker's speed at each step's end, where it replays a motion (`AttackPlan.motion`)
        self._motion = None if motion is None else [float(v) for v in motion]
        vehicle, dt = config.vehicle_of(0), config.step_s  # the attacker's
        self.attacker_vehicle = vehicle
        self.followers = followers or followers_of(config)  # given: an episode carried on from a batch
        gains = cruise_params(config)  # the attacker is the same kind of car
        self.attacker_cruise = CruiseControl(gains, config.attacker_cruise_mps, dt)
        #: with the authors' code's options the attacker cruises as their code has it: their follower
        #: controller with nobody ahead (its own PIDs, never reset)
        self._attacker_as_run = (SwitchingController(gains, setpoint_m=config.setpoint_m, target_speed_mps=config.attacker_cruise_mps,
                                                     vehicle=vehicle, step_s=dt) if gains.as_run else None)
        # ... and plays its attack as their controller does: a new pedal each control period
        self._attacker_every = max(1, int(round((gains.control_period_s or dt) / dt)))
        self.attacker_actuator = Actuator(vehicle, dt, attacker_max_speed_mps)
        #: in traffic, where it does not attack the attacker drives as a careful driver would (`CautiousDriver`)
        #: behind whatever is ahead of it, never into the traffic it blends into
        self._attacker_driver = (CautiousDriver(gains, setpoint_m=config.setpoint_m, time_gap_s=ATTACKER_TIME_GAP_S,
                                                target_speed_mps=config.attacker_cruise_mps, vehicle=vehicle, step_s=dt)
                                 if config.traffic is not None else None)
        n = config.followers + 1
        #: the maneuver's other car: a benign lead cruising like the attacker, or an obstacle at a constant speed
        self._others = [(i, CruiseControl(gains, config.speed_mps, dt) if self.maneuver.other_cruises else None,
                         Actuator(config.vehicle_of(i), dt, attacker_max_speed_mps), config.vehicle_of(i))
                        for i in range(n, len(self.ids))]
        #: the cars Python commands (the attacker, the Python-commanded followers, the other car): advance
        #: returns their speeds
        self.commanded = (0, *(i for i, f in enumerate(self.followers, start=1) if not f.sumo_driven),
                          *(i for i, _, _, _ in self._others))
        #: the platoon's V2V channel (`v2v`), and each car's speed a step ago (the accelerations its beacons carry)
        hear_all = frozenset(i for i, f in enumerate(self.followers, start=1) if f.hears_all)
        self.channel = (Channel(config.v2v, dt, n, beacons, [config.vehicle_of(i).length_m for i in range(n)], hear_all)
                        if config.v2v is not None else None)
        self._last_speeds: list[float] | None = None
        #: each Python follower, as the step loop calls it: its index, its command, its actuator, its inbox
        self._python = [(i, f.command, f.actuator.apply, MappingProxyType(self.channel.inbox(i)) if self.channel is not None else None)
                        for i, f in enumerate(self.followers, start=1) if not f.sumo_driven]
        #: whether the cars are the paper's column, pair i - 1 car i and the car ahead (no lane change, no traffic)
        self._one_ahead = not self.maneuver.lateral and config.traffic is None
        #: whether a follower reads the beacons of the car ahead of it in the platoon only while its radar sees it
        self._match = config.v2v is not None and config.v2v.match_radar and config.others_cut_in
        #: the SUMO-driven followers that read beacons, and the step's beacons for SUMO to be given: (follower,
        #: whether it reads every car ahead's, the newest beacon of each car it reads), where one is new
        self._sumo_listening = [(i, f.hears_all) for i, f in enumerate(self.followers, start=1) if f.sumo_driven and f.listens]
        self._fed: dict[int, tuple] = {}
        self.beacons_for_sumo: list[tuple[int, bool, tuple]] = []
        self._with_mode = [f.controller for f in self.followers if f.has_mode]
        #: the followers, their radars and channel stepped in C where they may be (`compiled`): as the Python below,
        #: bit for bit; not for followers carried on from a batch, whose radars have sensed already
        self._attacking = False  # whether the attacker attacked at the last step (a new cruise window starts its PID afresh)
        #: an attacker that only attacks and cruises (as printed, or as the authors' code has it; among traffic, a careful
        #: driver between attacks; obeying its lights or not), which the C may step
        self._plain = (self._motion is None and (self._attacker_driver is None or self._attacker_as_run is None)
                       and not self._others  # (its attack is plain floats: attack_u above)
                       # a numpy float32 top speed (from the Python API) computes in float32 in the Python
                       and type(self.attacker_actuator.max_speed_mps) in (float, int))
        self._compiled, self._attacker_in_c = None, False
        self._in_c: tuple | None = None  # from which step the column's loop in C records its commands (`played_in_c`)
        #: on a route through traffic lights: what each car sees of the next one at this step (`signals.Stop` or
        #: None, set by the step loop), and the drivers that obey them (`signals.SignalDriver`, by car)
        self.stops: list | None = None  # (None: nobody sees a light that asks anything of it)
        #: each step, what each car saw of the next light (`signals.light_code`): the trace's light_X
        self.lights: list[list[float]] = []
        self._lit = lights
        self._dark = [0.0] * len(self.ids)
        self._drivers: dict[int, SignalDriver] = {}
        if lights and config.signals != "ignore":
            obeying = [i for i in self.commanded if i != 0 or config.signals == "obey"]
            self._drivers = {i: SignalDriver(config.vehicle_of(i), dt) for i in obeying}
            self._python = [(i, self._obeying(i, command), apply, inbox) for i, command, apply, inbox in self._python]
        #: the drivers of the attacker and its followers, by car (None: no driver), where any obeys: in C their signals
        #: cap the commands
        self._car_drivers = ([self._drivers.get(i) for i in range(config.followers + 1)]
                             if any(i <= config.followers for i in self._drivers) else None)
        if followers is None:
            self.compile()
        self.commands: list[list[float]] = []
        self.modes: list[list[float]] = []
        self.pairs: list[list[Pair]] = []  # per sample, lane-changing maneuvers only: who followed whom

    def compile(self) -> None:
        """Its followers (and its attacker) stepped in C where they may be (`compiled`), from the state they are in: as
        the Python below, bit for bit. Made before its first step, or where a batch's arrays hand it on
        (`batch.PlatoonBatch.detach`), once its controllers carry the state the arrays left."""
        self._compiled = compiled_followers(self, attacker=self._plain)
        #: whether the attacker is stepped in C with them: the whole step is then the C's
        self._attacker_in_c = self._compiled is not None and self._plain

    def played_in_c(self, k: int, commands: np.ndarray, modes: np.ndarray | None) -> None:
        """From step k on, its commands (and modes) are the rows of ``commands`` (``modes``) the column's loop in C fills
        (`engine.loop`), after those it recorded before."""
        self._in_c = (k, commands, modes)

    def _obeying(self, i: int, command):
        """Follower ``i``'s command, which its driver holds below what the signal ahead allows (`signals`)."""
        limit = self._drivers[i].limit

        def obeyed(gap, speed, *rest):
            c = command(gap, speed, *rest)
            if type(c) is not float or not -1.0 <= c <= 1.0:  # a user's command: said as without lights
                c = checked_command(c, i, len(self.commands))
            stops = self.stops
            return min(c, limit(stops[i] if stops else None, speed))
        return obeyed

    def advance(self, k: int, positions: list[float], speeds: list[float], pairs: list[Pair]) -> list[float]:
        """Commands for step k from the sensed state and the maneuver's ``pairs`` (who follows whom in
        each lane); returns the speed at the step's end of each car in ``commanded`` (SUMO moves its
        own followers)."""
        if self._attacker_in_c:  # the attacker and the followers, in C
            commands, new_speeds = [], []
            if self._lit:  # what each car sees of the next light, recorded
                self.lights.append([light_code(stop) for stop in self.stops] if self.stops else self._dark)
            self._compiled(k, positions, speeds, pairs, commands, new_speeds, self.modes, *self._caps(speeds, 0))
            self.commands.append(commands)
            return new_speeds
        if self._one_ahead or not self._python and self._attacker_driver is None:
            ahead = None  # the column (car i follows car i - 1, at pair i - 1's gap), or nobody Python commands asks
        elif self._compiled is not None:  # the followers find theirs in C: the attacker's alone, the nearer of two
            ahead = {}
            for a, b, gap in pairs:
                if b == 0 and (not ahead or gap < ahead[0][1]):
                    ahead[0] = (a, gap)
        else:
            ahead = {}
            for a, b, gap in pairs:  # a car covering two lanes may have two: the nearer counts
                if b not in ahead or gap < ahead[b][1]:
                    ahead[b] = (a, gap)
        speed = speeds[0]
        u = self._attacker_command(k, speed, speeds, ahead)
        stops = self.stops
        if self._lit:  # on a route through traffic lights: what each car sees of the next one, recorded
            self.lights.append([light_code(stop) for stop in stops] if stops else self._dark)
        if 0 in self._drivers:  # its driver stops it for red, attacking or not
            u = min(u, self._drivers[0].limit(stops[0] if stops else None, speed))
        commands = [u]
        new_speeds = [self.attacker_actuator.apply(u, speed)]
        if self._motion is not None:  # it drives as the motion says; the trace keeps the pedal that asks for it
            v = self._motion[k]
            commands[0] = acceleration_to_command((v - speed) / self.config.step_s, self.attacker_vehicle)
            new_speeds[0] = v
        self._followers_advance(k, positions, speeds, pairs, ahead, commands, new_speeds)
        for i, cruise, actuator, vehicle in self._others:
            if cruise is None:  # the obstacle holds its speed
                commands.append(0.0)
                new_speeds.append(self.config.obstacle_speed_mps)
                continue
            c = acceleration_to_command(cruise.acceleration(speeds[i]), vehicle)
            if i in self._drivers:
                c = min(c, self._drivers[i].limit(stops[i] if stops else None, speeds[i]))
            commands.append(c)
            new_speeds.append(actuator.apply(c, speeds[i]))
        self.commands.append(commands)
        if self._with_mode and self._compiled is None:
            self.modes.append([c.mode for c in self._with_mode])
        return new_speeds

    def _attacker_command(self, k: int, speed: float, speeds: list[float], ahead: dict | None) -> float:
        """The attacker's pedal at step k: its attack, or where the signal is NaN its cruise (among traffic, a
        careful driver's behind what is ahead; with the authors' code's options, their controller's)."""
        u = self.attack_u[k]
        if self._attacker_driver is not None and u != u:  # in traffic, between attacks: it follows what is ahead
            if self._attacking:
                self._attacker_driver.cruise.reset()
                self._attacking = False
            leader, gap = ahead.get(0, (0, FREE_ROAD_GAP_M))
            u = self._attacker_driver.command(gap, speed, speeds[leader])
        elif self._attacker_as_run is not None:  # the authors' attacker: their controller on a free road, or its attack
            attack = self.attack_u[k - k % self._attacker_every]  # the attack's pedal at this control period's start
            u = self._attacker_as_run.command_as_run(FREE_ROAD_GAP_M, speed, speed, act=attack != attack)
            if u is None:  # attacking: the attack sets the pedal, and holds it for the period
                u = self._attacker_as_run.held = attack
        elif u != u:  # NaN: no attack here, the attacker cruises like everyone else
            if self._attacking:  # a new cruise window: the PID starts afresh (no kick, no stale integral)
                self.attacker_cruise.reset()
                self._attacking = False
            u = acceleration_to_command(self.attacker_cruise.acceleration(speed), self.attacker_vehicle)
        else:
            self._attacking = True
        return u

    def _followers_advance(self, k: int, positions: list[float], speeds: list[float], pairs: list[Pair], ahead: dict | None,
                           commands: list[float], new_speeds: list[float]) -> None:
        """Each follower Python commands: its command and its speed at the step's end, appended (in C where they may be)."""
        channel = self.channel
        if self._compiled is not None:  # its followers' modes too
            # (the attacker's cap is the Python's, above)
            self._compiled(k, positions, speeds, pairs, commands, new_speeds, self.modes, *self._caps(speeds, 1))
        elif channel is None:
            for i, command, apply, _ in self._python:
                # nobody ahead in its lane: a free road
                leader, gap = (i - 1, pairs[i - 1][2]) if ahead is None else ahead.get(i, (i, FREE_ROAD_GAP_M))
                c = command(gap, speeds[i], speeds[leader])
                if type(c) is not float or not -1.0 <= c <= 1.0:  # not a plain command: say why, or take the float it is
                    c = checked_command(c, i, k)
                commands.append(c)
                new_speeds.append(apply(c, speeds[i]))
        else:
            accels, now = self._accelerations(speeds), k * channel.step_s
            channel.send(k, positions, speeds, accels)
            if self._sumo_listening:
                self._feed_sumo()
            match = self._match
            for i, command, apply, inbox in self._python:
                leader, gap = (i - 1, pairs[i - 1][2]) if ahead is None else ahead.get(i, (i, FREE_ROAD_GAP_M))
                # whether its radar sees the car whose beacons it reads as the one ahead (or nobody)
                matched = not match or leader == i - 1 or leader == i
                c = command(gap, speeds[i], speeds[leader], accels[i], inbox, positions[i], now, matched)
                if type(c) is not float or not -1.0 <= c <= 1.0:
                    c = checked_command(c, i, k)
                commands.append(c)
                new_speeds.append(apply(c, speeds[i]))

    def _caps(self, speeds: list[float], first: int) -> tuple:
        """The C's last argument (`compiled`): the highest command each car's signal allows (None: no driver; the
        attacker's None from ``first`` 1), as `_obeying` and `_attacker_command`'s caller cap the Python's; none where
        nobody obeys a signal."""
        if self._car_drivers is None:
            return ()
        stops = self.stops
        return ([None if d is None or i < first else d.limit(stops[i] if stops else None, speeds[i])
                 for i, d in enumerate(self._car_drivers)],)

    def _feed_sumo(self) -> None:
        """The step's beacons for SUMO's cooperative followers: the newest of each car each reads, where one is new."""
        self.beacons_for_sumo = []
        for i, every in self._sumo_listening:
            inbox = self.channel.inbox(i)
            newest = tuple(inbox.get(j) for j in (range(i) if every else (0, i - 1)))
            if None not in newest and newest != self._fed.get(i):
                self._fed[i] = newest
                self.beacons_for_sumo.append((i, every, newest))

    def _accelerations(self, speeds: list[float]) -> list[float]:
        """Each car of the platoon's acceleration over its last step [m/s^2] (0 at the first)."""
        current = speeds[:len(self.ids)]
        last = self._last_speeds or current
        self._last_speeds = current
        dt = self.config.step_s
        return [(v - w) / dt for v, w in zip(current, last)]

    def trace(self, times_s: np.ndarray, positions: np.ndarray, speeds: np.ndarray,
              lateral_m: np.ndarray | None = None) -> tuple[Trace, dict[str, float], dict[str, float] | None]:
        """Assemble the Trace from the sensed rows (samples x cars) and the recorded commands (and, for a
        lane-changing maneuver, the recorded pairs and each car's lateral position); with it the minimum
        gaps (`assemble_trace`)."""
        commands = rows_array(self.commands, len(self.commanded))
        modes = np.array(self.modes, dtype=float).reshape(-1, len(self._with_mode)) if self._with_mode else None
        if self._in_c is not None:  # the rows the loop in C filled, up to the last sample
            k, in_c, modes_in_c = self._in_c
            commands = np.concatenate([commands, in_c[k:times_s.size - 1]])
            if modes is not None:
                modes = np.concatenate([modes, modes_in_c[k:times_s.size - 1]])
        if modes is not None and not modes.size:
            modes = None
        trace, min_gaps, warmup_min_gaps = assemble_trace(self.config, self.followers, self.commanded, times_s, positions,
                                                          speeds, commands, modes, self.pairs, lateral_m)
        if self.channel is not None and self.channel.falsify is not None:
            trace.signals.update(sent_signals(self.channel.sent, times_s.size, self.channel.liar))
        if self.lights:  # on a route through traffic lights: what each car saw of the next one
            seen = _hold_last(np.array(self.lights, dtype=float), times_s.size)
            trace.signals.update({f"light_{vid}": seen[:, i] for i, vid in enumerate(self.ids)})
        return trace, min_gaps, warmup_min_gaps


def cruise_params(config: EpisodeConfig) -> SwitchingParams:
    """The gains the attacker (and a benign lead) cruise with: the followers' PID gains when they all
    run the paper's controller (or its time-gap variant), the default gains otherwise."""
    uniform = isinstance(config.controller, ControllerConfig) and not config.controller.sumo_model
    params = config.controller.build_params() if uniform else None
    return params if isinstance(params, SwitchingParams) else SwitchingParams()
