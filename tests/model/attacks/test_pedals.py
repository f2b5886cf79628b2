"""Attack families: every point of each box is a valid attack; PCHIP never leaves [-1, 1]."""

from __future__ import annotations

import numpy as np
import pytest

from d4sumo.errors import ConfigError
from d4sumo.model.attacks.pedals import (
    FAMILIES, FAMILY_CLASSES, Intermittent, Knots, Spline, attack_signal, make_attack)

TIMES = np.arange(1200) * 0.05


def box_points(family, rng, n=200):
    corners = np.array([family.lower, family.upper])
    return np.vstack([corners, rng.uniform(family.lower, family.upper, size=(n, family.dimension))])


@pytest.mark.parametrize("name", FAMILIES)
def test_every_point_of_the_box_is_a_valid_attack(name):
    family = make_attack(name)
    rng = np.random.default_rng(7)
    for x in box_points(family, rng):
        u = family.signal(x, TIMES)
        assert u.shape == TIMES.shape
        active = u[~np.isnan(u)]
        assert np.all((active >= -1.0) & (active <= 1.0))


def test_pchip_knots_never_overshoot_while_the_cubic_spline_would():
    rng = np.random.default_rng(3)
    pchip, spline = Knots(), Spline()
    overshoots = 0
    for x in rng.choice([-1.0, 1.0], size=(50, pchip.dimension)):
        u = pchip.signal(x, TIMES)
        assert np.all(np.abs(u) <= 1.0)
        raw = spline._signal(x, TIMES)  # before clipping
        overshoots += bool(np.any(np.abs(raw) > 1.0 + 1e-9))
        assert np.all(np.abs(spline.signal(x, TIMES)) <= 1.0)
    assert overshoots > 0  # the reason the paper picks PCHIP


def test_knots_pass_through_their_values_and_hold_after_the_horizon():
    k = Knots(delta_s=6.0, horizon_s=48.0)
    assert k.dimension == 9
    x = np.linspace(-1, 1, 9)
    assert np.allclose(k.signal(x, k.knot_times_s), x)
    assert np.all(k.signal(x, np.array([48.0, 50.0, 59.95])) == 1.0)


def test_persistent_is_a_square_wave_between_plus_and_minus_c_from_t_a():
    family = make_attack("persistent")
    u = family.signal([0.8, 0.5, 4.0], TIMES)
    assert np.all(np.isnan(u[TIMES < 4.0]))
    active = u[TIMES >= 4.0]
    assert set(np.round(active, 9)) == {0.8, -0.8}
    # period 2 s: +c for 1 s, then -c
    assert u[np.searchsorted(TIMES, 4.5)] == 0.8 and u[np.searchsorted(TIMES, 5.5)] == -0.8


def test_intermittent_windows_are_ordered_for_every_box_point():
    family = Intermittent()
    rng = np.random.default_rng(1)
    for x in box_points(family, rng):
        t1, t2, t3, t4 = family.window_times(x)
        assert t1 <= t2 <= t3 <= t4 < 60.0
    u = family.signal([2.0, 3.0, 1.0, 2.0, 1.0, -1.0], TIMES)
    assert np.isnan(u[TIMES < 2.0]).all()
    assert (u[(TIMES >= 2.0) & (TIMES <= 5.0)] == 1.0).all()
    assert (u[(TIMES >= 6.0) & (TIMES <= 8.0)] == -1.0).all()
    assert np.isnan(u[TIMES > 8.0]).all()


@pytest.mark.parametrize(
    "name, params, message",
    [
        ("knots", [0.0] * 8, "9 values"),
        ("knots", [2.0] + [0.0] * 8, "m0"),
        ("persistent", [0.5, 5.0, 1.0], "f_hz"),
        ("sine", [float("nan"), 0.1, 0.0], "amplitude"),
    ],
)
def test_bad_parameters_name_the_parameter(name, params, message):
    with pytest.raises(ConfigError, match=message):
        make_attack(name).check(params)


def test_unknown_family_lists_the_allowed_ones():
    with pytest.raises(ConfigError, match="persistent"):
        make_attack("zigzag")


@pytest.mark.parametrize("kwargs, message", [
    (dict(delta_s=0.0), r"attack.delta_s: got 0.0; allowed: a number in \[0.05, 600\] seconds"),
    (dict(horizon_s=47.0), "attack.horizon_s: got 47.0; allowed: a whole multiple of delta_s=6 s"),
    (dict(interpolation="linear"), "attack.interpolation: got 'linear'; allowed: an option of an attack family: delta_s, horizon_s"),
])
def test_bad_knot_settings(kwargs, message):
    with pytest.raises(ConfigError, match=message):
        Knots(**kwargs)


def test_a_family_owns_its_options_and_leaves_other_families_options_out():
    """One [attack] table serves a sweep of several families: each reads its own options."""
    assert make_attack("knots", {"delta_s": 4, "horizon_s": 8}).options == {"delta_s": 4.0, "horizon_s": 8.0}
    assert make_attack("knots", delta_s=4, horizon_s=8).names == ("m0", "m1", "m2")
    assert make_attack("spline").options == {"delta_s": 6.0, "horizon_s": 48.0}
    assert make_attack("persistent", {"delta_s": 4}).options == {}
    with pytest.raises(ConfigError, match="attack.delta_s: got -1"):  # checked even where not read
        make_attack("persistent", {"delta_s": -1})
    assert set(FAMILY_CLASSES) == set(FAMILIES) and all(FAMILY_CLASSES[n].name == n for n in FAMILIES)


# --- the attacks as the authors' code played them ------------------------------------------------


def test_the_coded_persistent_attack_is_sign_of_sin_of_f_t_in_rad_per_s_on_the_episodes_clock():
    """u = sign(sin(f t)) c from t_a, t since the episode's start: with f = 1 rad/s, sin(1) > 0, sin(3.5) < 0."""
    family = make_attack("persistent-coded")
    u = family.signal([0.6, 1.0, 1.0], np.array([0.0, 0.5, 1.0, 2.0, 3.5, 4.0]))
    assert np.isnan(u[:2]).all() and u[2:].tolist() == [0.6, 0.6, -0.6, -0.6]
    # t, not t - t_a: at t = 4 s with t_a = 3.5 s, sin(4) < 0 although sin(4 - 3.5) > 0
    assert family.signal([1.0, 1.0, 3.5], np.array([4.0])).tolist() == [-1.0]
    assert np.isnan(family.signal([1.0, 1.0, 0.0], np.array([0.0, 4.0]))).all()  # `elif attack_time:`: at 0, no attack
    assert family.names == ("c", "f_rad_s", "t_a_s") and family.upper.tolist() == [1.0, 10.0, 10.0]


def test_the_coded_intermittent_attack_has_whole_second_edges_and_throttles_only():
    family = make_attack("intermittent-coded")
    assert family.lower.tolist() == [10, 21, 31, 41, 0, 0] and family.upper.tolist() == [20, 30, 40, 50, 1, 1]
    # 10.4 -> 10, 21.5 -> 22 (half to even, as Python's round), 31.5 -> 32, 42.6 -> 43; the windows compare
    # the code's clock, 0.1 s added call by call: 100 additions make 9.99999999999998, 220 pass 22
    clock, running = [], 0.0
    for _ in range(500):
        clock.append(running)
        running += 0.1
    t = np.array([9.9, 10.0, 10.1, 21.9, 22.0, 30.0, 32.0, 43.0, 43.1])
    u = family.signal([10.4, 21.5, 31.5, 42.6, 0.3, 0.7], t)
    expected = [0.3 if 10 <= clock[round(x * 10)] <= 22 else 0.7 if 32 <= clock[round(x * 10)] <= 43 else None for x in t]
    assert expected == [None, None, 0.3, 0.3, None, None, 0.7, None, None]  # 430 additions pass 43
    assert [None if v != v else v for v in u.tolist()] == expected


def test_the_coded_knot_attack_is_an_interpolating_cubic_spline_through_8_knots_over_40_s():
    from scipy.interpolate import CubicSpline

    family = make_attack("knots-coded")
    assert family.dimension == 8 and np.allclose(np.diff(family.knot_times_s), 40 / 7)
    x = np.array([0.0, 0.4, -0.2, 0.5, 0.2, -0.3, 0.6, -0.5])
    assert np.allclose(family.signal(x, family.knot_times_s), x, atol=1e-12)  # through its knots
    t = np.linspace(0.0, 40.0, 81)
    # scipy's splrep/splev interpolating spline is the not-a-knot cubic spline
    assert np.allclose(family.signal(x, t), np.clip(CubicSpline(family.knot_times_s, x)(t), -1, 1), atol=1e-9)
    assert family.signal(x, np.array([80.0])).tolist() in ([-1.0], [1.0])  # extrapolated past the last knot, as splev does
    wild = np.array([0.0, 1.0, -1.0, 1.0, -1.0, 1.0, -1.0, 1.0])
    assert np.abs(family.signal(wild, t)).max() == 1.0  # its overshoot clipped, as the code clips each pedal


def test_knots_are_one_signal_and_every_other_familys_parameters_scalars():
    """The layout `auto`'s suffix moves read: a time to cut at exists only in a signal."""
    assert make_attack("knots").signals == (9,) and make_attack("spline").signals == (9,)
    assert make_attack("knots-coded").signals == (8,)
    assert make_attack("sine").signals == (1,) * make_attack("sine").dimension
    assert make_attack("intermittent").signals == (1,) * 6


@pytest.mark.parametrize("change, said", [
    ({"params": "abc"}, "attack parameters: got \"'abc'\"; allowed: 9 numbers for knots"),
    ({"params": np.zeros((3, 3))}, "allowed: 9 values for knots"),
    ({"steps": -1}, r"steps: got -1; allowed: a whole number in \[1,"),
    ({"steps": 10.5}, "steps: got 10.5"),
    ({"step_s": 0}, r"step_s: got 0; allowed: a number in \(0, 3600\] s"),
    ({"start_step": -5}, r"start_step: got -5; allowed: a whole number in \[0, 400\]"),
    ({"start_step": 500}, "start_step: got 500"),
    ({"family": "knots"}, r"family: got \"'knots'\"; allowed: an AttackFamily"),
])
def test_attack_signal_refuses_bad_arguments_naming_them(change, said):
    """Regression: these ended in numpy's own errors (negative dimensions, broadcasting), an AttributeError,
    or were taken (a start after the episode gave all NaN, a step of 0 s all zeros, 2-D parameters)."""
    args = {"family": make_attack("knots"), "params": [0.0] * 9, "steps": 400, "step_s": 0.15, "start_step": 0, **change}
    with pytest.raises(ConfigError, match=said):
        attack_signal(args.pop("family"), args.pop("params"), **args)


def test_a_pedal_family_of_ones_own_is_a_class_registered_by_its_name():
    """docs/contributing.md's route: a subclass of AttackFamily and register_family, then a campaign of it."""
    import numpy as np

    from d4sumo.model.attacks.pedals import FAMILY_CLASSES, AttackFamily, Parameter, register_family
    from d4sumo.search.campaign import Campaign

    class Ramp(AttackFamily):
        name = "ramp"
        parameters = (Parameter("a", -1.0, 1.0), Parameter("b", -1.0, 1.0))

        def _signal(self, x, t):
            return x[0] + (x[1] - x[0]) * (t - t[0]) / max(t[-1] - t[0], 1e-9)

    register_family(Ramp)
    try:
        with pytest.raises(ValueError):
            register_family(type("Other", (AttackFamily,), {"name": "knots"}))  # never silently replaced
        campaign = Campaign(attack="ramp", optimizer="random", samples=2)
        assert campaign.family().names == ("a", "b")
        u = campaign.family().signal(np.array([1.0, -1.0]), np.linspace(0.0, 10.0, 11))
        assert u[0] == 1.0 and u[-1] == -1.0
    finally:
        del FAMILY_CLASSES["ramp"]
