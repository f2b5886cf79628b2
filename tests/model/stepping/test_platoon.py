"""The platoon's control step and the SUMO-free reference integration: no SUMO."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from d4sumo.engine.ballistic import integrate
from d4sumo.model.attacks.pedals import attack_signal, make_attack
from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.model.controllers.control import MODE_ACC, CruiseControl, SwitchingParams, register_controller
from d4sumo.model.attacks.maneuvers import Maneuver
from d4sumo.model.attacks.maneuvers import initial_state
from d4sumo.model.controllers.commands import ControllerError
from d4sumo.model.stepping.platoon import Platoon, collisions_at
from d4sumo.model.world.vehicle import acceleration_to_command

ALTERNATING = [1, -1, 1, -1, 1, -1, 1, -1, 1]


def knots(config, values):
    return attack_signal(make_attack("knots"), values, steps=config.steps, step_s=config.step_s,
                         start_step=config.attack_start_step)


@pytest.mark.parametrize("setpoint", [7.0, 7.1, 6.3, 11.9, 11.900000001, 2.35, 14.999999])
@pytest.mark.parametrize("start", ["rest", "steady", "warmup"])
def test_a_platoon_spaced_at_its_setpoint_starts_in_acc_whatever_the_rounding(setpoint, start):
    """Regression: at 7.1 m the gaps measured from positions exceeded the setpoint by ~1e-15 m, so
    v2 and v3 started in cruise mode while v1 started in ACC."""
    config = EpisodeConfig(setpoint_m=setpoint, start=start)
    episode = integrate(config, np.full(config.steps, np.nan))
    assert [episode.trace[f"mode_v{i}"][0] for i in (1, 2, 3)] == [MODE_ACC] * 3


def test_setpoints_a_nanometre_apart_give_the_same_verdict():
    """Regression: 11.9 m was a success and 11.900000001 m an attacker crash for the same attack."""
    verdicts = []
    for setpoint in (11.9, 11.900000001, 11.899999999):
        config = EpisodeConfig(setpoint_m=setpoint, speed_mps=25.0, start="rest")
        e = integrate(config, knots(config, ALTERNATING), 40.0)
        verdicts.append((e.outcome, e.first_collision.pair, e.first_collision.time_s))
    assert len(set(verdicts)) == 1


def test_an_overlap_below_a_millimetre_is_a_collision_and_a_touch_is_not():
    lead = Maneuver(EpisodeConfig(followers=2))
    ids = ("v0", "v1", "v2")
    positions = [100.0, 100.0 - 4.5 - 3.0, 100.0 - 4.5 - 3.0 - 4.5 + 0.0004]  # v1-v2 overlap 0.4 mm
    hits = collisions_at(7.4, lead.pairs(positions), positions, [20.0, 21.0, 22.5], ids)
    assert [c.pair for c in hits] == ["v1-v2"]
    assert hits[0].time_s == 7.4 and hits[0].position_m == positions[2]
    assert hits[0].speed_diff_kmh == pytest.approx(1.5 * 3.6)
    touching = [100.0, 95.5, 80.0]  # v0-v1 bumpers touch: gap exactly 0
    assert collisions_at(7.4, lead.pairs(touching), touching, [20.0, 20.0, 20.0], ids) == ()


def test_the_episode_ends_at_the_first_overlap_and_the_verdicts_agree():
    config = EpisodeConfig(setpoint_m=6.118633151283105, start="steady")
    values = [-0.7434975895033542, -0.00799454828211621, -0.7807212009393558, -0.3290245197619086, 0.6116075492610233,
              -0.45921552198458704, 0.7687692730609377, -0.051854840905022126, -0.23664748282734083]
    e = integrate(config, knots(config, values), 40.0)
    gaps = e.trace.gaps()
    assert e.outcome == "success" and e.first_collision.pair == "v2-v3"
    assert -1e-3 < gaps[-1, 2] < 0 and np.all(gaps[:-1] >= 0)
    assert e.min_gaps_m()["v2-v3"] == gaps[-1, 2]


def test_the_attackers_cruise_pid_starts_afresh_after_an_attack_window():
    """Regression: after an intermittent window the PID's stale derivative and integral kicked in."""
    config = EpisodeConfig(start="steady", followers=1)
    u = np.full(config.steps, np.nan)
    u[20:40] = -1.0  # brake for 1 s, then cruise again
    platoon = Platoon(config, u, attacker_max_speed_mps=40.0)
    positions, speeds = initial_state(config)
    for k in range(40):
        speeds = platoon.advance(k, positions, speeds, platoon.maneuver.pairs(positions))
    fresh = CruiseControl(SwitchingParams(), config.speed_mps, config.step_s)
    platoon.advance(40, positions, speeds, platoon.maneuver.pairs(positions))
    expected = acceleration_to_command(fresh.acceleration(speeds[0]), config.vehicle)
    assert platoon.commands[-1][0] == expected


def test_the_actuator_lag_does_not_wind_up_while_the_car_stands_still():
    """Regression: 5 s of braking at standstill left -8 m/s^2 in the lag, delaying the next throttle."""
    from d4sumo.model.world.vehicle import Actuator, VehicleParams

    vehicle = VehicleParams()
    act = Actuator(vehicle, 0.05)
    for _ in range(100):
        assert act.apply(-1.0, 0.0) == 0.0
    fresh = Actuator(vehicle, 0.05)
    assert act.apply(1.0, 0.0) == fresh.apply(1.0, 0.0) > 0.0


def test_the_actuator_lag_does_not_wind_up_at_the_speed_limit():
    from d4sumo.model.world.vehicle import Actuator, VehicleParams

    act = Actuator(VehicleParams(), 0.05, max_speed_mps=40.0)
    for _ in range(100):
        assert act.apply(1.0, 40.0) == 40.0
    assert act.apply(-1.0, 40.0) < 40.0  # braking acts at once, not after the lag unwinds 3.5 m/s^2


def test_warmup_drives_from_rest_and_the_attack_starts_after_it():
    config = EpisodeConfig(start="warmup", warmup_s=15.0, duration_s=60.0)
    assert config.attack_start_step == 300 and config.steps == 1500 and config.total_s == 75.0
    u = knots(config, ALTERNATING)
    assert np.all(np.isnan(u[:300])) and u[300] == 1.0
    e = integrate(config, u, 40.0)
    assert e.trace["speed_v0"][0] == 0.0
    assert abs(e.trace["speed_v0"][300] - 25.0) < 1.0  # at speed when the attack begins
    assert e.outcome != "no_crash"


def test_warmup_is_part_of_the_configuration_only_when_used():
    assert "warmup_s" not in EpisodeConfig(start="rest", warmup_s=20.0).to_dict()["scenario"]
    assert EpisodeConfig(start="warmup", warmup_s=20.0).to_dict()["scenario"]["warmup_s"] == 20.0


class Broken:
    """A user's controller that fails: NaN, or an exception."""

    Params = SwitchingParams

    def __init__(self, params, **kwargs):
        pass

    def command(self, gap_m, speed_mps, lead_speed_mps):
        return math.nan


def test_a_controller_returning_nan_is_refused_with_the_car_and_step():
    register_controller("test-nan", Broken)
    config = EpisodeConfig(controller=ControllerConfig(cls="test-nan"))
    with pytest.raises(ControllerError, match="v1 returned nan at step 0"):
        integrate(config, np.full(config.steps, np.nan))


def test_each_car_brakes_and_is_measured_as_its_own_vehicle():
    """A truck (12 m, brakes at 4 m/s^2) in a platoon of cars: its actuator and controller use its limits,
    and every gap behind it is measured from its own rear bumper."""
    truck = {"length_m": 12.0, "max_decel_mps2": 4.0, "vclass": "truck"}
    config = EpisodeConfig(start="steady", setpoint_m=10.0, duration_s=20.0, vehicles={"v1": truck})
    platoon = Platoon(config, np.full(config.steps, np.nan), 40.0)
    assert platoon.followers[0].actuator.decel_max == 4.0 and platoon.followers[1].actuator.decel_max == 8.0
    assert platoon.followers[0].controller.vehicle.length_m == 12.0
    brake = np.full(config.steps, -1.0)  # the attacker brakes at full from 25 m/s
    mixed, uniform = integrate(config, brake, 40.0), integrate(dataclasses.replace(config, vehicles=()), brake, 40.0)
    t = mixed.trace
    assert np.array_equal(t["gap_1"], t["pos_v1"] - 12.0 - t["pos_v2"])
    assert np.array_equal(t["gap_0"], t["pos_v0"] - 4.5 - t["pos_v1"])
    assert mixed.min_gaps_m()["v1-v2"] == pytest.approx(float(t["gap_1"].min()))
    # the truck stops later than a car would: the attacker's gap to it closes further
    assert mixed.min_gaps_m()["v0-v1"] < uniform.min_gaps_m()["v0-v1"]
    assert mixed.outcome == "attacker_crash" and mixed.first_collision.pair == "v0-v1"


# --- how far an episode reaches (issue 37) ---------------------------------------------------------


def test_an_episode_reaches_as_far_as_its_fastest_start_and_strongest_throttle_take_it_up_to_the_limit():
    from d4sumo.model.attacks.maneuvers import maneuver_of
    from d4sumo.model.stepping.platoon import longest_duration_s, reach_m, reach_s, road_needed_m

    assert reach_m(0.0, 2.0, 20.0, 5.0) == 25.0  # still accelerating
    assert reach_m(0.0, 2.0, 20.0, 15.0) == 100.0 + 20.0 * 5.0  # 10 s to the limit, then at it
    assert reach_m(25.0, 3.5, 20.0, 10.0) == 200.0  # above the limit: at the limit (the attacker is held to it)
    for v, a, limit, t in [(0.0, 2.0, 20.0, 5.0), (0.0, 2.0, 20.0, 15.0), (25.0, 3.5, 33.0, 40.0), (30.0, 0.0, 33.0, 9.0)]:
        assert reach_s(v, a, limit, reach_m(v, a, limit, t)) == pytest.approx(t)
    # from rest the platoon needs far less road than the limit for the whole episode: 3.5 m/s^2 to 33.33 m/s
    rest = EpisodeConfig(start="rest", duration_s=60.0)
    front = max(car.position_m for car in maneuver_of(rest).cars())
    assert road_needed_m(rest, 33.33) == pytest.approx(front + 33.33 * 60.0 - 33.33 ** 2 / (2 * 3.5))
    longest = longest_duration_s(rest, road_needed_m(rest, 33.33), 33.33)
    assert longest == pytest.approx(60.0)
