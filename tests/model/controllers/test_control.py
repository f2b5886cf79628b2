"""Control without SUMO: the switching controller and its variants, the registry of controllers."""

from __future__ import annotations

import pytest

from d4sumo.errors import ConfigError
from d4sumo.model.config import ControllerConfig
from d4sumo.model.controllers.control import (
    MODE_ACC, MODE_CC, CruiseControl, SwitchingController, SwitchingParams, register_controller, resolve_controller)
from d4sumo.model.world.vehicle import Actuator, VehicleParams

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


def test_a_registered_name_is_never_silently_replaced():
    class Other(SwitchingController):
        pass

    with pytest.raises(ValueError, match="already registered"):
        register_controller("switching", Other)


def test_a_controller_class_can_be_named_by_import_path():
    assert resolve_controller("d4sumo.model.controllers.control:SwitchingController") is SwitchingController
    cfg = ControllerConfig(cls="d4sumo.model.controllers.control:SwitchingController", params=(("acc_kp", 1.5),))
    assert dict(cfg.params)["acc_kp"] == 1.5


@pytest.mark.parametrize(
    "name, params, field",
    [
        ("nope", (), "controller.class"),
        ("no.such.module:X", (), "controller.class"),
        ("d4sumo.model.world.vehicle:VehicleParams", (), "controller.class"),  # not a controller
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
    from d4sumo.model.controllers.control import TimeGapController, TimeGapParams

    paper = SwitchingController(SwitchingParams(), setpoint_m=7.0, target_speed_mps=25.0, vehicle=VEHICLE, step_s=0.05)
    zero = TimeGapController(TimeGapParams(time_gap_s=0.0), setpoint_m=7.0, target_speed_mps=25.0, vehicle=VEHICLE, step_s=0.05)
    for gap, v, v_lead in [(7.0, 25.0, 25.0), (6.0, 20.0, 18.0), (30.0, 24.0, 25.0), (7.5, 24.5, 20.0), (2.0, 10.0, 0.0)]:
        assert zero.command(gap, v, v_lead) == paper.command(gap, v, v_lead)
        assert zero.mode == paper.mode


def test_the_time_gap_controller_wants_more_room_the_faster_it_goes():
    from d4sumo.model.controllers.control import TimeGapController, TimeGapParams

    c = TimeGapController(TimeGapParams(time_gap_s=1.0), setpoint_m=7.0, target_speed_mps=25.0, vehicle=VEHICLE, step_s=0.05)
    # at the paper's setpoint gap and 20 m/s it is 20 m too close: ACC mode, braking
    assert c.command(7.0, 20.0, 20.0) < 0.0 and c.mode == MODE_ACC
    assert c.desired_gap_m(20.0) == pytest.approx(27.0)
    assert ControllerConfig("timegap", (("time_gap_s", 1.5),)).label == "timegap(time_gap_s=1.5)"


# --- the controller as the authors' code ran it (its options; values computed by hand) ------------


def test_the_authors_pid_starts_with_its_initial_integral_and_integrates_by_trapezoids():
    """Low-level PID at commit d458f6c: Kp 0.1, Ki 0.1, Kd 0.005, integral from 5, clamped at 10."""
    from d4sumo.model.controllers.control import CodePID

    pid = CodePID(0.1, 0.1, 0.005, 0.1, clamp=10.0, limit=1.0, integral=5.0)
    assert pid.step(0.0) == pytest.approx(0.5)  # Ki x 5 of throttle before any error
    pid = CodePID(0.1, 0.1, 0.005, 0.1, clamp=10.0, limit=1.0, integral=5.0)
    assert pid.step(2.0) == pytest.approx(0.1 * 2 + 0.1 * 5)  # first call: no derivative, the integral as it starts
    # then de = (1 - 2) / 0.1 = -10, integral 5 + (1 + 2) 0.1 / 2 = 5.15
    assert pid.step(1.0) == pytest.approx(0.1 * 1 + 0.005 * -10 + 0.1 * 5.15)
    saturated = CodePID(0.0, 1.0, 0.0, 0.1, clamp=10.0, limit=100.0, integral=9.9)
    saturated.step(5.0)
    assert saturated.step(5.0) == pytest.approx(10.0)  # 9.9 + 0.5, clamped at 10


def test_the_authors_cruise_pid_takes_the_derivative_of_the_error_filtered_over_1_s():
    from d4sumo.model.controllers.control import CodePID

    pid = CodePID(0.4, 0.01, 0.1, 0.1, filter_s=1.0, clamp=20.0, limit=3.0)
    assert pid.step(5.0) == pytest.approx(2.0)  # filtered 0.5, no derivative yet
    # filtered 0.1 (5 - 0.5) + 0.5 = 0.95; de = (0.95 - 0.5) / 0.1 = 4.5; integral (5 + 5) 0.1 / 2 = 0.5
    assert pid.step(5.0) == pytest.approx(0.4 * 5 + 0.1 * 4.5 + 0.01 * 0.5)
    assert pid.step(50.0) == 3.0  # the output clipped at 3 m/s^2


def _code_controller(**options):
    from d4sumo.model.controllers.control import SwitchingController, SwitchingParams

    params = SwitchingParams(switching_rule="code", **options)
    return SwitchingController(params, setpoint_m=7.0, target_speed_mps=20.0, vehicle=VehicleParams(), step_s=0.05)


@pytest.mark.parametrize("mode, gap, lead, expected", [
    (MODE_CC, 31.9, 19.0, MODE_ACC),   # within d + 25 and the car ahead slower than 20 m/s: ACC
    (MODE_CC, 32.0, 19.0, MODE_CC),    # d + 25 is not within
    (MODE_CC, 10.0, 20.0, MODE_CC),    # the car ahead at the target speed is not slower
    (MODE_CC, 10.0, 25.0, MODE_CC),
    (MODE_ACC, 42.0, 19.0, MODE_ACC),  # hysteresis: ACC holds up to d + 25 + 10
    (MODE_ACC, 42.1, 19.0, MODE_CC),
    (MODE_ACC, 20.0, 21.0, MODE_ACC),  # the car ahead at v_d + 1 does not release it
    (MODE_ACC, 20.0, 21.1, MODE_CC),
    (MODE_ACC, 35.0, 20.5, MODE_ACC),  # between the edges the mode stays
])
def test_the_authors_switching_rule_engages_and_releases_at_its_edges(mode, gap, lead, expected):
    c = _code_controller()
    c.mode = mode
    assert c._select_mode_code(gap, 15.0, lead) == expected


def test_the_authors_controller_gives_no_pedal_first_and_acts_once_a_control_period():
    c = _code_controller(first_command_zero=True, control_period_s=0.1, cruise_pid="code", low_level="pid")
    assert c.command(100.0, 0.0, 0.0) == 0.0  # its first call
    assert c.command(100.0, 0.0, 0.0) == 0.0  # held for the second step of the period
    u = c.command(100.0, 0.0, 0.0)  # cruising from rest: cruise PID 0.4 x 20 clipped at 3 m/s^2, low-level PID
    assert u == pytest.approx(0.1 * 3.0 + 0.1 * 5.0) and c.command(100.0, 0.05, 0.0) == u  # acts, then holds


def test_an_option_the_chosen_rule_does_not_read_is_refused():
    from d4sumo.model.controllers.control import SwitchingParams

    with pytest.raises(ConfigError, match='controller.engage_margin_m: got 30.0; allowed: an option of switching_rule = "code"'):
        SwitchingParams(engage_margin_m=30.0)
    with pytest.raises(ConfigError, match='controller.low_ki: got 0.35; allowed: an option of low_level = "pid"'):
        SwitchingParams(low_ki=0.35)
    with pytest.raises(ConfigError, match="controller.switching_rule: got 'eq2'; allowed: one of eq1, code"):
        SwitchingParams(switching_rule="eq2")
    assert not SwitchingParams().as_run and SwitchingParams(low_level="pid").as_run


def test_the_authors_options_are_stored_only_where_they_differ_from_the_paper():
    """A campaign stored before them keeps its identity: its definition has none of them."""
    from d4sumo.model.config import ControllerConfig

    assert set(ControllerConfig("switching").to_dict()) == {"class", "cruise_kp", "cruise_ki", "cruise_kd", "cruise_integral_clamp",
                                                           "cruise_output_limit_mps2", "acc_kp", "acc_kv", "eps_x_m", "eps_v_mps"}
    assert ControllerConfig("switching", (("low_level", "pid"),)).to_dict()["low_level"] == "pid"


