"""The car's body without SUMO: the pedal map, the actuator's lag and limits, coasting."""

from __future__ import annotations

import math

import pytest

from d4sumo.model.world.vehicle import Actuator, VehicleParams, acceleration_to_command, command_to_acceleration

VEHICLE = VehicleParams()
DT = 0.05


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


def test_a_coasting_car_slows_with_no_pedal_and_a_standing_one_does_not_roll_back():
    actuator = Actuator(VehicleParams(coast_decel_mps2=2.0, actuator_lag_s=0.0), 0.05)
    assert actuator.apply(0.0, 10.0) == pytest.approx(10.0 - 2.0 * 0.05)
    assert actuator.apply(0.0, 0.0) == 0.0
    assert actuator.apply(1.0, 10.0) == pytest.approx(10.0 + (3.5 - 2.0) * 0.05)  # the drag acts under throttle too
    assert "coast_decel_mps2" not in VehicleParams().to_dict() and VehicleParams(coast_decel_mps2=1.0).to_dict()["coast_decel_mps2"] == 1.0
