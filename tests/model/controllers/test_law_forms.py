"""Each law that has more than one form, checked form against form over its whole input space, mechanically:
the paper's switching controller and its time-gap variant (`control.SwitchingController`, `TimeGapController`,
their arrays `arrays.SwitchingArray` and their C in `fmus/switching.h`, which the compiled followers and the
FMUs both run), with the rules they go through (acceleration to pedal, the actuator); and the cooperative laws'
one decision, the mitigation's switch, against their C. Pure code, no SUMO.

Random draws alone would rarely land on the switch's thresholds, where a rounding would change the mode; so
every step draws each input from the thresholds themselves, a few units in the last place either side,
the edges of the domain (standing, touching, nobody ahead, over the target speed) and the rest of it, from
every mode the hysteresis can be in. Every command, mode and speed must be the same float in every form.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from d4sumo.model.controllers import compiled
from d4sumo.model.controllers.arrays import ActuatorArray, SwitchingArray
from d4sumo.model.controllers.commands import checked_command
from d4sumo.model.controllers.control import (
    GAP_TOLERANCE_M, SPEED_TOLERANCE_MPS, SwitchingController, SwitchingParams, TimeGapController, TimeGapParams)
from d4sumo.model.world.lanes import FREE_ROAD_GAP_M
from d4sumo.model.world.vehicle import Actuator, VehicleParams

pytestmark = pytest.mark.skipif(compiled.Followers is None, reason="the extension was not built (no C compiler)")


def _near(value: float, rng: np.random.Generator) -> float:
    """``value`` or a few units in its last place away, either side."""
    for _ in range(int(rng.integers(0, 4))):
        value = math.nextafter(value, math.inf if rng.random() < 0.5 else -math.inf)
    return value


def _forms(rng: np.random.Generator, time_gap: bool):
    params = (TimeGapParams if time_gap else SwitchingParams)(acc_kp=float(rng.uniform(0.2, 2.0)), acc_kv=float(rng.uniform(0.2, 3.0)),
                             eps_x_m=float(rng.choice([1.0, 0.3, 4.0])), eps_v_mps=float(rng.choice([1.0, 0.1, 2.5])),
                             cruise_kp=float(rng.uniform(0.1, 1.0)), cruise_ki=float(rng.choice([0.01, 0.0, 0.2])),
                             cruise_kd=float(rng.choice([0.1, 0.0, 0.5])), cruise_integral_clamp=float(rng.choice([20.0, 0.5])),
                             cruise_output_limit_mps2=float(rng.choice([3.0, 1.0])),
                             **({"time_gap_s": float(rng.choice([0.0, 0.4, 1.5]))} if time_gap else {}))
    vehicle = VehicleParams(max_accel_mps2=float(rng.uniform(1.0, 5.0)), max_decel_mps2=float(rng.uniform(3.0, 10.0)),
                            actuator_lag_s=float(rng.choice([0.0, 0.5, 0.3])))
    setpoint, target, step = float(rng.uniform(2.0, 30.0)), float(rng.uniform(5.0, 40.0)), float(rng.choice([0.05, 0.1, 0.01]))
    own = dict(setpoint_m=setpoint, target_speed_mps=target, vehicle=vehicle, step_s=step)
    cls = TimeGapController if time_gap else SwitchingController
    python = cls(params, **own)
    arrays = SwitchingArray(cls(params, **own), (1, 1), step)
    drive = Actuator(vehicle, step, math.inf)
    drive_arrays = ActuatorArray(vehicle, step, (1, 1), math.inf)
    gains = (params.cruise_kp, params.cruise_ki, params.cruise_kd, params.cruise_integral_clamp, params.cruise_output_limit_mps2,
             params.acc_kp, params.acc_kv, params.eps_x_m, params.eps_v_mps) + ((params.time_gap_s,) if time_gap else ())
    law = (5 if time_gap else 4, True, (setpoint, target, step, vehicle.max_accel_mps2, vehicle.max_decel_mps2), gains, 0.0, (0.0, 0.0),
           (drive.accel_max, drive.decel_max, drive.alpha, drive.step_s, drive.max_speed_mps, 0.0, drive.coast), None)
    in_c = compiled.Followers(None, [0.0, 0.0], [()], [], None, [law], checked_command).advance
    h = params.time_gap_s if time_gap else 0.0

    def gaps(speed: float) -> tuple[float, ...]:
        """The inputs that decide: the switch's thresholds on the gap as the law computes them at this speed,
        and the domain's edges."""
        desired = setpoint + h * speed if time_gap else setpoint
        return (desired + params.eps_x_m - GAP_TOLERANCE_M, desired + GAP_TOLERANCE_M, desired, desired + params.eps_x_m,
                0.0, -0.5, FREE_ROAD_GAP_M)

    speeds = (target + params.eps_v_mps - SPEED_TOLERANCE_MPS, target + SPEED_TOLERANCE_MPS, target, 0.0,
              target + params.eps_v_mps)
    return python, arrays, drive, drive_arrays, in_c, gaps, speeds, target


def _draw(rng: np.random.Generator, special: tuple[float, ...], low: float, high: float) -> float:
    return _near(float(rng.choice(special)), rng) if rng.random() < 0.6 else float(rng.uniform(low, high))


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("law", ["switching", "timegap"])
def test_the_switching_laws_are_the_same_float_in_python_in_arrays_and_in_c_over_their_whole_input_space(law, seed):
    rng = np.random.default_rng(seed)
    thresholds_met = set()
    for _ in range(25):
        python, arrays, drive, drive_arrays, in_c, gaps_at, speeds, target = _forms(rng, law == "timegap")
        for k in range(400):
            speed = _draw(rng, speeds, 0.0, 1.3 * target)
            gaps = gaps_at(speed)
            gap = _draw(rng, gaps, -1.0, 120.0)
            lead = speed if rng.random() < 0.3 else _draw(rng, speeds, 0.0, 1.3 * target)
            u = python.command(gap, speed, lead)
            u_arrays = arrays.command(np.array([[gap]]), np.array([[speed]]), np.array([[lead]]))
            commands, new_speeds, modes = [], [], []
            in_c(k, [gap + 5.0, 0.0], [lead, speed], [(0, 1, gap)], commands, new_speeds, modes)
            assert commands == [u] and u_arrays[0, 0] == u, (k, gap, speed, lead)
            assert modes == [[python.mode]] and arrays.mode[0, 0] == python.mode, (k, gap, speed, lead)
            v = drive.apply(u, speed)
            assert new_speeds == [v] and drive_arrays.apply(u_arrays, np.array([[speed]]))[0, 0] == v
            thresholds_met.update(i for i, g in enumerate(gaps) if g == gap)
    assert len(thresholds_met) == 7  # every threshold was met exactly, not only near


@pytest.mark.parametrize("law", ["cacc", "ploeg", "consensus"])
def test_the_mitigations_switch_is_the_same_in_python_and_in_c_at_its_threshold(law, monkeypatch):
    """The cooperative laws' one decision (`cacc.Fallback.check`: the beacon's speed of the car ahead against the
    radar's, within ``fallback_mps``) met exactly and a few ulps either side, every step, in a platoon whose radar
    reads a step late while the beacons arrive at once: the disagreement is each car's change of speed, drawn at
    the threshold. Every command, mode and speed the same float in Python and in C."""
    from d4sumo.model.config import ControllerConfig, EpisodeConfig
    from d4sumo.model.attacks.maneuvers import maneuver_of
    from d4sumo.model.stepping.platoon import Platoon
    from d4sumo.model.world.sensing import RadarParams

    rng = np.random.default_rng(["cacc", "ploeg", "consensus"].index(law))
    met = 0
    for _ in range(8):
        threshold = float(rng.uniform(0.3, 2.0))
        params = (("fallback_mps", threshold), ("fallback_headway_s", float(rng.uniform(0.8, 1.5))))
        config = EpisodeConfig(followers=int(rng.integers(1, 5)), controller=ControllerConfig(law, params), start="steady",
                               setpoint_m=float(rng.uniform(3.0, 10.0)), radar=RadarParams(latency_s=0.05),
                               v2v={"beacon_interval_s": 0.05})
        attack = np.full(config.steps, np.nan)
        fast = Platoon(config, attack, 40.0)
        assert fast._compiled is not None
        monkeypatch.setattr(compiled, "ENABLED", False)
        python = Platoon(config, attack, 40.0)
        monkeypatch.setattr(compiled, "ENABLED", True)
        n = config.followers + 1
        pairs_at = maneuver_of(config).pairs
        x = list(np.cumsum(rng.uniform(8.0, 20.0, n))[::-1] + 100.0)
        v = [25.0] * n
        for k in range(300):
            # each car's change of speed: the threshold exactly, a few ulps off it, or anything
            for i in range(n):
                step = _near(threshold, rng) if rng.random() < 0.7 else float(rng.uniform(0.0, 3.0))
                v[i] = max(0.0, v[i] + (step if rng.random() < 0.5 else -step))
                met += step == threshold
            x = [xi + vi * 0.05 for xi, vi in zip(x, v)]
            pairs = pairs_at(x)
            assert fast.advance(k, x, list(v), pairs) == python.advance(k, x, list(v), pairs), (law, k)
        assert fast.commands == python.commands and fast.modes == python.modes
        assert any(1.0 in row for row in python.modes) and any(0.0 in row for row in python.modes)  # both sides met
    assert met > 100
