"""Command line: parse flags, call the library, print. The CLI stays thin: flags become dotted keys
laid over the config file (`inputs`), and the library checks the one resulting document.

Every error a user can cause ends as one line `d4sumo: error: ...` and exit code 2.
"""

from __future__ import annotations

import argparse
import contextlib
import json
import logging
import os
import re
import signal
import sys
import threading
import tomllib
from pathlib import Path
from typing import Any, Sequence


from . import __version__
from .model.attacks import FAMILIES
from .model.config import MANEUVERS, START_MODES, EpisodeConfig
from .errors import ConfigError, D4sumoError, check_number
from .model.batch import DEFAULT_BATCH
from .search.optimizers import EARLIER_OPTIONS, OPTIMIZERS, as_set_flags
from .engine.scenarios import MAX_COPIES

EXIT_USAGE = 2

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


def _add_episode_options(p: argparse.ArgumentParser) -> None:
    g = p.add_argument_group("scenario (flags override the config file)")
    g.add_argument("--config", type=Path, help="TOML config file ([scenario], [vehicle], [controller], [attack], [spec], [search])")
    g.add_argument("--network", help="scenario variant (see `d4sumo scenarios`) or a folder [highway_4lane]")
    g.add_argument("--followers", type=int, help="followers behind the attacker, 1..10 [3]")
    g.add_argument("--setpoint", type=float, help="bumper-to-bumper setpoint distance d in m [7]")
    g.add_argument("--speed", type=float, help="target speed in m/s [25]")
    g.add_argument("--start", choices=START_MODES,
                   help="rest: all at 0 m/s; steady: all at the target speed; warmup: drive from rest for --warmup s, "
                        "attack after [rest]")
    g.add_argument("--maneuver", choices=MANEUVERS,
                   help="inlane: the attacker leads the platoon in its lane (the paper); cutin: it changes into the "
                        "platoon's lane in front of a follower; cutout: it leads, then leaves the lane to reveal a "
                        "slower car (multi-lane roads; the optimiser picks the lane change time t_lc_s) [inlane]")
    g.add_argument("--warmup", type=float, help="seconds driven from rest before the attack with --start warmup [15]")
    g.add_argument("--step", type=float, help="simulation step in s [0.05]")
    g.add_argument("--duration", type=float, help="seconds from the attack's start to the episode's end [60]")
    g.add_argument("--length", type=float, help="vehicle length in m [4.5]")
    g.add_argument("--controller",
                   help="follower controller: switching, timegap, a SUMO car-following model as sumo:MODEL (sumo:ACC, "
                        "sumo:CACC, sumo:IDM, ...) or package.module:ClassName; a comma-separated list gives one per "
                        "follower, v1 first [switching]")
    g.add_argument(
        "--set",
        action="append",
        default=[],
        metavar="TABLE.KEY=VALUE",
        help="any value of the config file, e.g. --set controller.acc_kp=1.2, --set controller.tau=1.2 (sumo:MODEL), "
             "--set controller.v2.tau=1.2 (one follower of a mixed platoon) or --set search.ce.batch_size=20 (repeatable)",
    )


def _add_spec_options(g) -> None:
    g.add_argument("--formula", help="an STL formula (rtamt syntax) over the trace's signals instead of the paper's psi")
    g.add_argument("--d-safe", type=float, dest="d_safe", help="d_safe of the paper's psi in m [0]")


def _add_knot_options(g) -> None:
    g.add_argument("--delta", type=float, help="knot spacing Delta in s [6]")
    g.add_argument("--horizon", type=float, help="last knot time in s [48; with --knots, the knots' span]")


def _parse_value(text: str) -> Any:
    """A --set value as TOML would read it (number, bool, quoted string, list), else the bare string."""
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def _floats(option: str, text: str) -> list[float]:
    try:
        values = [float(v) for v in text.split(",")]
    except ValueError:
        raise ConfigError(option, text, "comma-separated numbers, e.g. -1,1,0.5") from None
    return values


def document(args: argparse.Namespace) -> tuple[dict, dict]:
    """The config file with the flags laid over it, and the flags' own keys (for error messages)."""
    from .inputs import read_document, with_overrides

    doc = read_document(args.config) if getattr(args, "config", None) else {}
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
        values = _floats("--knots", knots)
        delta = flags.get("attack.delta_s", doc.get("attack", {}).get("delta_s", 6.0))
        flags.update({"attack.family": "knots", "attack.params": values})
        if "attack.horizon_s" not in flags and isinstance(delta, (int, float)):
            flags["attack.horizon_s"] = delta * (len(values) - 1) or delta
    if constant is not None:
        flags.update({"attack.family": "constant", "attack.params": [constant]})
    if "attack.params" in flags and "attack.family" not in flags and "family" not in doc.get("attack", {}):
        raise ConfigError("--params", args.params, "an attack family with it: --attack NAME --params ...")
    for item in getattr(args, "set", []):
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise ConfigError("--set", item, "TABLE.KEY=VALUE, e.g. scenario.setpoint_m=5")
        flags[key.strip()] = _parse_value(value.strip())
    return with_overrides(doc, flags), flags


def episode_plan(family, params, config: EpisodeConfig):
    """The attacker's command at every step's start (NaN, cruise, before the attack or with none) and its lane change."""
    from .model.maneuvers import attack_plan

    return attack_plan(family, params, config)


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


def check_display(gui: bool) -> None:
    """sumo-gui needs a display: say so at once instead of a minute of retries."""
    if gui and sys.platform.startswith("linux") and not (os.environ.get("DISPLAY") or os.environ.get("WAYLAND_DISPLAY")):
        raise ConfigError("--gui", "no display", "a graphical session (DISPLAY is not set); use --fcd and `d4sumo plot` instead")


def check_fcd_written(path: Path | None) -> None:
    """SUMO does not fail when its output cannot be written (a full disk): check the file is whole."""
    if path is None:
        return
    try:
        with open(path, "rb") as fh:
            fh.seek(max(0, path.stat().st_size - 200))
            whole = b"</fcd-export>" in fh.read()
    except OSError:
        whole = False
    if not whole:
        raise D4sumoError(f"--fcd: {path} was not written completely (is the disk full?)")


# --- commands ------------------------------------------------------------------------------------


def cmd_scenarios(args: argparse.Namespace) -> int:
    from .engine.scenarios import SCENARIOS_DIR, build_road, list_scenarios

    names = list_scenarios()
    if not names:
        raise ConfigError("sumo_scenarios", str(SCENARIOS_DIR), "a folder of scenario variants")
    print(f"{'name':24s} {'lanes':>5s} {'length_m':>9s} {'limit_mps':>9s}  net")
    for name in names:
        road = build_road(name)
        print(f"{name:24s} {road.lanes:5d} {road.length_m:9.0f} {road.speed_limit_mps:9.2f}  {road.net_file}")
    return 0


def cmd_simulate(args: argparse.Namespace) -> int:
    from .inputs import attack_of, episode_config
    from .engine.scenarios import build_road
    from .engine.simulation import simulate
    from .search.spec import Specification

    doc, _ = document(args)
    config = episode_config(doc)
    family, params = attack_of(doc)
    spec_table = doc.get("spec", {})
    d_safe = check_number("spec.d_safe_m", spec_table.get("d_safe_m", 0.0), -1e3, 1e3, "m")
    formula = spec_table.get("formula")
    spec = None
    if formula is not None or config.followers >= 2 or config.maneuver_class.lateral:
        spec = Specification(followers=config.followers, step_s=config.step_s, formula=formula, d_safe_m=d_safe,
                             duration_s=config.duration_s, start_step=config.attack_start_step,
                             maneuver=config.maneuver)  # as a campaign scores
    fcd = check_output_file("--fcd", args.fcd)
    check_display(args.gui)
    road = build_road(config.network)
    episode = simulate(config, episode_plan(family, params, config), road=road, fcd_path=fcd, gui=args.gui)
    check_fcd_written(fcd)
    robustness = spec.robustness(episode.trace) if spec else None
    summary = episode_summary(config, family, params, episode, robustness, d_safe, fcd)
    summary["formula"] = formula
    _report(summary, road.name, args.json)
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
    maneuver = f", {sc['maneuver']}" if "maneuver" in sc else ""
    print(f"{road_name}: {sc['followers']} followers, setpoint {sc['setpoint_m']:g} m, {sc['speed_mps']:g} m/s, start {sc['start']}{maneuver}; {what}")
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
        what = "the formula" if s.get("formula") else f"psi (d_safe {s['d_safe_m']:g} m)"
        print(f"robustness of {what}: {s['robustness']:.4f}")
    if s["fcd"]:
        print(f"FCD written to {s['fcd']}")


def cmd_falsify(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from .search.campaign import Evaluator, open_store, run_campaign
    from .inputs import campaign_of

    doc, _ = document(args)
    campaign = campaign_of(doc)
    evaluator = Evaluator(campaign)  # parses the formula and builds the road: fail before writing anything
    check_batch(args.batch)
    counts = {"success": 0, "attacker_crash": 0, "no_crash": 0, "error": 0}
    best = [None]
    with open_store(args.db) as store, contextlib.ExitStack() as stack:
        known = store.find_campaign(campaign.definition())
        stored = 0 if known is None else sum(s.index < campaign.samples for s in store.iter_samples(known))
        if known is not None and not args.quiet:
            print(f"d4sumo: campaign {known} in {args.db}: " + (
                f"all {campaign.samples} samples stored already, nothing to run (a larger --samples extends it)"
                if stored >= campaign.samples else f"{stored} of {campaign.samples} samples stored already: resuming"),
                file=sys.stderr)
        # the bar counts what this run plays; the stored samples are where it starts
        bar = stack.enter_context(tqdm(total=campaign.samples, initial=stored, desc=f"{campaign.attack}/{campaign.optimizer}",
                                       unit="sample", disable=args.quiet or stored >= campaign.samples, file=sys.stderr,
                                       dynamic_ncols=True))
        told = [0]

        def progress(r) -> None:
            counts[r.outcome] += 1
            if r.robustness is not None and (best[0] is None or r.robustness > best[0]):
                best[0] = r.robustness
            told[0] += 1
            if told[0] > stored:  # the stored samples come first, told to the optimiser again
                bar.update(1)
            bar.set_postfix(success=counts["success"], best=f"{best[0]:.3f}" if best[0] is not None else "-", refresh=False)

        if known is None:
            for earlier in EARLIER_OPTIONS.get(campaign.optimizer, ()):
                before = campaign.replace(optimizer_options=tuple({**dict(campaign.optimizer_options), **earlier}.items()))
                if before != campaign and store.find_campaign(before.definition()) is not None:
                    bar.write(f"d4sumo: note: {args.db} holds this campaign as an earlier d4sumo ran it; this starts a new "
                              f"one. To go on with that one: {as_set_flags(campaign.optimizer, earlier)}", file=sys.stderr)
                    break
        try:
            summary = run_campaign(campaign, store, evaluator=evaluator, on_sample=progress, batch=args.batch)
        except KeyboardInterrupt as exc:
            bar.close()
            print(f"d4sumo: campaign interrupted; every sample it finished is in {args.db}: run the same command to resume",
                  file=sys.stderr)
            exc.said = True  # main need not say it again
            raise
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
    attack = f"{campaign.config.maneuver}, {campaign.attack}" if campaign.config.maneuver_class.lateral else campaign.attack
    print(f"campaign {summary.campaign_id} ({attack}, {campaign.optimizer}, seed {campaign.seed}) in {args.db}: {len(summary.samples)} samples")
    print("  " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    if top is not None:
        c = top.collision
        hit = f", {c['pair']} at {c['time_s']:.2f} s, {c['position_m']:.1f} m, {c['speed_diff_kmh']:.1f} km/h" if c else ""
        print(f"  best: sample {top.id} ({top.outcome}), robustness {top.robustness:.4f}{hit}")
        print(f"  params: {', '.join(f'{v:.3f}' for v in top.params)}")
        print(f"  replay it: d4sumo replay {args.db} {top.id} --fcd best_fcd.xml")
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    from .search.campaign import Campaign, Evaluator, open_store
    from .engine.simulation import simulate

    fcd = check_output_file("--fcd", args.fcd)
    check_display(args.gui)
    with open_store(args.db, create=False) as store:
        row = store.sample(args.sample)
        campaign = Campaign.from_definition(store.campaign(row.campaign_id).definition,
                                            where=f"{args.db}: campaign {row.campaign_id}", imports=True)
    if row.outcome == "error":
        print(f"d4sumo: note: sample {row.id} was stored as errored ({row.error}); replaying it", file=sys.stderr)
    evaluator = Evaluator(campaign)
    episode = simulate(campaign.config, evaluator.plan(row.params), road=evaluator.road, fcd_path=fcd, gui=args.gui)
    check_fcd_written(fcd)
    rho = evaluator.spec.robustness(episode.trace)
    summary = episode_summary(campaign.config, evaluator.family, row.params, episode, rho, campaign.d_safe_m, fcd)
    summary.update(sample_id=row.id, campaign_id=row.campaign_id, formula=campaign.formula,
                   stored_robustness=row.robustness, stored_outcome=row.outcome,
                   reproduced=(row.robustness == rho and row.outcome == episode.outcome))
    _report(summary, evaluator.road.name, args.json)
    if not args.json:
        print("reproduces the stored sample exactly" if summary["reproduced"] else
              f"differs from the stored sample (stored robustness {row.robustness}, outcome {row.outcome})")
    return 0


def _pair_order(pair: str) -> tuple:
    """Pairs front to back as the cars are named (v0-v1 before v1-v2 before v10-v11), others after."""
    cars = pair.split("-")
    return tuple((0, int(c[1:]), "") if c[1:].isdigit() and c[0] == "v" else (1, 0, c) for c in cars)


def cmd_export(args: argparse.Namespace) -> int:
    import csv

    from .results.analysis import system_label
    from .search.campaign import Campaign, open_store

    with open_store(args.db, create=False) as store:
        campaigns = {c.id: c for c in store.campaigns()}
        if args.campaign is not None and args.campaign not in campaigns:
            raise ConfigError("--campaign", args.campaign, f"a campaign id of {args.db}: {', '.join(map(str, campaigns)) or 'none'}")
        names: dict[int, tuple[str, ...]] = {}
        systems = {cid: system_label(c.definition["config"]) for cid, c in campaigns.items()}
        columns: list[str] = []
        for cid, c in campaigns.items():
            names[cid] = Campaign.from_definition(c.definition, where=str(args.db)).family().names
            columns += [n for n in names[cid] if n not in columns]
        # every pair of cars that followed each other in some sample: its minimum bumper gap
        pairs = sorted({p for s in store.iter_samples(args.campaign) for p in s.min_gaps}, key=_pair_order)
        header = ["sample_id", "campaign_id", "index", "network", "followers", "setpoint_m", "speed_mps", "start", "maneuver", "system",
                  "attack", "optimizer", "seed", "robustness", "outcome", "pair", "time_s", "position_m", "speed_diff_kmh", "wall_s",
                  "error"] + [f"min_gap_{p}_m" for p in pairs] + columns
        out_path = check_output_file("--out", args.out)
        tmp = out_path.with_name(f".{out_path.name}.part") if out_path else None
        out = open(tmp, "w", newline="") if tmp else sys.stdout
        try:
            writer = csv.writer(out)
            writer.writerow(header)
            rows = 0
            for s in store.iter_samples(args.campaign):
                d = campaigns[s.campaign_id].definition
                sc = d["config"]["scenario"]
                params = dict(zip(names[s.campaign_id], s.params))
                writer.writerow([s.id, s.campaign_id, s.index, sc["network"], sc["followers"], sc["setpoint_m"], sc["speed_mps"],
                                 sc["start"], sc.get("maneuver", "inlane"), systems[s.campaign_id], d["attack"]["family"], d["optimizer"], d["seed"], s.robustness, s.outcome, s.pair,
                                 s.time_s, s.position_m, s.speed_diff_kmh, round(s.wall_s, 6), s.error]
                                + [s.min_gaps.get(p, "") for p in pairs] + [params.get(n, "") for n in columns])
                rows += 1
            if tmp:
                out.close()
                os.replace(tmp, out_path)  # whole or not at all
        except OSError as exc:
            if tmp is None:  # standard output (a closed pipe, say): main handles it
                raise
            raise D4sumoError(f"--out: {out_path} could not be written ({exc.strerror}); nothing was written") from None
        finally:
            if tmp:
                out.close()
                tmp.unlink(missing_ok=True)
    if args.out:
        print(f"{rows} samples written to {args.out}", file=sys.stderr)
    return 0


def cmd_sweep(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from .sweep import Sweep, check_dask_address, run_sweep

    if args.workers is not None and not 1 <= args.workers <= 1024:
        raise ConfigError("--workers", args.workers, "a whole number in [1, 1024]")
    if args.dask is not None:
        check_dask_address(args.dask)
    check_number("--dask-timeout", args.dask_timeout, 0.0, 3600.0, "seconds", low_open=True)
    check_batch(args.batch)
    sweep = Sweep.load(args.sweep)
    bar = None  # made at the first progress report: an error before it stays one line

    def progress(done: int, total: int, successes: int) -> None:
        nonlocal bar
        if bar is None:
            bar = tqdm(total=total, desc=f"sweep {sweep.name}", unit="sample", disable=args.quiet, file=sys.stderr,
                       dynamic_ncols=True, initial=done)
        bar.update(done - bar.n)
        bar.set_postfix(success=successes, refresh=False)

    try:
        result = run_sweep(sweep, args.db, workers=args.workers, dask_address=args.dask, dask_timeout_s=args.dask_timeout,
                           progress=progress, batch=args.batch)
    except KeyboardInterrupt as exc:
        if bar is not None:
            bar.close()
        print(f"d4sumo: sweep interrupted; every sample it finished is in {args.db}: run the same command to resume",
              file=sys.stderr)
        exc.said = True  # main need not say it again
        raise
    except BaseException:
        if bar is not None:
            bar.close()
        raise
    if bar is not None:
        bar.close()
    print(f"sweep {sweep.name}: {result.campaigns} campaigns, {result.samples} samples, {result.successes} successes "
          f"in {result.wall_s:.1f} s -> {args.db}")
    print(f"  report: d4sumo report {args.db} --out report/")
    return 0


def cmd_report(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from .search.campaign import open_store
    from .results.report import build_report

    if args.out.exists() and not args.out.is_dir():
        raise ConfigError("--out", str(args.out), "a folder for index.html and its figures (this is a file)")
    if not args.out.parent.is_dir():
        raise ConfigError("--out", str(args.out), f"a folder in an existing folder ({args.out.parent} does not exist)")
    if not 0 <= args.severe <= 100:
        raise ConfigError("--severe", args.severe, "a whole number in [0, 100]")
    for db in args.db:  # every database readable and sound before any output
        with open_store(db, create=False) as store:
            store.campaigns()
            for _ in store.iter_samples():
                pass
    try:  # a folder that can be made here (/proc's parent exists, yet nothing can be made in it)
        (args.out / "fcd").mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise ConfigError("--out", str(args.out), f"a folder that can be created and written ({exc.strerror})") from None
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
    from .results.report import plot_figure

    print(plot_figure(args.db, args.kind, args.out, sample=args.sample, fcd_path=check_output_file("--fcd", args.fcd),
                      attack=args.attack, optimizer=args.optimizer, start=args.start, setpoint_m=args.setpoint,
                      speed_mps=args.speed))
    return 0


# --- entry point ---------------------------------------------------------------------------------


class Parser(argparse.ArgumentParser):
    """argparse, but a usage error is one line (and exit 2), not the whole usage."""

    def error(self, message: str):
        self.exit(EXIT_USAGE, f"d4sumo: error: {message} (see `{self.prog} --help`)\n")


def _add_batch_option(p) -> None:
    p.add_argument("--batch", type=int, default=DEFAULT_BATCH, metavar="N",
                   help=f"play up to N episodes an optimiser proposes together side by side in one SUMO (1: one at a "
                        f"time; the results are the same, bit for bit) [{DEFAULT_BATCH}]")


def check_batch(value: int) -> int:
    if not 1 <= value <= MAX_COPIES:
        raise ConfigError("--batch", value, f"a whole number of episodes in [1, {MAX_COPIES}]")
    return value


def build_parser() -> argparse.ArgumentParser:
    parser = Parser(prog="d4sumo", description="Adversarial driving maneuvers against ACC platoons, on SUMO.")
    parser.add_argument("--version", action="version", version=f"d4sumo {__version__}")
    parser.add_argument("-v", "--verbose", action="store_true", help="log progress details")
    sub = parser.add_subparsers(dest="command", required=True, parser_class=Parser)

    p = sub.add_parser("scenarios", help="list the network variants shipped with d4sumo")
    p.set_defaults(func=cmd_scenarios)

    p = sub.add_parser("simulate", help="play one episode and summarise it")
    _add_episode_options(p)
    g = p.add_argument_group("attack (with none, the attacker cruises at the target speed)")
    g.add_argument("--knots", help="knot values in [-1, 1], comma-separated, joined by PCHIP (one every --delta s)")
    g.add_argument("--constant", type=float, help="a constant attacker command in [-1, 1] from the attack's start")
    g.add_argument("--attack", choices=FAMILIES, help="attack family (with --params)")
    g.add_argument("--params", help="comma-separated parameter values of the family, e.g. --attack sine --params 0.5,0.2,0")
    _add_knot_options(g)
    g = p.add_argument_group("specification and output")
    _add_spec_options(g)
    g.add_argument("--fcd", type=Path, help="write SUMO's FCD output (with accelerations) to this file")
    g.add_argument("--json", action="store_true", help="print a machine-readable summary")
    g.add_argument("--gui", action="store_true", help="watch the episode in sumo-gui (needs a display)")
    p.set_defaults(func=cmd_simulate)

    p = sub.add_parser("falsify", help="run a campaign: search for attacks that make the followers crash")
    _add_episode_options(p)
    g = p.add_argument_group("search")
    g.add_argument("--attack", choices=[f for f in FAMILIES if f != "constant"], help="attack family [knots]")
    _add_knot_options(g)
    g.add_argument("--optimizer", choices=OPTIMIZERS,
                   help="bo, turbo (trust-region BO, for many parameters), ce, ce-bucket (the paper's VerifAI sampler), cmaes, random or halton [bo]")
    g.add_argument("--samples", type=int, help="budget: episodes to simulate [100]")
    g.add_argument("--seed", type=int, help="seed: the same seed repeats the campaign exactly [0]")
    _add_spec_options(g)
    _add_batch_option(g)
    p.add_argument("--db", type=Path, default=Path("results.sqlite"), help="results database (created if new) [results.sqlite]")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--json", action="store_true", help="print a machine-readable summary")
    p.set_defaults(func=cmd_falsify)

    p = sub.add_parser("sweep", help="run a grid of campaigns (local processes or a Dask cluster); resumable")
    p.add_argument("sweep", type=Path, help="sweep file (TOML: [grid] of lists, [search] samples, fixed tables)")
    p.add_argument("--db", type=Path, default=Path("results.sqlite"), help="results database [results.sqlite]")
    p.add_argument("--workers", type=int, help="local worker processes [number of cores]")
    p.add_argument("--dask", metavar="ADDRESS",
                   help="run on a Dask scheduler (e.g. tcp://10.0.0.5:8786), or 'local' for a local Dask cluster of --workers")
    p.add_argument("--dask-timeout", type=float, default=30.0, metavar="S", help="seconds to wait for the scheduler [30]")
    _add_batch_option(p)
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
    p.add_argument("--fcd", type=Path, help="also keep the replay's FCD in this file (time-space, accel)")
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


def _join_negative_lists(argv: list[str]) -> list[str]:
    """``--params -0.5,0.2,1`` as ``--params=-0.5,0.2,1``: argparse would take the list for an option."""
    out = []
    i = 0
    while i < len(argv):
        if argv[i] in LIST_OPTIONS and i + 1 < len(argv) and re.fullmatch(r"-[0-9.][0-9.eE+\-,\s]*", argv[i + 1]):
            out.append(f"{argv[i]}={argv[i + 1]}")
            i += 2
        else:
            out.append(argv[i])
            i += 1
    return out


def main(argv: Sequence[str] | None = None) -> int:
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGTERM, _on_sigterm)
    parser = build_parser()
    try:
        args = parser.parse_args(_join_negative_lists(list(sys.argv[1:] if argv is None else argv)))
    except SystemExit as exc:  # usage errors (one line, exit 2), --help, --version
        return int(exc.code or 0)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(levelname)s %(name)s: %(message)s" if args.verbose else "d4sumo: %(message)s")
    flags: dict[str, str] = {}
    for dest, key in FLAG_KEYS.items():
        if getattr(args, dest, None) is not None:
            flags[key] = "--" + dest.replace("_", "-")
    if getattr(args, "knots", None) is not None:
        flags.update({"attack.params": "--knots", "attack.family": "--knots"})
    elif getattr(args, "attack", None) is not None and args.command == "simulate":
        flags["attack.params"] = "--params"  # named even when it is missing
    try:
        code = args.func(args)
        sys.stdout.flush()  # inside the try: a closed pipe surfaces here, not at exit
        return code
    except ConfigError as exc:
        flag = flags.get(exc.field) or flags.get(exc.field.split(":")[0])
        field = f"{flag} ({exc.field})" if flag and not exc.field.startswith("--") else exc.field
        print(f"d4sumo: error: {field}: got {exc.given!r}; allowed: {exc.allowed}", file=sys.stderr)
        return EXIT_USAGE
    except D4sumoError as exc:
        print(f"d4sumo: error: {exc}", file=sys.stderr)
        return EXIT_USAGE
    except BrokenPipeError:
        # the reader went away (`d4sumo export db | head`): stop quietly, as command-line tools do
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        return 141
    except KeyboardInterrupt as exc:
        if not isinstance(exc, Terminated) and not getattr(exc, "said", False):
            print("d4sumo: interrupted", file=sys.stderr)
        return 143 if isinstance(exc, Terminated) else 130


if __name__ == "__main__":
    sys.exit(main())
