"""Errors that reach the user as one clear line (never a traceback)."""

from __future__ import annotations

import math


class D4sumoError(Exception):
    """Base class for every error d4sumo reports to its user."""


class ConfigError(D4sumoError, ValueError):
    """A configuration value is invalid: says which field, what was given and what is allowed."""

    def __init__(self, field: str, given: object, allowed: str):
        self.field = field
        self.given = given
        self.allowed = allowed
        super().__init__(f"{field}: got {given!r}; allowed: {allowed}")


class SumoError(D4sumoError):
    """SUMO could not be found, could not build a network, or failed during an episode."""


def check_number(field: str, value: object, low: float, high: float, unit: str = "", *, low_open: bool = False) -> float:
    """``value`` if it is a finite number in the range, else a ConfigError saying what is allowed."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    ok = ok and (low < value if low_open else low <= value) and value <= high
    if not ok:
        bracket = "(" if low_open else "["
        raise ConfigError(field, value, f"a number in {bracket}{low:g}, {high:g}] {unit}".rstrip())
    return float(value)
