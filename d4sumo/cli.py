"""Command line: parse flags and the TOML config, call the library, print. Flags override the file.

Every error a user can cause ends as one line `d4sumo: error: ...` and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import logging
import sys
import tomllib
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from . import __version__
from .attacks import FAMILIES, make_attack
from .config import START_MODES, EpisodeConfig, load_toml
from .errors import ConfigError, D4sumoError, check_number

EXIT_USAGE = 2

# flag dest -> dotted config key: the flags that set [scenario]/[vehicle]/[controller] values
EPISODE_FLAGS = {
    "network": "scenario.network",
    "followers": "scenario.followers",
    "setpoint": "scenario.setpoint_m",
    "speed": "scenario.speed_mps",
    "start": "scenario.start",
    "step": "scenario.step_s",
    "duration": "scenario.duration_s",
    "length": "vehicle.length_m",
    "controller": "controller.class",
}


def _add_episode_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scenario (override the config file)")
    g.add_argument("--config", help="TOML config file ([scenario], [vehicle], [controller], [attack], [spec], [search])")
    g.add_argument("--network", help="scenario variant (see `d4sumo scenarios`) or a folder [highway_4lane]")
    g.add_argument("--followers", type=int, help="followers behind the attacker, 1..10 [3]")
    g.add_argument("--setpoint", type=float, help="bumper-to-bumper setpoint distance d in m [7]")
    g.add_argument("--speed", type=float, help="target speed in m/s [25]")
    g.add_argument("--start", choices=START_MODES, help="rest: all at 0 m/s; steady: all at the target speed [rest]")
    g.add_argument("--step", type=float, help="simulation step in s [0.05]")
    g.add_argument("--duration", type=float, help="episode length in s [60]")
    g.add_argument("--length", type=float, help="vehicle length in m [4.5]")
    g.add_argument("--controller", help="follower controller: 'switching' or 'package.module:ClassName'")
    g.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="SECTION.KEY=VALUE",
        help="any [scenario], [vehicle] or [controller] value, e.g. --set controller.acc_kp=1.2 (repeatable)",
    )


def _add_attack_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("attack")
    g.add_argument("--attack", choices=FAMILIES, help="attack family (with --params)")
    g.add_argument("--params", help="comma-separated parameter values of the family")
    g.add_argument("--knots", help="knot values in [-1, 1], comma-separated, joined by PCHIP (one every --delta s)")
    g.add_argument("--constant", type=float, help="a constant attacker command in [-1, 1] from t = 0")
    g.add_argument("--delta", type=float, help="knot spacing Delta in s [6]")
    g.add_argument("--horizon", type=float, help="last knot time in s [48]; set with --knots to the knots' span by default")


def _parse_value(text: str) -> Any:
    """A --set value as TOML would read it (number, bool, quoted string), else the bare string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _floats(option: str, text: str) -> list[float]:
    try:
        return [float(v) for v in text.split(",") if v.strip()]
    except ValueError:
        raise ConfigError(option, text, "comma-separated numbers, e.g. -1,1,0.5") from None


def episode_config(args: argparse.Namespace, doc: dict) -> EpisodeConfig:
    overrides: dict[str, Any] = {}
    for dest, key in EPISODE_FLAGS.items():
        value = getattr(args, dest, None)
        if value is not None:
            overrides[key] = value
    for item in args.set:
        key, sep, value = item.partition("=")
        if not sep:
            raise ConfigError("--set", item, "SECTION.KEY=VALUE, e.g. scenario.setpoint_m=5")
        overrides[key.strip()] = _parse_value(value.strip())
    return EpisodeConfig.from_dict(doc, overrides)


def attack_choice(args: argparse.Namespace, doc: dict):
    """(family, parameter vector) from --knots / --constant / --attack --params, or the [attack] table."""
    table = dict(doc.get("attack", {}))
    allowed = {"family", "params", "delta_s", "horizon_s"}
    for key in table:
        if key not in allowed:
            raise ConfigError(f"attack.{key}", table[key], f"a key of [attack]: {', '.join(sorted(allowed))}")
    given = [name for name in ("knots", "constant", "attack") if getattr(args, name, None) is not None]
    if len(given) > 1:
        raise ConfigError("--" + "/--".join(given), "together", "one attack: --knots, --constant or --attack with --params")
    delta = args.delta if args.delta is not None else table.get("delta_s", 6.0)
    if args.knots is not None:
        values = _floats("--knots", args.knots)
        if not values:
            raise ConfigError("--knots", args.knots, "at least one value in [-1, 1]")
        horizon = args.horizon if args.horizon is not None else delta * (len(values) - 1) or delta
        family = make_attack("knots", delta_s=delta, horizon_s=horizon)
        return family, family.check(values, "--knots")
    if args.constant is not None:
        family = make_attack("constant")
        return family, family.check([args.constant], "--constant")
    name = args.attack or table.get("family")
    if name is None:
        return None, None
    horizon = args.horizon if args.horizon is not None else table.get("horizon_s", 48.0)
    family = make_attack(name, delta_s=delta, horizon_s=horizon)
    if args.params is not None:
        values = _floats("--params", args.params)
    elif "params" in table:
        values = table["params"]
    else:
        raise ConfigError("--params", None, f"{family.dimension} values for {family.name}: {', '.join(family.names)}")
    return family, family.check(values, "--params")


def attack_signal(family, params, config: EpisodeConfig) -> np.ndarray:
    """The attacker's command at every step's start; NaN (cruise) when no attack is given."""
    times = np.arange(config.steps) * config.step_s
    if family is None:
        return np.full(config.steps, np.nan)
    return family.signal(params, times)


# --- commands ------------------------------------------------------------------------------------


def cmd_scenarios(args: argparse.Namespace) -> int:
    from .scenarios import SCENARIOS_DIR, build_road, list_scenarios

    names = list_scenarios()
    if not names:
        raise ConfigError("sumo_scenarios", str(SCENARIOS_DIR), "a folder of scenario variants")
    print(f"{'name':24s} {'lanes':>5s} {'length_m':>9s} {'limit_mps':>9s}  net")
    for name in names:
        road = build_road(name)
        print(f"{name:24s} {road.lanes:5d} {road.length_m:9.0f} {road.speed_limit_mps:9.2f}  {road.net_file}")
    return 0


def cmd_simulate(args: argparse.Namespace) -> int:
    from .scenarios import build_road
    from .simulation import simulate
    from .spec import psi_robustness

    doc = load_toml(args.config) if args.config else {}
    config = episode_config(args, doc)
    family, params = attack_choice(args, doc)
    d_safe = check_number("--d-safe", args.d_safe if args.d_safe is not None else doc.get("spec", {}).get("d_safe_m", 0.0), -1e3, 1e3, "m")
    road = build_road(config.network)
    episode = simulate(config, attack_signal(family, params, config), road=road, fcd_path=args.fcd, gui=args.gui)
    robustness = psi_robustness(episode.trace, d_safe) if config.followers >= 2 else None
    summary = {
        "d4sumo": __version__,
        "config": config.to_dict(),
        "attack": None if family is None else {**family.describe(), "values": [float(v) for v in params]},
        "outcome": episode.outcome,
        "first_collision": episode.first_collision.to_dict() if episode.first_collision else None,
        "collisions": [c.to_dict() for c in episode.collisions],
        "min_gaps_m": {k: round(v, 4) for k, v in episode.min_gaps_m().items()},
        "robustness": robustness,
        "d_safe_m": d_safe,
        "simulated_s": float(episode.trace.times_s[-1]),
        "fcd": str(args.fcd) if args.fcd else None,
    }
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        _print_summary(summary, road.name)
    return 0


def _print_summary(s: dict, road_name: str) -> None:
    sc = s["config"]["scenario"]
    attack = s["attack"]
    what = "no attack (the attacker cruises)" if attack is None else f"{attack['family']} {attack['values']}"
    print(f"{road_name}: {sc['followers']} followers, setpoint {sc['setpoint_m']:g} m, {sc['speed_mps']:g} m/s, start {sc['start']}; {what}")
    c = s["first_collision"]
    if c is None:
        print(f"outcome: {s['outcome']} in {s['simulated_s']:.2f} s")
    else:
        print(
            f"outcome: {s['outcome']}: {c['pair']} collided at t = {c['time_s']:.2f} s, "
            f"{c['position_m']:.1f} m along the road, speed difference {c['speed_diff_kmh']:.1f} km/h"
        )
    print("min gaps: " + ", ".join(f"{k} {v:.2f} m" for k, v in s["min_gaps_m"].items()))
    if s["robustness"] is not None:
        print(f"robustness of psi (d_safe {s['d_safe_m']:g} m): {s['robustness']:.4f}")
    if s["fcd"]:
        print(f"FCD written to {s['fcd']}")


# --- entry point ---------------------------------------------------------------------------------


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(prog="d4sumo", description="Adversarial driving maneuvers against ACC platoons, on SUMO.")
    parser.add_argument("--version", action="version", version=f"d4sumo {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("scenarios", help="list the network variants in sumo_scenarios/")
    p.set_defaults(func=cmd_scenarios)

    p = sub.add_parser("simulate", help="play one episode and summarise it")
    _add_episode_options(p)
    _add_attack_options(p)
    p.add_argument("--d-safe", type=float, dest="d_safe", help="d_safe of the specification in m [0]")
    p.add_argument("--fcd", type=Path, help="write SUMO's FCD output (with accelerations) to this file")
    p.add_argument("--json", action="store_true", help="print a machine-readable summary")
    p.add_argument("--gui", action="store_true", help="watch the episode in sumo-gui (needs a display)")
    p.set_defaults(func=cmd_simulate)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except ConfigError as exc:
        flag = {key: f"--{dest}" for dest, key in EPISODE_FLAGS.items()}.get(exc.field)
        field = f"{flag} ({exc.field})" if flag else exc.field
        print(f"d4sumo: error: {field}: got {exc.given!r}; allowed: {exc.allowed}", file=sys.stderr)
        return EXIT_USAGE
    except D4sumoError as exc:
        print(f"d4sumo: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt:
        print("d4sumo: interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
