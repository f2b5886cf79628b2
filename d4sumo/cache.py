"""Where d4sumo keeps what it builds once and reads again: ``$XDG_CACHE_HOME/d4sumo`` (``~/.cache/d4sumo`` where it is
not set), a folder a kind: built networks (``nets``), roads and FMUs kept by their content (``roads``, ``fmus``),
traffic warm-ups (``traffic-states``), checked vehicle types and additional files. Deleting it costs only the
building again."""

from __future__ import annotations

import os
from pathlib import Path


def cache_folder(kind: str) -> Path:
    """The cache's folder for one kind of thing (not created here)."""
    return Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache") / "d4sumo" / kind


def default_cache_dir() -> Path:
    """The built networks' folder: the other kinds stand beside it."""
    return cache_folder("nets")
