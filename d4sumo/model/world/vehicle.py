"""A car's body: its size, its limits and its drivetrain (`Actuator`), the map from a throttle/brake
command to the acceleration it asks for, and the SUMO vehicle class and shape it is given.

Pure code, no SUMO: SUMO's classes and shapes are its names for them, which a car's [vehicle] table
is checked against.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any, Mapping

from ... import ledger
from ...errors import ConfigError, check_keys, check_number

#: SUMO's classes of road vehicle (its vClass): a lane's permissions say which may drive on it
VEHICLE_CLASSES = ("passenger", "private", "taxi", "hov", "emergency", "authority", "army", "vip", "evehicle", "delivery",
                   "truck", "trailer", "bus", "coach", "motorcycle", "moped", "custom1", "custom2")
#: how sumo-gui draws a car (SUMO's guiShape; "": the class's own shape)
GUI_SHAPES = ("", "passenger", "passenger/sedan", "passenger/hatchback", "passenger/wagon", "passenger/van", "delivery",
              "truck", "truck/semitrailer", "truck/trailer", "bus", "bus/city", "bus/flexible", "bus/overland", "evehicle",
              "emergency", "firebrigade", "police", "motorcycle", "moped", "scooter", "unknown")


@dataclass(frozen=True)
class VehicleParams:
    """Vehicle body and actuator: [vehicle] for every car, and a [vehicle.vI] table for a car that differs
    (`EpisodeConfig.vehicle_of`)."""

    length_m: float = 4.5
    max_accel_mps2: float = 3.5  # at full throttle, u = +1
    max_decel_mps2: float = 8.0  # at full brake, u = -1 (a positive number)
    actuator_lag_s: float = 0.5  # first-order lag between command and acceleration
    #: a moving car's deceleration with no pedal (engine braking, drag, rolling resistance), added to what
    #: the pedal asks for; 0: none (the model as printed). Not a calibration of any car: CARLA's figures
    #: are not in the authors' code.
    coast_decel_mps2: float = 0.0
    #: SUMO's vehicle class: which lanes it may use (a road that closes a lane of the platoon's to it is
    #: refused); the car's dimensions and limits are the keys above, never the class's defaults
    vclass: str = "passenger"
    shape: str = ""  # how sumo-gui draws it (SUMO's guiShape; "": the class's own)

    def __post_init__(self) -> None:
        for name, low, high, unit in (("length_m", 0.5, 30.0, "metres"), ("max_accel_mps2", 0.1, 20.0, "m/s^2"),
                                      ("max_decel_mps2", 0.1, 20.0, "m/s^2 (positive)"), ("actuator_lag_s", 0.0, 5.0, "seconds"),
                                      ("coast_decel_mps2", 0.0, 5.0, "m/s^2 (positive)")):
            object.__setattr__(self, name, check_number(f"vehicle.{name}", getattr(self, name), low, high, unit))
        if self.vclass not in VEHICLE_CLASSES:
            raise ConfigError("vehicle.vclass", self.vclass, f"one of SUMO's road vehicle classes: {', '.join(VEHICLE_CLASSES)}")
        if self.shape not in GUI_SHAPES:
            raise ConfigError("vehicle.shape", self.shape, f"one of SUMO's shapes: {', '.join(s for s in GUI_SHAPES if s)}, or \"\"")

    def to_dict(self) -> dict:
        """As a definition stores it: the keys added after the first (coasting, class, shape) only where
        they differ from their defaults (campaigns stored before them keep their identity)."""
        return ledger.stored("vehicle", dataclasses.asdict(self))



def command_to_acceleration(u: float, vehicle: VehicleParams) -> float:
    """Map a throttle/brake command in [-1, 1] to the acceleration it asks for [m/s^2]."""
    return u * vehicle.max_accel_mps2 if u >= 0.0 else u * vehicle.max_decel_mps2


def acceleration_to_command(a_mps2: float, vehicle: VehicleParams) -> float:
    """The low-level controller: a wanted acceleration to throttle (u > 0) or brake (u < 0), never both."""
    u = a_mps2 / vehicle.max_accel_mps2 if a_mps2 >= 0.0 else a_mps2 / vehicle.max_decel_mps2
    return 1.0 if u > 1.0 else (-1.0 if u < -1.0 else u)


class Actuator:
    """A car's drivetrain: command -> first-order-lagged acceleration -> speed (never below 0).

    The lag is discretised exactly for a command held over one step. The speed is integrated from
    the sensed speed, so the simulator stays the single source of the car's state.
    """

    __slots__ = ("accel_max", "decel_max", "alpha", "step_s", "max_speed_mps", "accel_mps2", "coast")

    def __init__(self, vehicle: VehicleParams, step_s: float, max_speed_mps: float = math.inf):
        self.accel_max = vehicle.max_accel_mps2
        self.decel_max = vehicle.max_decel_mps2
        lag = vehicle.actuator_lag_s
        self.alpha = 1.0 if lag <= 0.0 else 1.0 - math.exp(-step_s / lag)
        self.step_s = step_s
        self.max_speed_mps = max_speed_mps
        self.accel_mps2 = 0.0
        self.coast = vehicle.coast_decel_mps2

    def apply(self, u: float, speed_mps: float) -> float:
        """Hold command u for one step from ``speed_mps``; return the speed at the step's end [m/s]."""
        target = u * self.accel_max if u >= 0.0 else u * self.decel_max
        self.accel_mps2 += (target - self.accel_mps2) * self.alpha
        drag = self.coast if speed_mps > 0.0 else 0.0  # a standing car does not roll back
        v = speed_mps + (self.accel_mps2 - drag) * self.step_s if drag else speed_mps + self.accel_mps2 * self.step_s
        if v < 0.0:  # brakes stop the car, they never reverse it
            v = 0.0
        elif v > self.max_speed_mps:
            v = self.max_speed_mps
        else:
            return v
        # Clamped: the drivetrain's acceleration is what the car actually did, so the lag does not
        # wind up while the car stands still or rides the speed limit.
        self.accel_mps2 = (v - speed_mps) / self.step_s + drag
        return v


def car_tables(given: Any, vehicle: VehicleParams, ids: tuple[str, ...], followers: int) -> tuple[tuple[str, tuple], ...]:
    """The [vehicle.vI] tables (a mapping, or (car id, table) pairs), checked (a car of the platoon, whose ids are
    ``ids``, keys of [vehicle], values in range) and reduced to what differs from ``vehicle``: a table that
    changes nothing is dropped."""
    if isinstance(given, Mapping):
        given = tuple(given.items())
    if not isinstance(given, (list, tuple)) or not all(isinstance(t, (list, tuple)) and len(t) == 2 for t in given):
        raise ConfigError("vehicle", given, "a [vehicle.vI] table per car that differs")
    keys = [f.name for f in dataclasses.fields(VehicleParams)]
    base = dataclasses.asdict(vehicle)
    out = {}
    for car, table in given:
        if car not in ids:
            raise ConfigError(f"vehicle.{car}", _short_table(table),
                              f"a car of this platoon: {', '.join(ids)} (v0 the attacker, v1..v{followers} the followers)")
        table = dict(table) if isinstance(table, (Mapping, list, tuple)) else table
        if not isinstance(table, dict):
            raise ConfigError(f"vehicle.{car}", table, "a table of [vehicle] keys")
        check_keys(f"vehicle.{car}", table, keys)
        try:
            own = VehicleParams(**{**base, **table})
        except ConfigError as exc:  # name the car's table: vehicle.v2.length_m
            raise ConfigError(exc.field.replace("vehicle.", f"vehicle.{car}.", 1), exc.given, exc.allowed) from None
        differs = tuple((k, v) for k, v in dataclasses.asdict(own).items() if v != base[k])
        if differs:
            out[car] = differs
    return tuple(sorted(out.items(), key=lambda item: ids.index(item[0])))


def _short_table(table: Any) -> Any:
    return dict(table) if isinstance(table, (list, tuple)) and all(isinstance(t, (list, tuple)) and len(t) == 2 for t in table) else table
