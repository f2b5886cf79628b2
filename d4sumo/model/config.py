"""The episode configuration: frozen, validated on construction, round-trips through TOML/JSON.

Its tables in a config file are [scenario], [vehicle] and [controller] (every key optional; defaults
from SPEC section 1); `inputs` reads the whole file, flags included. Beside it: the [controller] table
(`controllers`), which road a campaign plays on (`network`), and its form as a campaign's definition
stores it (`definition`).
"""

from __future__ import annotations

import dataclasses
import functools
import re
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..errors import ConfigError, check_int, check_number
from .controllers import carfollowing
from .controllers.control import SwitchingParams
from . import definition
from .controllers.table import ControllerConfig, listens as _listens
from .definition import TABLES
from .world.network import builds_network, files_digest, is_network_path, network_digest, sumo_options
from .world.sensing import RadarParams
from .world.traffic import TrafficParams
from .world.v2v import ChannelParams
from .world.vehicle import VehicleParams, car_tables
from .attacks.maneuvers import MANEUVERS as MANEUVER_CLASSES, REAR_START_M, SWERVE_KNOTS, SWERVE_LANES

#: rest: all cars at 0 m/s, attack from t = 0 (the paper's transient attack); steady: all cars at the
#: target speed with setpoint gaps, attack from t = 0 (an exact equilibrium of the paper's controller);
#: warmup: the paper's steady-state procedure, drive from rest for warmup_s with the attacker cruising,
#: attack after (every system then starts from its own steady state).
START_MODES = ("rest", "steady", "warmup")
MAX_FOLLOWERS = 10
MAX_LANE = 15  # the leftmost lane index scenario.lane may name
#: inlane: the paper's attacker, leading the platoon in its lane; cutin: it changes into the platoon's lane
#: in front of a follower; cutout: it leads, then leaves the lane to reveal a slower car; swerve: it leads,
#: its lane over time searched with its pedals (see `maneuvers`)
MANEUVERS = tuple(MANEUVER_CLASSES)


@dataclass(frozen=True)
class EpisodeConfig:
    """One episode of the paper's scenario: road, platoon, start mode, step and duration."""

    network: str = "highway_4lane"  # a folder of sumo_scenarios/, or a path: a folder of node and edge files, a *.net.xml
    #: the content of the files a network path names (`network_digest`), taken when the configuration is made
    #: (None): what identifies a user's road, as the demand's does its traffic; "" for a shipped variant, and in
    #: campaigns stored before it was a key (their road is taken as it is)
    network_sha256: str | None = None
    route: tuple[str, ...] = ()  # the edges the platoon drives (none: the network's one chain of edges)
    #: the platoon's lane on the route's first edge (SUMO's index, 0 the rightmost); none: the rightmost
    #: lane that leads on through every junction of the route. Its index may change along the route
    lane: int | None = None
    followers: int = 3  # N followers behind the attacker: ids v1..vN
    setpoint_m: float = 7.0  # bumper-to-bumper distance d the ACC keeps
    speed_mps: float = 25.0  # target speed v_d of every car
    start: str = "rest"  # see START_MODES
    step_s: float = 0.05
    duration_s: float = 60.0  # from the attack's start to the episode's end
    warmup_s: float = 15.0  # start = "warmup": seconds driven from rest before the attack starts
    vehicle: VehicleParams = field(default_factory=VehicleParams)
    #: the cars whose vehicle differs from [vehicle], each with what differs: its [vehicle.vI] table, as
    #: (car id, ((key, value), ...)) pairs (a mapping is taken too); a car id is one of `vehicle_ids`
    vehicles: tuple[tuple[str, tuple[tuple[str, Any], ...]], ...] = ()
    #: one controller for every follower, or one per follower (v1 first): a mixed platoon
    controller: ControllerConfig | tuple[ControllerConfig, ...] = field(default_factory=ControllerConfig)
    #: the Python-commanded followers' radar, the [radar] table (`sensing`); none: they sense the truth
    radar: RadarParams | None = None
    #: SUMO's traffic around the platoon, the [traffic] table (`traffic`); none: the platoon drives alone
    traffic: TrafficParams | None = None
    #: the platoon's V2V channel, the [v2v] table (`v2v`); none: no beacons, unless a follower's controller
    #: reads them (cacc, ploeg): then the default channel
    v2v: ChannelParams | None = None
    #: the maximum deceleration the attacker declares to the cars behind it (SUMO's apparentDecel),
    #: which SUMO's models may plan with; it can truly brake at vehicle.max_decel_mps2, the default
    attacker_declared_decel_mps2: float | None = None
    maneuver: str = "inlane"  # see MANEUVERS
    cutin_follower: int = 1  # cutin: the attacker starts beside, and aims in front of, this follower (1 = v1)
    cutin_offset_m: float = 0.0  # cutin: the attacker's rear bumper ahead of that follower's front bumper at t = 0
    lane_change_s: float = 2.0  # cutin/cutout: how long SUMO takes to move the attacker across (0: in one step)
    obstacle_distance_m: float = 150.0  # cutout: bumper gap from the attacker to the car ahead of it at t = 0
    obstacle_speed_mps: float = 0.0  # cutout: the constant speed of that car (0: stopped)
    swerve_knots: int = SWERVE_KNOTS  # swerve: how many times over the attack its lane is a parameter
    swerve_lanes: int = SWERVE_LANES  # swerve: the lanes it may use, the platoon's and those to its left
    #: the attacker cruises (before its attack and between windows) at the target speed plus this; the
    #: authors' parametric scenarios: -5 m/s
    attacker_cruise_offset_mps: float = 0.0
    #: the episode ends, without a collision, once the attacker is this far from its start (0: never);
    #: the authors' scenarios: 760 m
    end_distance_m: float = 0.0
    #: a pair of cars has collided (the episode ends, and the outcome is theirs) once its bumper gap is
    #: below this [m]; 0: once they overlap. The authors' code: 0.05 (centres within 5 m of 4.95 m cars)
    collision_gap_m: float = 0.0
    #: traffic lights along the route (`signals`): every car of the platoon stops for red as SUMO's drivers do
    #: ("obey"); the attacker runs red, as part of its attack, and the followers stop ("attacker_runs_red");
    #: or every car of the platoon drives through, as d4sumo 0.18 and before did ("ignore")
    signals: str = "obey"
    #: a network file (*.net.xml) taken back to plain XML and rebuilt by netconvert, as d4sumo 0.18 and before did
    #: (its signal programmes netconvert's defaults, its coordinates moved); false: SUMO runs the file as given
    rebuild: bool = False
    #: where the platoon joins its route: its rearmost car's rear bumper this far along the route's first edge [m]
    #: (before a merge, inside dense traffic); the platoon must fit on that edge
    join_m: float = REAR_START_M
    #: SUMO additional files every episode loads (a .sumocfg's: detectors, variable speed signs, rerouters, signal
    #: programmes of one's own), and their content (sha256 over them, in order), taken when first read
    additional: tuple[str, ...] = ()
    additional_sha256: str = ""
    #: SUMO options given as they are (a .sumocfg's that change nothing d4sumo decides: `sumocfg.PASSED`)
    sumo_options: tuple[tuple[str, str], ...] = ()

    def __post_init__(self) -> None:
        """Every key checked, each in one line naming it and what is allowed, in the order a reader meets them:
        the road, the clock, the systems under test, the world around them, the maneuver."""
        self._check_road()
        self._check_clock()
        controllers = self._check_systems()
        self._check_world(controllers)
        self._check_maneuver()

    def _fix(self, name: str, value: Any) -> None:
        object.__setattr__(self, name, value)  # a frozen dataclass's own checks normalise its values

    def _check_road(self) -> None:
        """The road, where on it the platoon drives, how many cars, how fast, the lights and SUMO's own files."""
        fix = self._fix
        if not isinstance(self.network, str) or not self.network:
            raise ConfigError("scenario.network", self.network, "a shipped variant (see `d4sumo scenarios`), a folder of node "
                                                                "and edge files, or a *.net.xml")
        if self.network_sha256 is None or not is_network_path(self.network):
            fix("network_sha256", network_digest(self.network))
        elif not isinstance(self.network_sha256, str) or not re.fullmatch(r"([0-9a-f]{64})?", self.network_sha256):
            raise ConfigError("scenario.network_sha256", self.network_sha256, "the digest d4sumo takes of scenario.network "
                                                                              "(leave it out), or \"\" (the road as it is)")
        if not isinstance(self.route, (list, tuple)) or not all(isinstance(e, str) and e for e in self.route):
            raise ConfigError("scenario.route", self.route, "a list of edge ids, e.g. [\"e1\", \"e2\"]")
        fix("route", tuple(self.route))
        if self.lane is not None:
            fix("lane", check_int("scenario.lane", self.lane, 0, MAX_LANE, "(a lane of the route's first edge, 0 the rightmost)"))
        fix("followers", check_int("scenario.followers", self.followers, 1, MAX_FOLLOWERS))
        fix("setpoint_m", check_number("scenario.setpoint_m", self.setpoint_m, 0.0, 200.0, "metres", low_open=True))
        fix("speed_mps", check_number("scenario.speed_mps", self.speed_mps, 0.0, 70.0, "m/s", low_open=True))
        if self.start not in START_MODES:
            raise ConfigError("scenario.start", self.start, f"one of {', '.join(START_MODES)}")
        if self.signals not in SIGNAL_RULES:
            raise ConfigError("scenario.signals", self.signals, f"one of {', '.join(SIGNAL_RULES)}")
        if not is_network_path(self.network):  # d4sumo's own roads have no traffic lights: one configuration, whatever it says
            fix("signals", "obey")
        if isinstance(self.additional, str):
            fix("additional", (self.additional,))
        if not isinstance(self.additional, (list, tuple)) or not all(isinstance(p, str) and p for p in self.additional):
            raise ConfigError("scenario.additional", self.additional, "SUMO additional files, e.g. [\"detectors.add.xml\"]")
        fix("additional", tuple(self.additional))
        if self.additional and not self.additional_sha256:
            fix("additional_sha256", files_digest("scenario.additional", self.additional))
        if not isinstance(self.additional_sha256, str) or (self.additional_sha256 and not self.additional):
            raise ConfigError("scenario.additional_sha256", self.additional_sha256, "the digest d4sumo takes of "
                                                                                    "scenario.additional (leave it out)")
        fix("sumo_options", sumo_options(self.sumo_options))
        fix("join_m", check_number("scenario.join_m", self.join_m, 0.0, 100_000.0, "metres along the route's first edge"))
        if not isinstance(self.rebuild, bool):
            raise ConfigError("scenario.rebuild", self.rebuild, "true or false")
        if builds_network(self.network):  # node and edge files are built by netconvert: nothing else to do
            fix("rebuild", True)

    def _check_clock(self) -> None:
        """The step, the episode's duration and the warm-up."""
        fix = self._fix
        fix("step_s", check_number("scenario.step_s", self.step_s, 0.001, 1.0, "seconds"))
        fix("duration_s", check_number("scenario.duration_s", self.duration_s, self.step_s, 3600.0, "seconds"))
        fix("warmup_s", check_number("scenario.warmup_s", self.warmup_s, 0.0, 600.0, "seconds"))
        if self.start == "warmup" and not _on_grid(self.warmup_s, self.step_s):  # read only with a warm-up
            raise ConfigError("scenario.warmup_s", self.warmup_s, f"a whole number of steps of {self.step_s:g} s")

    def _check_systems(self) -> tuple[ControllerConfig, ...]:
        """The cars, the followers' controllers (one, or one each) and their radar."""
        fix = self._fix
        if not isinstance(self.vehicle, VehicleParams):
            raise ConfigError("vehicle", self.vehicle, "a [vehicle] table")
        if isinstance(self.controller, (list, tuple)):
            if len(self.controller) != self.followers:
                raise ConfigError("controller", f"{len(self.controller)} controllers",
                                  f"one per follower ({self.followers}: --controller A,B,C or [[controller]] tables), or one "
                                  "for all (--followers sets how many)")
            fix("controller", tuple(self.controller))
        controllers = self.controllers
        if not all(isinstance(c, ControllerConfig) for c in controllers):
            raise ConfigError("controller", self.controller, "a [controller] table")
        if len(set(controllers)) == 1 and isinstance(self.controller, tuple):  # the same for all: one table
            fix("controller", controllers[0])
        for c in controllers:  # SUMO rounds an action step to whole steps, silently; so would the control period
            step = dict(c.params).get("actionStepLength") if c.sumo_model else None
            if step is not None and not (step >= self.step_s and _on_grid(step, self.step_s)):
                raise ConfigError(f"{c.where}.actionStepLength", step, f"a whole number of steps of {self.step_s:g} s")
            period = dict(c.params).get("control_period_s") if not c.sumo_model else None
            if period and not (period >= self.step_s and _on_grid(period, self.step_s)):
                raise ConfigError(f"{c.where}.control_period_s", period, f"0, or a whole number of steps of {self.step_s:g} s")
        if isinstance(self.radar, Mapping):
            fix("radar", RadarParams.from_table(self.radar))
        if self.radar is not None:
            if not isinstance(self.radar, RadarParams):
                raise ConfigError("radar", self.radar, "a [radar] table")
            if self.radar.perfect:  # the truth, as without one: the same episodes, the same campaign
                fix("radar", None)
            elif all(c.sumo_model for c in controllers):
                raise ConfigError("radar", self.radar.to_dict(), "a platoon with a follower a Python controller commands "
                                                                 "(SUMO's models sense on their own)")
            elif not _on_grid(self.radar.latency_s, self.step_s):
                raise ConfigError("radar.latency_s", self.radar.latency_s, f"a whole number of steps of {self.step_s:g} s")
        return controllers

    def _check_world(self, controllers: tuple[ControllerConfig, ...]) -> None:
        """The maneuver's name, the V2V channel, SUMO's traffic."""
        fix = self._fix
        if self.maneuver not in MANEUVERS:
            raise ConfigError("scenario.maneuver", self.maneuver, f"one of {', '.join(MANEUVERS)}")
        if isinstance(self.v2v, Mapping):
            fix("v2v", ChannelParams.from_table(self.v2v))
        listening = [_listens(c) for c in controllers]
        if self.v2v is not None:
            if not isinstance(self.v2v, ChannelParams):
                raise ConfigError("v2v", self.v2v, "a [v2v] table")
            if not any(x is not False for x in listening):
                raise ConfigError("v2v", self.v2v.label, "a platoon with a follower whose controller reads V2V beacons "
                                                         "(cacc, ploeg, consensus, sumo:CC with a cooperative active_controller, "
                                                         "or your own with listens = True)")
            for name in ("beacon_interval_s", "latency_s"):
                value = getattr(self.v2v, name)
                if not _on_grid(value, self.step_s):
                    raise ConfigError(f"v2v.{name}", value, f"a whole number of steps of {self.step_s:g} s")
        elif any(listening):  # a cooperative controller's platoon exchanges beacons: Plexe's default channel
            fix("v2v", ChannelParams())
        for i, c in enumerate(controllers, start=1):
            if i >= carfollowing.CC_CONSENSUS_CARS and c.sumo_model and carfollowing.hears_all(c.sumo_model, dict(c.params)):
                raise ConfigError("scenario.followers", self.followers, f"at most {carfollowing.CC_CONSENSUS_CARS - 1} with "
                                                                        "SUMO's CONSENSUS (Plexe's platoons are of 8 cars at most)")
        if isinstance(self.traffic, Mapping):
            fix("traffic", TrafficParams.from_table(self.traffic))
        if self.traffic is not None:
            if not isinstance(self.traffic, TrafficParams):
                raise ConfigError("traffic", self.traffic, "a [traffic] table")
            if self.start != "steady":  # a platoon standing on a road with traffic at speed is a crash of its own
                raise ConfigError("scenario.start", self.start, "steady with [traffic] (the platoon joins the traffic at its speed)")
            if not _on_grid(self.traffic.warmup_s, self.step_s):
                raise ConfigError("traffic.warmup_s", self.traffic.warmup_s, f"a whole number of steps of {self.step_s:g} s")
            if not is_network_path(self.network) and not self.traffic.junction_collisions:  # one edge, no junction: one
                fix("traffic", dataclasses.replace(self.traffic, junction_collisions=True))  # configuration, whatever it says
            if not MANEUVER_CLASSES[self.maneuver].lateral and self.traffic.edging_sensed:  # in lane, cars are SUMO's
                fix("traffic", dataclasses.replace(self.traffic, edging_sensed=False))  # leaders: one configuration, stored as before
        if self.v2v is not None and self.v2v.match_in_maneuvers and (self.traffic is not None
                                                                      or not MANEUVER_CLASSES[self.maneuver].lateral):
            fix("v2v", dataclasses.replace(self.v2v, match_in_maneuvers=False))  # no maneuver's, or traffic's: one configuration
        if self.v2v is not None and not self.v2v.match_radar and not self.others_cut_in:  # the radar sees the platoon's
            fix("v2v", dataclasses.replace(self.v2v, match_radar=True))  # car ahead all along: one configuration

    def _check_maneuver(self) -> None:
        """Each car's own vehicle, the attacker's declared brake, the maneuver's settings and when an episode ends."""
        fix = self._fix
        fix("vehicles", car_tables(self.vehicles, self.vehicle, self.vehicle_ids, self.followers))
        declared = self.vehicle_of(0).max_decel_mps2 if self.attacker_declared_decel_mps2 is None else self.attacker_declared_decel_mps2
        fix("attacker_declared_decel_mps2", check_number("scenario.attacker_declared_decel_mps2", declared, 0.0, 20.0,
                                                         "m/s^2 (positive)", low_open=True))
        fix("cutin_follower", check_int("scenario.cutin_follower", self.cutin_follower, 1, MAX_FOLLOWERS,
                                        f"(a follower: 1 for v1 .. {self.followers} for v{self.followers})"))
        fix("cutin_offset_m", check_number("scenario.cutin_offset_m", self.cutin_offset_m, -500.0, 500.0, "metres"))
        fix("lane_change_s", check_number("scenario.lane_change_s", self.lane_change_s, 0.0, 20.0, "seconds"))
        # SUMO rounds it to whole steps, silently; only a maneuver that changes lanes reads it
        if MANEUVER_CLASSES[self.maneuver].lateral and not _on_grid(self.lane_change_s, self.step_s):
            raise ConfigError("scenario.lane_change_s", self.lane_change_s, f"a whole number of steps of {self.step_s:g} s")
        fix("swerve_knots", check_int("scenario.swerve_knots", self.swerve_knots, 1, 50))
        fix("swerve_lanes", check_int("scenario.swerve_lanes", self.swerve_lanes, 2, 6, "(the platoon's lane and those to its left)"))
        fix("obstacle_distance_m", check_number("scenario.obstacle_distance_m", self.obstacle_distance_m, 0.0, 5000.0,
                                                "metres", low_open=True))
        fix("obstacle_speed_mps", check_number("scenario.obstacle_speed_mps", self.obstacle_speed_mps, 0.0, self.speed_mps,
                                               f"m/s (at most the target speed, {self.speed_mps:g})"))
        fix("attacker_cruise_offset_mps", check_number("scenario.attacker_cruise_offset_mps", self.attacker_cruise_offset_mps,
                                                       -self.speed_mps, 30.0, f"m/s (the attacker cruises at {self.speed_mps:g} + this, at least 0)"))
        fix("end_distance_m", check_number("scenario.end_distance_m", self.end_distance_m, 0.0, 1e5, "metres (0: never)"))
        fix("collision_gap_m", check_number("scenario.collision_gap_m", self.collision_gap_m, 0.0, 5.0, "metres (0: an overlap)"))
        self.maneuver_class.check(self)

    @property
    def attack_start_step(self) -> int:
        """The step at which the attack starts (0 except after a warm-up)."""
        return int(round(self.warmup_s / self.step_s)) if self.start == "warmup" else 0

    @property
    def attack_start_s(self) -> float:
        return self.attack_start_step * self.step_s

    @property
    def steps(self) -> int:
        """Number of simulation steps in a full episode (warm-up included)."""
        return self.attack_start_step + int(round(self.duration_s / self.step_s))

    @property
    def total_s(self) -> float:
        return self.steps * self.step_s

    @property
    def attacker_cruise_mps(self) -> float:
        """The speed the attacker cruises at where it does not attack."""
        return self.speed_mps + self.attacker_cruise_offset_mps if self.attacker_cruise_offset_mps else self.speed_mps

    @functools.cached_property
    def as_run(self) -> bool:
        """Whether the episode runs any of the authors' code's options that the batch's arrays do not play
        (its controllers, a coasting car, a slower attacker, an end distance): its platoons are then
        commanded one by one, side by side in one SUMO all the same."""
        return (any(isinstance(p := c.build_params(), SwitchingParams) and p.as_run for c in self.controllers if not c.sumo_model)
                or any(v.coast_decel_mps2 for v in self.car_vehicles) or bool(self.attacker_cruise_offset_mps or self.end_distance_m))

    @functools.cached_property
    def batch_arrays(self) -> bool:
        """Whether a batch's arrays may play its platoons: they play the model as printed, one vehicle for
        every car (otherwise its platoons are commanded one by one, side by side in one SUMO all the same)."""
        return not self.as_run and not self.vehicles and self.radar is None and self.traffic is None and self.v2v is None

    @functools.cached_property
    def car_vehicles(self) -> tuple[VehicleParams, ...]:
        """Each car's vehicle, in the order of `vehicle_ids`: [vehicle], with its [vehicle.vI] table laid over."""
        own = dict(self.vehicles)
        return tuple(dataclasses.replace(self.vehicle, **dict(own[vid])) if vid in own else self.vehicle
                     for vid in self.vehicle_ids)

    def vehicle_of(self, car: int) -> VehicleParams:
        """The vehicle of car ``car`` (an index into `vehicle_ids`: 0 the attacker, I the follower vI)."""
        return self.car_vehicles[car]

    @property
    def controllers(self) -> tuple[ControllerConfig, ...]:
        """Each follower's controller, v1 first."""
        if isinstance(self.controller, tuple):
            return self.controller
        return (self.controller,) * self.followers

    def listening(self, follower: int) -> bool | None:
        """Whether follower vI's controller reads V2V beacons (None: a user's class not imported here)."""
        return _listens(self.controllers[follower - 1])

    @property
    def sumo_driven(self) -> bool:
        """Whether any follower is driven by a SUMO car-following model."""
        return any(c.sumo_model for c in self.controllers)

    @property
    def system_label(self) -> str:
        """The system under test in a few words: the controller, or each follower's for a mixed platoon, and
        the cars whose vehicle differs (``switching; v2: length_m=12, vclass=truck``)."""
        label = (self.controller.label if isinstance(self.controller, ControllerConfig)
                 else " / ".join(c.label for c in self.controller))
        for car, differs in self.vehicles:
            label += f"; {car}: " + ", ".join(f"{k}={v:g}" if isinstance(v, float) else f"{k}={v}" for k, v in differs)
        if self.radar is not None:
            label += "; radar: " + self.radar.label
        if self.v2v is not None:
            label += "; v2v: " + self.v2v.label
        return label

    def for_sample(self, index: int) -> "EpisodeConfig":
        """The episode sample ``index`` of a campaign plays: this one, or where each sample meets its own
        traffic (`TrafficParams.per_sample`), this one in that traffic."""
        if self.traffic is None or not self.traffic.per_sample:
            return self
        return dataclasses.replace(self, traffic=self.traffic.for_sample(index))

    @property
    def whole_network(self) -> bool:
        """Whether the road is the route through the network whole (`scenarios.build_road`): a network file run
        as given, or a user's traffic demand that drives its other ways too. Else a route's edges alone are the road."""
        return bool(self.route) and (self.network_given or self.traffic is not None and bool(self.traffic.demand))

    @property
    def network_given(self) -> bool:
        """Whether SUMO runs the network file as given (`rebuild`): its signal programmes, connections,
        priorities, coordinates and geo-reference; a route through it, the whole network around."""
        return not self.rebuild

    @property
    def world_label(self) -> str:
        """What is around the platoon, in a few words: its traffic, or "" when it drives alone."""
        return f"traffic {self.traffic.label}" if self.traffic is not None else ""

    @property
    def vehicle_ids(self) -> tuple[str, ...]:
        """The attacker v0, the followers v1..vN, then the maneuver's other car (lead or obstacle), if any."""
        other = self.maneuver_class.other_car
        return tuple(f"v{i}" for i in range(self.followers + 1)) + ((other,) if other else ())

    @property
    def maneuver_class(self) -> type:
        """The attacker's maneuver (a class of `maneuvers`)."""
        return MANEUVER_CLASSES[self.maneuver]

    @property
    def others_cut_in(self) -> bool:
        """Whether a car from outside the platoon may come between a follower and the car ahead of it in the
        platoon: a traffic car (`v2v.ChannelParams.match_radar`). (A lane-changing maneuver's cars exchange
        beacons in the platoon's own topology, the attacker leading it, as before; as d4sumo 0.20.0 had it, they
        count too: `v2v.ChannelParams.match_in_maneuvers`.)"""
        return self.traffic is not None or (self.v2v is not None and self.v2v.match_in_maneuvers)

    # --- TOML/JSON round trip: its definition (`definition`) ---------------------------------------

    def to_dict(self) -> dict:
        """As a campaign's definition stores it (`definition.stored`)."""
        return definition.stored(self)

    @classmethod
    def from_dict(cls, doc: Mapping[str, Any]) -> "EpisodeConfig":
        """Build from the [scenario], [vehicle] and [controller] tables of a document (`definition.tables`)."""
        return cls(**definition.tables(doc, [f.name for f in dataclasses.fields(cls) if f.name not in TABLES]))


#: what the platoon does at a red light (`EpisodeConfig.signals`)
SIGNAL_RULES = ("obey", "attacker_runs_red", "ignore")


def _on_grid(value: float, step: float) -> bool:
    count = value / step
    return abs(count - round(count)) <= 1e-9 * max(1.0, count)
