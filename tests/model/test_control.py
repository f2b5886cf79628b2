"""Physics and control without SUMO: the switching controller, the low-level map, the actuator."""

from __future__ import annotations

import math

import pytest

from d4sumo.errors import ConfigError
from d4sumo.model.config import ControllerConfig
from d4sumo.model.control import (MODE_ACC, MODE_CC, Actuator, CruiseControl, SwitchingController, SwitchingParams,
                                  VehicleParams, acceleration_to_command, command_to_acceleration, register_controller,
                                  resolve_controller)

VEHICLE = VehicleParams()
DT = 0.05


def follow(leader_speed, *, setpoint, gap0, v0, target=25.0, duration=40.0):
    """A follower behind a leader with a prescribed speed profile (ballistic positions, as SUMO).

    Returns the lists of gaps [m], follower speeds and modes, stopping at the first overlap."""
    ctl = SwitchingController(SwitchingParams(), setpoint_m=setpoint, target_speed_mps=target, vehicle=VEHICLE, step_s=DT)
    act = Actuator(VEHICLE, DT)
    x_lead, v_lead = gap0 + VEHICLE.length_m, leader_speed(0.0)
    x, v = 0.0, v0
    gaps, speeds, modes = [gap0], [v], []
    for k in range(int(duration / DT)):
        u = ctl.command(x_lead - VEHICLE.length_m - x, v, v_lead)
        modes.append(ctl.mode)
        v_new = act.apply(u, v)
        v_lead_new = leader_speed((k + 1) * DT)
        x += 0.5 * (v + v_new) * DT
        x_lead += 0.5 * (v_lead + v_lead_new) * DT
        v, v_lead = v_new, v_lead_new
        gaps.append(x_lead - VEHICLE.length_m - x)
        speeds.append(v)
        if gaps[-1] < 0:
            break
    return gaps, speeds, modes


def test_acc_settles_at_the_setpoint_behind_a_constant_speed_leader():
    gaps, speeds, modes = follow(lambda t: 20.0, setpoint=7.0, gap0=5.0, v0=20.0)
    assert modes[0] == MODE_ACC
    assert abs(gaps[-1] - 7.0) < 0.05
    assert abs(speeds[-1] - 20.0) < 0.05
    assert min(gaps) > 0


def braking_leader():
    """Full brake (8 m/s^2) from 25 m/s through the same actuator lag every car has."""
    act, speeds = Actuator(VEHICLE, DT), [25.0]
    for _ in range(2000):
        speeds.append(act.apply(-1.0, speeds[-1]))
    return lambda t: speeds[int(round(t / DT))]


def test_follower_at_2m_setpoint_hits_a_leader_braking_at_8mps2():
    gaps, _, _ = follow(braking_leader(), setpoint=2.0, gap0=2.0, v0=25.0)
    assert gaps[-1] < 0


def test_follower_at_15m_setpoint_stops_behind_a_leader_braking_at_8mps2():
    gaps, speeds, _ = follow(braking_leader(), setpoint=15.0, gap0=15.0, v0=25.0)
    assert min(gaps) > 0.5  # 1.0 m: the paper finds no collision from 14 m on
    assert speeds[-1] < 0.01  # it stopped behind the leader


def test_mode_switching_follows_the_hysteresis_rule():
    ctl = SwitchingController(SwitchingParams(), setpoint_m=7.0, target_speed_mps=25.0, vehicle=VEHICLE, step_s=DT)
    # (gap, speed) -> mode: CC when gap >= 8 or v >= 26; ACC when gap <= 7 and v <= 25; else keep
    sequence = [
        ((9.0, 20.0), MODE_CC),
        ((7.5, 20.0), MODE_CC),  # inside the band: stays CC
        ((7.0, 20.0), MODE_ACC),
        ((7.9, 20.0), MODE_ACC),  # inside the band: stays ACC
        ((8.0, 20.0), MODE_CC),
        ((6.0, 25.0), MODE_ACC),
        ((6.0, 25.5), MODE_ACC),  # speed inside the band: stays ACC
        ((6.0, 26.0), MODE_CC),
        ((6.0, 25.5), MODE_CC),
    ]
    for (gap, speed), expected in sequence:
        assert ctl.select_mode(gap, speed) == expected, (gap, speed)


def test_acc_law_is_the_papers():
    p = SwitchingParams()
    ctl = SwitchingController(p, setpoint_m=7.0, target_speed_mps=25.0, vehicle=VEHICLE, step_s=DT)
    a = ctl.desired_acceleration(6.0, 20.0, 21.0)
    assert a == pytest.approx(p.acc_kp * (6.0 - 7.0) + p.acc_kv * (21.0 - 20.0))


def test_cruise_pid_output_is_clamped_and_integral_bounded():
    cruise = CruiseControl(SwitchingParams(), target_speed_mps=25.0, step_s=DT)
    assert cruise.acceleration(0.0) == 3.0  # 0.4 * 25 = 10 m/s^2 asked, 3 allowed
    for _ in range(10_000):
        cruise.acceleration(0.0)
    assert cruise.integral == 20.0
    assert cruise.acceleration(30.0) == -3.0


def test_low_level_map_saturates_and_inverts_the_actuator_gains():
    assert acceleration_to_command(3.5, VEHICLE) == 1.0
    assert acceleration_to_command(10.0, VEHICLE) == 1.0
    assert acceleration_to_command(-8.0, VEHICLE) == -1.0
    assert acceleration_to_command(-20.0, VEHICLE) == -1.0
    for a in (-6.0, -1.0, 0.0, 1.0, 2.0):
        assert command_to_acceleration(acceleration_to_command(a, VEHICLE), VEHICLE) == pytest.approx(a)


def test_actuator_lag_reaches_63_percent_after_one_time_constant():
    act = Actuator(VEHICLE, DT)
    v = 10.0
    for _ in range(int(VEHICLE.actuator_lag_s / DT)):
        v = act.apply(1.0, v)
    assert act.accel_mps2 == pytest.approx(3.5 * (1 - math.exp(-1)), rel=1e-9)


def test_speed_never_goes_negative_and_the_limit_holds():
    act = Actuator(VEHICLE, DT, max_speed_mps=30.0)
    v = 1.0
    for _ in range(100):
        v = act.apply(-1.0, v)
        assert v >= 0.0
    assert v == 0.0
    for _ in range(2000):
        v = act.apply(1.0, v)
        assert v <= 30.0
    assert v == 30.0


def test_a_registered_name_is_never_silently_replaced():
    class Other(SwitchingController):
        pass

    with pytest.raises(ValueError, match="already registered"):
        register_controller("switching", Other)


def test_a_controller_class_can_be_named_by_import_path():
    assert resolve_controller("d4sumo.model.control:SwitchingController") is SwitchingController
    cfg = ControllerConfig(cls="d4sumo.model.control:SwitchingController", params=(("acc_kp", 1.5),))
    assert dict(cfg.params)["acc_kp"] == 1.5


@pytest.mark.parametrize(
    "name, params, field",
    [
        ("nope", (), "controller.class"),
        ("no.such.module:X", (), "controller.class"),
        ("d4sumo.model.control:VehicleParams", (), "controller.class"),  # not a controller
        ("switching", (("bogus", 1.0),), "controller.bogus"),
        ("switching", (("acc_kp", -1.0),), "controller.acc_kp"),
        ("switching", (("acc_kp", "fast"),), "controller.acc_kp"),
    ],
)
def test_bad_controller_configs_name_the_field(name, params, field):
    with pytest.raises(ConfigError) as info:
        ControllerConfig(cls=name, params=params)
    assert info.value.field == field


# --- the constant time-gap controller (the paper's mitigation) ----------------------------------


@pytest.mark.parametrize("time_gap_s", [0.5, 1.0, 2.0])
def test_the_time_gap_controller_keeps_its_desired_gap_at_steady_state(time_gap_s):
    import numpy as np

    from d4sumo.engine.ballistic import integrate
    from d4sumo.model.config import EpisodeConfig

    config = EpisodeConfig(controller=ControllerConfig("timegap", (("time_gap_s", time_gap_s),)), duration_s=120.0)
    episode = integrate(config, np.full(config.steps, np.nan))  # the attacker only cruises
    trace = episode.trace
    assert episode.outcome == "no_crash"
    for i in range(1, config.followers + 1):
        desired = config.setpoint_m + time_gap_s * trace[f"speed_v{i}"][-1]  # d(v) = s0 + h v
        assert trace[f"gap_{i - 1}"][-1] == pytest.approx(desired, abs=0.01)
        assert trace[f"mode_v{i}"][-1] == MODE_ACC
        assert trace[f"speed_v{i}"][-1] == pytest.approx(trace["speed_v0"][-1], abs=0.01)


def test_the_time_gap_controller_at_zero_time_gap_is_the_papers_controller():
    from d4sumo.model.control import TimeGapController, TimeGapParams

    paper = SwitchingController(SwitchingParams(), setpoint_m=7.0, target_speed_mps=25.0, vehicle=VEHICLE, step_s=0.05)
    zero = TimeGapController(TimeGapParams(time_gap_s=0.0), setpoint_m=7.0, target_speed_mps=25.0, vehicle=VEHICLE, step_s=0.05)
    for gap, v, v_lead in [(7.0, 25.0, 25.0), (6.0, 20.0, 18.0), (30.0, 24.0, 25.0), (7.5, 24.5, 20.0), (2.0, 10.0, 0.0)]:
        assert zero.command(gap, v, v_lead) == paper.command(gap, v, v_lead)
        assert zero.mode == paper.mode


def test_the_time_gap_controller_wants_more_room_the_faster_it_goes():
    from d4sumo.model.control import TimeGapController, TimeGapParams

    c = TimeGapController(TimeGapParams(time_gap_s=1.0), setpoint_m=7.0, target_speed_mps=25.0, vehicle=VEHICLE, step_s=0.05)
    # at the paper's setpoint gap and 20 m/s it is 20 m too close: ACC mode, braking
    assert c.command(7.0, 20.0, 20.0) < 0.0 and c.mode == MODE_ACC
    assert c.desired_gap_m(20.0) == pytest.approx(27.0)
    assert ControllerConfig("timegap", (("time_gap_s", 1.5),)).label == "timegap(time_gap_s=1.5)"
