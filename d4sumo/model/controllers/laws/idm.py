"""The Intelligent Driver Model (Treiber, Hennecke and Helbing, 2000) as a follower's law on d4sumo's
radar and actuator: the car-following model of traffic science, here a foil for the paper's ACC (no mode
to switch, a smooth brake that grows with the square of how much closer the car ahead is than wanted).

a = a_max (1 - (v / v0)^delta - (s* / s)^2),  s* = s0 + max(0, v T + v (v - v_lead) / (2 sqrt(a_max b)))

with s the bumper gap its radar measures, v0 the scenario's target speed and s0 its setpoint (the gap at
standstill, as the time-gap controller has it). Where its radar sees nobody, the free-road term alone. The
wanted acceleration becomes the pedal through the car's own limits (`vehicle.acceleration_to_command`).
SUMO's own IDM, which SUMO drives, is ``sumo:IDM`` (`carfollowing`). Where the paper's controller steps in C, so
does this law (`compiled`, csrc/laws.h: the same operations on the same doubles; tests/model/controllers/test_compiled.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from ....errors import check_number
from ...world.vehicle import VehicleParams, acceleration_to_command


@dataclass(frozen=True)
class IDMParams:
    """Treiber and Kesting's values for a motorway (Traffic Flow Dynamics, 2013), the setpoint as s0."""

    time_gap_s: float = 1.0  # T: the time gap wanted in steady following
    accel_mps2: float = 1.0  # a_max: the acceleration it drives with (the car's limit bounds it too)
    comfortable_decel_mps2: float = 1.5  # b
    delta: float = 4.0  # how the free-road acceleration falls as the speed nears the target

    def __post_init__(self) -> None:
        for name, low, unit in (("time_gap_s", 0.0, "seconds"), ("accel_mps2", 1e-3, "m/s^2"),
                                ("comfortable_decel_mps2", 1e-3, "m/s^2"), ("delta", 1e-3, "an exponent")):
            object.__setattr__(self, name, check_number(f"controller.{name}", getattr(self, name), low, 100.0, unit))


class IDMController:
    """The IDM on what the radar measured (see the module)."""

    law_name = "idm"
    Params = IDMParams

    def __init__(self, params: IDMParams, *, setpoint_m: float, target_speed_mps: float, vehicle: VehicleParams,
                 step_s: float):
        self.params, self.vehicle = params, vehicle
        self.s0_m, self.v0_mps = setpoint_m, target_speed_mps
        self._root_ab = 2.0 * math.sqrt(params.accel_mps2 * params.comfortable_decel_mps2)

    def observe(self, o) -> float:
        p, v = self.params, o.speed_mps
        free = 1.0 - (v / self.v0_mps) ** p.delta if self.v0_mps > 0.0 else -1.0
        if not o.leader:
            return acceleration_to_command(p.accel_mps2 * free, self.vehicle)
        wanted = self.s0_m + max(0.0, v * p.time_gap_s - v * o.relative_speed_mps / self._root_ab)
        gap = max(o.gap_m, 1e-3)  # touching: the strongest brake its limits allow
        return acceleration_to_command(p.accel_mps2 * (free - (wanted / gap) ** 2), self.vehicle)
