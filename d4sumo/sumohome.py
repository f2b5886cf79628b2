"""Where SUMO is installed: its folder and its programs (the eclipse-sumo package's, else $SUMO_HOME's
or PATH's). Read by the model (SUMO's schema of its car-following models) and the engine alike."""

from __future__ import annotations

import os
import shutil
from pathlib import Path

from .errors import SumoError


def sumo_home() -> str:
    """SUMO's installation folder: the eclipse-sumo package's, else $SUMO_HOME."""
    try:
        import sumo  # the eclipse-sumo wheel ships SUMO's binaries and data

        return str(sumo.SUMO_HOME)
    except ImportError:
        home = os.environ.get("SUMO_HOME")
        if not home:
            raise SumoError("SUMO not found: install the eclipse-sumo package (pip install eclipse-sumo) or set SUMO_HOME") from None
        return home


def sumo_binary(name: str, explicit: str | None = None) -> str:
    """Path of a SUMO program (netconvert, sumo-gui): the given path, the eclipse-sumo package's, or PATH's."""
    if explicit:
        if not (Path(explicit).is_file() and os.access(explicit, os.X_OK)):
            raise SumoError(f"{name}: {explicit!r} is not an executable file")
        return explicit
    try:
        import sumo  # the eclipse-sumo wheel ships SUMO's binaries

        candidate = Path(sumo.SUMO_HOME) / "bin" / name
        if candidate.is_file():
            return str(candidate)
    except ImportError:
        pass
    found = shutil.which(name)
    if not found:
        raise SumoError(f"{name} not found: install the eclipse-sumo package (pip install eclipse-sumo) or put {name} on PATH")
    return found
