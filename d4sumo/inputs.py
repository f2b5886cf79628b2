"""One input document for every way in: command-line flags, config files and sweep files.

A document is the tables of a config file:

    [scenario]   network, route, lane, followers, setpoint_m, speed_mps, start, step_s, duration_s, warmup_s,
                 maneuver (inlane, cutin, cutout, swerve) and its settings (cutin_follower, cutin_offset_m,
                 lane_change_s, obstacle_distance_m, obstacle_speed_mps, swerve_knots, swerve_lanes)
    [vehicle]    length_m, max_accel_mps2, max_decel_mps2, actuator_lag_s, coast_decel_mps2, vclass, shape;
                 [vehicle.v2] (any car: v0 the attacker, vI a follower, lead, obstacle): what differs for it
    [controller] class = "switching", "timegap", "sumo:MODEL" or "package.module:ClassName", and its
                 parameters; [[controller]] tables (one per follower, v1 first) for a mixed platoon
    [radar]      range_m, gap_noise_m, speed_noise_mps, latency_s, seed: what the followers' controllers
                 measure of the car ahead (none: the truth)
    [traffic]    vehicles_per_hour, warmup_s, clear_m, seed, [traffic.types.NAME] (share and SUMO <vType>
                 attributes): SUMO's traffic around the platoon (none: it drives alone)
    [v2v]        beacon_interval_s, latency_s, loss, seed: the platoon's V2V channel (cooperative controllers)
    [attack]     family, params (simulate only), and the families' options (knots: delta_s, horizon_s)
    [spec]       d_safe_m, formula
    [search]     optimizer, samples, seed; [search.bo], [search.ce]: the optimisers' options

Flags are dotted keys laid over the document (``--setpoint 5`` is ``scenario.setpoint_m = 5``,
``--set search.ce.batch_size=20`` any key), so a flag, a config file and a sweep file are checked by
the same code: every table for unknown keys, every value for its type and range, before anything runs.
"""

from __future__ import annotations

import copy
import dataclasses
import logging
from typing import Any, Mapping

import numpy as np

from . import sumocfg
from .errors import ConfigError, is_number
from .model.attacks.pedals import ATTACK_OPTIONS, FAMILIES, AttackFamily, make_attack, resolve_attack_options
from .model.config import EpisodeConfig, VehicleParams
from .model.definition import TABLES
from .tomlfiles import read_toml
from .model.world.sensing import RadarParams
from .model.world.traffic import TrafficParams
from .model.world.v2v import ChannelParams
from .model.attacks.messages import MESSAGE_KEYS, attack_box
from .search import situation
from .search.campaign import Campaign
from .presets import PRESETS, apply_preset
from .search.optimizers import DEFAULT_OPTIMIZER, OPTIMIZERS, resolve_options

SECTIONS = ("scenario", "vehicle", "controller", "radar", "traffic", "v2v", "attack", "spec", "search")
SCENARIO_KEYS = tuple(f.name for f in dataclasses.fields(EpisodeConfig) if f.name not in TABLES)
TABLE_KEYS: dict[str, tuple[str, ...]] = {
    "scenario": SCENARIO_KEYS,
    "vehicle": tuple(f.name for f in dataclasses.fields(VehicleParams)),
    "radar": tuple(f.name for f in dataclasses.fields(RadarParams)),
    "traffic": tuple(f.name for f in dataclasses.fields(TrafficParams)),
    "v2v": tuple(f.name for f in dataclasses.fields(ChannelParams)),
    "attack": ("family", "params", *MESSAGE_KEYS, *ATTACK_OPTIONS),
    "spec": ("d_safe_m", "formula"),
    "search": ("optimizer", "samples", "seed", "boundary", *OPTIMIZERS),
}


def read_document(path, field: str = "--config", extra_keys: tuple[str, ...] = ()) -> dict:
    """A config file's tables, checked (unknown tables and keys refused); ``extra_keys`` are other
    top-level keys the caller reads itself (a sweep file's name and grid)."""
    doc = read_toml(path, field)
    check_document(doc, str(path), extra_keys)
    return doc


def check_document(doc: Mapping[str, Any], source: str = "config", extra_keys: tuple[str, ...] = ()) -> None:
    for key, value in doc.items():
        if key in extra_keys:
            continue
        if key == "preset":
            if value not in PRESETS:
                raise ConfigError("preset", _short(value), f"one of {', '.join(PRESETS)}")
            continue
        if key not in SECTIONS:
            raise ConfigError(f"{source}: {key}", _short(value), f"the tables {', '.join(SECTIONS)}"
                              + (f" and {', '.join(extra_keys)}" if extra_keys else ""))
        if key == "controller" and isinstance(value, list):  # a mixed platoon: one table (or name) per follower
            for i, item in enumerate(value, 1):
                if not isinstance(item, (Mapping, str)):
                    raise ConfigError(f"controller.v{i}", _short(item), "a [[controller]] table or a controller name")
            continue
        if not isinstance(value, Mapping):
            raise ConfigError(f"{source}: [{key}]", _short(value), "a table")
        allowed = TABLE_KEYS.get(key)
        for k, v in value.items():
            if key == "vehicle" and isinstance(v, Mapping) and k not in allowed:  # [vehicle.vI]: a car's own table
                continue
            if allowed is not None and k not in allowed:
                raise ConfigError(f"{key}.{k}", _short(v), f"a key of [{key}]: {', '.join(allowed)}")
            if key == "search" and k in OPTIMIZERS and not isinstance(v, Mapping):
                raise ConfigError(f"search.{k}", _short(v), f"a table of {k}'s options ([search.{k}])")


def with_overrides(doc: Mapping[str, Any], overrides: Mapping[str, Any]) -> dict:
    """A copy of the document with dotted keys set (``scenario.setpoint_m``, ``search.ce.batch_size``)."""
    out = copy.deepcopy(dict(doc))
    for dotted, value in overrides.items():
        parts = dotted.split(".")
        if dotted == "controller":  # the whole system under test: a name, a table, or one per follower
            if not isinstance(value, (str, list, Mapping)):
                raise ConfigError("controller", _short(value), "a controller name, a table, or a list of them (one per follower)")
            out["controller"] = {"class": value} if isinstance(value, str) else copy.deepcopy(value)
            continue
        if dotted == "radar":  # a whole [radar] table (a sweep's grid.radar point; {} the perfect one)
            if not isinstance(value, Mapping):
                raise ConfigError("radar", _short(value), "a [radar] table, e.g. {gap_noise_m = 0.5, latency_s = 0.2}")
            out["radar"] = copy.deepcopy(dict(value))
            continue
        if dotted == "v2v":  # a whole [v2v] table (a sweep's grid.v2v point; {} the default channel)
            if not isinstance(value, Mapping):
                raise ConfigError("v2v", _short(value), "a [v2v] table, e.g. {latency_s = 0.2, loss = 0.1}")
            out["v2v"] = copy.deepcopy(dict(value))
            continue
        if dotted == "traffic":  # a whole [traffic] table (a sweep's grid.traffic point; {} none: the platoon alone)
            if not isinstance(value, Mapping):
                raise ConfigError("traffic", _short(value), "a [traffic] table, e.g. {vehicles_per_hour = 1200}")
            if value:
                out["traffic"] = copy.deepcopy(dict(value))
            else:
                out.pop("traffic", None)
            continue
        if len(parts) < 2 or parts[0] not in SECTIONS or not all(parts):
            raise ConfigError(dotted, _short(value), f"a key as TABLE.KEY with TABLE one of {', '.join(SECTIONS)}")
        if parts[0] == "controller" and isinstance(out.get("controller"), list):
            parts = _follower_key(out["controller"], dotted, value)
        table: Any = out
        for part in parts[:-1]:
            if isinstance(part, int):  # a follower's table in a mixed platoon
                table = table[part]
                continue
            child = table.get(part, {})
            if not (isinstance(child, dict) or (part == "controller" and isinstance(child, list))):
                raise ConfigError(dotted, _short(value), f"a key inside a table ({part} is not one)")
            table = table.setdefault(part, {})
        table[parts[-1]] = value
    check_document(out, "flags")
    return out


def _follower_key(controllers: list, dotted: str, value: Any) -> list:
    """In a mixed platoon a controller key names its follower (controller.v2.tau): the path to it,
    with the follower's entry made a table."""
    parts = dotted.split(".")
    names = [f"v{i}" for i in range(1, len(controllers) + 1)]
    if len(parts) < 3 or parts[1] not in names:
        raise ConfigError(dotted, _short(value), f"a key of one follower in a mixed platoon, as controller.VEHICLE.KEY "
                                                 f"with VEHICLE one of {', '.join(names)}")
    i = names.index(parts[1])
    if isinstance(controllers[i], str):
        controllers[i] = {"class": controllers[i]}
    return ["controller", i, *parts[2:]]


def _get(doc: Mapping[str, Any], dotted: str, default: Any = None) -> Any:
    table, _, key = dotted.partition(".")
    return doc.get(table, {}).get(key, default)


def episode_config(doc: Mapping[str, Any]) -> EpisodeConfig:
    _, searched = situation.split(doc)  # (a campaign's are taken out before)
    if searched:
        table, _, key = situation.field(searched[0][0]).partition(".")
        raise ConfigError(f"{table}.{key}", _short(doc[table][key]), "a single value: an episode plays one situation (falsify and sweep "
                                                        "search a range or choices)")
    expanded, note = sumocfg.expanded(doc)
    config = EpisodeConfig.from_dict(apply_preset(expanded))
    if note:  # said once the configuration is sound: bad input stays one line
        logging.getLogger("d4sumo.sumocfg").warning("%s", note)
    return config


def link_collision_distance(doc: Mapping[str, Any]) -> dict:
    """The document with the paper's psi and the collisions drawing their line at one distance: the psi
    scores a success where the outcome counts one only if ``spec.d_safe_m`` is ``scenario.collision_gap_m``.
    One given sets the other; both given and different is refused. A formula of one's own scores what it
    says, and leaves both as given."""
    doc = copy.deepcopy(dict(doc))
    spec, scenario = doc.get("spec", {}), doc.get("scenario", {})
    if not isinstance(spec, Mapping) or not isinstance(scenario, Mapping) or spec.get("formula") is not None:
        return doc
    d_safe, gap = spec.get("d_safe_m"), scenario.get("collision_gap_m")
    if d_safe is not None and gap is not None:
        if is_number(d_safe) and is_number(gap) and float(d_safe) != float(gap):
            raise ConfigError("spec.d_safe_m", d_safe, f"scenario.collision_gap_m ({gap!r} m): the paper's psi scores a success "
                                                       "where a collision is (or give spec.formula, a formula of your own)")
    elif d_safe is not None:
        if not (is_number(d_safe) and 0.0 <= float(d_safe) <= 5.0):
            raise ConfigError("spec.d_safe_m", _short(d_safe), "a number in [0, 5] m with the paper's psi (it is where a collision "
                                                               "is, scenario.collision_gap_m), or give spec.formula")
        doc.setdefault("scenario", {})["collision_gap_m"] = d_safe
    elif gap is not None:
        doc.setdefault("spec", {})["d_safe_m"] = gap
    return doc


def _family(doc: Mapping[str, Any], choices=FAMILIES) -> AttackFamily:
    name = _get(doc, "attack.family", "knots")
    if not isinstance(name, str) or name not in choices:
        raise ConfigError("attack.family", _short(name), f"one of {', '.join(choices)}")
    return make_attack(name, _attack_options(doc))


def _attack_options(doc: Mapping[str, Any]) -> dict[str, Any]:
    """The [attack] table's family options (every family's: each family reads its own)."""
    return {k: v for k, v in doc.get("attack", {}).items() if k in ATTACK_OPTIONS}


def _attack_box(doc: Mapping[str, Any]) -> AttackFamily:
    """The attack family of an episode: the signal family, with the lane change time when the
    maneuver changes lanes, and a message attack's parameters (`messages`)."""
    attack = doc.get("attack", {})
    return attack_box(episode_config(doc), _family(doc), attack.get("message", ""), attack.get("message_field", "accel"),
                      _attack_options(doc), attack.get("message_sender", 0))


def attack_of(doc: Mapping[str, Any]) -> tuple[AttackFamily | None, np.ndarray | None]:
    """The one attack an episode plays: (family, parameter vector), or (None, None) for no attack."""
    doc = apply_preset(doc)
    attack = doc.get("attack", {})
    resolve_attack_options("constant", _attack_options(doc))  # every option given is checked, read or not
    if "family" not in attack:
        if "params" in attack:
            raise ConfigError("attack.params", _short(attack["params"]), "parameters with an attack family (--attack or [attack] family)")
        lie = next((k for k in MESSAGE_KEYS if k in attack), None)
        if lie is not None:  # checked as a campaign checks it, then refused: with no attack, nothing lies
            _attack_box({**doc, "attack": {**attack, "message": attack.get("message", "offset")}})
            raise ConfigError(f"attack.{lie}", _short(attack[lie]), "a message attack beside an attack family and its "
                                                                    "params (--attack FAMILY --params ...): with no attack the "
                                                                    "attacker only cruises, and its beacons tell the truth")
        return None, None
    family = _attack_box(doc)
    if "params" not in attack:
        raise ConfigError("attack.params", None, f"{family.dimension} values for {family.name}: {', '.join(family.names)}")
    params = attack["params"]
    if not isinstance(params, (list, tuple)) or not all(is_number(v) for v in params):
        raise ConfigError("attack.params", _short(params), f"a list of {family.dimension} numbers for {family.name}: {', '.join(family.names)}")
    return family, family.check(params, "attack.params")


def campaign_of(doc: Mapping[str, Any]) -> Campaign:
    """The campaign a document describes (the optimiser chooses the attack's parameters)."""
    doc = apply_preset(link_collision_distance(doc), campaign=True)  # what the document sets wins over a preset
    if "params" in doc.get("attack", {}):
        raise ConfigError("attack.params", _short(doc["attack"]["params"]), "no fixed parameters in a campaign: the optimiser chooses them")
    fixed, ranges = situation.split(doc)
    config = episode_config(fixed if ranges else doc)
    family = _family(doc, tuple(f for f in FAMILIES if f != "constant"))
    optimizer = _get(doc, "search.optimizer", DEFAULT_OPTIMIZER)
    if not isinstance(optimizer, str) or optimizer not in OPTIMIZERS:
        raise ConfigError("search.optimizer", _short(optimizer), f"one of {', '.join(OPTIMIZERS)}")
    for name in OPTIMIZERS:  # every optimiser's table is checked, not only the one used
        if name in doc.get("search", {}):
            resolve_options(name, doc["search"][name])
    options = doc.get("search", {}).get(optimizer, {})
    return Campaign(
        config=config,
        attack=family.name,
        optimizer=optimizer,
        samples=_get(doc, "search.samples", 100),
        seed=_get(doc, "search.seed", 0),
        d_safe_m=_get(doc, "spec.d_safe_m", 0.0),
        formula=_get(doc, "spec.formula"),
        attack_options=tuple(family.options.items()),
        optimizer_options=tuple(options.items()),
        message=doc.get("attack", {}).get("message", ""),
        message_field=doc.get("attack", {}).get("message_field", "accel"),
        message_sender=doc.get("attack", {}).get("message_sender", 0),
        situation=ranges,
        boundary=_get(doc, "search.boundary", 0.0),
    )


def _short(value: Any) -> Any:
    """A value as shown in an error message: long ones cut."""
    text = repr(value)
    return value if len(text) <= 80 else text[:77] + "..."
