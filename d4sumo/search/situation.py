"""The situation searched with the attack: numeric keys of a campaign's [scenario], [vehicle], [controller],
[radar], [traffic] and [v2v] tables given as a range (``setpoint_m = [3, 10]``, ``v2v.loss = [0, 0.5]``) or a list
of choices (``start = ["rest", "steady"]``, ``v2v.latency_s = {choices = [0, 0.1, 0.3]}``) rather than a value. The
optimiser searches each as one more parameter after the attack's (`maneuvers.SituatedAttack`), so every sample
stores the situation it played in its parameters (after the attack's, in the order of their names), and a replay
plays it again exactly; each episode's configuration is the campaign's with those values (`configured`).

How the box holds them, each scaled to the unit cube as the attack's parameters are:

- a range of a real-valued key is a continuous parameter over it;
- a range of a whole-number key (a seed) is a parameter over [low, high + 1) whose whole part is the value;
- a range of a [traffic] key is searched over `TRAFFIC_LEVELS` evenly spaced values, a parameter over
  [0, TRAFFIC_LEVELS) whose whole part is the level: each level's warm-up is played once and cached
  (`engine.warmup`), where every value of a continuum would warm its own traffic up (300 s of driving);
- k choices are a parameter over [0, k) whose whole part is the choice (k itself the last), as a swerving
  attacker's lanes are.

Samples whose situations a batch of episodes carries per episode (the setpoint, the target speed and the start:
`batch.batch_key`) play side by side in one SUMO; samples of another key play in batches of their own
configuration (`evaluator.play_together`).
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from typing import Any, Mapping

import numpy as np

from ..errors import ConfigError, is_number
from ..model.attacks.maneuvers import SituatedAttack
from ..model.attacks.pedals import AttackFamily, Parameter
from ..model.config import EpisodeConfig
from ..model.controllers.table import ControllerConfig
from ..model.world.sensing import RadarParams

#: the tables whose numeric keys a campaign may search ([scenario]'s are named bare, the others' table.key)
TABLES = ("scenario", "vehicle", "controller", "radar", "traffic", "v2v")
#: the keys searched over named choices, and the choices a batch may mix (a warm-up moves the attack's start)
CHOICES = {"start": ("rest", "steady")}
#: numeric keys that cannot vary within one campaign, and why
FIXED = {
    "followers": "the number of followers is the campaign's: its specification and its batches' arrays hold them",
    "lane": "the platoon's lane is its road's",
    "step_s": "the attack's signal and the specification are made for one step",
    "duration_s": "the attack's signal and the specification are made for one length of episode",
    "warmup_s": "the specification scores from the attack's start, one step for the campaign",
    "collision_gap_m": "it is the specification's d_safe_m, one for the campaign",
    "swerve_knots": "the attack's box holds its lanes",
    "swerve_lanes": "the attack's box holds its lanes",
}
#: a [traffic] key's range is searched over this many evenly spaced values (each a warm-up of its own, cached)
TRAFFIC_LEVELS = 11

#: one key's range, (key, low, high) (whole-number ends: a whole-number key), or its choices, (key, (choice, ...))
Entry = tuple


def field(key: str) -> str:
    """The key as a document names it: scenario.setpoint_m, v2v.loss."""
    return key if "." in key else f"scenario.{key}"


def _is_list(value: Any) -> bool:
    return isinstance(value, (list, tuple))


def _unit(key: str) -> str:
    for suffix, unit in (("vehicles_per_hour", "vehicles per hour per lane"), ("_mps2", "m/s^2"), ("_mps", "m/s"),
                         ("_m", "m"), ("_s", "s")):
        if key.endswith(suffix):
            return unit
    return ""


def _searched(table: str, key: str, value: Any) -> bool:
    """Whether a document's value asks for a search: a {choices = [...]} table, a list on a key of [scenario]
    that holds a number or named choices (a route's, a list of files', is the key's own), or a list of numbers."""
    if isinstance(value, Mapping):
        return "choices" in value
    if not _is_list(value):
        return False
    if table == "scenario":
        return key in CHOICES or _numeric_scenario_key(key)
    return len(value) > 0 and all(is_number(v) for v in value)


def _numeric_scenario_key(key: str) -> bool:
    default = getattr(EpisodeConfig, key, None)
    return is_number(default) or default is None and key in ("lane", "attacker_declared_decel_mps2")


def split(doc: Mapping[str, Any]) -> tuple[dict, tuple[Entry, ...]]:
    """A document's tables with each searched key at its range's low end or its first choice (which the
    configuration checks), and what it searches, each checked (`entry`)."""
    fixed, entries = dict(doc), []
    for table in TABLES:
        given = doc.get(table)
        if not isinstance(given, Mapping):  # (a mixed platoon's [[controller]]: one table per follower, not searched)
            continue
        values = dict(given)
        for key, value in given.items():
            if not _searched(table, key, value):
                continue
            name = key if table == "scenario" else f"{table}.{key}"
            checked = entry(name, value)
            values[key] = value[0] if _is_list(value) else value["choices"][0]  # as given: a whole number stays one
            entries.append(checked)
        fixed[table] = values
    radar = fixed.get("radar")
    if any(e[0].startswith("radar.") for e in entries) and radar.get("seed", 0) != 0 and RadarParams.from_table(radar).perfect:
        # its low corner senses the truth, which the configuration holds as no radar: the seed would be lost
        raise ConfigError("radar.seed", radar["seed"], "0 (or left out) where the radar's ranges start at the truth (no noise, "
                                                       "no latency): start one above it to keep the seed")
    return fixed, tuple(entries)


def entry(key: str, value: Any) -> Entry:
    """One searched key, checked: a range of two numbers, low below high, or two or more distinct choices; a
    ConfigError naming the key otherwise."""
    name, given = field(key), list(value) if _is_list(value) else dict(value) if isinstance(value, Mapping) else value
    bare = key.rpartition(".")[2]
    if key in CHOICES:
        allowed = CHOICES[key]
        if not _is_list(value) or len(value) < 2 or not all(isinstance(v, str) for v in value):
            raise ConfigError(name, given, f"a value, or a list of two or more choices of {', '.join(allowed)}")
        _once(name, value)
        for v in value:
            if v not in allowed:
                raise ConfigError(name, given, f"choices of {', '.join(allowed)} (the starts a batch may mix: a warm-up "
                                               "moves when the attack begins)")
        return key, tuple(value)
    if bare in FIXED and "." not in key:
        raise ConfigError(name, given, f"a single value: {FIXED[bare]}")
    if isinstance(value, Mapping):
        choices = value.get("choices")
        if set(value) != {"choices"} or not _is_list(choices) or len(choices) < 2 \
                or not all(is_number(v) and math.isfinite(v) for v in choices):
            raise ConfigError(name, given, "a value, a range [low, high], or {choices = [a, b, ...]} of two or more numbers")
        _once(name, choices)
        return key, tuple(float(v) if isinstance(v, float) else v for v in choices)
    unit = _unit(bare)
    if not (_is_list(value) and len(value) == 2 and all(is_number(v) and math.isfinite(v) for v in value)):
        raise ConfigError(name, given, f"a value, or a range [low, high] of two numbers{' in ' + unit if unit else ''}")
    low, high = float(value[0]), float(value[1])
    if not low < high:
        raise ConfigError(name, given, f"a range [low, high] with low below high ({'empty' if low == high else 'reversed'})")
    return key, low, high


def _once(name: str, choices) -> None:
    if len(set(choices)) != len(choices):
        raise ConfigError(name, list(choices), "a list of choices, each once")


def played(config: EpisodeConfig, key: str) -> Any:
    """The value a configuration holds for a searched key (None where it holds none)."""
    if "." not in key:
        return getattr(config, key, None)
    table, _, name = key.partition(".")
    held = _table(config, table)
    if isinstance(held, ControllerConfig):
        return dict(held.params).get(name)
    return getattr(held, name, None) if held is not None and not isinstance(held, tuple) else None


def _table(config: EpisodeConfig, table: str) -> Any:
    """A configuration's table; a perfect radar's (which the configuration holds as none, `EpisodeConfig.radar`) the
    default one, whose keys a range starting at the truth moves."""
    held = getattr(config, table, None)
    return RadarParams() if held is None and table == "radar" else held


def check(config: EpisodeConfig, entries: tuple) -> tuple[Entry, ...]:
    """The entries, in their stored form, each checked (`entry`), each key once, each a number's key the
    configuration holds (a whole-number key's range with whole ends), and every corner of the box a configuration
    the episode accepts (a ConfigError naming the key otherwise)."""
    out = []
    for e in entries:
        if not (_is_list(e) and len(e) in (2, 3) and isinstance(e[0], str)):
            raise ConfigError("situation", list(e) if _is_list(e) else e, "(key, low, high) or (key, choices)")
        key = e[0]
        table = key.partition(".")[0] if "." in key else "scenario"
        if table not in TABLES or table == "scenario" and "." in key:
            raise ConfigError(field(key), list(e[1:]), f"a key of {', '.join(f'[{t}]' for t in TABLES)}")
        checked = entry(key, {"choices": list(e[1])} if len(e) == 2 and key not in CHOICES else
                        list(e[1]) if len(e) == 2 else list(e[1:]))
        out.append(_typed(config, checked))
    if len({e[0] for e in out}) != len(out):
        raise ConfigError("situation", [e[0] for e in out], "each key once")
    # in the order of their names: a database stores a definition's keys sorted, and the parameters must be laid
    # out as it reads them back (given start first, a replay read the setpoint from the start's parameter)
    out.sort(key=lambda e: e[0])
    for corner in corners(config, tuple(out)):
        del corner  # built: the configuration's own checks passed
    return tuple(out)


def _typed(config: EpisodeConfig, e: Entry) -> Entry:
    """An entry of a number's key the configuration holds; a whole-number key's ends whole, as ints."""
    key = e[0]
    if key in CHOICES:
        return e
    value = played(config, key)
    shown = list(e[1]) if len(e) == 2 else list(e[1:])
    if key.startswith("controller.") and isinstance(config.controller, tuple):
        raise ConfigError(field(key), shown, "a single value in a mixed platoon (one [controller] table searches its keys)")
    if not is_number(value):
        raise ConfigError(field(key), shown, "a single value: ranges and choices are taken on keys that hold a number")
    if not isinstance(value, int):
        return (key, tuple(float(v) for v in e[1])) if len(e) == 2 else (key, float(e[1]), float(e[2]))
    ends = e[1] if len(e) == 2 else e[1:]
    if not all(float(v).is_integer() for v in ends):
        raise ConfigError(field(key), shown, "whole numbers: the key holds one")
    return (key, tuple(int(v) for v in ends)) if len(e) == 2 else (key, int(e[1]), int(e[2]))


def _levels(e: Entry) -> int:
    """How many values a range is searched over: TRAFFIC_LEVELS for a real [traffic] key, else 0 (a continuum, or
    whole numbers)."""
    return TRAFFIC_LEVELS if len(e) == 3 and e[0].startswith("traffic.") and isinstance(e[1], float) else 0


def _whole(e: Entry) -> bool:
    return len(e) == 3 and isinstance(e[1], int)


def corners(config: EpisodeConfig, entries: tuple[Entry, ...]) -> list[EpisodeConfig]:
    """The configuration at every corner of the situation's box (each range at its ends, every choice)."""
    ends = [((e[0], e[1]), (e[0], e[2])) if len(e) == 3 else tuple((e[0], c) for c in e[1]) for e in entries]
    return [configured(config, dict(choice)) for choice in itertools.product(*ends)]


def box(attack: AttackFamily, entries: tuple[Entry, ...]) -> AttackFamily:
    """The search's box: the attack's, then each searched key as one parameter named after it."""
    if not entries:
        return attack
    return SituatedAttack(attack, tuple(_parameter(e) for e in entries))


def _parameter(e: Entry) -> Parameter:
    if len(e) == 2:
        return Parameter(e[0], 0.0, float(len(e[1])), f"(its whole part the choice: {', '.join(f'{i} {c}' for i, c in enumerate(e[1]))})")
    levels = _levels(e)
    if levels:
        return Parameter(e[0], 0.0, float(levels), f"(its whole part the level: 0 {e[1]:g}, {levels - 1} {e[2]:g} {_unit(e[0])})")
    if _whole(e):
        return Parameter(e[0], float(e[1]), float(e[2] + 1), "(its whole part the value)")
    return Parameter(e[0], e[1], e[2], _unit(e[0].rpartition(".")[2]))


def values(entries: tuple[Entry, ...], x) -> dict[str, Any]:
    """The situation's values a sample's own parameters (``x``, the situation's alone) give: a range's value (a
    level's, a whole number), a choice."""
    out = {}
    for e, v in zip(entries, np.asarray(x, dtype=float).tolist()):
        if len(e) == 2:
            out[e[0]] = e[1][min(int(v), len(e[1]) - 1)]
        elif _levels(e):
            level = min(int(v), _levels(e) - 1)
            out[e[0]] = e[1] + level * (e[2] - e[1]) / (_levels(e) - 1)
        elif _whole(e):
            out[e[0]] = min(int(math.floor(v)), e[2])
        else:
            out[e[0]] = float(v)
    return out


def configured(config: EpisodeConfig, situation: Mapping[str, Any]) -> EpisodeConfig:
    """The configuration with these keys at these values (each table's own checks run again)."""
    scenario = {k: v for k, v in situation.items() if "." not in k}
    tables: dict[str, dict] = {}
    for k, v in situation.items():
        if "." in k:
            table, _, name = k.partition(".")
            tables.setdefault(table, {})[name] = v
    for table, changed in tables.items():
        held = _table(config, table)
        if isinstance(held, ControllerConfig):
            scenario[table] = ControllerConfig(held.cls, tuple((k, changed.get(k, v)) for k, v in held.params), held.where)
        else:
            scenario[table] = dataclasses.replace(held, **changed)
    return dataclasses.replace(config, **scenario) if scenario else config


def config_for(config: EpisodeConfig, family: AttackFamily, entries: tuple[Entry, ...], params) -> EpisodeConfig:
    """The configuration a sample with these parameters plays: the campaign's, its searched keys at the sample's
    values."""
    if not isinstance(family, SituatedAttack):
        return config
    return configured(config, values(entries, family.situation_values(params)))


def stored(entries: tuple[Entry, ...]) -> dict[str, Any]:
    """The entries as a definition stores them: {key: [low, high]}, {key: [choice, ...]} (named choices) or
    {key: {"choices": [number, ...]}}."""
    return {e[0]: [e[1], e[2]] if len(e) == 3 else list(e[1]) if e[0] in CHOICES else {"choices": list(e[1])}
            for e in entries}


def restored(table: Any) -> tuple[Entry, ...]:
    """A definition's stored entries, as `stored` wrote them (a ConfigError for anything else)."""
    if not isinstance(table, Mapping):
        raise ConfigError("situation", table, "a table {key: [low, high], [choice, ...] or {choices = [...]}}")
    return tuple(entry(key, value) for key, value in table.items())


# --- the boundary between safe and unsafe situations: where the success rate crosses one half ---------------------

#: the kernel's width, as a share of each range
BANDWIDTH = 0.1


def locating(index: int, share: float) -> bool:
    """Whether sample ``index`` (0-based) is spent locating the boundary, at this share of the budget."""
    return math.floor((index + 1) * share) > math.floor(index * share)


def kernel_estimate(points: np.ndarray, successes: np.ndarray, at: np.ndarray, bandwidth: float = BANDWIDTH
                    ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The success rate at each row of ``at`` estimated from samples (rows of ``points``, in the same scaled units, and
    how far each succeeded, 0 to 1): each sample weighed by a Gaussian of its distance, ``bandwidth`` wide; with s the
    weighted successes and n the weighted samples, the mean and standard deviation of Beta(1 + s, 1 + n - s), a
    uniform prior updated. Returns (rate, sd, n)."""
    z = (at[:, None, :] - points[None, :, :]) / bandwidth
    w = np.exp(-0.5 * np.sum(z * z, axis=-1))  # (at, samples)
    n = w.sum(axis=1)
    s = w @ successes
    a, b = 1.0 + s, 1.0 + n - s
    return a / (a + b), np.sqrt(a * b / ((a + b) ** 2 * (a + b + 1.0))), n
