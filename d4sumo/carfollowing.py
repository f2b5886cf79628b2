"""SUMO's own car-following models as systems under test: their names and the attributes each accepts.

A follower controller named ``sumo:MODEL`` (``sumo:ACC``, ``sumo:CACC``, ``sumo:IDM``, ...) is driven by
SUMO's model of that name. SUMO silently ignores a vehicle-type attribute its model does not read, so
names and types are checked here against the schema of the installed SUMO (``data/xsd/types/route.xsd``:
one ``carFollowing-MODEL`` type per model); SUMO itself checks the values when it loads the type
(`simulation.check_followers`). No SUMO process runs here.

What d4sumo sets itself, from the rest of the config, and a user may not override in the table:
the body and drivetrain limits of the car (``length``, ``accel``, ``emergencyDecel`` from ``[vehicle]``),
the desired speed (``maxSpeed`` = the target speed, ``speedFactor`` 1, ``speedDev`` 0) and, for ``CC``,
``lanesCount`` (from the road). Everything else not given keeps SUMO's default for the model.
"""

from __future__ import annotations

import functools
import math
import xml.etree.ElementTree as ET
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping

from .errors import ConfigError, check_int, check_number, is_number

PREFIX = "sumo:"
XSD = "{http://www.w3.org/2001/XMLSchema}"

#: Attributes of every model that shape its car following (the model's own come from the schema).
COMMON = ("tau", "minGap", "decel", "apparentDecel", "actionStepLength", "sigma")
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
#: d4sumo's own keys in a sumo: table (snake_case, unlike SUMO's attributes).
SPEED_MODE_DEFAULT = 31  # SUMO's default: every safety check on
#: Plexe's CC model runs one of its controllers; the others need data fed in by the application.
CC_CONTROLLERS = {"DRIVER": 0, "ACC": 1}


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
        if self.kind == "int":
            return check_int(field, value, int(max(self.low, -1e9)), int(min(self.high, 1e9)))
        low, high = max(self.low, -1e9), min(self.high, 1e9)
        return check_number(field, value, low, high, low_open=self.low_open)


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
    from .scenarios import sumo_home

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


def model_of(name: str) -> str:
    """The SUMO model of a ``sumo:MODEL`` controller name, checked."""
    model = name[len(PREFIX):]
    known = models()
    if model not in known:
        raise ConfigError("controller.class", name, f"one of {', '.join(PREFIX + m for m in sorted(known))}")
    return model


def check_params(name: str, values: Mapping[str, Any], field: str = "controller") -> tuple[tuple[str, Any], ...]:
    """The table of a ``sumo:MODEL`` controller: SUMO attributes of that model plus d4sumo's own keys
    (``speed_mode``; ``active_controller`` for CC), checked and with d4sumo's defaults filled in."""
    model = model_of(name)
    attributes = models()[model]
    out: dict[str, Any] = {}
    for key, value in values.items():
        where = f"{field}.{key}"
        if key == "speed_mode":
            out[key] = check_int(where, value, 0, 255)
        elif key == "active_controller" and model == "CC":
            if value not in CC_CONTROLLERS:
                raise ConfigError(where, value, f"one of {', '.join(CC_CONTROLLERS)}")
            out[key] = value
        elif key in SET_BY_D4SUMO:
            raise ConfigError(where, value, f"not set here: d4sumo sets {key} from {SET_BY_D4SUMO[key]}")
        elif key in attributes:
            if not (is_number(value) or isinstance(value, (bool, str))):
                raise ConfigError(where, value, "a number, true/false or a string")
            out[key] = attributes[key].check(where, value)
        else:
            own = ["speed_mode"] + (["active_controller"] if model == "CC" else [])
            raise ConfigError(where, value, f"an attribute SUMO's {model} model reads: {', '.join(sorted(attributes) + own)}")
    out.setdefault("speed_mode", SPEED_MODE_DEFAULT)
    if model == "CC":
        out.setdefault("active_controller", "ACC")
    return tuple(sorted(out.items()))


def vtype_attributes(model: str, params: Mapping[str, Any]) -> dict[str, str]:
    """The model's attributes as SUMO reads them in a <vType> (d4sumo's own keys left out)."""
    out = {"carFollowModel": model}
    for key, value in params.items():
        if key in ("speed_mode", "active_controller"):
            continue
        out[key] = ("true" if value else "false") if isinstance(value, bool) else (value if isinstance(value, str) else repr(float(value)) if isinstance(value, float) else str(value))
    return out
