"""The attack's maneuver: where the cars start, and who follows whom in each lane. Pure code, no SUMO.

    inlane  the paper's attack: the attacker v0 leads the platoon v1 .. vN in lane 0.
    cutin   a benign car `lead` cruising at the target speed leads the platoon (lead, v1 .. vN) in lane 0;
            the attacker starts in lane 1 beside follower k (scenario.cutin_follower), its rear bumper
            scenario.cutin_offset_m ahead of vk's front bumper, plays its signal and changes into lane 0
            at t_lc_s.
    cutout  the attacker leads the platoon in lane 0 with a slower or stopped car `obstacle` ahead
            (scenario.obstacle_distance_m, obstacle_speed_mps); at t_lc_s it changes to lane 1, revealing
            the obstacle to v1.
    swerve  the attacker leads the platoon in lane 0 and swerves: the lane it is in (0 .. scenario.swerve_lanes
            - 1) from each of scenario.swerve_knots times spread over the attack is searched with its pedals,
            so it may drop back beside a follower and cut in ahead of it, leave and come back.

Lanes are numbered from the platoon's (0; a lane to its left is 1). The optimiser picks t_lc_s (seconds
from the attack's start), or a swerving attacker's lanes, parameters the maneuver adds to the attack
family's box; SUMO performs each lane change.

A maneuver says, at each step, which cars follow which: the *pairs* (leader, follower, bumper gap) of
cars next to each other in a lane. A car changing lanes occupies both lanes from the moment its body
crosses the lane line. Every follower's leader, every collision (a pair with gap < 0) and every gap
signal of the trace come from these pairs, with one arithmetic, so verdicts and traces always agree.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ...errors import ConfigError
from .pedals import AttackFamily, Parameter
from ..world.lanes import Pair, lane_pairs
from ..world.settings import EpisodeSettings

@dataclass(frozen=True)
class Car:
    id: str
    lane: int
    position_m: float  # front bumper, along the road
    speed_mps: float


def initial_state(config: EpisodeSettings, front: int = 0) -> tuple[list[float], list[float]]:
    """Front-bumper positions and speeds at t = 0 of a column of followers + 1 cars in one lane, front to
    back, each a setpoint behind the rear bumper of the car ahead: the attacker and the followers, or with
    ``front`` the index of another car (a cut-in's benign lead) in the attacker's place."""
    n = config.followers + 1
    lengths = [config.vehicle_of(i).length_m for i in (front, *range(1, n))]
    rear = lengths[-1] + config.join_m
    if len(set(lengths)) == 1:  # one vehicle for all: the arithmetic every stored campaign was played with
        positions = [rear + (lengths[0] + config.setpoint_m) * (n - 1 - i) for i in range(n)]
    else:
        positions = [rear]
        for length in reversed(lengths[:-1]):  # from the rearmost forwards
            positions.append(positions[-1] + config.setpoint_m + length)
        positions.reverse()
    speed = config.speed_mps if config.start == "steady" else 0.0  # rest and warmup start standing
    return positions, [speed] * n


#: The rearmost car's rear bumper starts this far from the road's start [m], unless scenario.join_m says.
REAR_START_M = 10.0


class Maneuver:
    """The paper's maneuver (`inlane`): nobody changes lanes, so the order is v0, v1, .., vN for the
    whole episode (in a lane, cars pass each other only through a collision, which ends it)."""

    name = "inlane"
    lateral = False  # whether the attacker changes lanes
    lanes_needed = 1
    other_car: str | None = None  # the id of the car the maneuver adds to the attacker and the followers
    other_cruises = False  # that car cruises at the target speed (else it holds its own constant speed)
    settings: tuple[str, ...] = ()  # the scenario keys the maneuver reads

    def __init__(self, config: EpisodeSettings):
        self.config = config
        self.ids = config.vehicle_ids
        self.lengths_m = [v.length_m for v in config.car_vehicles]  # by index into ids
        #: each pair of the column (leader, follower, the leader's length): `pairs` runs at every step
        self._column = [(i, i + 1, self.lengths_m[i]) for i in range(len(self.lengths_m) - 1)]

    @classmethod
    def check(cls, config: EpisodeSettings) -> None:
        """Refuse settings this maneuver cannot play (each value's own range is checked by the config)."""

    @classmethod
    def lanes_for(cls, config: EpisodeSettings) -> int:
        """How many lanes, from the platoon's up, the maneuver drives."""
        return cls.lanes_needed

    @classmethod
    def added_parameters(cls, scenario: dict) -> int:
        """How many parameters the maneuver adds after the signal family's, for a [scenario] table."""
        return 0

    def cars(self) -> list[Car]:
        """Every car at t = 0, in the order of ``config.vehicle_ids``."""
        positions, speeds = initial_state(self.config)
        return [Car(i, 0, x, v) for i, x, v in zip(self.ids, positions, speeds)]

    def start_lanes(self) -> list[int]:
        return [car.lane for car in self.cars()]

    def family(self, longitudinal: AttackFamily) -> AttackFamily:
        """The attack's box: the longitudinal family's, plus what the maneuver adds."""
        return longitudinal

    def target_lane(self) -> int | None:
        """The lane the attacker changes into (None: it keeps its lane)."""
        return None

    def pairs(self, positions: Sequence[float], lanes: Sequence[tuple[int, ...]] | None = None) -> list[Pair]:
        """(leader, follower, gap) of the cars next to each other in a lane, frontmost first."""
        if len(positions) != len(self.lengths_m):
            lengths = self.lengths_m
            return [(i, i + 1, positions[i] - lengths[i] - positions[i + 1]) for i in range(len(positions) - 1)]
        return [(a, b, positions[a] - length - positions[b]) for a, b, length in self._column]


class LaneChange(Maneuver):
    """A maneuver in which the attacker changes lanes once, at t_lc_s, a parameter of the attack."""

    lateral = True
    lanes_needed = 2
    settings = ("maneuver", "lane_change_s")

    def family(self, longitudinal: AttackFamily) -> AttackFamily:
        return LaneChangeAttack(longitudinal, self.config.duration_s)

    @classmethod
    def added_parameters(cls, scenario: dict) -> int:
        return 1  # t_lc_s

    def pairs(self, positions: Sequence[float], lanes: Sequence[tuple[int, ...]] | None = None) -> list[Pair]:
        if lanes is None:
            raise ValueError("a lane-changing maneuver needs each car's lanes")
        return lane_pairs(positions, lanes, self.lengths_m)


class CutIn(LaneChange):
    name = "cutin"
    other_car = "lead"
    other_cruises = True
    settings = (*LaneChange.settings, "cutin_follower", "cutin_offset_m")

    @classmethod
    def check(cls, config: EpisodeSettings) -> None:
        if config.cutin_follower > config.followers:
            raise ConfigError("scenario.cutin_follower", config.cutin_follower,
                              f"a follower: 1 for v1 .. {config.followers} for v{config.followers}")
        positions, _ = initial_state(config, front=len(config.vehicle_ids) - 1)
        rear = positions[config.cutin_follower] + config.cutin_offset_m  # the attacker's rear bumper
        if rear < 0.0:  # SUMO would read a negative position from the road's end
            raise ConfigError("scenario.cutin_offset_m", config.cutin_offset_m,
                              f"at least {-(rear - config.cutin_offset_m):g} m: the attacker starts on the road")

    def cars(self) -> list[Car]:
        lead = len(self.ids) - 1
        positions, speeds = initial_state(self.config, front=lead)  # the benign lead where the paper's attacker would be
        k = self.config.cutin_follower
        attacker = positions[k] + self.config.cutin_offset_m + self.lengths_m[0]
        followers = [Car(i, 0, x, v) for i, x, v in zip(self.ids[1:-1], positions[1:], speeds[1:])]
        return [Car("v0", 1, attacker, speeds[0]), *followers, Car("lead", 0, positions[0], speeds[0])]

    def target_lane(self) -> int:
        return 0


class CutOut(LaneChange):
    name = "cutout"
    other_car = "obstacle"
    settings = (*LaneChange.settings, "obstacle_distance_m", "obstacle_speed_mps")

    @classmethod
    def check(cls, config: EpisodeSettings) -> None:
        closed = (config.speed_mps - config.obstacle_speed_mps) * config.attack_start_s  # at most, cruising
        if config.obstacle_distance_m <= closed:
            raise ConfigError("scenario.obstacle_distance_m", config.obstacle_distance_m,
                              f"more than the attacker may close on the obstacle during the {config.warmup_s:g} s warm-up "
                              f"({closed:g} m), or it hits it before the attack starts")

    def cars(self) -> list[Car]:
        column = super().cars()
        front = column[0].position_m + self.config.obstacle_distance_m + self.lengths_m[-1]
        return [*column, Car("obstacle", 0, front, self.config.obstacle_speed_mps)]

    def target_lane(self) -> int:
        return 1


class Swerve(LaneChange):
    """The attacker leads the platoon in its lane, as in the paper's maneuver, and swerves: the lane it is
    in from each of ``swerve_knots`` times spread evenly over the attack (the first at its start) is a
    parameter, searched with its pedals, among the platoon's lane (0) and the ``swerve_lanes`` - 1 to its
    left. It may drop back beside a follower and cut in ahead of it, leave the lane and come back."""

    name = "swerve"
    settings = (*LaneChange.settings, "swerve_knots", "swerve_lanes")

    @classmethod
    def check(cls, config: EpisodeSettings) -> None:
        # SUMO starts a change only once the one before is done, and moves one lane a change: knots closer
        # than the widest move takes would play another plan than the one searched (measured: with knots
        # as far apart as a change takes, SUMO played the first change alone)
        needed = (lane_change_steps(config.lane_change_s, config.step_s) + 1) * (config.swerve_lanes - 1)

        def fits(knots: int) -> bool:
            steps = [lane_change_steps(t, config.step_s) for t in swerve_knot_times(config.duration_s, knots)]
            return all(b - a >= needed for a, b in zip(steps, steps[1:]))

        if not fits(config.swerve_knots):
            most = max(k for k in range(1, config.swerve_knots) if fits(k))
            widest = f"{config.swerve_lanes - 1} lane changes" if config.swerve_lanes > 2 else "a lane change"
            raise ConfigError("scenario.swerve_knots", config.swerve_knots,
                              f"at most {most} over the {config.duration_s:g} s attack: lane knots at least {widest} "
                              f"(scenario.lane_change_s, {config.lane_change_s:g} s each) and a step apart")

    @classmethod
    def lanes_for(cls, config: EpisodeSettings) -> int:
        return config.swerve_lanes

    @classmethod
    def added_parameters(cls, scenario: dict) -> int:
        knots = scenario.get("swerve_knots", SWERVE_KNOTS)
        return knots if isinstance(knots, int) and 1 <= knots <= 50 else 0  # a bad one is refused with the configuration

    def family(self, longitudinal: AttackFamily) -> AttackFamily:
        return SwerveAttack(longitudinal, self.config.duration_s, self.config.swerve_knots, self.config.swerve_lanes)

    def target_lane(self) -> None:  # its lanes are the attack's: `AttackPlan.lane_changes`
        return None


#: every maneuver by name: a new kind of attacker is a new class here
MANEUVERS: dict[str, type[Maneuver]] = {m.name: m for m in (Maneuver, CutIn, CutOut, Swerve)}
#: a swerving attacker's lane knots, and the lanes it may use, unless the scenario says
SWERVE_KNOTS = 6
SWERVE_LANES = 2


def maneuver_of(config: EpisodeSettings) -> Maneuver:
    return MANEUVERS[config.maneuver](config)


#: the attack parameter of a lane-changing maneuver: when the attacker begins its lane change (seconds
#: from the attack's start)
LANE_CHANGE_PARAMETER = "t_lc_s"


class ManeuverAttack(AttackFamily):
    """A longitudinal attack family plus the parameters a maneuver adds after its own (``added``, laid out
    in time as ``added_signals``). Its name and options stay the longitudinal family's; its signal is
    the longitudinal family's, of the first parameters."""

    def __init__(self, longitudinal: AttackFamily, added: tuple[Parameter, ...], added_signals: tuple[int, ...]):
        self.longitudinal = longitudinal
        self.name = longitudinal.name
        self.options = longitudinal.options
        self.parameters = (*longitudinal.parameters, *added)
        self._first_added = len(longitudinal.parameters)
        self._added_signals = added_signals

    @property
    def signals(self) -> tuple[int, ...]:
        return (*self.longitudinal.signals, *self._added_signals)

    def _signal(self, x: np.ndarray, t: np.ndarray) -> np.ndarray:
        return self.longitudinal._signal(x[:self._first_added], t)

    def describe(self) -> dict:
        d = self.longitudinal.describe()
        d["parameters"] = [p.__dict__ for p in self.parameters]
        return d


class LaneChangeAttack(ManeuverAttack):
    """A longitudinal attack family plus the time of the attacker's lane change, `LANE_CHANGE_PARAMETER`:
    a scalar after the longitudinal ones."""

    def __init__(self, longitudinal: AttackFamily, window_s: float):
        super().__init__(longitudinal, (Parameter(LANE_CHANGE_PARAMETER, 0.0, float(window_s), "s"),), (1,))

    def lane_change_s(self, params) -> float:
        return float(self.check(params)[self._first_added])


class SituatedAttack(ManeuverAttack):
    """An attack's box (``attack``) plus the keys of the situation searched with it, after its own parameters
    (`search.situation`): the attacker's plan is the attack's, of the first parameters; the episode's
    configuration takes the rest. Its signal parameters stay the attack's (``longitudinal``)."""

    def __init__(self, attack: AttackFamily, added: tuple[Parameter, ...]):
        super().__init__(attack, added, (1,) * len(added))
        self.attack = attack
        self.longitudinal = getattr(attack, "longitudinal", attack)

    def _signal(self, x: np.ndarray, t: np.ndarray) -> np.ndarray:
        return self.attack._signal(x[:self._first_added], t)

    def attack_params(self, params) -> np.ndarray:
        return self.check(params)[:self._first_added]

    def situation_values(self, params) -> np.ndarray:
        return self.check(params)[self._first_added:]


def attack_of(family: AttackFamily, params=None) -> tuple[AttackFamily, object]:
    """The attack's own box and parameters: where a situation is searched with it (`SituatedAttack`), without the
    situation's, which never change the attacker's plan; else ``family`` and ``params`` as they are."""
    if isinstance(family, SituatedAttack):
        return family.attack, (None if params is None else family.attack_params(params))
    return family, params


def swerve_knot_times(window_s: float, knots: int) -> list[float]:
    """When a swerving attacker's lane knots take hold, from the attack's start [s]: evenly, the first at once."""
    return [j * float(window_s) / knots for j in range(knots)]


class SwerveAttack(ManeuverAttack):
    """A longitudinal attack family plus a swerving attacker's lanes: ``lane_1`` .. ``lane_K``, the lane it
    is in from each of K times spread evenly over the attack window on (``lane_j`` from (j - 1) x window / K
    s), each a number in [0, lanes] read as its whole part (``lanes`` reads as the leftmost, lanes - 1):
    one signal after the longitudinal ones."""

    def __init__(self, longitudinal: AttackFamily, window_s: float, knots: int, lanes: int):
        added = tuple(Parameter(f"lane_{j}", 0.0, float(lanes), "(its whole part the lane: 0 the platoon's)")
                      for j in range(1, knots + 1))
        super().__init__(longitudinal, added, (knots,))
        self.knots, self.lanes = knots, lanes
        self.knot_times_s = swerve_knot_times(window_s, knots)

    def lane_schedule(self, params) -> list[tuple[float, int]]:
        """The attacker's lane changes: (seconds from the attack's start, the lane it changes to), one where
        a knot's lane differs from the one before (the platoon's lane, 0, before the first)."""
        x = self.check(params)
        changes, lane = [], 0
        for t_s, value in zip(self.knot_times_s, x[self._first_added:]):
            wanted = min(int(math.floor(value)), self.lanes - 1)
            if wanted != lane:
                changes.append((t_s, wanted))
                lane = wanted
        return changes

    def change_steps(self, params, config: EpisodeSettings) -> list[tuple[int, int]]:
        """The lane changes as steps of an episode: (the step at whose start each begins, its lane), those
        that begin before the episode's last step."""
        start = config.attack_start_step
        steps = [(start + lane_change_steps(t_s, config.step_s), lane) for t_s, lane in self.lane_schedule(params)]
        return [(k, lane) for k, lane in steps if k < config.steps]


@dataclass(frozen=True)
class AttackPlan:
    """What the attacker does in an episode: its command at each step's start (NaN: it cruises), the
    step at whose start it begins its lane change (None: it keeps its lane), a swerving attacker's
    lane changes: (step at whose start it begins, the lane it changes to), in time order, and what it
    tells over the air."""

    u: np.ndarray
    lane_change_step: int | None = None
    lane_changes: tuple[tuple[int, int], ...] = ()
    #: a message attack's falsifier of the attacker's V2V beacons (`messages.BeaconFalsifier`); None: it tells the truth
    beacons: object = None
    #: the attacker's speed at each step's end as another run drove it (an exported scenario's trajectory,
    #: `results.openscenario`): it then drives exactly so, whatever its pedals; None: its pedals drive it
    motion: np.ndarray | None = None


def lane_changes(plan: AttackPlan, maneuver: Maneuver) -> list[tuple[int, int]]:
    """Every lane change of the attacker's plan: (step at whose start it begins, the lane it changes to,
    counted from the platoon's), in time order."""
    once = [(plan.lane_change_step, maneuver.target_lane())] if plan.lane_change_step is not None else []
    return [*once, *plan.lane_changes]


def attack_plan(family: AttackFamily | None, params, config: EpisodeSettings) -> AttackPlan:
    """The plan of an attack that begins after the warm-up (if any): the longitudinal signal, and the
    lane change at the step nearest to t_lc_s after the attack's start."""
    from .pedals import attack_signal

    family, params = attack_of(family, params)  # the situation's values are the configuration's, not the plan's
    u = attack_signal(family, params, steps=config.steps, step_s=config.step_s, start_step=config.attack_start_step)
    if hasattr(family, "falsifier"):  # a message attack (`messages`): its pedals, and its lie over the air
        return AttackPlan(u, beacons=family.falsifier(params, config))
    if isinstance(family, SwerveAttack):
        return AttackPlan(u, lane_changes=tuple(family.change_steps(params, config)))
    t_lc_s = family.lane_change_s(params) if family is not None else None
    if t_lc_s is None:
        return AttackPlan(u)
    step = config.attack_start_step + lane_change_steps(t_lc_s, config.step_s)
    return AttackPlan(u, step if step < config.steps else None)


def inert_parameters(family: AttackFamily, config: EpisodeSettings, draws: int = 4) -> list[int]:
    """The parameters that change nothing in an episode of this configuration (a knot that acts only past
    its end, say): each moved from a few points of the box (``draws``, fixed) to a few other values, none
    changed the attacker's plan. The search still spends its samples over them."""
    family, _ = attack_of(family)  # the situation's keys change the episode, never the plan
    rng = np.random.default_rng(0)
    lower, upper = family.lower, family.upper
    inert = []
    for i in range(getattr(family, "message_first", len(lower))):  # a message attack's own are the lie, not the plan
        moved = False
        for x in rng.uniform(lower, upper, size=(draws, len(lower))):
            plan = attack_plan(family, x, config)
            for value in rng.uniform(lower[i], upper[i], size=2):
                y = x.copy()
                y[i] = value
                other = attack_plan(family, y, config)
                if (not np.array_equal(plan.u, other.u, equal_nan=True) or plan.lane_change_step != other.lane_change_step
                        or plan.lane_changes != other.lane_changes):
                    moved = True
                    break
            if moved:
                break
        if not moved:
            inert.append(i)
    return inert


#: a lane change time within this many steps of a half step counts as the half step (which rounds up)
HALF_STEP_TOLERANCE = 1e-9


def lane_change_steps(t_lc_s: float, step_s: float) -> int:
    """The whole steps nearest to t_lc_s, a half step rounding up whatever the rounding of t_lc_s / step_s
    (1.075 s / 0.05 s is 21.499999999999996 in floating point: it rounds to 22, as 1.025 s to 21)."""
    return int(math.floor(t_lc_s / step_s + 0.5 + HALF_STEP_TOLERANCE))


def check_road_lanes(config: EpisodeSettings, road_name: str, lanes: int) -> None:
    needed = config.maneuver_class.lanes_for(config)
    if lanes < needed:
        field, given = (("scenario.swerve_lanes", needed) if config.maneuver == "swerve"
                        else ("scenario.maneuver", config.maneuver))
        lower = f" from its lane {config.lane}: a lower scenario.lane" if config.lane else ""
        raise ConfigError(field, given, f"a road with at least {needed} lanes that lead on, the platoon's and those to its "
                                        f"left ({road_name} has {lanes}{lower}), or maneuver inlane")
