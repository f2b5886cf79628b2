"""SUMO's own car-following models as systems under test: their names and the attributes each accepts.

A follower controller named ``sumo:MODEL`` (``sumo:ACC``, ``sumo:CACC``, ``sumo:IDM``, ...) is driven by
SUMO's model of that name. SUMO silently ignores a vehicle-type attribute its model does not read, so
names and types are checked here against the schema of the installed SUMO (``data/xsd/types/route.xsd``:
one ``carFollowing-MODEL`` type per model); SUMO itself checks the values when it loads the type
(`simulation.check_followers`). No SUMO process runs here.

What d4sumo sets itself, from the rest of the config, and a user may not override in the table:
the body and drivetrain limits of the car (``length``, ``accel``, ``emergencyDecel`` from ``[vehicle]``),
the desired speed (``maxSpeed`` = the target speed, ``speedFactor`` 1, ``speedDev`` 0) and, for ``CC``,
``lanesCount`` (from the road). ``sigma`` (a driver's random dawdling) defaults to 0: the followers are
deterministic, like the attacker. Everything else not given keeps SUMO's default for the model, and the
followers run with SUMO's default speed mode (31: SUMO applies it only to speeds set through TraCI, which
d4sumo never sets for them).
"""

from __future__ import annotations

import functools
import math
import numbers
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from ...errors import ConfigError, is_number

PREFIX = "sumo:"
XSD = "{http://www.w3.org/2001/XMLSchema}"

#: Attributes of every model that shape its car following (the model's own come from the schema).
COMMON = ("tau", "minGap", "decel", "apparentDecel", "actionStepLength")
#: Set by d4sumo from the rest of the config: a follower is the same car as the attacker.
SET_BY_D4SUMO = {
    "length": "vehicle.length_m",
    "accel": "vehicle.max_accel_mps2",
    "emergencyDecel": "vehicle.max_decel_mps2",
    "maxSpeed": "scenario.speed_mps (the followers' desired speed)",
    "desiredMaxSpeed": "scenario.speed_mps (the followers' desired speed)",
    "speedFactor": "scenario.speed_mps (the followers' desired speed)",
    "speedDev": "scenario.speed_mps (the followers' desired speed)",
    "lanesCount": "the road's lanes",
}
#: d4sumo's defaults where SUMO's would make the followers random: a driver's dawdling (Krauss-type
#: models draw it from SUMO's own random stream, which the campaign's seed does not reach).
DEFAULTS = {"sigma": 0.0}
#: Models whose motion (with ``sigma`` 0 where they have it) depends on nothing but the cars around:
#: their platoons may share one SUMO (a batch). The others draw from SUMO's random streams, which SUMO
#: deals out by the order in which cars enter the simulation, so beside other platoons they would drive
#: differently (EIDM, W99, Wiedemann, BKerner, PWagner2009 did in tests/test_simulation.py).
SHARE_SUMO = frozenset({"ACC", "CACC", "CC", "Daniel1", "IDM", "IDMM", "Krauss", "KraussOrig1", "KraussPS", "SmartSK"})


def shares_sumo(model: str, params: Mapping[str, Any]) -> bool:
    """Whether a follower driven by ``model`` with ``params`` drives alike whatever else SUMO simulates. Not
    Plexe's CONSENSUS: it reads GPS positions, whose rounding depends on where on the map its road is (a
    batch's copies of the road lie elsewhere), so on a curving road a batch would drift from alone by
    1e-13 m and, in time, change a verdict."""
    return (model in SHARE_SUMO and float(params.get("sigma", DEFAULTS["sigma"])) == 0.0
            and not hears_all(model, params))


#: Plexe's CC model runs one of its controllers (its ACTIVE_CONTROLLER); the cooperative ones read the V2V
#: beacons the application feeds in (d4sumo's channel, `v2v`), the others do without
CC_CONTROLLERS = {"DRIVER": 0, "ACC": 1, "CACC": 2, "PLOEG": 4, "CONSENSUS": 5, "FLATBED": 6}
CC_COOPERATIVE = frozenset({"CACC", "PLOEG", "CONSENSUS", "FLATBED"})
#: the most cars a platoon of Plexe's CONSENSUS may have (its MAX_N_CARS)
CC_CONSENSUS_CARS = 8


def listens(model: str, params: Mapping[str, Any]) -> bool:
    """Whether SUMO's ``model`` with ``params`` reads V2V beacons (Plexe's cooperative controllers)."""
    return model == "CC" and params.get("active_controller") in CC_COOPERATIVE


def hears_all(model: str, params: Mapping[str, Any]) -> bool:
    """Whether SUMO's ``model`` with ``params`` reads every car ahead's beacons (Plexe's CONSENSUS)."""
    return model == "CC" and params.get("active_controller") == "CONSENSUS"


def vehicle_data(message, x_m: float, y_m: float, heading: tuple[float, float]) -> str:
    """A beacon as Plexe's CONSENSUS takes it (its CC_PAR_VEHICLE_DATA: index, speed, acceleration, x, y,
    time, length, controller acceleration, speed x, speed y, angle, ':' between), its position and speed
    laid out from ``(x_m, y_m)`` along ``heading`` (a unit vector): the receiver's own place, less its
    distance along the road, so that Plexe's GPS distance is the distance along the road."""
    m = message
    hx, hy = heading
    return ":".join((str(m.sender), *(repr(float(v)) for v in (
        m.speed_mps, m.accel_mps2, x_m, y_m, m.time_s, m.length_m, m.accel_mps2, hx * m.speed_mps, hy * m.speed_mps, 0.0))))


def beacon_parameters(message) -> dict[str, str]:
    """A beacon as Plexe's CC model takes it (its PAR_LEADER_SPEED_AND_ACCELERATION and
    PAR_PRECEDING_SPEED_AND_ACCELERATION: speed, acceleration, x, y, time, controller acceleration, vx,
    vy, angle, ':' between): the position along the road as x, the acceleration as both."""
    m = message
    return ":".join(repr(float(v)) for v in (m.speed_mps, m.accel_mps2, m.position_m, 0.0, m.time_s, m.accel_mps2,
                                             m.speed_mps, 0.0, 0.0))


@dataclass(frozen=True)
class AttributeType:
    kind: str  # "float", "int", "bool" or "str"
    low: float = -math.inf
    high: float = math.inf
    low_open: bool = False

    def check(self, field: str, value: Any) -> Any:
        if self.kind == "bool":
            if not isinstance(value, bool):
                raise ConfigError(field, value, "true or false")
            return value
        if self.kind == "str":
            if not isinstance(value, str):
                raise ConfigError(field, value, "a string")
            return value
        whole = self.kind == "int"
        ok = (isinstance(value, numbers.Integral) if whole else is_number(value)) and not isinstance(value, bool)
        ok = ok and math.isfinite(float(value)) and (self.low < value if self.low_open else self.low <= value) and value <= self.high
        if not ok:
            raise ConfigError(field, value, f"{'a whole number' if whole else 'a number'}{self.range_text()}")
        return int(value) if whole else float(value)

    def range_text(self) -> str:
        bounds = []
        if self.low > -math.inf:
            bounds.append(f"{'>' if self.low_open else '>='} {self.low:g}")
        if self.high < math.inf:
            bounds.append(f"<= {self.high:g}")
        return (" " + " and ".join(bounds)) if bounds else ""


_TYPES = {
    "floatType": AttributeType("float"),
    "xsd:float": AttributeType("float"),
    "positiveFloatType": AttributeType("float", 0.0, low_open=True),
    "nonNegativeFloatType": AttributeType("float", 0.0),
    "nonNegativeFloatTypeWithErrorValue": AttributeType("float", 0.0),
    "positiveIntType": AttributeType("int", 1),
    "xsd:int": AttributeType("int"),
    "boolType": AttributeType("bool"),
    "xsd:string": AttributeType("str"),
}


def schema_path() -> Path:
    """The vehicle-type schema of the SUMO that d4sumo runs."""
    from ...sumohome import sumo_home

    path = Path(sumo_home()) / "data" / "xsd" / "types" / "route.xsd"
    if not path.is_file():
        raise ConfigError("controller.class", "sumo:", f"a SUMO installation with its schema ({path} is missing)")
    return path


@functools.lru_cache(maxsize=None)
def models() -> dict[str, dict[str, AttributeType]]:
    """Every car-following model SUMO's schema declares, with the attributes a user may set."""
    root = ET.parse(schema_path()).getroot()
    types = {t.get("name"): t for t in root.iter(f"{XSD}complexType")}
    base = _attributes(types["vTypeBaseType"])
    common = {name: base[name] for name in COMMON if name in base}
    out: dict[str, dict[str, AttributeType]] = {}
    for element in types["vTypeBaseType"].iter(f"{XSD}element"):
        name = element.get("name", "")
        if name.startswith("carFollowing-"):
            own = _attributes(types[element.get("type")])
            attributes = {**common, **own}
            out[name.removeprefix("carFollowing-")] = {k: v for k, v in attributes.items() if k not in SET_BY_D4SUMO}
    return out


def _attributes(complex_type: ET.Element) -> dict[str, AttributeType]:
    out = {}
    for attribute in complex_type.iter(f"{XSD}attribute"):
        name, type_name = attribute.get("name"), attribute.get("type")
        if type_name is None:  # an inline restriction, e.g. sigma in [0, 1]
            restriction = attribute.find(f".//{XSD}restriction")
            kind = AttributeType("float")
            if restriction is not None and restriction.get("base") == "xsd:float":
                low = restriction.find(f"{XSD}minInclusive")
                high = restriction.find(f"{XSD}maxInclusive")
                kind = AttributeType("float", float(low.get("value")) if low is not None else -math.inf,
                                     float(high.get("value")) if high is not None else math.inf)
            out[name] = kind
        else:
            out[name] = _TYPES.get(type_name, AttributeType("str"))
    return out


def is_sumo(name: Any) -> bool:
    return isinstance(name, str) and name.startswith(PREFIX)


def model_of(name: str, where: str = "controller") -> str:
    """The SUMO model of a ``sumo:MODEL`` controller name, checked."""
    model = name[len(PREFIX):]
    known = models()
    if model not in known:
        raise ConfigError(f"{where}.class", name, f"one of {', '.join(PREFIX + m for m in sorted(known))}")
    return model


def check_params(name: str, values: Mapping[str, Any], where: str = "controller") -> tuple[tuple[str, Any], ...]:
    """The table of a ``sumo:MODEL`` controller: SUMO attributes of that model (plus ``active_controller``
    for CC), checked, with d4sumo's defaults filled in."""
    model = model_of(name, where)
    attributes = models()[model]
    out: dict[str, Any] = {}
    for key, value in values.items():
        field = f"{where}.{key}"
        if key == "active_controller" and model == "CC":
            if value not in CC_CONTROLLERS:
                raise ConfigError(field, value, f"one of {', '.join(CC_CONTROLLERS)}")
            out[key] = value
        elif key in SET_BY_D4SUMO:
            raise ConfigError(field, value, f"not set here: d4sumo sets {key} from {SET_BY_D4SUMO[key]}")
        elif key in attributes:
            out[key] = attributes[key].check(field, value)
        else:
            own = ["active_controller"] if model == "CC" else []
            raise ConfigError(field, value, f"an attribute SUMO's {model} model reads: {', '.join(sorted(attributes) + own)}")
    for key, value in DEFAULTS.items():
        if key in attributes:
            out.setdefault(key, value)
    if model == "CC":
        out.setdefault("active_controller", "ACC")
    return tuple(sorted(out.items()))


def vtype_attributes(model: str, params: Mapping[str, Any], *, lanes: int = 1) -> dict[str, str]:
    """The model's attributes as SUMO reads them in a <vType> (d4sumo's own keys left out)."""
    out = {"carFollowModel": model}
    if model == "CC":  # Plexe's model must know the road's lanes
        out["lanesCount"] = str(lanes)
    for key, value in params.items():
        if key == "active_controller":
            continue
        if isinstance(value, bool):
            out[key] = "true" if value else "false"
        else:
            out[key] = value if isinstance(value, str) else repr(value)
    return out


def runtime_parameters(model: str, params: Mapping[str, Any], speed_mps: float, car: int = 1) -> dict[str, str]:
    """Per-vehicle parameters SUMO's model reads after insertion (TraCI's setParameter), by key (``car``:
    the follower's index, 1 for v1)."""
    if model != "CC":
        return {}
    # Plexe's CC: which of its controllers drives, and the cruise speed it holds
    out = {"carFollowModel.ccac": str(CC_CONTROLLERS[params["active_controller"]]), "carFollowModel.ccds": repr(speed_mps)}
    if params["active_controller"] == "CONSENSUS":  # its place in the platoon, of which it reads the cars ahead
        out.update({"carFollowModel.ccvp": str(car), "carFollowModel.ccps": str(car + 1)})
    return out
