"""The control laws over arrays: many episodes (and followers) in one numpy operation.

A batch of episodes played side by side (`batch`) runs these instead of one object per car. Each
performs, element by element, exactly the floating-point operations of its scalar counterpart in `control`,
in the same order, so an episode played in a batch is bit for bit the episode played alone (a test
checks it). Every method takes and returns arrays of one shape (episodes, or episodes x cars).
Constants are 0-d arrays: numpy combines them with an array a third faster than a Python float,
with the same result.
"""

from __future__ import annotations

import math

import numpy as np

from .control import (
    GAP_TOLERANCE_M, MODE_ACC, MODE_CC, SwitchingController, SwitchingParams, TimeGapController, VehicleParams)


def _c(value: float) -> np.ndarray:
    return np.array(value, dtype=float)


def per_row(values, shape: tuple[int, ...]) -> np.ndarray:
    """A value that may differ between episodes (rows: a batch of several campaigns' episodes): a 0-d
    array when it is the same in every row, else one value per row, broadcasting against ``shape``.
    Each element is the very float the scalar code uses, so the arithmetic stays the same."""
    values = [float(v) for v in values]
    if len(set(values)) <= 1:
        return _c(values[0])
    return np.array(values, dtype=float).reshape((len(values),) + (1,) * (len(shape) - 1))


_ZERO, _ONE, _MINUS_ONE = _c(0.0), _c(1.0), _c(-1.0)


class ActuatorArray:
    """`Actuator` over an array of cars; ``max_speed_mps`` broadcasts against the cars' shape. ``lags_s``: each
    row's actuator lag where it differs from row to row (`per_row`; none: the vehicle's)."""

    def __init__(self, vehicle: VehicleParams, step_s: float, shape: tuple[int, ...], max_speed_mps, lags_s=None):
        self.accel_max = _c(vehicle.max_accel_mps2)
        self.decel_max = _c(vehicle.max_decel_mps2)
        self.alpha = per_row([1.0 if lag <= 0.0 else 1.0 - math.exp(-step_s / lag) for lag in (lags_s or [vehicle.actuator_lag_s])],
                             shape)
        self.step_s = _c(step_s)
        self.max_speed_mps = np.broadcast_to(np.asarray(max_speed_mps, dtype=float), shape)
        self.accel_mps2 = np.zeros(shape)

    def apply(self, u: np.ndarray, speed_mps: np.ndarray) -> np.ndarray:
        target = u * np.where(u >= _ZERO, self.accel_max, self.decel_max)
        accel = self.accel_mps2 + (target - self.accel_mps2) * self.alpha
        v = speed_mps + accel * self.step_s
        clamped = np.minimum(np.maximum(v, _ZERO), self.max_speed_mps)
        hit = clamped != v
        if np.count_nonzero(hit):  # what the car actually did: no wind-up while clamped
            accel = np.where(hit, (clamped - speed_mps) / self.step_s, accel)
        self.accel_mps2 = accel
        return clamped


class CruiseArray:
    """`CruiseControl` over an array of cars; only the cars in ``active`` use it (and change its state).
    ``target_speed_mps``: one speed, or an array broadcasting against ``shape`` (`per_row`); ``params``: its gains,
    or each row's (a batch whose episodes search them)."""

    def __init__(self, params: "SwitchingParams | list[SwitchingParams]", target_speed_mps, step_s: float, shape: tuple[int, ...]):
        rows = params if isinstance(params, list) else [params]
        gain = lambda name, sign=1.0: per_row([sign * getattr(p, name) for p in rows], shape)  # noqa: E731
        self.kp, self.ki, self.kd = gain("cruise_kp"), gain("cruise_ki"), gain("cruise_kd")
        self.clamp, self.minus_clamp = gain("cruise_integral_clamp"), gain("cruise_integral_clamp", -1.0)
        self.limit, self.minus_limit = gain("cruise_output_limit_mps2"), gain("cruise_output_limit_mps2", -1.0)
        self.step_s = _c(step_s)
        self.target_mps = np.asarray(target_speed_mps, dtype=float)
        self.integral = np.zeros(shape)
        self.prev_error = np.zeros(shape)
        self.engaged = np.zeros(shape, dtype=bool)  # False: prev_error is None (no derivative kick)

    def disengage(self, where: np.ndarray) -> None:
        self.engaged &= ~where

    def reset(self, where: np.ndarray) -> None:
        self.integral = np.where(where, _ZERO, self.integral)
        self.engaged &= ~where

    def acceleration(self, speed_mps: np.ndarray, active: np.ndarray | None = None) -> np.ndarray:
        """The PID's output for every car; the state moves on for the ``active`` ones (None: all)."""
        e = self.target_mps - speed_mps
        i = np.minimum(np.maximum(self.integral + e * self.step_s, self.minus_clamp), self.clamp)
        d = np.where(self.engaged, (e - self.prev_error) / self.step_s, _ZERO)
        if active is None:
            self.integral, self.prev_error = i, e
            self.engaged[...] = True
        else:
            self.integral = np.where(active, i, self.integral)
            self.prev_error = np.where(active, e, self.prev_error)
            self.engaged |= active
        a = self.kp * e + self.ki * i + self.kd * d
        return np.minimum(np.maximum(a, self.minus_limit), self.limit)


class CommandArray:
    """`acceleration_to_command` over an array: a wanted acceleration to throttle/brake in [-1, 1]."""

    def __init__(self, vehicle: VehicleParams):
        self.accel_max, self.decel_max = _c(vehicle.max_accel_mps2), _c(vehicle.max_decel_mps2)

    def __call__(self, a_mps2: np.ndarray) -> np.ndarray:
        u = a_mps2 / np.where(a_mps2 >= _ZERO, self.accel_max, self.decel_max)
        return np.minimum(np.maximum(u, _MINUS_ONE), _ONE)


class SwitchingArray:
    """`SwitchingController` (or `TimeGapController`) over an array of followers (episodes x cars): built from one
    such controller per episode (row), whose setpoint, target speed and gains may differ from row to row (a batch
    of several campaigns' episodes, or of a campaign that searches them)."""

    def __init__(self, controllers: "SwitchingController | list[SwitchingController]", shape: tuple[int, ...], step_s: float):
        rows = controllers if isinstance(controllers, list) else [controllers]
        controller = rows[0]
        self.cruise = CruiseArray([c.params for c in rows], per_row([c.target_speed_mps for c in rows], shape), step_s, shape)
        self.mode = np.full(shape, MODE_CC)
        self._mode_known = False
        self._time_gap = isinstance(controller, TimeGapController)
        # the thresholds of Eq. 1's switch, with the same arithmetic as SwitchingController.select_mode
        self._setpoint = per_row([c.setpoint_m for c in rows], shape)
        self._cc_gap = per_row([c.setpoint_m + c._eps_x - GAP_TOLERANCE_M for c in rows], shape)
        self._acc_gap = per_row([c.setpoint_m + GAP_TOLERANCE_M for c in rows], shape)
        self._h = per_row([getattr(c, "time_gap_s", 0.0) for c in rows], shape)
        self._eps_x, self._tolerance = per_row([c._eps_x for c in rows], shape), _c(GAP_TOLERANCE_M)
        self._cc_speed = per_row([c._cc_speed for c in rows], shape)
        self._acc_speed = per_row([c._acc_speed for c in rows], shape)
        self._acc_kp, self._acc_kv = per_row([c._acc_kp for c in rows], shape), per_row([c._acc_kv for c in rows], shape)
        self._command = CommandArray(controller.vehicle)

    def command(self, gap_m: np.ndarray, speed_mps: np.ndarray, lead_speed_mps: np.ndarray) -> np.ndarray:
        if self._time_gap:  # d(v) = s0 + h v
            desired = self._setpoint + self._h * speed_mps
            cc_gap, acc_gap = desired + self._eps_x - self._tolerance, desired + self._tolerance
        else:
            desired, cc_gap, acc_gap = self._setpoint, self._cc_gap, self._acc_gap
        cc = (gap_m >= cc_gap) | (speed_mps >= self._cc_speed)
        acc = (gap_m <= acc_gap) & (speed_mps <= self._acc_speed)
        held = self.mode if self._mode_known else MODE_CC  # inside the hysteresis band at start: cruise
        mode = np.where(cc, MODE_CC, np.where(acc, MODE_ACC, held))
        changed = mode != self.mode
        if np.count_nonzero(changed):
            self.cruise.disengage(changed & (mode == MODE_ACC))
        self.mode = mode
        self._mode_known = True
        a = self._acc_kp * (gap_m - desired) + self._acc_kv * (lead_speed_mps - speed_mps)
        cruising = mode == MODE_CC
        if np.count_nonzero(cruising):
            a = np.where(cruising, self.cruise.acceleration(speed_mps, cruising), a)
        return self._command(a)


#: controller classes whose law also runs over arrays (exactly these classes: a subclass may change the law)
ARRAY_KERNELS: dict[type, type] = {SwitchingController: SwitchingArray, TimeGapController: SwitchingArray}
