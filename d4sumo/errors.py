"""Errors that reach the user as one clear line (never a traceback)."""

from __future__ import annotations

import math
import numbers

import numpy as np


class D4sumoError(Exception):
    """Base class for every error d4sumo reports to its user."""


def refusal(field: str, given: object, allowed: str) -> str:
    """The one line that refuses a value: which field, what was given, what is allowed."""
    return f"{field}: got {given!r}; allowed: {allowed}"


class ConfigError(D4sumoError, ValueError):
    """A configuration value is invalid: says which field, what was given and what is allowed."""

    def __init__(self, field: str, given: object, allowed: str):
        self.field = field
        self.given = given
        self.allowed = allowed
        super().__init__(refusal(field, given, allowed))


class SumoError(D4sumoError):
    """SUMO could not be found, could not build a network, or failed during an episode."""


class NotSimulable(D4sumoError):
    """A stored campaign whose follower controller cannot be had here (a module that does not import, an
    FMU that is missing or has changed): its samples can be read, not replayed."""


class WarmupCollision(D4sumoError):
    """Cars collided in the warm-up, before the attack started: the episode scores no attack. The warm-up
    is the same whatever the attack, so every episode of that configuration ends so."""


def is_number(value: object) -> bool:
    """A real number (Python's or numpy's), not a bool."""
    return isinstance(value, numbers.Real) and not isinstance(value, (bool, np.bool_))


def check_number(field: str, value: object, low: float, high: float, unit: str = "", *, low_open: bool = False) -> float:
    """``value`` as a float if it is a finite number in the range, else a ConfigError saying what is allowed.

    numpy scalars are accepted; the result is always a Python float, so 7, 7.0 and np.float32(7) are
    the same value wherever it is stored or hashed."""
    ok = is_number(value) and math.isfinite(float(value))
    ok = ok and (low < value if low_open else low <= value) and value <= high
    if not ok:
        bracket = "(" if low_open else "["
        raise ConfigError(field, _plain(value), f"a number in {bracket}{low:g}, {high:g}] {unit}".rstrip())
    return float(value)


def check_int(field: str, value: object, low: int, high: int, what: str = "") -> int:
    """``value`` as an int if it is a whole number in [low, high] (numpy integers too), else a ConfigError."""
    if not (isinstance(value, numbers.Integral) and not isinstance(value, (bool, np.bool_)) and low <= value <= high):
        raise ConfigError(field, _plain(value), f"a whole number in [{low}, {high}] {what}".rstrip())
    return int(value)


def _plain(value: object) -> object:
    """numpy scalars shown as Python values in messages."""
    return value.item() if isinstance(value, np.generic) else value


def table_of(cls, table: object, section: str):
    """A dataclass of a config table (``[section]``) built from ``table``: a mapping of its fields only,
    else a ConfigError naming the table or the unknown key."""
    import dataclasses
    from collections.abc import Mapping

    if not isinstance(table, Mapping):
        raise ConfigError(section, table, f"a [{section}] table")
    keys = [f.name for f in dataclasses.fields(cls)]
    for key, value in table.items():
        if key not in keys:
            raise ConfigError(f"{section}.{key}", value, f"a key of [{section}]: {', '.join(keys)}")
    return cls(**table)


def check_keys(section: str, table, allowed: list[str]) -> None:
    """Every key of ``table`` one of ``allowed``, else a ConfigError naming the first that is not."""
    for key in table:
        if key not in allowed:
            raise ConfigError(f"{section}.{key}", table[key], f"a key of [{section}]: {', '.join(allowed)}")
