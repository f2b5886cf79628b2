"""Traffic lights, as a driver of the platoon obeys them. Pure code, no SUMO.

The driver overrides the car's controller (the ACC, a cruise control, the attacker's pedals) where a
signal ahead demands it, as SUMO's own drivers do: the car's command is the lesser of the controller's
and the one that stops it at the stop line. The rule, each step, for the next signal on the car's way
(`Stop`: which one, the distance from the car's front bumper to its stop line, and its state, SUMO's link
state letter):

- red (``r``, ``R``) or red-yellow (``u``): stop;
- yellow (``y``, ``Y``), the first time the car sees it so: stop if it can at a comfortable deceleration
  (`COMFORTABLE_DECEL_MPS2`, or its full brake if that is less); where it cannot, it drives on, and on
  through that signal should it turn red before the car reaches the line (it is committed, as a driver at
  an amber light is);
- any other state (green, off, blinking): drive on.

A car that stops is held below the speed from which the comfortable deceleration b stops it before the
line, as SUMO's drivers are (Krauss's stopping speed), counting the distance it covers while its
actuator's lag T brings the brakes on: v T + v^2 / (2 b) = d, d the distance to a margin before the line
(`STOP_MARGIN_M`). It drives on until then, brakes along it, harder where the signal turned red too near
for it (up to full brake), and creeps up to the line where it stopped short. It asks for the acceleration
that follows that speed as it falls, plus what reaches it over twice its lag (one step without a lag), as a
command (`vehicle.acceleration_to_command`).
"""

from __future__ import annotations

import math
from typing import NamedTuple

from .vehicle import VehicleParams, acceleration_to_command

#: SUMO's default comfortable deceleration of a passenger car [m/s^2]: its drivers stop for amber when this stops them
COMFORTABLE_DECEL_MPS2 = 4.5
#: where a stopping car aims, before the stop line [m]
STOP_MARGIN_M = 1.0
RED = frozenset("rRu")
YELLOW = frozenset("yY")


class Stop(NamedTuple):
    """The next signal on a car's way: which one (its index along the route), the distance from the car's front
    bumper to its stop line [m], and its state (SUMO's link state letter)."""

    signal: int
    distance_m: float
    state: str


def light_code(stop: Stop | None) -> float:
    """What a car sees of the next light, as a number a trace holds: 2 red (or red-yellow), 1 amber, 0 green or
    none within reach."""
    if stop is None:
        return 0.0
    return 2.0 if stop.state in RED else 1.0 if stop.state in YELLOW else 0.0


class SignalDriver:
    """One car's driver at the route's signals: the command its signals allow (see the module)."""

    __slots__ = ("vehicle", "lag_s", "reach_s", "comfortable_mps2", "committed", "stopping")

    def __init__(self, vehicle: VehicleParams, step_s: float):
        self.vehicle = vehicle
        self.lag_s = vehicle.actuator_lag_s
        #: how soon it means to be at the speed it aims for: over twice its lag, the speed settles without
        #: overshooting much (a damping of 0.7)
        self.reach_s = max(2.0 * vehicle.actuator_lag_s, step_s)
        self.comfortable_mps2 = min(COMFORTABLE_DECEL_MPS2, vehicle.max_decel_mps2)
        self.committed = -1  # the signal it drives on through, having found it amber too near to stop
        self.stopping = -1  # the signal it stops for

    def limit(self, stop: Stop | None, speed_mps: float) -> float:
        """The highest command the signal ahead allows: 1.0 (full throttle) where it does not demand a stop."""
        if stop is None:  # no light within reach asks anything: a stop decided at amber is over
            self.stopping = -1
            return 1.0
        if stop.signal == self.committed:
            return 1.0
        red = stop.state in RED
        if not red and stop.state not in YELLOW:
            self.stopping = -1  # green again: a stop decided at amber is over
            return 1.0
        room = stop.distance_m - STOP_MARGIN_M - speed_mps * self.lag_s
        needed = speed_mps * speed_mps / (2.0 * room) if room > 0.0 else (0.0 if speed_mps == 0.0 else float("inf"))
        if not red and stop.signal != self.stopping and needed > self.comfortable_mps2:
            self.committed = stop.signal  # amber too near to stop: through it, even if it turns red
            return 1.0
        self.stopping = stop.signal
        # the speed from which braking comfortably, once its lag has passed, stops it before the line:
        # v lag + v^2 / (2 b) = the distance to it
        b, lag, line = self.comfortable_mps2, self.lag_s, stop.distance_m - STOP_MARGIN_M
        root = math.sqrt((b * lag) ** 2 + 2.0 * b * line) if line > 0.0 else b * lag
        aim = root - b * lag
        # along that speed, as the car nears the line (at its speed), plus what brings it back to it
        along = -speed_mps * b / root if root > 0.0 else 0.0
        return acceleration_to_command(along + (aim - speed_mps) / self.reach_s, self.vehicle)
