"""Cooperative platoons (issue 38), for real in SUMO: CACC followers reading V2V beacons drive the paper's
scenarios without a collision when nobody attacks, and batches equal episodes alone."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
from conftest import assert_same_episode

from d4sumo.engine.simulation import simulate, simulate_batch
from d4sumo.model.attacks.pedals import make_attack
from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.model.attacks.maneuvers import attack_plan

pytestmark = pytest.mark.sumo


@pytest.mark.parametrize("cls", ["cacc", "ploeg", "consensus"])
def test_with_honest_beacons_and_no_attack_a_cooperative_platoon_never_crashes_in_the_paper_scenarios(cls):
    """The control experiment: every start, setpoints 5 and 7 m, 20 to 30 m/s, the attacker cruising."""
    for start in ("rest", "steady", "warmup"):
        for setpoint in (5.0, 7.0):
            for speed in (20.0, 25.0, 30.0):
                config = EpisodeConfig(controller=ControllerConfig(cls), start=start, setpoint_m=setpoint, speed_mps=speed,
                                       duration_s=40.0)
                episode = simulate(config, np.full(config.steps, np.nan))
                assert episode.outcome == "no_crash", (start, setpoint, speed)
                assert min(episode.min_gaps.values()) > 0.5 * setpoint
                assert episode.trace["speed_v3"][-1] == pytest.approx(speed, abs=0.3)


def test_a_lossy_late_channel_plays_another_episode_the_same_every_time_and_batches_equal_alone():
    base = EpisodeConfig(controller=ControllerConfig("cacc"), start="steady", setpoint_m=5.0, duration_s=30.0)
    lossy = dataclasses.replace(base, v2v={"latency_s": 0.2, "loss": 0.3, "seed": 1})
    family = make_attack("knots")
    rng = np.random.default_rng(5)
    plans = [attack_plan(family, family.lower + rng.random(family.dimension) * (family.upper - family.lower), base)
             for _ in range(6)]
    ideal, late = simulate(base, plans[0]), simulate(lossy, plans[0])
    assert not np.array_equal(ideal.trace["speed_v2"], late.trace["speed_v2"])
    assert_same_episode(late, simulate(lossy, plans[0]))
    for c in (base, lossy):
        batch = simulate_batch(c, plans)
        for plan, together in zip(plans, batch):
            assert_same_episode(together, simulate(c, plan))


@pytest.mark.parametrize("cls", ["switching", "timegap", "cacc", "ploeg", "consensus"])
@pytest.mark.parametrize("world", ["ideal", "imperfect"])
def test_in_sumo_the_compiled_followers_play_the_python_episode_bit_for_bit(cls, world, monkeypatch):
    """The followers stepped in C (`compiled`) against the Python they stand for, on the paper's knots
    attacks (a batch of them too; the paper's controller alone, which batches play over arrays), crashes
    included; ``imperfect``: a noisy, late radar of limited range, and for the cooperative laws a late and
    lossy channel, the mitigation, and the attacker's lies about its speed."""
    from d4sumo.model.controllers import compiled as in_c
    from d4sumo.model.attacks.messages import attack_box
    from d4sumo.model.world.sensing import RadarParams

    paper = cls in ("switching", "timegap")
    headway = {"cacc": (), "switching": (), "timegap": (("time_gap_s", 0.3),)}.get(cls, (("h_s", 0.1),))  # closely spaced behind an attacker that brakes harder
    imperfect = world == "imperfect"
    config = EpisodeConfig(controller=ControllerConfig(cls, headway + ((("fallback_mps", 1.0),) if imperfect and not paper else ())),
                           start="steady", setpoint_m=8.0 if paper else 3.0, duration_s=20.0,
                           vehicles={"v0": {"max_decel_mps2": 9.5}, "v1": {"max_decel_mps2": 5.0}},
                           radar=RadarParams(range_m=120.0, gap_noise_m=0.3, speed_noise_mps=0.2, latency_s=0.1, seed=3) if imperfect else None,
                           v2v={"latency_s": 0.1, "loss": 0.2, "seed": 4} if imperfect and not paper else None)
    family = attack_box(config, make_attack("knots"), "offset", "speed") if imperfect and not paper else make_attack("knots")
    rng = np.random.default_rng(11)
    plans = [attack_plan(family, family.lower + rng.random(family.dimension) * (family.upper - family.lower), config)
             for _ in range(8)]
    compiled = [simulate(config, plan) for plan in plans] if paper else simulate_batch(config, plans)
    monkeypatch.setattr(in_c, "ENABLED", False)
    python = [simulate(config, plan) for plan in plans]
    for a, b in zip(compiled, python):
        assert_same_episode(a, b)
    assert any(e.collisions for e in python) and not all(e.collisions for e in python)


def test_sumo_consensus_on_a_curving_motorway_batches_equal_alone_bit_for_bit():
    """Regression: Plexe's CONSENSUS reads GPS positions, whose rounding depends on where its road lies on the
    map; a batch's copies of SUMO's Bremen motorway lie elsewhere, and its speeds drifted from alone's by
    1e-13 m/s until a verdict changed. Such a platoon now plays in a SUMO of its own."""
    from pathlib import Path

    from conftest import random_plans
    from d4sumo.sumohome import sumo_home

    bremen = Path(sumo_home()) / "tools" / "game" / "highway" / "highway.net.xml"
    config = EpisodeConfig(network=str(bremen), route=("145354574", "189597495", "E0", "191842213"), start="steady",
                           setpoint_m=15.0, duration_s=20.0, followers=4,
                           controller=ControllerConfig("sumo:CC", (("active_controller", "CONSENSUS"),)))
    plans = random_plans(config, 4, seed=1)
    for plan, together in zip(plans, simulate_batch(config, plans)):
        assert_same_episode(together, simulate(config, plan))


@pytest.mark.parametrize("cls, plexe, setpoint", [("cacc", "CACC", 5.0), ("ploeg", "PLOEG", 2.0), ("consensus", "CONSENSUS", 15.0)])
def test_the_python_cacc_agrees_with_plexe_in_sumo_fed_the_same_beacons(cls, plexe, setpoint):
    """SUMO's CC model (Plexe's) with its CACC or Ploeg's, fed the channel's beacons as Plexe's application
    does, against d4sumo's Python law on the same attacks: the same outcomes, speeds within 0.3 m/s (the
    engines differ in discretisation). Ploeg's standstill gap is Plexe's 2 m; SUMO's car may not exceed
    the target speed (its maxSpeed), so the attacker here brakes or holds, never speeds away. CONSENSUS
    reads every car ahead's beacons, GPS positions; its standstill distance is Plexe's 15 m."""
    python = EpisodeConfig(controller=ControllerConfig(cls), start="steady", setpoint_m=setpoint, duration_s=40.0)
    table = (("active_controller", plexe), ("decel", 8.0), ("minGap", 0.0), ("tauEngine", 0.5))
    table += (("constSpacing", setpoint),) if plexe == "CACC" else ()
    sumo = dataclasses.replace(python, controller=ControllerConfig("sumo:CC", table))
    assert sumo.v2v == python.v2v  # Plexe's controllers read the same channel
    family = make_attack("knots")
    rng = np.random.default_rng(2)
    for _ in range(4):
        x = -rng.random(family.dimension)
        ours, plexes = simulate(python, attack_plan(family, x, python)), simulate(sumo, attack_plan(family, x, sumo))
        assert ours.outcome == plexes.outcome
        n = min(len(ours.trace), len(plexes.trace))
        for j in (1, 2, 3):
            assert np.max(np.abs(ours.trace[f"speed_v{j}"][:n] - plexes.trace[f"speed_v{j}"][:n])) < (0.5 if plexe == "CONSENSUS" else 0.3)
            assert np.max(np.abs(ours.trace[f"gap_{j - 1}"][:n] - plexes.trace[f"gap_{j - 1}"][:n])) < 0.8


def test_an_attacker_that_lies_about_its_speed_is_rammed_by_the_cacc_that_believes_it():
    """The attacker slows gently (its pedal at -0.1) and, from 5 s on, tells the platoon it drives 5 m/s
    faster: v1's CACC runs into it. The trace keeps what it said beside what was true."""
    from d4sumo.model.attacks.messages import attack_box

    config = EpisodeConfig(controller=ControllerConfig("cacc"), start="steady", setpoint_m=5.0, duration_s=40.0)
    box = attack_box(config, make_attack("knots"), "offset", "speed")
    x = np.full(box.dimension, -0.1)
    x[9:] = 5.0, 5.0  # msg_value, msg_start_s
    episode = simulate(config, attack_plan(box, x, config))
    assert episode.outcome == "attacker_crash" and episode.first_collision.pair == "v0-v1"
    assert 7.0 < episode.first_collision.time_s < 8.5
    lie = episode.trace["sent_speed_v0"] - episode.trace["speed_v0"]
    t = episode.trace.times_s
    assert np.all(np.abs(lie[(t >= 5.0) & (t % 0.1 < 0.025)] - 5.0) < 1e-9)  # at each beacon from 5 s on
    assert np.all(np.abs(lie[(t < 4.9) & (t % 0.1 < 0.025)]) < 1e-9)
    honest = simulate(config, attack_plan(box, np.r_[x[:9], 0.0, 5.0], config))
    assert honest.outcome == "no_crash"  # the same pedals, the truth told


@pytest.mark.parametrize("cls", ["cacc", "ploeg"])
def test_an_insider_that_lies_to_the_car_behind_it_changes_that_car_alone(cls):
    """v2 drives as its controller says and claims an acceleration 3 m/s^2 below its own from 2 s on: only
    v3 reads v2's beacons (as the car ahead's), so the attacker, v1 and v2 drive exactly as with the
    truth told, and v3 does not. The trace keeps what v2 said."""
    from d4sumo.model.attacks.messages import attack_box

    config = EpisodeConfig(controller=ControllerConfig(cls), start="steady", setpoint_m=5.0, duration_s=20.0)
    box = attack_box(config, make_attack("knots"), "offset", "accel", sender=2)
    x = np.r_[np.linspace(-0.6, 0.4, 9), -3.0, 2.0]  # the attacker's pedals, then msg_value, msg_start_s
    lied, honest = simulate(config, attack_plan(box, x, config)), simulate(config, attack_plan(box, np.r_[x[:9], 0.0, 2.0], config))
    n = min(len(lied.trace), len(honest.trace))
    for j in (0, 1, 2):
        assert np.array_equal(lied.trace[f"pos_v{j}"][:n], honest.trace[f"pos_v{j}"][:n])
    assert np.max(np.abs(lied.trace["speed_v3"][:n] - honest.trace["speed_v3"][:n])) > 0.5
    t, v = lied.trace.times_s, lied.trace["speed_v2"]
    lie = lied.trace["sent_accel_v2"] - np.r_[0.0, np.diff(v) / config.step_s]  # a beacon's: its last step's
    beacon = np.round(t / config.step_s) % 2 == 0
    assert np.allclose(lie[beacon & (t >= 2.0)], -3.0, atol=1e-9) and np.allclose(lie[beacon & (t < 1.95)], 0.0, atol=1e-9)
    assert "sent_accel_v0" not in lied.trace.signals


@pytest.mark.parametrize("cls", ["cacc", "ploeg"])
def test_the_mitigation_never_distrusts_honest_beacons_in_the_paper_scenarios(cls):
    for start in ("rest", "steady", "warmup"):
        for speed in (20.0, 30.0):
            config = EpisodeConfig(controller=ControllerConfig(cls, (("fallback_mps", 1.0),)), start=start, setpoint_m=5.0,
                                   speed_mps=speed, duration_s=40.0)
            episode = simulate(config, np.full(config.steps, np.nan))
            assert episode.outcome == "no_crash"
            assert all(episode.trace[f"mode_v{i}"].max() == 0.0 for i in (1, 2, 3)), (start, speed)


def test_the_mitigation_saves_v1_from_the_lie_and_the_followers_behind_it_crash_instead():
    """v1 checks the attacker's beacons against its radar and falls back to ACC; v2 and v3 check the honest
    beacons of the car ahead, keep believing the leader's lie about its speed, and v2 runs into v1."""
    from d4sumo.model.attacks.messages import attack_box

    config = EpisodeConfig(controller=ControllerConfig("cacc", (("fallback_mps", 1.0),)), start="steady", setpoint_m=5.0,
                           duration_s=40.0)
    box = attack_box(config, make_attack("knots"), "offset", "speed")
    x = np.full(box.dimension, -0.1)
    x[9:] = 5.0, 5.0
    episode = simulate(config, attack_plan(box, x, config))
    assert episode.outcome == "success" and episode.first_collision.pair == "v1-v2"
    assert episode.trace["mode_v1"].max() == 1.0 and episode.trace["mode_v2"].max() == 0.0
    assert episode.min_gaps["v0-v1"] > 0.0  # v1 did not ram the attacker, as it does without the mitigation
