"""The IDM as a follower's law (d4sumo/model/controllers/laws/idm.py): pure code, no SUMO."""

from __future__ import annotations

import math

import numpy as np
import pytest

from d4sumo.engine.ballistic import integrate
from d4sumo.errors import ConfigError
from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.model.controllers.control import registered_controllers, resolve_controller
from d4sumo.model.controllers.laws.idm import IDMController, IDMParams
from d4sumo.model.world.sensing import Observation
from d4sumo.model.world.vehicle import VehicleParams

VEHICLE = VehicleParams()


def idm(**params) -> IDMController:
    return IDMController(IDMParams(**params), setpoint_m=2.0, target_speed_mps=30.0, vehicle=VEHICLE, step_s=0.05)


def test_it_is_registered_from_its_own_file():
    assert "idm" in registered_controllers() and resolve_controller("idm") is IDMController


def test_in_steady_following_at_its_equilibrium_gap_it_neither_brakes_nor_accelerates():
    law = idm()
    for v in (5.0, 15.0, 25.0):
        # a = 0 where (s*/s)^2 = 1 - (v/v0)^4, with s* = s0 + v T behind a car as fast
        gap = (2.0 + v * 1.0) / math.sqrt(1.0 - (v / 30.0) ** 4)
        assert law.observe(Observation(v, gap, v, True)) == pytest.approx(0.0, abs=1e-12)
        assert law.observe(Observation(v, gap * 1.1, v, True)) > 0.0 > law.observe(Observation(v, gap * 0.9, v, True))


def test_on_a_free_road_it_accelerates_to_the_target_speed_and_no_further():
    law = idm()
    assert law.observe(Observation(30.0, 1000.0, 30.0, False)) == 0.0
    assert law.observe(Observation(10.0, 1000.0, 10.0, False)) == pytest.approx((1.0 - (10 / 30) ** 4) / VEHICLE.max_accel_mps2)
    assert law.observe(Observation(35.0, 1000.0, 35.0, False)) < 0.0


def test_closing_in_brakes_as_treibers_formula_says():
    """Found by review: only a full brake was asserted, which the closing-in term's mistakes also give."""
    v, lead, gap = 20.0, 17.0, 30.0
    wanted = 2.0 + v * 1.0 + v * (v - lead) / (2.0 * math.sqrt(1.0 * 1.5))  # s* = s0 + v T + v dv / (2 sqrt(a b))
    a = 1.0 * (1.0 - (v / 30.0) ** 4 - (wanted / gap) ** 2)
    assert -1.0 < a / VEHICLE.max_decel_mps2 < 0.0  # a moderate brake: the pedal says the acceleration exactly
    assert idm().observe(Observation(v, gap, lead, True)) == pytest.approx(a / VEHICLE.max_decel_mps2, rel=1e-12)
    # moving apart, the closing-in term lowers the wanted gap ...
    wanted = 2.0 + v * 1.0 + v * (v - 22.0) / (2.0 * math.sqrt(1.5))
    a = 1.0 - (v / 30.0) ** 4 - (wanted / 40.0) ** 2
    assert idm().observe(Observation(v, 40.0, 22.0, True)) == pytest.approx(a / VEHICLE.max_accel_mps2, rel=1e-12)
    # ... never below s0: the term inside max(0, ...) may not go negative
    a = 1.0 - (v / 30.0) ** 4 - (2.0 / 40.0) ** 2
    assert idm().observe(Observation(v, 40.0, 40.0, True)) == pytest.approx(a / VEHICLE.max_accel_mps2, rel=1e-12)


def test_closing_in_fast_on_a_short_gap_is_a_full_brake():
    assert idm().observe(Observation(25.0, 5.0, 10.0, True)) == -1.0
    assert idm().observe(Observation(25.0, 0.0, 25.0, True)) == -1.0  # touching: no division by zero


def test_a_platoon_of_idm_followers_settles_behind_a_cruising_attacker_without_a_crash():
    config = EpisodeConfig(controller=ControllerConfig("idm"), start="steady", setpoint_m=7.0, speed_mps=25.0)
    episode = integrate(config, np.full(config.steps, np.nan))
    assert not episode.collisions
    # each opens the 7 m start to more than its time gap (behind a car at its own target speed, the free-road
    # term asks for little more speed), and goes on a little slower than the car ahead
    for i in range(3):
        assert episode.trace[f"gap_{i}"][-1] > 7.0 + 25.0 * 1.0
        assert 23.0 < episode.trace[f"speed_v{i + 1}"][-1] < episode.trace[f"speed_v{i}"][-1]


def test_bad_parameters_are_one_line_naming_the_key():
    with pytest.raises(ConfigError, match=r"controller\.delta: got -1.*allowed"):
        ControllerConfig("idm", (("delta", -1.0),)).build_params()
    with pytest.raises(ConfigError, match=r"controller\.tau"):
        ControllerConfig("idm", (("tau", 1.0),)).build_params()
