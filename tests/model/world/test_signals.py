"""A driver at traffic lights (`signals.SignalDriver`), without SUMO: the car, its actuator's lag included,
stops before the line for red, decides once at amber, and drives on at green."""

from __future__ import annotations

import pytest

from d4sumo.model.world.signals import COMFORTABLE_DECEL_MPS2, STOP_MARGIN_M, SignalDriver, Stop
from d4sumo.model.world.vehicle import Actuator, VehicleParams

STEP_S = 0.05


def approach(line_m: float, speed_mps: float, states, vehicle: VehicleParams = VehicleParams(), steps: int = 600,
             wanted: float = 0.3):
    """A car at 0 m driving on at ``speed_mps`` (its controller asking for ``wanted``) towards a stop line at
    ``line_m``, the signal in ``states(k)`` at step k; its positions and speeds, step by step."""
    driver, actuator = SignalDriver(vehicle, STEP_S), Actuator(vehicle, STEP_S)
    x, v, xs, vs = 0.0, speed_mps, [0.0], [speed_mps]
    for k in range(steps):
        stop = Stop(0, line_m - x, states(k)) if x < line_m else None
        u = min(wanted, driver.limit(stop, v))
        v_next = actuator.apply(u, v)
        x += (v + v_next) / 2 * STEP_S  # SUMO's ballistic update
        v = v_next
        xs.append(x)
        vs.append(v)
    return xs, vs


def test_a_car_stops_for_red_before_the_line_near_it_braking_no_harder_than_comfortable():
    xs, vs = approach(120.0, 13.0, lambda k: "r")
    assert max(xs) < 120.0  # never past the line
    assert 120.0 - STOP_MARGIN_M - 1.0 < xs[-1] < 120.0  # and stopped near it
    assert vs[-1] < 1e-3
    decelerations = [(a - b) / STEP_S for a, b in zip(vs, vs[1:])]
    assert max(decelerations) <= COMFORTABLE_DECEL_MPS2 + 0.3  # the lag's transient aside


def test_red_too_near_to_stop_comfortably_brakes_harder_and_holds_it_stopped():
    xs, vs = approach(25.0, 13.0, lambda k: "r")  # 13 m/s 25 m short of the line: 3.4 m/s^2 planned without lag
    decelerations = [(a - b) / STEP_S for a, b in zip(vs, vs[1:])]
    assert max(decelerations) > COMFORTABLE_DECEL_MPS2
    assert vs[-1] < 1e-3 and xs[-1] < 25.0 + 3.0


def test_amber_far_away_is_stopped_for_and_amber_too_near_is_driven_through_even_once_red():
    xs, _ = approach(100.0, 13.0, lambda k: "y" if k < 60 else "r")
    assert max(xs) < 100.0
    xs, _ = approach(12.0, 13.0, lambda k: "y" if k < 5 else "r")  # 12 m short at 13 m/s: 7 m/s^2 to stop
    assert xs[-1] > 100.0


def test_green_lets_it_go_and_a_car_stopped_short_creeps_up_to_the_line():
    xs, vs = approach(120.0, 13.0, lambda k: "r" if k < 300 else "G")
    stopped = [x for x, v in zip(xs[:300], vs[:300]) if v < 0.05]
    assert stopped and max(stopped) < 120.0
    assert xs[-1] > 200.0  # on its way after the light turned green
    # stopped 20 m short: it creeps up to the line and stops there again
    xs, vs = approach(20.0, 0.0, lambda k: "r", wanted=1.0)
    assert 20.0 - STOP_MARGIN_M - 1.0 < xs[-1] < 20.0 and vs[-1] < 1e-3


def test_no_signal_and_green_leave_the_command_alone():
    driver = SignalDriver(VehicleParams(), STEP_S)
    assert driver.limit(None, 13.0) == 1.0
    for state in "GgOos":
        assert driver.limit(Stop(0, 5.0, state), 13.0) == 1.0


@pytest.mark.parametrize("lag", [0.0, 0.5, 1.0])
def test_whatever_the_actuator_lag_the_car_stops_before_the_line(lag):
    vehicle = VehicleParams(actuator_lag_s=lag)
    for speed in (8.0, 13.0, 25.0):
        xs, vs = approach(150.0, speed, lambda k: "r", vehicle=vehicle, steps=1000)
        assert max(xs) < 150.0 and vs[-1] < 1e-3, (lag, speed)
