"""The attacker's specification and its robustness (SPEC section 3).

    psi = F( OR_{i=1..N-1} gap_i <= d_safe )  and  G( gap_0 > d_safe )

rho > 0: the followers came within d_safe of each other (with d_safe = 0: collided) while the attacker
stayed clear of v1 the whole time: a successful attack. The optimisers maximise rho. When the attacker
changes lanes (a cut-in or cut-out) the same meaning is said over whoever follows whom in each lane:

    psi = F( victim_gap <= d_safe )  and  G( attacker_gap > d_safe )

victim_gap: the smallest gap between two cars neither of which is the attacker; attacker_gap: the
smallest gap between the attacker and the car ahead of or behind it (see `trace`).
"""

from __future__ import annotations

import logging
import re
import threading
import types
from fractions import Fraction
from typing import Sequence

import numpy as np

from ..errors import ConfigError
from ..model.attacks.maneuvers import MANEUVERS
from ..model.stepping.trace import Trace


def paper_formula(followers: int, d_safe_m: float = 0.0) -> str:
    """psi in rtamt's syntax over the trace's gap signals."""
    _needs_pair(followers)
    pairs = " or ".join(f"(gap_{i} <= {d_safe_m!r})" for i in range(1, followers))
    return f"(eventually({pairs})) and (always(gap_0 > {d_safe_m!r}))"


def lane_formula(d_safe_m: float = 0.0) -> str:
    """psi for a lane-changing attacker, over the gaps between whoever follows whom."""
    return f"(eventually(victim_gap <= {d_safe_m!r})) and (always(attacker_gap > {d_safe_m!r}))"


def default_formula(maneuver: str, followers: int, d_safe_m: float = 0.0, traffic: bool = False) -> str:
    """psi for the maneuver: over whoever follows whom where the attacker changes lanes or traffic may come
    between the cars (a follower hitting a traffic car is a victim's crash, not the attacker's), else over
    the paper's column of gaps."""
    lanes = MANEUVERS[maneuver].lateral or traffic
    return lane_formula(d_safe_m) if lanes else paper_formula(followers, d_safe_m)


def psi_robustness(trace: Trace, d_safe_m: float = 0.0) -> float:
    """Robustness of psi at t = 0, computed directly with numpy (discrete time, the trace's samples).

    F(x <= c) scores max_t (c - x); G(x > c) scores min_t (x - c); 'or' is max, 'and' is min.
    """
    _needs_pair(trace.followers)
    gaps = trace.gaps()
    adversarial = float(np.max(d_safe_m - gaps[:, 1:]))
    attacker_safe = float(np.min(gaps[:, 0] - d_safe_m))
    return min(adversarial, attacker_safe)


def _needs_pair(followers: int) -> None:
    if followers < 2:
        raise ConfigError(
            "scenario.followers", followers, "at least 2 for the paper's specification (two followers must be able to collide), or give your own formula"
        )


def trace_signals(followers: int, maneuver: str = "inlane") -> tuple[str, ...]:
    """Every signal a trace of N followers carries in a maneuver: the variables a formula may name."""
    cars = _car_ids(followers, maneuver)
    names = [f"{kind}_{c}" for kind in ("pos", "speed", "accel", "cmd", "gap") for c in cars]
    names += ["victim_gap", "attacker_gap"]
    if MANEUVERS[maneuver].lateral:
        names += [f"y_{c}" for c in cars]
    else:  # the paper's column of cars
        names += [f"gap_{i}" for i in range(followers)]
    names += [f"mode_v{i}" for i in range(1, followers + 1)]
    return tuple(names)


def _car_ids(followers: int, maneuver: str) -> list[str]:
    other = MANEUVERS[maneuver].other_car
    return [f"v{i}" for i in range(followers + 1)] + ([other] if other else [])


class Specification:
    """An STL formula over the trace's signals, scored by rtamt (discrete time, sampled at the step).

    The formula is parsed once; ``robustness(trace)`` evaluates it at t = 0 of the window that starts at
    ``start_step`` (the attack's start after a warm-up: the warm-up drive is not the attack's doing, and
    its first instant, every gap at the setpoint, would otherwise bound the paper's psi for every attack).
    Without a formula it is the paper's psi with ``d_safe_m``. Time bounds in a formula are in seconds,
    ``duration_s`` the window's length.
    """

    def __init__(self, *, followers: int, step_s: float, formula: str | None = None, d_safe_m: float = 0.0,
                 duration_s: float | None = None, start_step: int = 0, maneuver: str = "inlane", traffic: bool = False):
        import rtamt

        self.followers = followers
        self.start_step = start_step
        self.d_safe_m = d_safe_m
        self.formula = formula if formula is not None else default_formula(maneuver, followers, d_safe_m, traffic)
        if not isinstance(self.formula, str) or not self.formula.strip():
            raise ConfigError("spec.formula", formula, "an STL formula in rtamt syntax, e.g. eventually(gap_v2 <= 0)")
        declared = trace_signals(followers, maneuver)
        self._help = _signal_help(followers, maneuver)
        spec = rtamt.StlDiscreteTimeSpecification()
        for name in declared:
            spec.declare_var(name, "float")
        spec.spec = self.formula
        spec.set_sampling_period(round(step_s * 1000.0, 6), "ms", 0.1)
        unknown = _unknown_identifiers(self.formula, declared)
        lexed = _lexer_errors(spec, self.formula)
        if lexed:  # ANTLR's lexer prints these and drops the characters: the formula scored would not be the one given
            raise ConfigError("spec.formula", self.formula, f"an STL formula rtamt can parse ({lexed[0]})")
        try:
            with _quiet_rtamt():
                spec.parse()
        except KeyError as exc:  # rtamt's way of meeting an undeclared variable
            raise ConfigError("spec.formula", self.formula, f"signals among {self._help} (unknown: {exc.args[0]})") from None
        except Exception as exc:  # rtamt raises RTAMTException or ANTLR errors
            raise ConfigError("spec.formula", self.formula, f"an STL formula rtamt can parse ({str(exc).splitlines()[0].split(' expecting')[0][:200]})") from None
        implicit = set(spec.ast.var_object_dict) - set(declared) - {"out"}
        if implicit or unknown:
            raise ConfigError("spec.formula", self.formula, f"signals among {self._help} (unknown: {', '.join(sorted(implicit | unknown))})")
        _check_time_bounds(spec.ast, self.formula, step_s, duration_s)
        self.variables = tuple(n for n in declared if re.search(rf"\b{n}\b", self.formula))
        _speed_up_predicates(spec.offline_interpreter)
        #: the formula over whole arrays where every operator of it is one rtamt evaluates sample by sample (`_elementwise`)
        self._arrays = _elementwise(spec.ast.specs[0]) if len(spec.ast.specs) == 1 else None
        self._spec = spec
        self._lock = threading.Lock()  # one specification may serve the campaigns of several threads (`parsed`)
        if duration_s is not None:  # a formula that passes the checks never fails at evaluation
            samples = start_step + int(round(duration_s / step_s)) + 1
            trial = Trace(np.arange(samples) * step_s, {n: np.zeros(samples) for n in declared}, followers)
            try:
                value = self.robustness(trial)
            except Exception as exc:
                raise ConfigError("spec.formula", self.formula, f"an STL formula rtamt can evaluate ({type(exc).__name__}: {exc})") from None
            if value != value:
                raise ConfigError("spec.formula", self.formula, "an STL formula with a defined robustness (it gave NaN)")

    def robustness(self, trace: Trace) -> float:
        """The robustness at ``start_step`` (the attack's start; 0 unless scored after a warm-up), the
        window's own t = 0. An episode never ends before it: a collision in the warm-up is no episode
        (`errors.WarmupCollision`)."""
        trace = trace.window(self.start_step)
        signals = {}
        for name in self.variables:
            values = trace.signals.get(name)
            if values is None:
                raise ConfigError("spec.formula", self.formula, f"signals this trace has (it has no {name})")
            if not np.all(np.isfinite(values)):  # rtamt gives wrong robustness on NaN
                raise ValueError(f"signal {name} has NaN or infinite values: not scored")
            signals[name] = values
        if self._arrays is not None:
            rho = self._arrays(np.asarray(trace.times_s).size, {n: np.asarray(v, dtype=float) for n, v in signals.items()})
            if rho is not None:
                return float(rho[0])
        data = {"time": trace.times_s.tolist(), **{n: v.tolist() for n, v in signals.items()}}
        with self._lock:
            return float(self._spec.evaluate(data)[0][1])


_PARSED: dict[tuple, Specification] = {}


def parsed(**settings) -> Specification:
    """The `Specification` of these settings, parsed once in a process: a sweep's campaigns mostly share one, and
    each parse holds half a megabyte of rtamt's trees (the 156 campaigns of the paper's nonparametric grid held
    71 MiB of them in every worker). Its robustness is what a fresh one gives: each evaluation starts afresh."""
    key = tuple(sorted(settings.items()))
    spec = _PARSED.get(key)
    if spec is None:
        if len(_PARSED) >= 64:
            _PARSED.clear()
        spec = _PARSED[key] = Specification(**settings)
    return spec


_UNIT_S = {"": Fraction(1), "s": Fraction(1), "ms": Fraction(1, 1000), "us": Fraction(1, 10**6), "ns": Fraction(1, 10**9)}


def _check_time_bounds(ast, formula: str, step_s: float, duration_s: float | None) -> None:
    """Every time bound [a:b] of the formula: ordered, on the step grid, within the episode."""
    step = Fraction(step_s).limit_denominator(10**6)
    stack = list(getattr(ast, "specs", [ast]))
    while stack:
        node = stack.pop()
        stack.extend(getattr(node, "children", []))
        if not hasattr(node, "begin"):
            continue
        begin = Fraction(node.begin) * _UNIT_S.get(getattr(node, "begin_unit", ""), Fraction(1))
        end = Fraction(node.end) * _UNIT_S.get(getattr(node, "end_unit", ""), Fraction(1))
        where = f"bound [{_seconds(begin)}, {_seconds(end)}]"
        if begin < 0:
            raise ConfigError("spec.formula", formula, f"time bounds [a:b] with 0 <= a (the {where} starts before now)")
        if begin > end:
            raise ConfigError("spec.formula", formula, f"time bounds [a:b] with a <= b (the {where} is reversed)")
        if begin % step or end % step:
            raise ConfigError("spec.formula", formula, f"time bounds on the step grid, multiples of {step_s:g} s (the {where})")
        if duration_s is not None and end > Fraction(duration_s).limit_denominator(10**6):
            raise ConfigError("spec.formula", formula, f"time bounds within the episode of {duration_s:g} s (the {where})")


def _seconds(t: Fraction) -> str:
    """A bound for a message: rtamt reads 1e400 exactly, past what a float holds."""
    return f"{float(t):g} s" if abs(t) < 10**300 else "more than 1e300 s" if t > 0 else "less than -1e300 s"


def _lexer_errors(spec, formula: str) -> list[str]:
    """What rtamt's own lexer cannot read in ``formula``: ANTLR's token recognition errors."""
    from antlr4 import InputStream
    from antlr4.error.ErrorListener import ErrorListener

    class Collect(ErrorListener):
        def __init__(self):
            self.errors: list[str] = []

        def syntaxError(self, recognizer, offending, line, column, msg, e):
            self.errors.append(f"character {column + 1}: {msg}")

    lexer = spec.ast.antrlLexerType(InputStream(formula))
    lexer.removeErrorListeners()
    lexer.addErrorListener(collect := Collect())
    lexer.getAllTokens()
    return collect.errors


def _signal_help(followers: int, maneuver: str) -> str:
    cars = _car_ids(followers, maneuver)
    lateral = MANEUVERS[maneuver].lateral
    per_car = f"pos_X, speed_X, accel_X, cmd_X, gap_X{', y_X' if lateral else ''} (X = {', '.join(cars)})"
    column = "" if lateral else f", gap_I (I = 0..{followers - 1})"
    return f"{per_car}, victim_gap, attacker_gap{column}, mode_vI (I = 1..{followers})"


_KEYWORDS = {
    "and", "or", "not", "implies", "iff", "xor", "eventually", "always", "until", "since", "once",
    "historically", "precedes", "next", "prev", "rise", "fall", "abs", "sqrt", "exp", "pow", "true",
    "false", "F", "G", "U", "S", "O", "H", "X", "Y", "s", "ms", "us", "ns", "unless", "out",
}


def _unknown_identifiers(formula: str, declared: Sequence[str]) -> set[str]:
    words = set(re.findall(r"\b[A-Za-z_][A-Za-z0-9_]*\b", formula))
    return {w for w in words if w not in _KEYWORDS and w not in declared and not re.fullmatch(r"[eE]\d*", w)}


class _quiet_rtamt:
    """rtamt logs through the root logger when it meets an undeclared variable; we report it ourselves."""

    def __enter__(self):
        self._level = logging.root.level
        logging.root.setLevel(logging.ERROR)

    def __exit__(self, *exc):
        logging.root.setLevel(self._level)


def _elementwise(root):
    """The formula as one function of whole arrays, ``f(samples, signals)`` -> its robustness at every sample (None where a
    value is NaN: rtamt then scores it), where every operator of it is one rtamt's offline interpreter evaluates sample by
    sample in Python: signals, constants, comparisons, not, and, or, and eventually and always without time bounds. Each
    does what rtamt's does on the same doubles, ties included (its min(a, b) is b < a ? b : a, its max b > a ? b : a, and
    a running max or min keeps the earliest of equal values: -0.0 and 0.0 stay apart), so the robustness is rtamt's, bit
    for bit (tests/search/test_spec.py holds it over random formulas and traces), at a tenth of its cost. Any other
    operator (a time bound, arithmetic, until): None, and rtamt scores the formula."""
    from rtamt.semantics.enumerations.comp_oper import StlComparisonOperator as Op
    from rtamt.syntax.node.ltl.always import Always
    from rtamt.syntax.node.ltl.conjunction import Conjunction
    from rtamt.syntax.node.ltl.constant import Constant
    from rtamt.syntax.node.ltl.disjunction import Disjunction
    from rtamt.syntax.node.ltl.eventually import Eventually
    from rtamt.syntax.node.ltl.neg import Neg
    from rtamt.syntax.node.ltl.predicate import Predicate
    from rtamt.syntax.node.ltl.variable import Variable

    class NaNMet(Exception):
        """A NaN (inf - inf) where rtamt's running max or min would carry it otherwise than numpy's."""

    def running(x: np.ndarray, later: np.ndarray) -> np.ndarray:
        """rtamt's backward running max or min (``later``: each value over its suffix), the earliest equal value kept."""
        if np.isnan(later[0]):
            raise NaNMet
        at = np.where(x == later, np.arange(x.size), x.size)
        return x[np.minimum.accumulate(at[::-1])[::-1]]

    def made(node):
        kind = type(node)
        if kind is Variable and not node.field:
            name = node.var
            return lambda n, s: s[name]
        if kind is Constant and type(node.val) in (int, float) and abs(node.val) < 2 ** 53:
            value = float(node.val)
            return lambda n, s: np.full(n, value)
        if kind is Neg:
            child = made(node.children[0])
            return child and (lambda n, s: -child(n, s))
        if kind in (Eventually, Always):
            child = made(node.children[0])
            if child is None:
                return None
            if kind is Eventually:
                return lambda n, s: running(x := child(n, s), np.maximum.accumulate(x[::-1])[::-1])
            return lambda n, s: running(x := child(n, s), np.minimum.accumulate(x[::-1])[::-1])
        if kind in (Predicate, Conjunction, Disjunction):
            left, right = made(node.children[0]), made(node.children[1])
            if left is None or right is None:
                return None
            if kind is Conjunction:
                return lambda n, s: np.where((r := right(n, s)) < (l := left(n, s)), r, l)
            if kind is Disjunction:
                return lambda n, s: np.where((r := right(n, s)) > (l := left(n, s)), r, l)
            op = node.operator.value
            if op in (Op.LEQ.value, Op.LESS.value):
                return lambda n, s: right(n, s) - left(n, s)
            if op in (Op.GEQ.value, Op.GREATER.value):
                return lambda n, s: left(n, s) - right(n, s)
            if op == Op.EQ.value:
                return lambda n, s: -np.abs(left(n, s) - right(n, s))
            if op == Op.NEQ.value:
                return lambda n, s: np.abs(left(n, s) - right(n, s))
        return None

    formula = made(root)
    if formula is None:
        return None

    def robustness(samples: int, signals: dict) -> np.ndarray | None:
        try:
            rho = formula(samples, signals)
        except NaNMet:
            return None
        return None if np.isnan(rho).any() else rho
    return robustness


def _speed_up_predicates(interpreter) -> None:
    """Evaluate rtamt's comparison predicates with the same arithmetic, minus a per-sample Enum lookup.

    rtamt 0.4's offline visitPredicate reads ``node.operator.value`` up to four times per sample; on
    our 1200-sample traces that is ~90% of its evaluation time. The replacement decides the operator
    once per node, then runs the identical expressions (tests compare it with stock rtamt).
    """
    from rtamt.semantics.enumerations.comp_oper import StlComparisonOperator as Op

    def visit_predicate(self, node, *args, **kwargs):
        left = self.visit(node.children[0], *args, **kwargs)
        right = self.visit(node.children[1], *args, **kwargs)
        op = node.operator.value
        if op == Op.EQ.value:
            return [-abs(a - b) for a, b in zip(left, right)]
        if op == Op.NEQ.value:
            return [abs(a - b) for a, b in zip(left, right)]
        if op in (Op.LEQ.value, Op.LESS.value):
            return [b - a for a, b in zip(left, right)]
        if op in (Op.GEQ.value, Op.GREATER.value):
            return [a - b for a, b in zip(left, right)]
        return type(self).visitPredicate(self, node, *args, **kwargs)  # unknown: rtamt's own error

    interpreter.visitPredicate = types.MethodType(visit_predicate, interpreter)
