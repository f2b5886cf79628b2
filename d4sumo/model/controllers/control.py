"""Longitudinal control of the cars: the paper's switching ACC/cruise controller (its Eq. 1) and its
constant time-gap variant (the paper's suggested mitigation); the cooperative laws are in `cacc`.

Pure code, no SUMO. A follower controller turns what the car senses (bumper gap to the car ahead,
its own speed, the speed of the car ahead) into a command u in [-1, 1] (-1 full brake, +1 full
throttle), which the car's actuator (`vehicle`) turns into an acceleration. Controllers are
pluggable: a config names a registered controller ("switching", "timegap", the registry at the end
of this module) or any class as "package.module:ClassName" that follows the `FollowerController`
protocol (imported by `plugins`). (Followers driven by SUMO's own car-following models are named
"sumo:MODEL"; see `carfollowing`.)
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Protocol

from ...errors import ConfigError, check_number
from .cacc import ConsensusCACC, PathCACC, PloegCACC  # the cooperative laws (they read V2V beacons)
from .fmu import PREFIX as FMU_PREFIX, fmu_controller, is_fmu
from .laws import LAWS
from .plugins import import_controller
from ..world.vehicle import VehicleParams, acceleration_to_command

#: Mode values recorded in traces (signal ``mode_vI``).
MODE_CC = 0.0
MODE_ACC = 1.0

#: Tolerances of the mode switch's comparisons. Gaps are differences of positions of some tens or
#: hundreds of metres, so a platoon spaced exactly at its setpoint measures a gap a few 1e-14 m off;
#: within these tolerances a value counts as at the threshold, so no mode decision hinges on rounding.
GAP_TOLERANCE_M = 1e-6
SPEED_TOLERANCE_MPS = 1e-6


SWITCHING_RULES = ("eq1", "code")
CRUISE_PIDS = ("d4sumo", "code")
LOW_LEVELS = ("exact", "pid")


@dataclass(frozen=True)
class SwitchingParams:
    """Gains of the paper's switching controller; defaults from the authors' public code.

    The options after the gains are how the authors' code ran it where it differs from the paper's text
    (their defaults: the text, as d4sumo always ran it). A campaign's definition holds them only where
    they differ from the defaults (`AS_RUN_DEFAULTS`), so campaigns stored before them keep their identity.
    """

    cruise_kp: float = 0.4  # [1/s] (m/s^2 per m/s of speed error)
    cruise_ki: float = 0.01  # [1/s^2]
    cruise_kd: float = 0.1  # [-]
    cruise_integral_clamp: float = 20.0  # [m] bound on the integrated speed error
    cruise_output_limit_mps2: float = 3.0
    acc_kp: float = 0.9304  # [1/s^2] (m/s^2 per m of gap error)
    acc_kv: float = 2.1599  # [1/s] (m/s^2 per m/s of speed difference)
    eps_x_m: float = 1.0  # hysteresis on the gap
    eps_v_mps: float = 1.0  # hysteresis on the speed
    #: "eq1": the paper's Eq. 1; "code": ACC engages within d + engage_margin_m when the car ahead is
    #: slower than the target speed, and lets go beyond d + engage_margin_m + release_margin_m or when
    #: the car ahead is faster than the target speed + eps_v_mps
    switching_rule: str = "eq1"
    engage_margin_m: float = 25.0
    release_margin_m: float = 10.0
    #: "d4sumo": rectangle-rule integral, derivative of the raw error; "code": the authors' PID, a
    #: trapezoid-rule integral and the derivative of the error filtered with time constant cruise_filter_s
    cruise_pid: str = "d4sumo"
    cruise_filter_s: float = 1.0
    #: from the wanted acceleration to the pedal: "exact" (its inverse map); "pid": the authors' second PID
    #: on (wanted - measured acceleration), its integral starting at low_integral_init, clamped at
    #: low_integral_clamp, its output at [-1, 1]
    low_level: str = "exact"
    low_kp: float = 0.1
    low_ki: float = 0.1
    low_kd: float = 0.005
    low_integral_init: float = 5.0
    low_integral_clamp: float = 10.0
    control_period_s: float = 0.0  # the controller acts this often, holding its command between (0: every step)
    first_command_zero: bool = False  # the authors' controllers return no pedal at their first call

    def __post_init__(self) -> None:
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            field = f"controller.{f.name}"
            if f.name in _CHOICES:
                if value not in _CHOICES[f.name]:
                    raise ConfigError(field, value, f"one of {', '.join(_CHOICES[f.name])}")
            elif f.name == "first_command_zero":
                if not isinstance(value, bool):
                    raise ConfigError(field, value, "true or false")
            else:
                low = 1e-3 if f.name in ("eps_x_m", "eps_v_mps") else 0.0  # hysteresis wider than the tolerances
                object.__setattr__(self, f.name, check_number(field, value, low, 1e6))
        for choice, chosen, options in (("switching_rule", "code", ("engage_margin_m", "release_margin_m")),
                                        ("cruise_pid", "code", ("cruise_filter_s",)),
                                        ("low_level", "pid", ("low_kp", "low_ki", "low_kd", "low_integral_init", "low_integral_clamp"))):
            for option in options:  # an option the chosen rule does not read is a mistake, not a no-op
                if getattr(self, choice) != chosen and getattr(self, option) != AS_RUN_DEFAULTS[option]:
                    raise ConfigError(f"controller.{option}", getattr(self, option),
                                      f"an option of {choice} = \"{chosen}\" (this controller's {choice} is \"{getattr(self, choice)}\")")

    @property
    def as_run(self) -> bool:
        """Whether any of the authors' code's options differs from the paper's text."""
        return any(getattr(self, k) != v for k, v in AS_RUN_DEFAULTS.items())


_CHOICES = {"switching_rule": SWITCHING_RULES, "cruise_pid": CRUISE_PIDS, "low_level": LOW_LEVELS}
#: the authors' code's options and their defaults (the paper's text): stored only where they differ
AS_RUN_DEFAULTS = {f.name: f.default for f in dataclasses.fields(SwitchingParams)
                   if f.name in ("switching_rule", "engage_margin_m", "release_margin_m", "cruise_pid", "cruise_filter_s",
                                 "low_level", "low_kp", "low_ki", "low_kd", "low_integral_init", "low_integral_clamp",
                                 "control_period_s", "first_command_zero")}


class CruiseControl:
    """Discrete PID on speed with a clamped integral and a clamped output [m/s^2]."""

    __slots__ = ("kp", "ki", "kd", "clamp", "limit", "step_s", "target_mps", "integral", "prev_error")

    def __init__(self, params: SwitchingParams, target_speed_mps: float, step_s: float):
        self.kp, self.ki, self.kd = params.cruise_kp, params.cruise_ki, params.cruise_kd
        self.clamp = params.cruise_integral_clamp
        self.limit = params.cruise_output_limit_mps2
        self.step_s = step_s
        self.target_mps = target_speed_mps
        self.integral = 0.0
        self.prev_error: float | None = None  # None: no derivative kick on (re)engagement

    def disengage(self) -> None:
        self.prev_error = None

    def reset(self) -> None:
        """Start afresh: no integrated error, no derivative kick."""
        self.integral = 0.0
        self.prev_error = None

    def acceleration(self, speed_mps: float) -> float:
        e = self.target_mps - speed_mps
        i = self.integral + e * self.step_s
        self.integral = i = self.clamp if i > self.clamp else (-self.clamp if i < -self.clamp else i)
        d = 0.0 if self.prev_error is None else (e - self.prev_error) / self.step_s
        self.prev_error = e
        a = self.kp * e + self.ki * i + self.kd * d
        return self.limit if a > self.limit else (-self.limit if a < -self.limit else a)


class CodePID:
    """The authors' PID (their controllers/pid.py), for their cruise control and their low-level control.

    Each call: the error is filtered (first order, time constant ``filter_s``; 0: unfiltered); from the
    second call on the integral adds the trapezoid of the last two errors (clamped at +/- ``clamp``) and
    the derivative is the filtered error's difference over the period; at the first call the derivative
    is 0 and the integral is its initial value. Output: Kp e + Kd de + Ki ie, clipped to +/- ``limit``.
    """

    __slots__ = ("kp", "ki", "kd", "period_s", "filter_s", "clamp", "limit", "integral", "prev_error", "filtered",
                 "prev_filtered")

    def __init__(self, kp: float, ki: float, kd: float, period_s: float, *, filter_s: float = 0.0,
                 clamp: float = 20.0, limit: float = 1.0, integral: float = 0.0):
        self.kp, self.ki, self.kd, self.period_s = kp, ki, kd, period_s
        self.filter_s, self.clamp, self.limit = filter_s, clamp, limit
        self.integral = integral
        self.prev_error: float | None = None
        self.filtered = 0.0
        self.prev_filtered = 0.0

    def step(self, error: float) -> float:
        self.prev_filtered = self.filtered
        if self.filter_s > 0.0:
            self.filtered = self.period_s / self.filter_s * (error - self.filtered) + self.filtered
        else:
            self.filtered = error
        if self.prev_error is None:
            de = 0.0
        else:
            de = (self.filtered - self.prev_filtered) / self.period_s
            i = self.integral + (error + self.prev_error) * self.period_s / 2.0
            self.integral = self.clamp if i > self.clamp else (-self.clamp if i < -self.clamp else i)
        self.prev_error = error
        out = self.kp * error + self.kd * de + self.ki * self.integral
        return self.limit if out > self.limit else (-self.limit if out < -self.limit else out)


class FollowerController(Protocol):
    """What the co-simulation needs of a follower's controller: one observation in, one command out.

    Constructed as ``cls(params, setpoint_m=..., target_speed_mps=..., vehicle=..., step_s=...)`` where
    ``params`` is an instance of ``cls.Params`` (a dataclass built from the config's controller table).
    Each step ``observe(observation)`` is given what the car knows (`sensing.Observation`: what its radar
    measured, its own state and, where it listens, the beacons) and returns the command u in [-1, 1].
    ``mode`` (optional) is recorded in the trace each step. A user's class written to the three-float form,
    ``command(gap_m, speed_mps, lead_speed_mps)``, keeps working (`plugins.observer`, the one adapter).
    """

    Params: type

    def observe(self, observation) -> float: ...


class SwitchingController:
    """The paper's switching policy (Eq. 1): cruise control (PID) or ACC, with hysteresis.

    CC when gap >= d + eps_x or v >= v_d + eps_v; ACC when gap <= d and v <= v_d; otherwise the mode
    stays (every comparison within GAP_TOLERANCE_M / SPEED_TOLERANCE_MPS of its threshold counts as
    reaching it). ACC: a = Kp (gap - d) + Kv (v_lead - v).
    """

    Params = SwitchingParams

    def __init__(
        self,
        params: SwitchingParams,
        *,
        setpoint_m: float,
        target_speed_mps: float,
        vehicle: VehicleParams,
        step_s: float,
    ):
        self.params = params
        self.vehicle = vehicle
        self.setpoint_m = setpoint_m
        self.target_speed_mps = target_speed_mps
        self.cruise = CruiseControl(params, target_speed_mps, step_s)
        self.mode = MODE_CC
        self._mode_known = False
        self._eps_x = params.eps_x_m
        self._cc_speed = target_speed_mps + params.eps_v_mps - SPEED_TOLERANCE_MPS
        self._acc_speed = target_speed_mps + SPEED_TOLERANCE_MPS
        self._acc_kp, self._acc_kv = params.acc_kp, params.acc_kv
        self._accel_max, self._decel_max = vehicle.max_accel_mps2, vehicle.max_decel_mps2
        self._as_run = params.as_run
        if self._as_run:
            self._as_run_setup(params, target_speed_mps, step_s)

    def _as_run_setup(self, params: SwitchingParams, target_speed_mps: float, step_s: float) -> None:
        """The authors' code's options (`SwitchingParams`): its rule, its PIDs, its control period."""
        period = params.control_period_s or step_s
        self._every = max(1, int(round(period / step_s)))  # steps between two actions
        self._period_s = self._every * step_s
        self._calls = 0
        self.held = 0.0
        self._prev_speed: float | None = None
        if params.cruise_pid == "code":
            self._code_cruise = CodePID(params.cruise_kp, params.cruise_ki, params.cruise_kd, self._period_s,
                                        filter_s=params.cruise_filter_s, clamp=params.cruise_integral_clamp,
                                        limit=params.cruise_output_limit_mps2)
        else:
            self.cruise = CruiseControl(params, target_speed_mps, self._period_s)
        if params.low_level == "pid":
            self._low = CodePID(params.low_kp, params.low_ki, params.low_kd, self._period_s,
                                clamp=params.low_integral_clamp, limit=1.0, integral=params.low_integral_init)
        self._engage_m = params.engage_margin_m
        self._release_m = params.engage_margin_m + params.release_margin_m

    def desired_gap_m(self, speed_mps: float) -> float:
        """The gap the ACC keeps: the setpoint d (Eq. 1)."""
        return self.setpoint_m

    def select_mode(self, gap_m: float, speed_mps: float) -> float:
        desired = self.desired_gap_m(speed_mps)
        if gap_m >= desired + self._eps_x - GAP_TOLERANCE_M or speed_mps >= self._cc_speed:
            mode = MODE_CC
        elif gap_m <= desired + GAP_TOLERANCE_M and speed_mps <= self._acc_speed:
            mode = MODE_ACC
        elif self._mode_known:
            mode = self.mode
        else:
            mode = MODE_CC  # inside the hysteresis band at start: cruise
        if mode != self.mode and mode == MODE_ACC:
            self.cruise.disengage()
        self.mode = mode
        self._mode_known = True
        return mode

    def desired_acceleration(self, gap_m: float, speed_mps: float, lead_speed_mps: float) -> float:
        """Eq. 1: the acceleration the active law asks for [m/s^2]."""
        if self.select_mode(gap_m, speed_mps) == MODE_CC:
            return self.cruise.acceleration(speed_mps)
        return self._acc_kp * (gap_m - self.desired_gap_m(speed_mps)) + self._acc_kv * (lead_speed_mps - speed_mps)

    def observe(self, o) -> float:
        """The command from what its radar measured (Eq. 1 reads the gap, its own speed, the speed ahead)."""
        return self.command(o.gap_m, o.speed_mps, o.lead_speed_mps)

    def command(self, gap_m: float, speed_mps: float, lead_speed_mps: float) -> float:
        """Eq. 1 on the three numbers it reads, through the actuator's inverse map to the pedal."""
        if self._as_run:
            return self.command_as_run(gap_m, speed_mps, lead_speed_mps)
        # acceleration_to_command inlined: this runs for every follower at every step
        a = self.desired_acceleration(gap_m, speed_mps, lead_speed_mps)
        u = a / self._accel_max if a >= 0.0 else a / self._decel_max
        return 1.0 if u > 1.0 else (-1.0 if u < -1.0 else u)

    # --- as the authors' code ran it ----------------------------------------------------------------

    def _select_mode_code(self, gap_m: float, speed_mps: float, lead_speed_mps: float) -> float:
        """The code's rule (comparisons within the tolerances count as at the threshold, not past it)."""
        d = self.desired_gap_m(speed_mps)
        if self.mode == MODE_CC:
            if gap_m < d + self._engage_m - GAP_TOLERANCE_M and lead_speed_mps < self.target_speed_mps - SPEED_TOLERANCE_MPS:
                self.mode = MODE_ACC
                if self.params.cruise_pid != "code":  # d4sumo's cruise PID re-engages without a derivative kick
                    self.cruise.disengage()
        elif gap_m > d + self._release_m + GAP_TOLERANCE_M or lead_speed_mps > self._cc_speed + 2 * SPEED_TOLERANCE_MPS:
            self.mode = MODE_CC
        self._mode_known = True
        return self.mode

    def command_as_run(self, gap_m: float, speed_mps: float, lead_speed_mps: float, act: bool = True) -> float | None:
        """One call of the authors' controller (every step; it acts once a control period and holds its
        pedal between). ``act`` False: at a control step whose pedal someone else sets (their attacker
        attacking), it only measures and returns None; the caller then sets ``held``, the pedal it holds."""
        calls = self._calls
        self._calls = calls + 1
        if calls % self._every:
            return self.held  # between two actions the pedal holds
        p = self.params
        # the measured acceleration: the speed's change over the last control period
        measured = 0.0 if self._prev_speed is None else (speed_mps - self._prev_speed) / self._period_s
        self._prev_speed = speed_mps
        if calls == 0 and p.first_command_zero:
            self.held = 0.0
            return 0.0
        if not act:
            return None
        if p.switching_rule == "code":
            mode = self._select_mode_code(gap_m, speed_mps, lead_speed_mps)
        else:
            mode = self.select_mode(gap_m, speed_mps)
        if mode == MODE_ACC:
            a = self._acc_kp * (gap_m - self.desired_gap_m(speed_mps)) + self._acc_kv * (lead_speed_mps - speed_mps)
        elif p.cruise_pid == "code":
            a = self._code_cruise.step(self.target_speed_mps - speed_mps)
        else:
            a = self.cruise.acceleration(speed_mps)
        if p.low_level == "pid":
            u = self._low.step(a - measured)
        else:
            u = a / self._accel_max if a >= 0.0 else a / self._decel_max
            u = 1.0 if u > 1.0 else (-1.0 if u < -1.0 else u)
        self.held = u
        return u


@dataclass(frozen=True)
class TimeGapParams(SwitchingParams):
    """The switching controller with a constant time-gap spacing policy (the paper's mitigation)."""

    time_gap_s: float = 1.0  # h: seconds of own speed added to the standstill distance


class TimeGapController(SwitchingController):
    """Eq. 1 with a speed-dependent desired gap: d(v) = s0 + h v, s0 the scenario's setpoint.

    The paper suggests ACCs "that can handle different distances at different speeds" as a
    mitigation; this is the textbook one. The mode switch and the ACC law use d(v) where Eq. 1 uses
    d: CC when gap >= d(v) + eps_x or v >= v_d + eps_v; ACC when gap <= d(v) and v <= v_d;
    ACC: a = Kp (gap - d(v)) + Kv (v_lead - v). At h = 0 it is the paper's controller.
    """

    Params = TimeGapParams

    def __init__(self, params: TimeGapParams, **kwargs):
        super().__init__(params, **kwargs)
        self.time_gap_s = params.time_gap_s

    def desired_gap_m(self, speed_mps: float) -> float:
        return self.setpoint_m + self.time_gap_s * speed_mps


class CautiousDriver:
    """A careful driver among traffic (the attacker where it does not attack): cruise control at its speed,
    never faster than the time-gap spacing law on the car ahead allows. Its acceleration is the smaller of
    the two, as production ACCs arbitrate speed and spacing control, with no mode to get stuck in: the
    paper's switching rule keeps cruising above v_d however close the car ahead (Eq. 1's hysteresis band),
    which no driver does. Spacing: a = Kp (gap - s0 - h v) + Kv (v_lead - v) with the paper's gains."""

    def __init__(self, params: SwitchingParams, *, setpoint_m: float, time_gap_s: float, target_speed_mps: float,
                 vehicle: VehicleParams, step_s: float):
        self.cruise = CruiseControl(params, target_speed_mps, step_s)
        self.setpoint_m, self.time_gap_s = setpoint_m, time_gap_s
        self._kp, self._kv = params.acc_kp, params.acc_kv
        self.vehicle = vehicle

    def command(self, gap_m: float, speed_mps: float, lead_speed_mps: float) -> float:
        a = self.cruise.acceleration(speed_mps)
        spacing = self._kp * (gap_m - self.setpoint_m - self.time_gap_s * speed_mps) + self._kv * (lead_speed_mps - speed_mps)
        return acceleration_to_command(min(a, spacing), self.vehicle)


# --- cooperative controllers (CACC): they read V2V beacons (`v2v`) -------------------------------


# --- registry of follower controllers ------------------------------------------------------------

_REGISTRY: dict[str, type] = {}


def register_controller(name: str, cls: type) -> None:
    """Make a controller class available under a short name; names are never silently replaced."""
    if name in _REGISTRY and _REGISTRY[name] is not cls:
        raise ValueError(f"a follower controller is already registered as {name!r}")
    _REGISTRY[name] = cls


register_controller("switching", SwitchingController)
register_controller("timegap", TimeGapController)
register_controller("cacc", PathCACC)
register_controller("ploeg", PloegCACC)
register_controller("consensus", ConsensusCACC)
for _name, _law in LAWS.items():  # the laws of one file each (`laws`)
    register_controller(_name, _law)


def registered_controllers() -> tuple[str, ...]:
    return tuple(sorted(_REGISTRY))


def user_module(name: str) -> str | None:
    """The module a controller name imports: None for a registered controller, a SUMO model or an FMU."""
    return (name.partition(":")[0] if name not in _REGISTRY and ":" in name and not name.startswith(("sumo:", FMU_PREFIX))
            else None)


def user_code(name: str) -> str | None:
    """The user's code a controller name runs, as said when it is loaded: its module, or its FMU (the name
    itself, ``fmu:PATH``); None for a registered controller or a SUMO model."""
    return name if is_fmu(name) else user_module(name)


def resolve_controller(name: str, params=()) -> type:
    """A registered name, or "package.module:ClassName" for a user's own controller class (`plugins`), or
    "fmu:PATH" for an FMU (its ``params``, (key, value) pairs, may name the content a campaign ran).

    (``sumo:MODEL`` names a SUMO car-following model: not a Python class, see `carfollowing`.)"""
    if name in _REGISTRY:
        return _REGISTRY[name]
    if is_fmu(name):
        return fmu_controller(name, params)
    if ":" not in name:
        raise ConfigError("controller.class", name, f"one of {', '.join(registered_controllers())}, a SUMO model as "
                                                    "'sumo:MODEL', an FMU as 'fmu:PATH' or 'package.module:ClassName'")
    return import_controller(name)
