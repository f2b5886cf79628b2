"""The paper's specification psi, computed directly."""

from __future__ import annotations

import numpy as np
import pytest

from d4sumo.errors import ConfigError
from d4sumo.model.stepping.trace import Trace
from d4sumo.search.spec import paper_formula, psi_robustness


def trace_of(gaps):
    gaps = np.asarray(gaps, dtype=float)
    return Trace(np.arange(gaps.shape[0]) * 0.05, {f"gap_{i}": gaps[:, i] for i in range(gaps.shape[1])}, gaps.shape[1])


def test_followers_colliding_with_the_attacker_clear_is_positive():
    assert psi_robustness(trace_of([[7, 7, 7], [5, 2, 7], [4, -0.3, 6]])) == pytest.approx(0.3)


def test_no_collision_is_negative_by_the_closest_approach():
    assert psi_robustness(trace_of([[7, 7, 7], [5, 2, 7], [4, 1.5, 6]])) == pytest.approx(-1.5)


def test_an_attacker_crash_is_negative_even_when_followers_collide():
    assert psi_robustness(trace_of([[7, 7, 7], [-0.2, -1.0, 7]])) == pytest.approx(-0.2)


def test_d_safe_shifts_the_threshold():
    assert psi_robustness(trace_of([[7, 7], [5, 1.5]]), d_safe_m=2.0) == pytest.approx(0.5)


def test_psi_needs_two_followers():
    with pytest.raises(ConfigError, match="at least 2"):
        psi_robustness(trace_of([[7], [3]]))
    assert paper_formula(3) == "(eventually((gap_1 <= 0.0) or (gap_2 <= 0.0))) and (always(gap_0 > 0.0))"


# --- rtamt ---------------------------------------------------------------------------------------

import rtamt  # noqa: E402

from d4sumo.search.spec import Specification, trace_signals  # noqa: E402


def random_trace(seed, followers=3, n=400):
    rng = np.random.default_rng(seed)
    signals = {name: np.cumsum(rng.normal(0, 0.3, n)) + rng.uniform(-2, 8) for name in trace_signals(followers)}
    return Trace(np.arange(n) * 0.05, signals, followers)


@pytest.mark.parametrize("seed", range(5))
def test_rtamt_agrees_with_numpy_on_psi(seed):
    trace = random_trace(seed)
    for d_safe in (0.0, 1.5):
        spec = Specification(followers=3, step_s=0.05, d_safe_m=d_safe)
        assert spec.robustness(trace) == pytest.approx(psi_robustness(trace, d_safe), abs=1e-9)


@pytest.mark.parametrize("op", ["<=", "<", ">=", ">", "==", "!=="])
def test_our_predicate_step_gives_stock_rtamts_robustness(op):
    formula = f"always[0:3](speed_v1 {op} 0.5 * speed_v0) or eventually(gap_1 {op} gap_2 - 1)"
    trace = random_trace(11)
    ours = Specification(followers=3, step_s=0.05, formula=formula).robustness(trace)
    stock = rtamt.StlDiscreteTimeSpecification()
    for name in ("speed_v0", "speed_v1", "gap_1", "gap_2"):
        stock.declare_var(name, "float")
    stock.spec = formula
    stock.set_sampling_period(50, "ms", 0.1)
    stock.parse()
    data = {"time": trace.times_s.tolist(), **{n: trace[n].tolist() for n in ("speed_v0", "speed_v1", "gap_1", "gap_2")}}
    assert ours == stock.evaluate(data)[0][1]


def test_time_bounds_are_in_seconds():
    times = np.arange(100) * 0.05
    trace = Trace(times, {**random_trace(0, n=100).signals, "speed_v0": times.copy()}, 3)
    spec = Specification(followers=3, step_s=0.05, formula="eventually[0:1](speed_v0 >= 5)")
    assert spec.robustness(trace) == pytest.approx(1.0 - 5.0)  # speed_v0 reaches 1.0 at t = 1 s


@pytest.mark.parametrize(
    "formula, message",
    [
        ("eventually(gap_7 <= 0)", "unknown: gap_7"),
        ("eventually(lateral_v1 <= 0)", "unknown: lateral_v1"),
        ("eventually(gap_1 <= ", "rtamt can parse"),
        ("   ", "STL formula"),
    ],
)
def test_bad_formulas_are_refused_clearly(formula, message):
    with pytest.raises(ConfigError, match=message):
        Specification(followers=3, step_s=0.05, formula=formula)


@pytest.mark.parametrize(
    "formula, message",
    [  # regression: ANTLR printed a line and dropped the character, and the rest was scored (and stored)
        ("eventually(gap_2 <= 0)?", r"character 23: token recognition error at: '\?'"),
        ("\u20acalways(gap_0 > 0)", "character 1: token recognition error"),
        ("always(gap_0 > 0) # a comment", "character 19: token recognition error at: '#'"),
        ("always(gap_0 > 0\x00)", "token recognition error"),
        # regression: an OverflowError (a traceback) and rtamt's "max() arg is an empty sequence"
        ("eventually[0:1e400](gap_0 > 0)", r"within the episode of 10 s \(the bound \[0 s, more than 1e300 s\]\)"),
        ("eventually[-1:3](gap_0 > 0)", r"with 0 <= a \(the bound \[-1 s, 3 s\] starts before now\)"),
    ],
)
def test_formulas_rtamt_would_misread_are_refused_in_one_line(formula, message, capfd):
    with pytest.raises(ConfigError, match=message):
        Specification(followers=3, step_s=0.05, formula=formula, duration_s=10.0)
    assert capfd.readouterr().err == ""  # nothing of ANTLR's own


def test_nan_never_reaches_rtamt():
    trace = random_trace(1)
    trace.signals["gap_1"][5] = np.nan
    with pytest.raises(ValueError, match="NaN"):
        Specification(followers=3, step_s=0.05).robustness(trace)


@pytest.mark.sumo
def test_rtamt_agrees_with_numpy_on_sumo_traces(road):
    from conftest import ATTACKER_CRASH_KNOTS, SUCCESS_KNOTS, knots_signal

    from d4sumo.engine.simulation import simulate
    from d4sumo.model.config import EpisodeConfig

    config = EpisodeConfig()
    spec = Specification(followers=3, step_s=config.step_s)
    for knots in (SUCCESS_KNOTS, ATTACKER_CRASH_KNOTS, [0.0] * 9):
        trace = simulate(config, knots_signal(knots, config), road=road).trace
        assert spec.robustness(trace) == pytest.approx(psi_robustness(trace), abs=1e-9)


def test_a_window_restarts_the_clock_and_an_episode_that_ended_before_it_is_scored_at_its_collision():
    from d4sumo.model.stepping.trace import Trace
    from d4sumo.search.spec import Specification

    times = np.arange(6) * 0.05
    gaps = {"gap_0": np.full(6, 5.0), "gap_1": np.array([7.0, 6.0, 5.0, 4.0, 3.0, 2.0]), "gap_2": np.full(6, 7.0)}
    trace = Trace(times, gaps, followers=3)
    w = trace.window(2)
    assert np.allclose(w.times_s, [0.0, 0.05, 0.1, 0.15]) and np.array_equal(w["gap_1"], [5.0, 4.0, 3.0, 2.0])
    assert trace.window(0) is trace
    spec = Specification(followers=3, step_s=0.05, start_step=2)
    assert spec.robustness(trace) == pytest.approx(-2.0)  # the closest gap in the window, not the 7 m before it
    crashed = Trace(times[:2], {"gap_0": np.array([5.0, 5.0]), "gap_1": np.array([1.0, -0.2]), "gap_2": np.array([7.0, 7.0])}, 3)
    assert crashed.window(2) is crashed  # at least two samples (rtamt needs them)
    assert spec.robustness(crashed) == pytest.approx(0.2)  # it ended (v1-v2 collided) before the window: scored there


def test_campaigns_of_one_formula_share_one_parsed_specification_which_scores_as_a_fresh_one_from_any_thread():
    """Each parse held half a megabyte of rtamt's trees, once per campaign: the paper's nonparametric grid (156
    campaigns, one formula) held 71 MiB of them in every worker. `spec.parsed` parses once; its robustness is a
    fresh specification's, from several threads at once too (a Dask worker of several threads)."""
    import threading

    from d4sumo.model.config import EpisodeConfig
    from d4sumo.search.campaign import Campaign

    a = Campaign(config=EpisodeConfig(setpoint_m=5.0), seed=1).specification()
    b = Campaign(config=EpisodeConfig(setpoint_m=9.0, speed_mps=30.0), optimizer="ce").specification()
    assert a is b
    assert Campaign(config=EpisodeConfig(followers=4)).specification() is not a
    config = EpisodeConfig()
    fresh = Specification(followers=config.followers, step_s=config.step_s, duration_s=config.total_s)
    rng = np.random.default_rng(3)
    steps = config.steps + 1
    traces = [Trace(np.arange(steps) * config.step_s,
                    {n: rng.uniform(-2, 20, steps) for n in trace_signals(config.followers)}, config.followers)
              for _ in range(40)]
    expected = [fresh.robustness(t) for t in traces]
    got: dict[int, list[float]] = {}

    def score(k: int) -> None:
        got[k] = [a.robustness(t) for t in traces]

    import sys

    interval = sys.getswitchinterval()
    sys.setswitchinterval(1e-6)  # the threads' evaluations interleave as finely as Python lets them
    try:
        threads = [threading.Thread(target=score, args=(k,)) for k in range(4)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
    finally:
        sys.setswitchinterval(interval)
    assert all(got[k] == expected for k in range(4)) and len(set(expected)) > 10


def _stock(formula: str, names, trace) -> float:
    """Stock rtamt's robustness at t = 0 (its own predicates, no array path)."""
    stock = rtamt.StlDiscreteTimeSpecification()
    for name in names:
        stock.declare_var(name, "float")
    stock.spec = formula
    stock.set_sampling_period(50, "ms", 0.1)
    stock.parse()
    return stock.evaluate({"time": trace.times_s.tolist(), **{n: trace[n].tolist() for n in names}})[0][1]


def _random_formula(rng, names, depth=0) -> str:
    """A formula of the operators scored over whole arrays: comparisons, not, and, or, eventually, always."""
    if depth >= 3 or rng.random() < 0.3:
        a, b = rng.choice(names), rng.choice([*names, "0.0", "-0.0", "1.5", "2"])
        return f"({a} {rng.choice(['<=', '<', '>=', '>', '==', '!=='])} {b})"
    kind = rng.choice(["not", "and", "or", "eventually", "always"])
    if kind in ("and", "or"):
        return f"({_random_formula(rng, names, depth + 1)} {kind} {_random_formula(rng, names, depth + 1)})"
    return f"{kind}({_random_formula(rng, names, depth + 1)})"


@pytest.mark.parametrize("seed", range(6))
def test_formulas_scored_over_whole_arrays_give_rtamts_robustness_bit_for_bit(seed):
    """The formula's operators over whole arrays (`spec._elementwise`): rtamt's robustness to the bit, its sign of zero
    too, on signals that tie (rounded to 0.5 m, zeros of both signs among them)."""
    rng = np.random.default_rng(seed)
    names = ("gap_0", "gap_1", "gap_2")
    checked = 0
    for _ in range(40):
        n = int(rng.integers(2, 60))  # rtamt fails on one sample
        signals = {name: np.round(rng.uniform(-3, 3, n) * 2) / 2 for name in trace_signals(3)}
        for name in names:
            signals[name][rng.random(n) < 0.3] = -0.0
        trace = Trace(np.arange(n) * 0.05, signals, 3)
        formula = _random_formula(rng, names)
        spec = Specification(followers=3, step_s=0.05, formula=formula)
        assert spec._arrays is not None, formula
        ours, stock = spec.robustness(trace), _stock(formula, names, trace)
        assert np.float64(ours).tobytes() == np.float64(stock).tobytes(), (formula, ours, stock)
        checked += ours == 0.0
    assert checked, "no robustness of zero: the sign of zero is not compared"


def test_the_paper_formula_scored_over_whole_arrays_is_rtamts_on_every_follower_count():
    for followers in (2, 3, 6):
        trace = random_trace(followers, followers=followers)
        spec = Specification(followers=followers, step_s=0.05)
        assert spec._arrays is not None
        names = [f"gap_{i}" for i in range(followers)]
        assert np.float64(spec.robustness(trace)).tobytes() == np.float64(_stock(spec.formula, names, trace)).tobytes()


def test_a_time_bound_or_arithmetic_is_rtamts_alone():
    for formula in ("eventually[0:1](gap_1 <= 0)", "always(gap_1 - gap_2 > 0)", "(gap_1 <= 0) until (gap_2 <= 0)"):
        assert Specification(followers=3, step_s=0.05, formula=formula)._arrays is None, formula
