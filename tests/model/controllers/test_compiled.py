"""A platoon's followers stepped in C against the Python they stand for: pure code, no SUMO."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from d4sumo.engine.ballistic import integrate
from d4sumo.model.controllers import compiled
from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.model.controllers.control import AS_RUN_DEFAULTS, PathCACC
from d4sumo.model.attacks.maneuvers import maneuver_of
from d4sumo.model.attacks.messages import BeaconFalsifier
from d4sumo.model.controllers.commands import ControllerError
from d4sumo.model.stepping.platoon import Platoon
from d4sumo.model.world.sensing import RadarParams
from d4sumo.model.world.v2v import ChannelParams

# mixed: switching and cooperative followers in one platoon; as-run: the paper's controller (or its time-gap variant)
# with the authors' code's options drawn (`SwitchingParams`), their attacker with it
LAWS = ("switching", "timegap", "idm", "cacc", "ploeg", "consensus", "mixed", "as-run")
COOPERATIVE = ("cacc", "ploeg", "consensus")
LIES = (("offset", {"msg_value": -4.0}), ("scaling", {"msg_factor": 1.5}), ("sinusoid", {"msg_amplitude": 3.0, "msg_frequency_hz": 0.5}),
        ("jam", {"msg_duration_s": 3.0}), ("delay", {"msg_delay_s": 1.0}), ("replay", {"msg_window_s": 2.0}), ("knots", {}))


@pytest.fixture
def python_only(monkeypatch):
    """Within it, every platoon is the Python's."""
    def off():
        monkeypatch.setattr(compiled, "ENABLED", False)
    return off


def test_the_extension_is_built_with_the_package():
    assert compiled.Followers is not None, (
        "d4sumo.model.controllers._followers was not built: install d4sumo with a C compiler (pip install -e .)")


def _config(rng: np.random.Generator, law: str, tight: bool = False, imperfect: bool = False) -> EpisodeConfig:
    """A platoon of one law with random cars, spacing, speed, step and beacon interval (``tight``: spaced
    closely behind an attacker that brakes harder than any follower; ``imperfect``: now and then a radar with
    a range, noise and latency, a late and lossy channel, the mitigation)."""
    followers = int(rng.integers(1, 7))
    step = float(rng.choice([0.05, 0.1]))
    vehicles = {f"v{i}": {"length_m": float(rng.uniform(3.0, 16.0)), "actuator_lag_s": float(rng.choice([0.0, 0.3, 0.5])),
                          "coast_decel_mps2": float(rng.choice([0.0, 0.4])), "max_decel_mps2": float(rng.uniform(4.0, 8.0))}
                for i in range(followers + 1) if rng.random() < 0.7}
    if tight:
        vehicles["v0"] = {**vehicles.get("v0", {}), "max_decel_mps2": 9.5}
    headway = float(rng.uniform(0.1, 0.3) if tight else rng.uniform(0.3, 1.2))
    switching = (("acc_kp", float(rng.uniform(0.3, 1.5))), ("acc_kv", float(rng.uniform(0.5, 3.0))),
                 ("eps_x_m", float(rng.choice([1.0, 0.5, 3.0]))), ("eps_v_mps", float(rng.choice([1.0, 0.2]))),
                 ("cruise_kp", float(rng.uniform(0.1, 1.0))), ("cruise_integral_clamp", float(rng.choice([20.0, 2.0]))))
    params = {"cacc": (("c1", float(rng.uniform(0.2, 0.8))),), "ploeg": (("h_s", headway),), "consensus": (("h_s", headway),),
              "switching": switching if rng.random() < 0.7 else (),
              "timegap": switching + (("time_gap_s", float(rng.choice([0.0, 0.5, 1.5]))),),
              "idm": (("time_gap_s", headway), ("accel_mps2", float(rng.uniform(0.5, 3.0))),
                      ("comfortable_decel_mps2", float(rng.uniform(1.0, 4.0))), ("delta", float(rng.choice([4.0, 2.5, 1.0]))))}
    if imperfect and rng.random() < 0.5:  # the cooperative laws' mitigation
        mitigation = (("fallback_mps", float(rng.uniform(0.5, 3.0))), ("fallback_headway_s", float(rng.uniform(0.8, 1.5))))
        params.update({kind: params[kind] + mitigation for kind in COOPERATIVE})
    if law == "as-run":  # the authors' code's options, each drawn (the time-gap variant takes them too)
        period = float(rng.choice([0.0, step, 0.1, 0.2, 0.3]))
        options = (("switching_rule", str(rng.choice(["eq1", "code"]))), ("cruise_pid", str(rng.choice(["d4sumo", "code"]))),
                   ("low_level", str(rng.choice(["exact", "pid"]))), ("control_period_s", period),
                   ("first_command_zero", bool(rng.random() < 0.5)))
        chosen = dict(options)
        if chosen["switching_rule"] == "code":
            options += (("engage_margin_m", float(rng.uniform(5.0, 30.0))), ("release_margin_m", float(rng.uniform(1.0, 15.0))))
        if chosen["cruise_pid"] == "code":
            options += (("cruise_filter_s", float(rng.choice([0.0, 0.5, 1.0]))),)
        if chosen["low_level"] == "pid":
            options += (("low_kp", float(rng.uniform(0.05, 0.3))), ("low_ki", float(rng.uniform(0.05, 0.4))),
                        ("low_kd", float(rng.uniform(0.0, 0.01))), ("low_integral_init", float(rng.choice([0.0, 5.0]))),
                        ("low_integral_clamp", float(rng.choice([10.0, 2.0]))))
        if not any(value != AS_RUN_DEFAULTS[key] for key, value in options):
            options += (("first_command_zero", True),)
        kind = str(rng.choice(["switching", "timegap"]))
        controller = ControllerConfig(kind, switching + options + (params["timegap"][-1:] if kind == "timegap" else ()))
    elif law == "mixed":  # each follower its own: the paper's, or a cooperative law reading the beacons
        kinds = [str(rng.choice(("switching", "timegap") + COOPERATIVE)) for _ in range(followers)]
        kinds[0] = "cacc"  # somebody listens: the platoon has its channel
        rng.shuffle(kinds)
        controller = tuple(ControllerConfig(kind, params[kind]) for kind in kinds)
    else:
        controller = ControllerConfig(law, params[law])
    radar, channel = None, {"beacon_interval_s": float(rng.choice([step, 0.1, 0.2, 0.5]))}
    if imperfect:
        if rng.random() < 0.5:
            radar = RadarParams(range_m=float(rng.choice([math.inf, 40.0, 150.0])), gap_noise_m=float(rng.choice([0.0, 0.5])),
                                speed_noise_mps=float(rng.choice([0.0, 0.3])), latency_s=float(rng.choice([0.0, 2 * step])),
                                seed=int(rng.integers(0, 100)))
        if rng.random() < 0.5:
            channel.update(latency_s=float(rng.choice([0.0, 3 * step])), loss=float(rng.choice([0.0, 0.3])), seed=int(rng.integers(0, 100)))
    setpoint = float((rng.uniform(6.0, 30.0) if law in ("switching", "timegap", "as-run") else rng.uniform(2.0, 5.0)) if tight else rng.uniform(3.0, 25.0))
    return EpisodeConfig(followers=followers, setpoint_m=setpoint, speed_mps=float(rng.uniform(15.0, 33.0)),
                         start=str(rng.choice(["rest", "steady"])), step_s=step, duration_s=20.0, vehicles=vehicles,
                         controller=controller, radar=radar,
                         v2v=None if law in ("switching", "timegap", "idm", "as-run") else ChannelParams(**channel))


def _liars(rng: np.random.Generator, config: EpisodeConfig) -> tuple:
    """Two alike falsifiers of one car's beacons (the attacker's, or an insider's), or none (a lie keeps what it was told)."""
    if rng.random() < 0.4:
        return None, None
    kind, values = LIES[int(rng.integers(len(LIES)))]
    field = str(rng.choice(["accel", "speed", "position"]))
    sender = int(rng.integers(0, config.followers))
    accel = rng.uniform(-8.0, 4.0, config.steps) if kind == "knots" else None
    values = {"msg_start_s": float(rng.uniform(0.0, 3.0)), **values}
    return tuple(BeaconFalsifier(kind, field, values, config.step_s, config.attack_start_step, accel, sender) for _ in range(2))


@pytest.mark.parametrize("law", LAWS)
def test_the_compiled_followers_command_what_the_python_does_bit_for_bit_whatever_they_sense_and_hear(law, python_only):
    rng = np.random.default_rng(LAWS.index(law))
    for _ in range(40):
        config = _config(rng, law, imperfect=True)
        attack = np.where(rng.random(config.steps) < 0.4, np.nan, rng.uniform(-1.0, 1.0, config.steps))
        lie, told = _liars(rng, config) if config.v2v is not None else (None, None)
        fast = Platoon(config, attack, 40.0, beacons=lie)
        assert fast._compiled is not None and fast._attacker_in_c  # the attacker in C too
        python_only()
        python = Platoon(config, attack, 40.0, beacons=told)
        compiled.ENABLED = True
        assert python._compiled is None
        pairs_at = maneuver_of(config).pairs
        n = config.followers + 1
        x = list(np.cumsum(rng.uniform(5.0, 40.0, n))[::-1] + 100.0)
        for k in range(200):
            # what the world senses, anything it may: a car far ahead (no leader: cruise), standing, over its limit
            x = [xi + float(rng.uniform(0.0, 3.0)) for xi in x]
            if rng.random() < 0.05:
                x[0] += 2000.0
            v = [float(rng.choice([0.0, rng.uniform(0.0, 40.0)], p=[0.05, 0.95])) for _ in range(n)]
            pairs = pairs_at(x)
            assert fast.advance(k, x, v, pairs) == python.advance(k, x, v, pairs)
        assert fast.commands == python.commands
        assert fast.modes == python.modes
        assert len(fast.modes) == (200 if law in ("switching", "timegap", "as-run") else len(fast.modes))  # every step's modes compared
        if config.v2v is not None:
            assert fast.channel.sent == python.channel.sent


@pytest.mark.parametrize("law", LAWS)
def test_an_episode_with_compiled_followers_is_the_python_episode_bit_for_bit_crash_included(law, python_only):
    rng = np.random.default_rng(7 + LAWS.index(law))
    crashes = 0
    for _ in range(16):
        config = _config(rng, law, tight=True, imperfect=True)
        period = int(rng.integers(2, 6)) * int(round(1.0 / config.step_s))  # full throttle, full brake, each for 2 to 5 s
        attack = np.tile(np.r_[np.ones(period), -np.ones(period)], config.steps)[:config.steps]
        attack[:config.attack_start_step] = np.nan
        fast = integrate(config, attack)
        python_only()
        python = integrate(config, attack)
        compiled.ENABLED = True
        assert fast.collisions == python.collisions
        assert fast.min_gaps == python.min_gaps
        assert fast.trace.signals.keys() == python.trace.signals.keys()
        for name, values in python.trace.signals.items():
            np.testing.assert_array_equal(fast.trace.signals[name], values, err_msg=name)
        crashes += bool(python.collisions)
    assert 3 <= crashes < 16, f"{crashes} of 16 attacks crash the platoon: the collision record is barely compared"


def test_a_follower_command_that_is_no_number_gets_the_python_error(python_only):
    config = EpisodeConfig(followers=2, controller=ControllerConfig("cacc"), start="steady")
    attack = np.full(config.steps, np.nan)
    x, v = [100.0, 80.0, 60.0], [25.0, math.nan, 25.0]
    errors = []
    for in_c in (True, False):
        if not in_c:
            python_only()
        platoon = Platoon(config, attack, 40.0)
        assert (platoon._compiled is not None) == in_c
        with pytest.raises(ControllerError) as error:
            platoon.advance(0, x, v, maneuver_of(config).pairs(x))
        errors.append(str(error.value))
    assert errors[0] == errors[1] == "the controller of v1 returned nan at step 0; allowed: a command in [-1, 1]"


class _OwnCACC(PathCACC):
    """A user's subclass: it may change anything, so the Python plays it."""


@pytest.mark.parametrize("change", [
    {"controller": (ControllerConfig("cacc"), ControllerConfig("sumo:ACC"))},
    {"maneuver": "cutin"},  # a lane change with a channel: the Python's
])
def test_the_python_plays_what_the_compiled_followers_do_not(change):
    config = EpisodeConfig(followers=2, **{"controller": ControllerConfig("cacc"), **change})
    assert Platoon(config, np.full(config.steps, np.nan), 40.0)._compiled is None
    for plain in (ControllerConfig("cacc"), ControllerConfig("switching"), ControllerConfig("timegap"), ControllerConfig("idm"),
                  ControllerConfig("switching", (("switching_rule", "code"),)),  # the authors' code's options
                  ControllerConfig("timegap", (("control_period_s", 0.1), ("low_level", "pid"))),
                  (ControllerConfig("cacc"), ControllerConfig("switching")), (ControllerConfig("cacc"), ControllerConfig("idm"))):
        config = EpisodeConfig(followers=2, controller=plain)
        assert Platoon(config, np.full(config.steps, np.nan), 40.0)._compiled is not None
    config = EpisodeConfig(followers=2, controller=ControllerConfig("switching"))
    lit = Platoon(config, np.full(config.steps, np.nan), 40.0, lights=True)
    assert lit._compiled is not None and lit._attacker_in_c  # the attacker obeys its lights in C too
    config = EpisodeConfig(followers=2, controller=ControllerConfig("switching"), maneuver="cutout")  # no channel: in C
    assert Platoon(config, np.full(config.steps, np.nan), 40.0)._compiled is not None


@pytest.mark.parametrize("signals", ("obey", "attacker_runs_red"))
def test_followers_at_traffic_lights_are_capped_in_c_as_their_drivers_cap_the_python(signals, python_only):
    """On a route through traffic lights each car's command is the lesser of its controller's and what its signal
    allows (`signals.SignalDriver`): in C the Python's drivers give each step's caps, and the C takes the lesser (the
    attacker's too, where it obeys them)."""
    from d4sumo.model.world.signals import Stop

    rng = np.random.default_rng(7 if signals == "obey" else 8)
    for _ in range(20):
        config = dataclasses.replace(_config(rng, str(rng.choice(["switching", "idm", "as-run"]))), signals=signals)
        attack = np.where(rng.random(config.steps) < 0.4, np.nan, rng.uniform(-1.0, 1.0, config.steps))
        fast = Platoon(config, attack, 40.0, lights=True)
        assert fast._compiled is not None
        python_only()
        python = Platoon(config, attack, 40.0, lights=True)
        compiled.ENABLED = True
        assert python._compiled is None
        n = config.followers + 1
        pairs_at = maneuver_of(config).pairs
        x = list(np.cumsum(rng.uniform(5.0, 40.0, n))[::-1] + 100.0)
        for k in range(150):
            x = [xi + float(rng.uniform(0.0, 2.0)) for xi in x]
            v = [float(rng.uniform(0.0, 30.0)) for _ in range(n)]
            stops = None if rng.random() < 0.2 else [
                None if rng.random() < 0.3 else Stop(int(rng.integers(0, 3)), float(rng.uniform(-2.0, 80.0)), str(rng.choice(list("GgyYrRuO"))))
                for _ in range(n)]
            fast.stops = python.stops = stops
            assert fast.advance(k, x, v, pairs_at(x)) == python.advance(k, x, v, pairs_at(x))
        assert fast.commands == python.commands and fast.modes == python.modes and fast.lights == python.lights
        assert any(c < -0.5 for row in fast.commands for c in row[1:])  # the caps brake now and then


@pytest.mark.parametrize("law", ("switching", "timegap", "idm", "as-run"))
def test_followers_out_of_the_column_follow_the_nearest_car_ahead_in_c_as_in_the_python(law, python_only):
    """A lane change or traffic: each follower follows the nearest car the step's pairs put ahead of it (the first of
    equal gaps), a traffic car (an index past the platoon's) included, or nobody (a free road at its own speed); among
    traffic the attacker, between attacks, is a careful driver behind what is ahead of it, in C too."""
    rng = np.random.default_rng(90 + LAWS.index(law))
    for _ in range(30):
        config = _config(rng, law, imperfect=True)
        if rng.random() < 0.5:  # among traffic: the attacker a careful driver between attacks, in C too
            config = dataclasses.replace(config, start="steady", traffic={"vehicles_per_hour": 600.0, "warmup_s": 30.0})
        else:
            config = dataclasses.replace(config, maneuver=str(rng.choice(["cutin", "cutout", "swerve"])))
        attack = np.where(rng.random(config.steps) < 0.4, np.nan, rng.uniform(-1.0, 1.0, config.steps))
        attack[:int(rng.integers(0, 60))] = np.nan  # cruising a while, behind whatever is ahead
        fast = Platoon(config, attack, 40.0)
        assert fast._compiled is not None
        assert fast._attacker_in_c or config.traffic is None or fast._attacker_as_run is not None  # (as run among traffic: Python)
        python_only()
        python = Platoon(config, attack, 40.0)
        compiled.ENABLED = True
        assert python._compiled is None
        n = len(config.vehicle_ids)  # the platoon and the maneuver's other car; then traffic cars, as sensed
        for k in range(150):
            m = n + int(rng.integers(0, 4))
            x = list(np.sort(rng.uniform(0.0, 300.0, m))[::-1])
            v = [float(rng.uniform(0.0, 40.0)) for _ in range(m)]
            pairs = [(int(rng.integers(0, m)), int(rng.integers(0, m)), float(rng.choice([4.0, rng.uniform(-1.0, 80.0)])))
                     for _ in range(int(rng.integers(0, 2 * n)))]
            assert fast.advance(k, x[:n], v, pairs) == python.advance(k, x[:n], v, pairs)
        assert fast.commands == python.commands
        assert fast.modes == python.modes


def test_the_python_plays_a_user_subclass():
    config = EpisodeConfig(followers=2, controller=ControllerConfig("cacc"))
    platoon = Platoon(config, np.full(config.steps, np.nan), 40.0)
    assert compiled.compiled_followers(platoon) is not None
    own = platoon.followers[1].controller
    own.__class__ = _OwnCACC  # a user's subclass may change anything: the law is looked up by the exact class
    assert compiled.compiled_followers(platoon) is None


def test_what_the_python_would_compute_otherwise_is_the_python_s():
    """Found by review: numpy float32 parameters (the Python computes part of the law in float32) and a lie
    of one's own (it may rename its sender) are played by the Python."""
    config = EpisodeConfig(followers=2, controller=ControllerConfig("ploeg", (("h_s", np.float32(0.7)),)))
    assert Platoon(config, np.full(config.steps, np.nan), 40.0)._compiled is None

    class OwnLie(BeaconFalsifier):
        pass

    config = EpisodeConfig(followers=2, controller=ControllerConfig("cacc"))
    own = OwnLie("offset", "speed", {"msg_start_s": 1.0, "msg_value": 3.0}, config.step_s, 0)
    assert Platoon(config, np.full(config.steps, np.nan), 40.0, beacons=own)._compiled is None


def test_the_extension_refuses_what_it_cannot_play_exactly_and_is_collected_in_a_cycle():
    """Found by review: an object never made crashed on its first step; a float32 position is refused, not
    computed in double where the Python computes in float32; a lie that refers back to it was never freed."""
    import gc

    with pytest.raises(RuntimeError):
        compiled.Followers.__new__(compiled.Followers).advance(0, [], [], [], [], [], [])
    config = EpisodeConfig(followers=1, controller=ControllerConfig("cacc"))
    platoon = Platoon(config, np.full(config.steps, np.nan), 40.0)
    with pytest.raises(TypeError, match="positions: a float"):
        platoon._compiled(0, [np.float32(50.0), np.float32(40.0)], [25.0, 25.0], [(0, 1, 5.5)], [], [], [])
    freed = []

    class Lie:
        def __call__(self, k, message):
            return message

        def __del__(self):
            freed.append(True)

    lie = Lie()
    from d4sumo.model.controllers.commands import checked_command
    from d4sumo.model.world.v2v import Message

    law = (1, False, (5.0, 25.0, 0.05, 3.5, 8.0), (0.5, 0.5, -0.1, -0.2, -0.04), 0.0, (0.0, 0.0), (3.5, 8.0, 0.1, 0.05, math.inf, 0.0, 0.0), None)
    lie.followers = compiled.Followers((0.05, 2, 0, 0.0), [4.5, 4.5], [(0,)], [], (lie, 0, Message, []), [law], checked_command)
    lie.followers.advance(0, [50.0, 40.0], [25.0, 25.0], [(0, 1, 5.5)], [], [], [])
    del lie
    gc.collect()
    assert freed == [True]


def test_an_attacker_whose_top_speed_is_a_float32_is_the_pythons(python_only):
    """Found by review: a numpy float32 attacker_max_speed_mps (the Python API) made the Python's clamped actuator
    compute in float32, the C in double: such an attacker stays the Python's, its commands and speeds the same."""
    config = EpisodeConfig(followers=2, controller=ControllerConfig("switching"), start="steady")
    attack = np.r_[np.full(20, np.nan), np.ones(config.steps - 20)]
    assert Platoon(config, attack, 26.0)._attacker_in_c
    fast = Platoon(config, attack, np.float32(26.0))
    assert fast._compiled is not None and not fast._attacker_in_c
    python_only()
    python = Platoon(config, attack, np.float32(26.0))
    compiled.ENABLED = True
    pairs_at = maneuver_of(config).pairs
    x, v = [100.0, 88.0, 76.0], [25.0, 25.0, 25.0]
    for k in range(200):
        new = fast.advance(k, x, v, pairs_at(x))
        assert [float(s) for s in new] == [float(s) for s in python.advance(k, x, v, pairs_at(x))]
        v = [float(s) for s in new]
        x = [xi + vi * config.step_s for xi, vi in zip(x, v)]
    assert v[0] == pytest.approx(26.0)  # it rode its top speed


def test_a_refused_authors_attacker_holds_nothing_and_a_leader_before_the_first_car_is_no_car():
    """Found by review: an authors' attacker refused for its radar kept its radar's generator (never released); a pair
    whose leader index is negative was read as nobody ahead, where the Python reads a speed from the end of its list."""
    import gc
    import sys

    from d4sumo.model.controllers.commands import checked_command

    config = EpisodeConfig(followers=2, controller=ControllerConfig("switching", (("switching_rule", "code"),)))
    platoon = Platoon(config, np.full(config.steps, np.nan), 40.0)
    law = compiled._law(platoon._attacker_as_run, platoon.attacker_actuator, False, None, False, 0, "")
    normal = object()
    with_radar = law[:7] + ((100.0, 0.0, 0.0, 0, normal),) + law[8:]
    laws = [compiled._law(f.controller, f.actuator, f.has_mode, None, False, i, "") for i, f in enumerate(platoon.followers, 1)]
    before = sys.getrefcount(normal)
    for _ in range(50):
        with pytest.raises(ValueError, match="no radar"):
            compiled.Followers(None, [0.0] * 3, [()] * 2, [], None, laws, checked_command, (platoon.attack_u, 1, with_radar), False)
    gc.collect()
    assert sys.getrefcount(normal) == before
    cutout = EpisodeConfig(followers=2, controller=ControllerConfig("switching"), maneuver="cutout")
    fast = Platoon(cutout, np.full(cutout.steps, np.nan), 40.0)
    with pytest.raises(IndexError, match="leader -1"):
        fast.advance(0, [100.0, 90.0, 80.0], [20.0, 20.0, 20.0, 25.0], [(-1, 1, 5.0)])
