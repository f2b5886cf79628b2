"""TOML read as d4sumo's inputs read it: a file (a config, a sweep) and a flag's value."""

from __future__ import annotations

import sys
from pathlib import Path
from typing import Any

if sys.version_info >= (3, 11):
    import tomllib
else:  # Python 3.10: the same parser, published as tomli
    import tomli as tomllib

from .errors import ConfigError


def read_toml(path: str | Path, field: str = "--config") -> dict:
    """Parse a TOML file; an unreadable, non-UTF-8 or malformed file is a ConfigError naming ``field``."""
    p = Path(path)
    try:
        data = p.read_bytes()
    except OSError as exc:
        raise ConfigError(field, str(p), f"a readable TOML file ({exc.strerror})") from None
    try:
        text = data.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ConfigError(field, str(p), f"a UTF-8 text file (byte {exc.start} is not UTF-8)") from None
    try:
        return tomllib.loads(text)
    except tomllib.TOMLDecodeError as exc:
        raise ConfigError(field, str(p), f"valid TOML ({exc})") from None


def toml_value(text: str) -> Any:
    """A flag's value as TOML reads it (number, bool, quoted string, list), else the bare string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text
