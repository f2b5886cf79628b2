"""Attack families: the attacker's throttle/brake signal u(t) in [-1, 1] from a parameter vector.

Each family has a parameter box; every point of the box is a valid attack (ordered times are
parameterised as offsets, so no sample is ever rejected). ``signal(params, times)`` returns u at the
given times, NaN where the attack is not active yet (the attacker then cruises at the target speed).
Pure code, no SUMO.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
from scipy.interpolate import CubicSpline, PchipInterpolator

from ...errors import ConfigError, check_int, check_number


def sine(x: np.ndarray) -> np.ndarray:
    """sin, element by element, from the C library (correctly rounded in glibc): numpy's own vectorised
    sin takes other paths on CPUs with AVX-512 and may differ in the last bit, and an episode must be
    the same on every machine."""
    return np.array([math.sin(v) for v in np.ravel(x)], dtype=float).reshape(np.shape(x))


@dataclass(frozen=True)
class Parameter:
    name: str
    low: float
    high: float
    unit: str = ""


class AttackFamily:
    """A parametric family of attack signals over a box of parameters.

    A family owns its name, its box (``parameters``) and its options (``OPTIONS``: name -> (default,
    low, high, unit), given in a config's ``[attack]`` table and stored resolved in each campaign's
    definition). A new family is a new class here and one line in `FAMILY_CLASSES`."""

    name: str = ""
    parameters: tuple[Parameter, ...] = ()
    OPTIONS: dict[str, tuple[float, float, float, str]] = {}
    #: its parameters are knots in time, one every ``delta_s`` (the report clusters them: `results.clusters`); and
    #: each knot shapes the signal only near it (PCHIP: knot k on (t_{k-2}, t_{k+2})), not everywhere (a global spline)
    knots_in_time: bool = False
    local_knots: bool = False

    def __init__(self, **options: float):
        self.options = resolve_attack_options(self.name, options)

    @property
    def dimension(self) -> int:
        return len(self.parameters)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(p.name for p in self.parameters)

    @property
    def signals(self) -> tuple[int, ...]:
        """How the parameters lay out in time, for an optimiser that reads them as signals (`auto`'s
        suffix moves; `Optimizer`): each parameter a scalar unless the family holds a signal (knots do).
        Part of how its campaigns replay: a family keeps its layout."""
        return (1,) * self.dimension

    @property
    def lower(self) -> np.ndarray:
        return np.array([p.low for p in self.parameters], dtype=float)

    @property
    def upper(self) -> np.ndarray:
        return np.array([p.high for p in self.parameters], dtype=float)

    def check(self, params: Sequence[float], field: str = "attack parameters") -> np.ndarray:
        """The parameter vector as an array, or a ConfigError naming the offending parameter."""
        try:
            x = np.asarray(params, dtype=float)
        except (TypeError, ValueError):
            raise ConfigError(field, repr(params)[:80], f"{self.dimension} numbers for {self.name}: {', '.join(self.names)}") from None
        x = x.reshape(-1) if x.ndim == 0 else x  # one number, for a family of one parameter
        if x.ndim != 1 or x.size != self.dimension:
            raise ConfigError(field, x.tolist(), f"{self.dimension} values for {self.name}: {', '.join(self.names)}")
        for value, p in zip(x, self.parameters):
            if not (p.low <= value <= p.high):  # NaN fails too
                raise ConfigError(f"{field}: {p.name}", float(value), f"a number in [{p.low:g}, {p.high:g}] {p.unit}".rstrip())
        return x

    def signal(self, params: Sequence[float], times_s: np.ndarray) -> np.ndarray:
        x = self.check(params)
        return np.clip(self._signal(x, np.asarray(times_s, dtype=float)), -1.0, 1.0)

    def _signal(self, x: np.ndarray, t: np.ndarray) -> np.ndarray:
        raise NotImplementedError

    def lane_change_s(self, params: Sequence[float]) -> float | None:
        """When the attacker begins a lane change (seconds from the attack's start), if it makes one."""
        return None

    def describe(self) -> dict:
        return {"family": self.name, "parameters": [p.__dict__ for p in self.parameters]}


class Constant(AttackFamily):
    """u(t) = c from t = 0: the simplest attack, for checks and demonstrations."""

    name = "constant"
    parameters = (Parameter("c", -1.0, 1.0),)

    def _signal(self, x, t):
        return np.full_like(t, x[0])


class Cruise(AttackFamily):
    """No pedal attack: the attacker cruises as everyone does. Alone it is no attack (refused); with a
    message attack (`messages`) the lie over the air is the whole attack."""

    name = "cruise"
    parameters = ()

    def _signal(self, x, t):
        return np.full_like(t, np.nan)


class Persistent(AttackFamily):
    """The paper's pi_s = (c, f, t_a): from t_a on, a square wave between +c and -c at frequency f.

    Each period starts with throttle (+c) for its first half, then brakes (-c).
    """

    name = "persistent"
    parameters = (
        Parameter("c", 0.0, 1.0),
        Parameter("f_hz", 0.02, 1.0, "Hz"),
        Parameter("t_a_s", 0.0, 20.0, "s"),
    )

    def _signal(self, x, t):
        c, f, t_a = x
        phase = np.mod((t - t_a) * f, 1.0)
        u = np.where(phase < 0.5, c, -c)
        return np.where(t >= t_a, u, np.nan)


class Intermittent(AttackFamily):
    """The paper's pi_p = (t1, t2, t3, t4, c1, c2): u = c1 on [t1, t2], u = c2 on [t3, t4].

    Times are searched as t1 and three non-negative durations (t2 - t1, t3 - t2, t4 - t3) so that
    every point of the box is ordered. The attacker cruises outside the two windows.
    """

    name = "intermittent"
    parameters = (
        Parameter("t1_s", 0.0, 20.0, "s"),
        Parameter("width1_s", 0.0, 10.0, "s"),
        Parameter("pause_s", 0.0, 10.0, "s"),
        Parameter("width2_s", 0.0, 10.0, "s"),
        Parameter("c1", -1.0, 1.0),
        Parameter("c2", -1.0, 1.0),
    )

    @staticmethod
    def window_times(x: Sequence[float]) -> tuple[float, float, float, float]:
        t1 = float(x[0])
        t2 = t1 + float(x[1])
        t3 = t2 + float(x[2])
        return t1, t2, t3, t3 + float(x[3])

    def _signal(self, x, t):
        t1, t2, t3, t4 = self.window_times(x)
        u = np.full_like(t, np.nan)
        u[(t >= t1) & (t <= t2)] = x[4]
        u[(t >= t3) & (t <= t4)] = x[5]
        return u


class Sine(AttackFamily):
    """u(t) = A sin(2 pi f t + phase) from t = 0: the paper's example of a parametric attack."""

    name = "sine"
    parameters = (
        Parameter("amplitude", 0.0, 1.0),
        Parameter("f_hz", 0.02, 1.0, "Hz"),
        Parameter("phase_rad", 0.0, 2.0 * math.pi, "rad"),
    )

    def _signal(self, x, t):
        a, f, phase = x
        return a * sine(2.0 * math.pi * f * t + phase)


class Knots(AttackFamily):
    """The nonparametric attack: one command every ``delta_s`` up to ``horizon_s``, joined by PCHIP
    (monotone between knots, never overshooting [-1, 1]). After the horizon the last knot's value is held.
    """

    name = "knots"
    knots_in_time = local_knots = True
    OPTIONS = {"delta_s": (6.0, 0.05, 600.0, "seconds"), "horizon_s": (48.0, 0.05, 3600.0, "seconds")}

    def __init__(self, **options: float):
        super().__init__(**options)
        delta_s, horizon_s = self.options["delta_s"], self.options["horizon_s"]
        if horizon_s < delta_s:
            raise ConfigError("attack.horizon_s", horizon_s, f"a number in [{delta_s:g}, 3600] seconds (at least delta_s = {delta_s:g})")
        count = horizon_s / delta_s
        if abs(count - round(count)) > 1e-9:
            raise ConfigError("attack.horizon_s", horizon_s, f"a whole multiple of delta_s={delta_s:g} s")
        self.delta_s, self.horizon_s = delta_s, horizon_s
        self.knot_times_s = np.arange(int(round(count)) + 1) * self.delta_s
        self.parameters = tuple(Parameter(f"m{i}", -1.0, 1.0) for i in range(self.knot_times_s.size))

    @property
    def signals(self) -> tuple[int, ...]:  # the knots: one signal
        return (self.dimension,)

    def _signal(self, x, t):
        tk = self.knot_times_s
        tc = np.clip(t, tk[0], tk[-1])  # hold the last value after the horizon
        return PchipInterpolator(tk, x)(tc)

    def describe(self) -> dict:
        return {**super().describe(), **self.options}


class Spline(Knots):
    """The knots joined as the authors' code joins them: a cubic spline, its overshoot clipped to
    [-1, 1]; kept for comparison."""

    name = "spline"
    local_knots = False  # a global cubic spline: every knot reaches every time

    def _signal(self, x, t):
        tk = self.knot_times_s
        return CubicSpline(tk, x)(np.clip(t, tk[0], tk[-1]))


# --- the attacks as the authors' code played them (the paper's tables came from it) --------------
#
# From the code the paper links (its line 75; ../PAPER-AS-RUN facts): the persistent attack at commit
# d458f6c, the intermittent one with it, the knot attack at its HEAD. Their time is the episode's, which
# starts with the attack (the code starts from rest and attacks from its first step or t_a).


class PersistentCoded(AttackFamily):
    """The persistent attack as coded: from t_a on, u = sign(sin(f t)) c, with f in rad/s and t the time
    since the episode's start (not since t_a); the paper's text has a square wave in Hz from t_a."""

    name = "persistent-coded"
    parameters = (
        Parameter("c", 0.0, 1.0),
        Parameter("f_rad_s", 0.0, 10.0, "rad/s"),
        Parameter("t_a_s", 0.0, 10.0, "s"),
    )

    def _signal(self, x, t):
        c, f, t_a = x
        if t_a == 0.0:  # the code tests `elif attack_time:`, false at 0: no attack at all
            return np.full_like(t, np.nan)
        return np.where(t >= t_a, np.sign(sine(f * t)) * c, np.nan)


#: the authors' control period: their controllers' clock adds it at every call
CODE_PERIOD_S = 0.1


def code_clock(t: np.ndarray) -> np.ndarray:
    """The authors' clock at times ``t`` (on their 0.1 s grid): ``self.t += dt`` summed call by call, which
    drifts from n x 0.1 (the 100th call reads 9.99999999999998, the 210th 21.00000000000003), so a window
    edge at a whole second starts or ends a call later or earlier than exact arithmetic would."""
    n = np.rint(np.asarray(t, dtype=float) / CODE_PERIOD_S).astype(int)
    sums = np.concatenate([[0.0], np.cumsum(np.full(int(n.max(initial=0)), CODE_PERIOD_S))])  # sums[k]: k additions
    return sums[np.clip(n, 0, None)]


class IntermittentCoded(AttackFamily):
    """The intermittent attack as coded: throttle (never brake) c1 on [t1, t2] and c2 on [t3, t4], each
    time rounded to a whole second (Python's round), the windows' ranges apart so every point is ordered;
    the attacker cruises outside them."""

    name = "intermittent-coded"
    parameters = (
        Parameter("t1_s", 10.0, 20.0, "s"),
        Parameter("t2_s", 21.0, 30.0, "s"),
        Parameter("t3_s", 31.0, 40.0, "s"),
        Parameter("t4_s", 41.0, 50.0, "s"),
        Parameter("c1", 0.0, 1.0),
        Parameter("c2", 0.0, 1.0),
    )

    def _signal(self, x, t):
        t1, t2, t3, t4 = (float(round(float(v))) for v in x[:4])
        t = code_clock(t)  # the windows compare the code's own clock, a running sum of 0.1 s
        u = np.full_like(t, np.nan)
        u[(t >= t1) & (t <= t2)] = x[4]
        u[(t >= t3) & (t <= t4)] = x[5]
        return u


class KnotsCoded(AttackFamily):
    """The knot attack as coded: 8 knots at linspace(0, 40, 8) s (one every 5.71 s), joined by scipy's
    interpolating cubic B-spline (splrep/splev; not PCHIP as the paper's text says), clipped to [-1, 1],
    played from the episode's first step; after the last knot the spline goes on (splev extrapolates)."""

    name = "knots-coded"
    knots_in_time = True  # a global B-spline: every knot reaches every time
    parameters = tuple(Parameter(f"m{i}", -1.0, 1.0) for i in range(8))
    knot_times_s = np.linspace(0.0, 40.0, 8)
    signals = (8,)  # the knots: one signal

    def _signal(self, x, t):
        from scipy.interpolate import splev, splrep

        return splev(t, splrep(self.knot_times_s, x))


#: every attack family by name; a new family is a class above and a line here
FAMILY_CLASSES: dict[str, type[AttackFamily]] = {
    "constant": Constant,
    "persistent": Persistent,
    "intermittent": Intermittent,
    "sine": Sine,
    "knots": Knots,
    "spline": Spline,
    "persistent-coded": PersistentCoded,
    "intermittent-coded": IntermittentCoded,
    "knots-coded": KnotsCoded,
    "cruise": Cruise,
}
FAMILIES = tuple(FAMILY_CLASSES)
#: every family's options: the keys an [attack] table may hold besides family and params
ATTACK_OPTIONS = tuple(dict.fromkeys(k for cls in FAMILY_CLASSES.values() for k in cls.OPTIONS))


def register_family(cls: type[AttackFamily]) -> type[AttackFamily]:
    """Make a pedal family of one's own available under its ``name`` from Python (a class decorator), as
    `control.register_controller` and `messages.register_lie` do; names are never silently replaced. (d4sumo's own
    are the lines of `FAMILY_CLASSES`, which the command line offers.)"""
    if not cls.name or FAMILY_CLASSES.get(cls.name, cls) is not cls:
        raise ValueError(f"attack family {cls.name!r}: a name of its own (taken: {', '.join(FAMILY_CLASSES)})")
    FAMILY_CLASSES[cls.name] = cls
    return cls


def _family_class(name: str) -> type[AttackFamily]:
    if name not in FAMILY_CLASSES:
        raise ConfigError("attack", name, f"one of {', '.join(FAMILY_CLASSES)}")
    return FAMILY_CLASSES[name]


def resolve_attack_options(name: str, options: Mapping[str, object] | None) -> dict[str, float]:
    """Every option of family ``name``, defaults filled in, each value checked. ``options`` may hold
    other families' options too (one [attack] table for a sweep of several families): each is
    checked by the family that reads it, and left out here."""
    options = dict(options or {})
    for key, value in options.items():
        owners = [cls for cls in FAMILY_CLASSES.values() if key in cls.OPTIONS]
        if not owners:
            raise ConfigError(f"attack.{key}", value, f"an option of an attack family: {', '.join(ATTACK_OPTIONS)}")
        _, low, high, unit = owners[0].OPTIONS[key]
        check_number(f"attack.{key}", value, low, high, unit)
    return {key: check_number(f"attack.{key}", options.get(key, default), low, high, unit)
            for key, (default, low, high, unit) in _family_class(name).OPTIONS.items()}


def make_attack(name: str, options: Mapping[str, object] | None = None, **more: object) -> AttackFamily:
    """An attack family by name, with its options (a mapping, or keywords: ``delta_s=4``); options of
    other families are checked and left out."""
    return _family_class(name)(**resolve_attack_options(name, {**dict(options or {}), **more}))


def attack_signal(family: AttackFamily | None, params: Sequence[float] | None, *, steps: int, step_s: float,
                  start_step: int = 0) -> np.ndarray:
    """The attacker's command at each step's start, for an attack that begins at step ``start_step``
    (after a warm-up); NaN where the attacker cruises (before the attack, or with no attack at all)."""
    steps = check_int("steps", steps, 1, 10**9)
    check_number("step_s", step_s, 0.0, 3600.0, "s", low_open=True)
    start_step = check_int("start_step", start_step, 0, steps)
    if family is not None and not isinstance(family, AttackFamily):
        raise ConfigError("family", repr(family), "an AttackFamily (make_attack(name)), or None for no attack")
    u = np.full(steps, np.nan)
    if family is None:
        return u
    times = np.arange(steps - start_step) * step_s  # since the attack's start: exact at its first step
    u[start_step:] = family.signal(params, times)
    return u
