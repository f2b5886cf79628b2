"""The situation searched with the attack: keys of the scenario given as a range (``setpoint_m = [3, 10]``) or a
list of choices (``start = ["rest", "steady"]``) rather than a value. The optimiser searches each as one more
parameter after the attack's (`maneuvers.SituatedAttack`), so every sample stores the situation it played in its
parameters (after the attack's, in the order of their names), and a replay plays it again exactly; each episode's
configuration is the campaign's with those values.

How the box holds them: a range is a continuous parameter over it; a list of k choices a parameter over [0, k]
whose whole part is the choice (k itself the last), as a swerving attacker's lanes are. Every optimiser searches
the box as it searches the attack's parameters (scaled to the unit cube): a choice's parameter is continuous to it,
and each choice owns an equal share of it.

This version searches the setpoint, the target speed and the start (from rest or steady state), the keys a batch
of episodes carries per episode (`batch.batch_key`): samples of other situations still play side by side in one
SUMO.
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

#: the keys of [scenario] a campaign may search over a range, and their units
KEYS = {"setpoint_m": "m", "speed_mps": "m/s"}
#: the keys it may search over choices, and the choices a batch may mix (a warm-up moves the attack's start)
CHOICES = {"start": ("rest", "steady")}

#: one key's range, (key, low, high), or its choices, (key, (choice, ...))
Entry = tuple


def _is_list(value: Any) -> bool:
    return isinstance(value, (list, tuple))


def _numeric(key: str) -> bool:
    """Whether a key of [scenario] holds one number (its default one)."""
    default = getattr(EpisodeConfig, key, None)
    return isinstance(default, (int, float)) and not isinstance(default, bool)


def _searched() -> str:
    return ", ".join([*(f"scenario.{k} (a range)" for k in KEYS), *(f"scenario.{k} (choices)" for k in CHOICES)])


def split(scenario: Mapping[str, Any]) -> tuple[dict, tuple[Entry, ...]]:
    """A [scenario] table's fixed values (each searched key at its range's low end or its first choice, which the
    configuration checks), and what it searches, each checked (`entry`)."""
    fixed, entries = dict(scenario), []
    for key, value in scenario.items():
        if not _is_list(value) or key not in KEYS and key not in CHOICES and not _numeric(key):
            continue  # a route, a list of files: the key's own
        checked = entry(key, value)
        fixed[key] = checked[1] if key in KEYS else checked[1][0]
        entries.append(checked)
    return fixed, tuple(entries)


def entry(key: str, value: Any) -> Entry:
    """One searched key, checked: a range of two numbers, low below high, or two or more distinct choices, on a key
    this version searches; a ConfigError naming ``scenario.key`` otherwise."""
    field, given = f"scenario.{key}", list(value) if _is_list(value) else value
    if key in CHOICES:
        allowed = CHOICES[key]
        if not _is_list(value) or len(value) < 2 or not all(isinstance(v, str) for v in value):
            raise ConfigError(field, given, f"a value, or a list of two or more choices of {', '.join(allowed)}")
        if len(set(value)) != len(value):
            raise ConfigError(field, given, "a list of choices, each once")
        for v in value:
            if v not in allowed:
                raise ConfigError(field, given, f"choices of {', '.join(allowed)} (the starts a batch may mix: a warm-up "
                                                "moves when the attack begins)")
        return key, tuple(value)
    if key not in KEYS:
        raise ConfigError(field, given, f"a single value: the keys searched are {_searched()}, those a batch of "
                                        "episodes may vary")
    if not (_is_list(value) and len(value) == 2 and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                                        and math.isfinite(v) for v in value)):
        raise ConfigError(field, given, f"a value, or a range [low, high] of two numbers in {KEYS[key]}")
    low, high = float(value[0]), float(value[1])
    if not low < high:
        raise ConfigError(field, given, f"a range [low, high] with low below high ({'empty' if low == high else 'reversed'})")
    return key, low, high


def check(config: EpisodeConfig, entries: tuple) -> tuple[Entry, ...]:
    """The entries, in their stored form, each checked (`entry`), each key once, the speed fixed where SUMO's models
    drive the followers, and every corner of the box a configuration the episode accepts (a ConfigError naming the
    key otherwise)."""
    out = []
    for e in entries:
        if not (_is_list(e) and len(e) in (2, 3) and isinstance(e[0], str)):
            raise ConfigError("situation", list(e) if _is_list(e) else e, "(key, low, high) or (key, choices)")
        out.append(entry(e[0], e[1] if len(e) == 2 else list(e[1:])))
    if len({e[0] for e in out}) != len(out):
        raise ConfigError("situation", [e[0] for e in out], "each key once")
    # in the order of their names: a database stores a definition's keys sorted, and the parameters must be laid
    # out as it reads them back (given start first, a replay read the setpoint from the start's parameter)
    out.sort(key=lambda e: e[0])
    if config.sumo_driven and any(e[0] == "speed_mps" for e in out):
        raise ConfigError("scenario.speed_mps", [list(e[1:]) for e in out if e[0] == "speed_mps"][0],
                          "a single value with followers SUMO's models drive: they read the target speed from their "
                          "vehicle type, one for a whole batch")
    for corner in corners(config, tuple(out)):
        del corner  # built: the configuration's own checks passed
    return tuple(out)


def corners(config: EpisodeConfig, entries: tuple[Entry, ...]) -> list[EpisodeConfig]:
    """The configuration at every corner of the situation's box (each range at its ends, every choice)."""
    ends = [((e[0], e[1]), (e[0], e[2])) if len(e) == 3 else tuple((e[0], c) for c in e[1]) for e in entries]
    return [dataclasses.replace(config, **dict(choice)) for choice in itertools.product(*ends)]


def box(attack: AttackFamily, entries: tuple[Entry, ...]) -> AttackFamily:
    """The search's box: the attack's, then each searched key as one parameter named after it."""
    if not entries:
        return attack
    return SituatedAttack(attack, tuple(
        Parameter(e[0], e[1], e[2], KEYS[e[0]]) if len(e) == 3 else
        Parameter(e[0], 0.0, float(len(e[1])), f"(its whole part the choice: {', '.join(f'{i} {c}' for i, c in enumerate(e[1]))})")
        for e in entries))


def values(entries: tuple[Entry, ...], x) -> dict[str, Any]:
    """The situation's values a sample's own parameters (``x``, the situation's alone) give: a range's value, a
    choice's name."""
    out = {}
    for e, v in zip(entries, np.asarray(x, dtype=float).tolist()):
        out[e[0]] = float(v) if len(e) == 3 else e[1][min(int(v), len(e[1]) - 1)]
    return out


def config_for(config: EpisodeConfig, family: AttackFamily, entries: tuple[Entry, ...], params) -> EpisodeConfig:
    """The configuration a sample with these parameters plays: the campaign's, its searched keys at the sample's
    values."""
    if not isinstance(family, SituatedAttack):
        return config
    return dataclasses.replace(config, **values(entries, family.situation_values(params)))


def stored(entries: tuple[Entry, ...]) -> dict[str, list]:
    """The entries as a definition stores them: {key: [low, high]} or {key: [choice, ...]}."""
    return {e[0]: [e[1], e[2]] if len(e) == 3 else list(e[1]) for e in entries}


def restored(table: Any) -> tuple[Entry, ...]:
    """A definition's stored entries, as `stored` wrote them (a ConfigError for anything else)."""
    if not isinstance(table, Mapping):
        raise ConfigError("situation", table, "a table {key: [low, high] or [choice, ...]}")
    return tuple(entry(key, value) for key, value in table.items())
