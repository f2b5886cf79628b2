"""What every command shares: the input document from flags and config file, and checks of the files a
command will write."""

from __future__ import annotations

import argparse
import os
import sys
from pathlib import Path
from typing import Any

from ..engine.scenarios import MAX_COPIES
from ..errors import ConfigError
from ..tomlfiles import toml_value
from ..model.attacks.maneuvers import MANEUVERS

EXIT_USAGE = 2
#: a replay that does not reproduce its stored sample: a failed check, as a test runner's exit 1
EXIT_DIFFERS = 1

#: flag dest -> the document key it sets
FLAG_KEYS = {
    "network": "scenario.network",
    "followers": "scenario.followers",
    "setpoint": "scenario.setpoint_m",
    "speed": "scenario.speed_mps",
    "start": "scenario.start",
    "maneuver": "scenario.maneuver",
    "warmup": "scenario.warmup_s",
    "step": "scenario.step_s",
    "duration": "scenario.duration_s",
    "length": "vehicle.length_m",
    "controller": "controller.class",
    "attack": "attack.family",
    "params": "attack.params",
    "delta": "attack.delta_s",
    "horizon": "attack.horizon_s",
    "d_safe": "spec.d_safe_m",
    "formula": "spec.formula",
    "optimizer": "search.optimizer",
    "samples": "search.samples",
    "seed": "search.seed",
}


#: options whose value is a comma-separated list of numbers, which may start with a minus sign
LIST_OPTIONS = ("--params", "--knots")


def _floats(option: str, text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise ConfigError(option, text, "comma-separated numbers, e.g. -1,1,0.5") from None
    return values


def document(args: argparse.Namespace) -> tuple[dict, dict]:
    """The config file with the flags laid over it, and the flags' own keys (for error messages)."""
    from ..inputs import read_document, with_overrides

    doc = read_document(args.config) if getattr(args, "config", None) else {}
    if getattr(args, "preset", None) is not None:
        doc["preset"] = args.preset
    flags: dict[str, Any] = {}
    for dest, key in FLAG_KEYS.items():
        value = getattr(args, dest, None)
        if value is not None:
            flags[key] = _floats(f"--{dest}", value) if dest == "params" else value
    if "," in (getattr(args, "controller", None) or ""):  # a mixed platoon
        flags["controller"] = [name.strip() for name in flags.pop("controller.class").split(",")]
    elif "controller.class" in flags and isinstance(doc.get("controller"), list):  # one controller for all, over a mixed file
        flags["controller"] = flags.pop("controller.class")
    knots, constant = getattr(args, "knots", None), getattr(args, "constant", None)
    given = [f"--{n}" for n, v in (("knots", knots), ("constant", constant), ("attack", getattr(args, "attack", None)))
             if v is not None]
    if len(given) > 1 and getattr(args, "command", "") == "simulate":
        raise ConfigError("/".join(given), "together", "one attack: --knots, --constant or --attack with --params")
    if knots is not None:
        flags.update({"attack.family": "knots", "attack.params": _floats("--knots", knots)})
    if constant is not None:
        flags.update({"attack.family": "constant", "attack.params": [constant]})
    if "attack.params" in flags and "attack.family" not in flags and "family" not in doc.get("attack", {}):
        raise ConfigError("--params", args.params, "an attack family with it: --attack NAME --params ...")
    for item in getattr(args, "set", []):
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError("--set", item, "TABLE.KEY=VALUE, e.g. scenario.setpoint_m=5")
        flags[key.strip()] = toml_value(value.strip())
    if knots is not None and "attack.horizon_s" not in flags:  # the knots' span: one every delta_s
        delta = flags.get("attack.delta_s", doc.get("attack", {}).get("delta_s", 6.0))
        name = flags.get("scenario.maneuver", doc.get("scenario", {}).get("maneuver", "inlane"))
        maneuver = MANEUVERS.get(name) if isinstance(name, str) else None  # a bad one is refused with the document
        scenario = {**doc.get("scenario", {}), **{k.removeprefix("scenario."): v for k, v in flags.items() if k.startswith("scenario.")}}
        added = maneuver.added_parameters(scenario) if maneuver is not None else 0  # then t_lc_s, or the lanes
        count = len(flags["attack.params"]) - added
        if count < 1:
            then = "t_lc_s" if name in ("cutin", "cutout") else f"lane_1 .. lane_{added}"
            raise ConfigError("--knots", knots, f"the knots, then {then} for maneuver {name} ({len(flags['attack.params'])} "
                                                f"value{'s' if len(flags['attack.params']) != 1 else ''} given)")
        if isinstance(delta, (int, float)):
            flags["attack.horizon_s"] = delta * (count - 1) or delta
    return with_overrides(doc, flags), flags


def check_output_file(option: str, path: Path | None) -> Path | None:
    """A file the command will write: its folder must exist, and it must not be a folder itself."""
    if path is None:
        return None
    if path.is_dir():
        raise ConfigError(option, str(path), "a file name (this is a folder)")
    if path.exists() and not path.is_file():
        raise ConfigError(option, str(path), "a regular file or a new file name")
    folder = path.parent
    if not folder.is_dir():
        raise ConfigError(option, str(path), f"a file in an existing folder ({folder} does not exist)")
    if not os.access(folder, os.W_OK) or (path.exists() and not os.access(path, os.W_OK)):
        raise ConfigError(option, str(path), "a file you may write (permission denied)")
    return path


def note_unused_flags(args: argparse.Namespace, config, family, formula: str | None = None) -> None:
    """A flag this episode does not read (a slip, or a leftover of an earlier command line): said, not
    silently dropped. ``family``: the attack family, or None (no attack); ``formula``: one of the user's."""
    unused = []
    if getattr(args, "d_safe", None) is not None and formula is not None:
        unused.append(("--d-safe", "it is the paper's psi's, and --formula scores a formula of your own"))
    if getattr(args, "warmup", None) is not None and config.start != "warmup":
        unused.append(("--warmup", f"start {config.start} has no warm-up drive (--start warmup has)"))
    options = getattr(family, "options", {}) if family is not None else {}
    for flag, key in (("--delta", "delta_s"), ("--horizon", "horizon_s")):
        if getattr(args, flag[2:], None) is not None and key not in options:
            unused.append((flag, f"the {family.name} attack has no {key} (the knots families have)" if family is not None
                               else "there is no attack (the attacker cruises)"))
    settings = {k for m in MANEUVERS.values() for k in m.settings} - set(config.maneuver_class.settings)
    for item in getattr(args, "set", []):  # a maneuver's setting set for another maneuver
        key = item.partition("=")[0].strip()
        if key.startswith("scenario.") and key.removeprefix("scenario.") in settings:
            unused.append((f"--set {key}", f"the {config.maneuver} maneuver does not read it"))
    for flag, why in unused:
        print(f"d4sumo: note: {flag} is unused: {why}", file=sys.stderr)
    if family is not None:
        note_inert_parameters(family, config)


def note_inert_parameters(family, config) -> None:
    """Parameters of the attack that change nothing in this episode (past its end): said, as the search
    still spends its samples over them."""
    from ..model.attacks.maneuvers import attack_of, inert_parameters

    family, _ = attack_of(family)  # a situation searched with it is no parameter of the attack's
    inert = inert_parameters(family, config)
    if inert:
        names = family.names
        knots = "horizon_s" in getattr(family, "options", {})
        hint = " (--horizon sets where the knots end)" if knots else ""
        print(f"d4sumo: note: {len(inert)} of the {family.name} attack's {len(names)} parameters "
              f"({', '.join(names[i] for i in inert)}) change nothing in a {config.duration_s:g} s episode: they act "
              f"past its end, and the search spends its samples over them all the same{hint}", file=sys.stderr)


def check_distinct(dbs) -> None:
    """Results databases each named once: one named twice would count every sample twice."""
    seen: dict[str, str] = {}
    for db in map(str, dbs):
        key = os.path.realpath(db)
        if key in seen:
            twice = "named twice" if seen[key] == db else f"the same file as {seen[key]}"
            raise ConfigError("db", db, f"each results database once (this one is {twice})")
        seen[key] = db


def check_display(gui: bool) -> None:
    """sumo-gui needs a display: say so at once instead of a minute of retries."""
    if gui and sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ConfigError("--gui", "no display", "a graphical session (DISPLAY is not set); use --fcd and `d4sumo plot` instead")


def check_batch(value: int) -> int:
    if not 1 <= value <= MAX_COPIES:
        raise ConfigError("--batch", value, f"a whole number of episodes in [1, {MAX_COPIES}]")
    return value
