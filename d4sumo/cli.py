"""Command line: parse flags and the TOML config, call the library, print. Flags override the file.

Every error a user can cause ends as one line `d4sumo: error: ...` and exit code 2.
"""

from __future__ import annotations

import argparse
import json
import logging
import signal
import sys
import threading
import tomllib
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from . import __version__
from .attacks import FAMILIES, attack_signal, make_attack
from .config import START_MODES, EpisodeConfig, load_toml
from .errors import ConfigError, D4sumoError, check_number
from .optimizers import OPTIMIZERS

EXIT_USAGE = 2

# flag dest -> dotted config key: the flags that set [scenario]/[vehicle]/[controller] values
EPISODE_FLAGS = {
    "network": "scenario.network",
    "followers": "scenario.followers",
    "setpoint": "scenario.setpoint_m",
    "speed": "scenario.speed_mps",
    "start": "scenario.start",
    "warmup": "scenario.warmup_s",
    "step": "scenario.step_s",
    "duration": "scenario.duration_s",
    "length": "vehicle.length_m",
    "controller": "controller.class",
}

# config fields -> flags of falsify
SEARCH_FLAGS = {"optimizer": "--optimizer", "samples": "--samples", "seed": "--seed", "attack": "--attack",
                "spec.formula": "--formula", "spec.d_safe_m": "--d-safe", "attack.delta_s": "--delta", "attack.horizon_s": "--horizon"}


def _add_episode_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scenario (override the config file)")
    g.add_argument("--config", help="TOML config file ([scenario], [vehicle], [controller], [attack], [spec], [search])")
    g.add_argument("--network", help="scenario variant (see `d4sumo scenarios`) or a folder [highway_4lane]")
    g.add_argument("--followers", type=int, help="followers behind the attacker, 1..10 [3]")
    g.add_argument("--setpoint", type=float, help="bumper-to-bumper setpoint distance d in m [7]")
    g.add_argument("--speed", type=float, help="target speed in m/s [25]")
    g.add_argument("--start", choices=START_MODES,
                   help="rest: all at 0 m/s; steady: all at the target speed; warmup: drive from rest for --warmup s, "
                        "attack after [rest]")
    g.add_argument("--warmup", type=float, help="seconds driven from rest before the attack with --start warmup [15]")
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
    _add_knot_options(g)


def _add_knot_options(g) -> None:
    g.add_argument("--delta", type=float, help="knot spacing Delta in s [6]")
    g.add_argument("--horizon", type=float, help="last knot time in s [48; with --knots, the knots' span]")


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


def episode_signal(family, params, config: EpisodeConfig) -> np.ndarray:
    """The attacker's command at every step's start; NaN (cruise) before the attack or with none."""
    return attack_signal(family, params, steps=config.steps, step_s=config.step_s, start_step=config.attack_start_step)


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
    episode = simulate(config, episode_signal(family, params, config), road=road, fcd_path=args.fcd, gui=args.gui)
    robustness = psi_robustness(episode.trace, d_safe) if config.followers >= 2 else None
    _report(episode_summary(config, family, params, episode, robustness, d_safe, args.fcd), road.name, args.json)
    return 0


def episode_summary(config, family, params, episode, robustness, d_safe, fcd) -> dict:
    return {
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
        "fcd": str(fcd) if fcd else None,
    }


def _report(summary: dict, road_name: str, as_json: bool) -> None:
    if as_json:
        print(json.dumps(summary, indent=2))
    else:
        _print_summary(summary, road_name)


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
        what = "the campaign's formula" if s.get("formula") else f"psi (d_safe {s['d_safe_m']:g} m)"
        print(f"robustness of {what}: {s['robustness']:.4f}")
    if s["fcd"]:
        print(f"FCD written to {s['fcd']}")


def _search_tables(doc: dict) -> tuple[dict, dict]:
    search, spec = dict(doc.get("search", {})), dict(doc.get("spec", {}))
    for table, allowed, name in ((search, ("optimizer", "samples", "seed"), "search"), (spec, ("d_safe_m", "formula"), "spec")):
        for key in table:
            if key not in allowed:
                raise ConfigError(f"{name}.{key}", table[key], f"a key of [{name}]: {', '.join(allowed)}")
    return search, spec


def _pick(flag, table: dict, key: str, default):
    return flag if flag is not None else table.get(key, default)


def campaign_from(args: argparse.Namespace, doc: dict):
    from .campaign import Campaign

    config = episode_config(args, doc)
    search, spec = _search_tables(doc)
    attack = dict(doc.get("attack", {}))
    for key in ("params",):
        if key in attack:
            raise ConfigError(f"attack.{key}", attack[key], "no fixed parameters in a campaign: the optimiser chooses them")
    return Campaign(
        config=config,
        attack=_pick(args.attack, attack, "family", "knots"),
        optimizer=_pick(args.optimizer, search, "optimizer", "bo"),
        samples=_pick(args.samples, search, "samples", 100),
        seed=_pick(args.seed, search, "seed", 0),
        d_safe_m=_pick(args.d_safe, spec, "d_safe_m", 0.0),
        formula=_pick(args.formula, spec, "formula", None),
        delta_s=_pick(args.delta, attack, "delta_s", 6.0),
        horizon_s=_pick(args.horizon, attack, "horizon_s", 48.0),
    )


def cmd_falsify(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from .campaign import Evaluator, run_campaign
    from .store import Store

    doc = load_toml(args.config) if args.config else {}
    campaign = campaign_from(args, doc)
    evaluator = Evaluator(campaign)  # parses the formula and builds the road: fail before writing anything
    counts = {"success": 0, "attacker_crash": 0, "no_crash": 0, "error": 0}
    best = [None]
    with Store(args.db) as store, tqdm(total=campaign.samples, desc=f"{campaign.attack}/{campaign.optimizer}", unit="sample",
                                      disable=args.quiet, file=sys.stderr, dynamic_ncols=True) as bar:

        def progress(r) -> None:
            counts[r.outcome] += 1
            if r.robustness is not None and (best[0] is None or r.robustness > best[0]):
                best[0] = r.robustness
            bar.update(1)
            bar.set_postfix(success=counts["success"], best=f"{best[0]:.3f}" if best[0] is not None else "-", refresh=False)

        summary = run_campaign(campaign, store, evaluator=evaluator, on_sample=progress)
    top = summary.best
    result = {
        "db": str(args.db),
        "campaign_id": summary.campaign_id,
        "attack": campaign.attack,
        "optimizer": campaign.optimizer,
        "seed": campaign.seed,
        "samples": len(summary.samples),
        "outcomes": counts,
        "best": None if top is None else {
            "sample_id": top.id, "index": top.index, "robustness": top.robustness, "outcome": top.outcome,
            "params": list(top.params), "collision": top.collision,
        },
    }
    if args.json:
        print(json.dumps(result, indent=2))
        return 0
    print(f"campaign {summary.campaign_id} ({campaign.attack}, {campaign.optimizer}, seed {campaign.seed}) in {args.db}: {len(summary.samples)} samples")
    print("  " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    if top is not None:
        c = top.collision
        hit = f", {c['pair']} at {c['time_s']:.2f} s, {c['position_m']:.1f} m, {c['speed_diff_kmh']:.1f} km/h" if c else ""
        print(f"  best: sample {top.id} ({top.outcome}), robustness {top.robustness:.4f}{hit}")
        print(f"  params: {', '.join(f'{v:.3f}' for v in top.params)}")
        print(f"  replay it: d4sumo replay {args.db} {top.id} --fcd best_fcd.xml")
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    from .campaign import Campaign, Evaluator
    from .simulation import simulate
    from .store import Store

    with Store(args.db, create=False) as store:
        row = store.sample(args.sample)
        definition = store.campaign(row.campaign_id).definition
    if row.outcome == "error":
        print(f"d4sumo: note: sample {row.id} was stored as errored ({row.error}); replaying it", file=sys.stderr)
    campaign = Campaign.from_definition(definition)
    evaluator = Evaluator(campaign)
    episode = simulate(campaign.config, evaluator.signal(row.params), road=evaluator.road, fcd_path=args.fcd, gui=args.gui)
    rho = evaluator.spec.robustness(episode.trace)
    summary = episode_summary(campaign.config, evaluator.family, row.params, episode, rho, campaign.d_safe_m, args.fcd)
    summary.update(sample_id=row.id, campaign_id=row.campaign_id, formula=campaign.formula,
                   stored_robustness=row.robustness, stored_outcome=row.outcome,
                   reproduced=(row.robustness == rho and row.outcome == episode.outcome))
    _report(summary, evaluator.road.name, args.json)
    if not args.json:
        print("reproduces the stored sample exactly" if summary["reproduced"] else
              f"differs from the stored sample (stored robustness {row.robustness}, outcome {row.outcome})")
    return 0


def cmd_export(args: argparse.Namespace) -> int:
    import csv

    from .attacks import make_attack
    from .store import Store

    with Store(args.db, create=False) as store:
        campaigns = {c.id: c for c in store.campaigns()}
        if args.campaign is not None and args.campaign not in campaigns:
            raise ConfigError("--campaign", args.campaign, f"a campaign id of {args.db}: {', '.join(map(str, campaigns)) or 'none'}")
        names: dict[int, tuple[str, ...]] = {}
        columns: list[str] = []
        for cid, c in campaigns.items():
            a = c.definition["attack"]
            names[cid] = make_attack(a["family"], delta_s=a.get("delta_s", 6.0), horizon_s=a.get("horizon_s", 48.0)).names
            columns += [n for n in names[cid] if n not in columns]
        header = ["sample_id", "campaign_id", "index", "network", "followers", "setpoint_m", "speed_mps", "start", "attack",
                  "optimizer", "seed", "robustness", "outcome", "pair", "time_s", "position_m", "speed_diff_kmh", "wall_s",
                  "error"] + columns
        out = open(args.out, "w", newline="") if args.out else sys.stdout
        try:
            writer = csv.writer(out)
            writer.writerow(header)
            rows = 0
            for s in store.iter_samples(args.campaign):
                d = campaigns[s.campaign_id].definition
                sc = d["config"]["scenario"]
                params = dict(zip(names[s.campaign_id], s.params))
                writer.writerow([s.id, s.campaign_id, s.index, sc["network"], sc["followers"], sc["setpoint_m"], sc["speed_mps"],
                                 sc["start"], d["attack"]["family"], d["optimizer"], d["seed"], s.robustness, s.outcome, s.pair,
                                 s.time_s, s.position_m, s.speed_diff_kmh, round(s.wall_s, 6), s.error]
                                + [params.get(n, "") for n in columns])
                rows += 1
        finally:
            if args.out:
                out.close()
    if args.out:
        print(f"{rows} samples written to {args.out}", file=sys.stderr)
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from .sweep import Sweep, run_sweep

    sweep = Sweep.load(args.sweep)
    if args.workers is not None and args.workers < 1:
        raise ConfigError("--workers", args.workers, "a whole number >= 1")
    bar = tqdm(total=sweep.samples, desc=f"sweep {sweep.name}", unit="sample", disable=args.quiet, file=sys.stderr,
               dynamic_ncols=True)

    def progress(done: int, total: int, successes: int) -> None:
        bar.update(done - bar.n)
        bar.set_postfix(success=successes, refresh=False)

    try:
        result = run_sweep(sweep, args.db, workers=args.workers, dask_address=args.dask, dask_timeout_s=args.dask_timeout,
                           progress=progress)
    except KeyboardInterrupt:
        bar.close()
        print(f"d4sumo: sweep interrupted; every sample it finished is in {args.db}: run the same command to resume",
              file=sys.stderr)
        raise
    bar.close()
    print(f"sweep {sweep.name}: {result.campaigns} campaigns, {result.samples} samples, {result.successes} successes "
          f"in {result.wall_s:.1f} s -> {args.db}")
    print(f"  report: d4sumo report {args.db} --out report/")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from .report import build_report

    steps = ["tables", "heatmaps", "time-space diagrams", "clusters"]
    with tqdm(total=len(steps), desc="report", disable=args.quiet, file=sys.stderr) as bar:
        def progress(what: str) -> None:
            if bar.n or what != steps[0]:
                bar.update(1)
            bar.set_postfix_str(what)

        index = build_report(args.db, args.out, severe=args.severe, progress=progress)
        bar.update(bar.total - bar.n)
    print(f"report written to {index}")
    return 0


def cmd_plot(args: argparse.Namespace) -> int:
    from . import figures
    from .analysis import cluster_knots, load_records

    records = load_records(args.db)
    if args.kind in ("time-space", "accel"):
        if args.sample is None:
            raise ConfigError("--sample", None, f"a sample id for a {args.kind} plot")
        from .report import collision_of, describe, replay_to_fcd

        matches = [r for r in records if r.sample_id == args.sample]
        if not matches:
            raise ConfigError("--sample", args.sample, f"a sample id of {', '.join(map(str, args.db))}")
        r = matches[0]
        fcd_path = args.out.with_suffix(".fcd.xml")
        fcd = replay_to_fcd(r, fcd_path)
        title = describe(r) if r.pair else f"sample {r.sample_id}: {r.outcome}"
        if args.kind == "time-space":
            figures.time_space(fcd, title, args.out, collision_of(r))
        else:
            figures.accelerations(fcd, title, args.out, collision_of(r))
        print(f"{args.kind} plot written to {args.out} (FCD: {fcd_path})")
        return 0
    filters = {"attack": args.attack, "optimizer": args.optimizer, "start": args.start,
               "setpoint_m": args.setpoint, "speed_mps": args.speed}
    chosen = [r for r in records if all(v is None or getattr(r, k) == v for k, v in filters.items())]
    if not chosen:
        raise ConfigError("filters", {k: v for k, v in filters.items() if v is not None}, "values that match stored samples")
    label = ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{v}" for k, v in filters.items() if v is not None) or "all samples"
    if args.kind == "heatmap":
        figures.heatmap(chosen, f"successes: {label}", args.out)
    else:
        clustering = cluster_knots(chosen, label)
        if clustering is None:
            raise ConfigError("filters", label, "a selection with at least 4 successful knot attacks")
        figures.clusters(clustering, args.out)
    print(f"{args.kind} plot written to {args.out}")
    return 0


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

    p = sub.add_parser("falsify", help="run a campaign: search for attacks that make the followers crash")
    _add_episode_options(p)
    g = p.add_argument_group("search")
    g.add_argument("--attack", choices=[f for f in FAMILIES if f != "constant"], help="attack family [knots]")
    _add_knot_options(g)
    g.add_argument("--optimizer", choices=OPTIMIZERS, help="bo, ce, random or halton [bo]")
    g.add_argument("--samples", type=int, help="budget: episodes to simulate [100]")
    g.add_argument("--seed", type=int, help="seed: the same seed repeats the campaign exactly [0]")
    g.add_argument("--formula", help="an STL formula (rtamt syntax) over the trace's signals instead of the paper's psi")
    g.add_argument("--d-safe", type=float, dest="d_safe", help="d_safe of the paper's psi in m [0]")
    p.add_argument("--db", type=Path, default=Path("results.sqlite"), help="results database (created if new) [results.sqlite]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print a machine-readable summary")
    p.set_defaults(func=cmd_falsify)

    p = sub.add_parser("sweep", help="run a grid of campaigns (local processes or a Dask cluster); resumable")
    p.add_argument("sweep", type=Path, help="sweep file (TOML: [grid] of lists, [search] samples, fixed tables)")
    p.add_argument("--db", type=Path, default=Path("results.sqlite"), help="results database [results.sqlite]")
    p.add_argument("--workers", type=int, help="local worker processes [number of cores]")
    p.add_argument("--dask", metavar="ADDRESS", help="run on this Dask distributed scheduler (e.g. tcp://10.0.0.5:8786)")
    p.add_argument("--dask-timeout", type=float, default=30.0, metavar="S", help="seconds to wait for the scheduler [30]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_sweep)

    p = sub.add_parser("report", help="HTML report: the paper's tables, heatmaps, time-space diagrams, clusters")
    p.add_argument("db", type=Path, nargs="+", help="results database(s)")
    p.add_argument("--out", type=Path, default=Path("report"), help="folder for index.html and figures [report]")
    p.add_argument("--severe", type=int, default=3, help="time-space diagrams of the N most severe attacks [3]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.set_defaults(func=cmd_report)

    p = sub.add_parser("plot", help="draw one figure: time-space, accel, heatmap or clusters")
    p.add_argument("kind", choices=("time-space", "accel", "heatmap", "clusters"))
    p.add_argument("db", type=Path, nargs="+", help="results database(s)")
    p.add_argument("--out", type=Path, required=True, help="image file (.png, .pdf, .svg)")
    p.add_argument("--sample", type=int, help="sample id (time-space, accel)")
    p.add_argument("--attack", help="only this attack family (heatmap, clusters)")
    p.add_argument("--optimizer", help="only this optimiser")
    p.add_argument("--start", choices=START_MODES, help="only this start mode")
    p.add_argument("--setpoint", type=float, help="only this setpoint in m")
    p.add_argument("--speed", type=float, help="only this target speed in m/s")
    p.set_defaults(func=cmd_plot)

    p = sub.add_parser("replay", help="re-simulate one stored sample exactly (FCD, sumo-gui)")
    p.add_argument("db", type=Path, help="results database")
    p.add_argument("sample", type=int, help="sample id (as printed by falsify and export)")
    p.add_argument("--fcd", type=Path, help="write SUMO's FCD output to this file")
    p.add_argument("--gui", action="store_true", help="watch it in sumo-gui (needs a display)")
    p.add_argument("--json", action="store_true", help="print a machine-readable summary")
    p.set_defaults(func=cmd_replay)

    p = sub.add_parser("export", help="write stored samples to CSV")
    p.add_argument("db", type=Path, help="results database")
    p.add_argument("--out", type=Path, help="CSV file [standard output]")
    p.add_argument("--campaign", type=int, help="only this campaign id")
    p.set_defaults(func=cmd_export)
    return parser


class Terminated(KeyboardInterrupt):
    """SIGTERM: stop as on Ctrl-C (workers stopped, nothing half-written), exit code 143."""


def _on_sigterm(signum, frame) -> None:
    raise Terminated()


def main(argv: Sequence[str] | None = None) -> int:
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _on_sigterm)
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    try:
        return args.func(args)
    except ConfigError as exc:
        flag = {**{key: f"--{dest}" for dest, key in EPISODE_FLAGS.items()}, **SEARCH_FLAGS}.get(exc.field)
        field = f"{flag} ({exc.field})" if flag else exc.field
        print(f"d4sumo: error: {field}: got {exc.given!r}; allowed: {exc.allowed}", file=sys.stderr)
        return EXIT_USAGE
    except D4sumoError as exc:
        print(f"d4sumo: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except KeyboardInterrupt as exc:
        if not isinstance(exc, Terminated):
            print("d4sumo: interrupted", file=sys.stderr)
        return 143 if isinstance(exc, Terminated) else 130


if __name__ == "__main__":
    sys.exit(main())
