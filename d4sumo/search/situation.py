"""The situation searched with the attack: keys of the scenario given as a range (``setpoint_m = [3, 10]``)
rather than a value. The optimiser searches each range as one more parameter after the attack's
(`maneuvers.SituatedAttack`), so every sample stores the situation it played in its parameters, and a
replay plays it again exactly; each episode's configuration is the campaign's with those values.

This version searches the setpoint and the target speed, the keys a batch of episodes carries per episode
(`batch.batch_key`): samples of other situations still play side by side in one SUMO.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from typing import Any, Mapping

import numpy as np

from ..errors import ConfigError
from ..model.attacks.maneuvers import SituatedAttack
from ..model.attacks.pedals import AttackFamily, Parameter
from ..model.config import EpisodeConfig

#: the keys of [scenario] a campaign may search, and their units
KEYS = {"setpoint_m": "m", "speed_mps": "m/s"}

#: one key's range: (key, low, high)
Range = tuple[str, float, float]


def _is_range(value: Any) -> bool:
    return isinstance(value, (list, tuple))


def _numeric(key: str) -> bool:
    """Whether a key of [scenario] holds one number (its default one)."""
    default = getattr(EpisodeConfig, key, None)
    return isinstance(default, (int, float)) and not isinstance(default, bool)


def split(scenario: Mapping[str, Any]) -> tuple[dict, tuple[Range, ...]]:
    """A [scenario] table's fixed values (each searched key at its range's low end, which the configuration
    checks), and its ranges, each checked: two numbers, low below high, on a key this version searches."""
    fixed, ranges = dict(scenario), []
    for key, value in scenario.items():
        if not _is_range(value) or key not in KEYS and not _numeric(key):  # a route, a list of files: the key's own
            continue
        field = f"scenario.{key}"
        if key not in KEYS:
            raise ConfigError(field, list(value), f"a single value: ranges are searched on {', '.join(f'scenario.{k}' for k in KEYS)} "
                                                  "(the keys a batch of episodes may vary)")
        if (len(value) != 2 or not all(isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)
                                       for v in value)):
            raise ConfigError(field, list(value), f"a value, or a range [low, high] of two numbers in {KEYS[key]}")
        low, high = float(value[0]), float(value[1])
        if not low < high:
            raise ConfigError(field, list(value), f"a range [low, high] with low below high ({'empty' if low == high else 'reversed'})")
        fixed[key] = low
        ranges.append((key, low, high))
    return fixed, tuple(ranges)


def check(config: EpisodeConfig, ranges: tuple[Range, ...]) -> tuple[Range, ...]:
    """The ranges, stored form (key, low, high as floats), each end within its key's own limits and every corner of
    the box a configuration the episode accepts (a ConfigError naming the key otherwise)."""
    out = []
    for entry in ranges:
        if not (isinstance(entry, (list, tuple)) and len(entry) == 3 and entry[0] in KEYS):
            raise ConfigError("situation", list(entry) if isinstance(entry, (list, tuple)) else entry,
                              f"(key, low, high) with a key of {', '.join(KEYS)}")
        key, low, high = entry
        _, (checked,) = split({key: [low, high]})
        out.append(checked)
    if len({key for key, _, _ in out}) != len(out):
        raise ConfigError("situation", [key for key, _, _ in out], "each key once")
    if config.sumo_driven and any(key == "speed_mps" for key, _, _ in out):
        raise ConfigError("scenario.speed_mps", [[low, high] for key, low, high in out if key == "speed_mps"][0],
                          "a single value with followers SUMO's models drive: they read the target speed from their "
                          "vehicle type, one for a whole batch")
    for corner in corners(config, tuple(out)):
        del corner  # built: the configuration's own checks passed
    return tuple(out)


def corners(config: EpisodeConfig, ranges: tuple[Range, ...]) -> list[EpisodeConfig]:
    """The configuration at every corner of the situation's box (each key at its low or high end)."""
    ends = [((key, low), (key, high)) for key, low, high in ranges]
    return [dataclasses.replace(config, **dict(choice)) for choice in itertools.product(*ends)]


def box(attack: AttackFamily, ranges: tuple[Range, ...]) -> AttackFamily:
    """The search's box: the attack's, then each range as one parameter named after its key."""
    if not ranges:
        return attack
    return SituatedAttack(attack, tuple(Parameter(key, low, high, KEYS[key]) for key, low, high in ranges))


def config_for(config: EpisodeConfig, family: AttackFamily, params) -> EpisodeConfig:
    """The configuration a sample with these parameters plays: the campaign's, its searched keys at the sample's
    values."""
    if not isinstance(family, SituatedAttack):
        return config
    values = family.situation_values(params)
    names = family.names[len(family.names) - len(values):]
    return dataclasses.replace(config, **{name: float(v) for name, v in zip(names, np.asarray(values).tolist())})


def stored(ranges: tuple[Range, ...]) -> dict[str, list[float]]:
    """The ranges as a definition stores them: {key: [low, high]}."""
    return {key: [low, high] for key, low, high in ranges}


def restored(table: Any) -> tuple[Range, ...]:
    """A definition's stored ranges, as `stored` wrote them (a ConfigError for anything else)."""
    if not isinstance(table, Mapping):
        raise ConfigError("situation", table, "a table {key: [low, high]}")
    return tuple((key, *value) if _is_range(value) and len(value) == 2 else (key, value) for key, value in table.items())
