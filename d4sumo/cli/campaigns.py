"""The commands that search: falsify (one campaign) and sweep (a grid of them)."""

from __future__ import annotations

import argparse
import contextlib
import json
import sys

from ..errors import ConfigError, check_number
from ..search.optimizers import DEFAULT_OPTIMIZER, EARLIER_DEFAULT_OPTIMIZER, EARLIER_OPTIONS, OPTIMIZERS, as_set_flags
from .common import check_batch, document, note_unused_flags
from .episodes import collision_text


def _as_earlier_versions_ran(campaign):
    """The campaign as earlier versions of d4sumo ran it (its optimiser, that optimiser's options, its inputs,
    in every combination), each with what differed and the flags that go on with it."""
    from ..search.campaign import INPUTS_CHANGED

    inputs = campaign.with_inputs_of_before()
    changed = {}  # version -> (the campaign as it ran it, the flags), where it ran it otherwise
    for version in INPUTS_CHANGED:
        flags = [f"--set {key}={value}" for key, value, _ in campaign.changes_of(version)]
        if (before := campaign.with_inputs_of(version)) is not campaign and before not in [b for b, _ in changed.values()]:
            changed[version] = (before, flags)
    input_flags = [*(["--set 'scenario.network_sha256=\"\"'"] if campaign.config.network_sha256 else []),
                   *(["--set traffic.insertion_checks=false"] if campaign.config.traffic else []),
                   *(f"--set {key}={value}" for key, value, _ in campaign.changes_of(INPUTS_CHANGED[-1]))]
    for base, flags in [(campaign, []), *changed.values(), *([(inputs, input_flags)] if inputs is not campaign else [])]:
        if campaign.optimizer == DEFAULT_OPTIMIZER:
            default_before = base.replace(optimizer=EARLIER_DEFAULT_OPTIMIZER)
            for earlier in ({}, *EARLIER_OPTIONS.get(EARLIER_DEFAULT_OPTIMIZER, ())):  # as each earlier version ran it
                yield (default_before.with_options(earlier),
                       f"run with {EARLIER_DEFAULT_OPTIMIZER}, the default optimiser of d4sumo 0.7 and before; this starts a "
                       f"new one with {DEFAULT_OPTIMIZER}",
                       [f"--optimizer {EARLIER_DEFAULT_OPTIMIZER}", as_set_flags(EARLIER_DEFAULT_OPTIMIZER, earlier), *flags])
        for earlier in EARLIER_OPTIONS.get(campaign.optimizer, ()):
            if (before := base.with_options(earlier)) != campaign:
                yield before, "as an earlier d4sumo ran it; this starts a new one", [as_set_flags(campaign.optimizer, earlier), *flags]
        version = next((v for v, (b, _) in changed.items() if b is base), None)
        if version is not None:
            what = ", ".join(did for _, _, did in campaign.changes_of(version))
            yield base, f"as d4sumo {version} or before ran it ({what}); this starts a new one", flags
        elif base is not campaign:
            yield (base, "as d4sumo 0.16 or before ran it (a road of one's own taken as found, traffic entering after the "
                         "warm-up unchecked, the platoon driving through red lights, demand files one after the other); "
                         "this starts a new one", flags)


def cmd_falsify(args: argparse.Namespace) -> int:
    """A campaign: checked before anything is written, run (resumed where one is stored), summarised."""
    campaign, evaluator = _falsify_inputs(args)
    summary, counts = _run_falsify(args, campaign, evaluator)
    result, nearest, without = _falsify_result(args, campaign, evaluator, summary, counts)
    if args.json:
        print(json.dumps(result, indent=2))
    else:
        _say_falsify(args, campaign, summary, counts, nearest, without, result["distinct_successes"])
    return 0


def _falsify_inputs(args: argparse.Namespace):
    """The campaign and its evaluator, every input checked (the formula parsed, the road built): it fails before
    writing anything."""
    from ..engine.simulation import check_traffic
    from ..inputs import campaign_of
    from ..search.runner import Evaluator

    doc, _ = document(args)
    campaign = campaign_of(doc)
    evaluator = Evaluator(campaign)  # parses the formula and builds the road: fail before writing anything
    check_traffic(campaign.config, evaluator.road)
    note_unused_flags(args, campaign.config, evaluator.family, campaign.formula)
    unused = sorted(k for k in doc.get("search", {}) if k in OPTIMIZERS and k != campaign.optimizer)
    if unused:  # e.g. --set search.bo.x with no --optimizer, since the default became auto
        print(f"d4sumo: note: the options of {', '.join(f'[search.{k}]' for k in unused)} are unused: this campaign runs "
              f"{campaign.optimizer} (--optimizer {unused[0]} runs {unused[0]})", file=sys.stderr)
    check_batch(args.batch)
    return campaign, evaluator


def _run_falsify(args: argparse.Namespace, campaign, evaluator):
    """The campaign run into its database with a progress bar: its summary and its outcomes counted."""
    from tqdm import tqdm

    from ..search.campaign import open_store
    from ..search.runner import run_campaign

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

        if known is None:  # the same campaign as an earlier d4sumo ran it: said, with the flags that go on with it
            for before, what, flags in _as_earlier_versions_ran(campaign):
                if store.find_campaign(before.definition()) is not None:
                    bar.write(f"d4sumo: note: {args.db} holds this campaign {what}. To go on with that one: "
                              f"{' '.join(f for f in flags if f)}", file=sys.stderr)
                    break
        try:
            summary = run_campaign(campaign, store, evaluator=evaluator, on_sample=progress, batch=args.batch)
        except KeyboardInterrupt as exc:
            bar.close()
            print(f"d4sumo: campaign interrupted; every sample it finished is in {args.db}: run the same command to resume",
                  file=sys.stderr)
            exc.said = True  # main need not say it again
            raise
    return summary, counts


def _falsify_result(args: argparse.Namespace, campaign, evaluator, summary, counts):
    """What `--json` prints, with how near the traffic came and what it does without the attack (among traffic)."""
    top = summary.best
    nearest = None
    if campaign.config.traffic is not None:  # how near the traffic came to each car of the platoon
        from ..results.analysis import nearest_traffic

        nearest = nearest_traffic((s.min_gaps for s in summary.samples), campaign.config.vehicle_ids)
    without = None
    if campaign.config.traffic is not None and not campaign.config.traffic.per_sample and not campaign.situation:
        from ..results.baseline import campaign_baseline  # one traffic, one situation: one episode tells

        without = campaign_baseline(evaluator.without_attack, False, ((s.index, s.outcome, (s.collision or {}).get("time_s"))
                                                                      for s in summary.samples), step_s=campaign.config.step_s)
    from ..results.analysis import crash_kinds, distinct_count

    wins = [s for s in summary.samples if s.outcome == "success"]
    family = evaluator.family
    result = {
        "db": str(args.db),
        "campaign_id": summary.campaign_id,
        "attack": campaign.attack,
        "optimizer": campaign.optimizer,
        "seed": campaign.seed,
        "samples": len(summary.samples),
        "outcomes": counts,
        # how many of the successes are different attacks, and different crashes
        "distinct_successes": {"attacks": distinct_count([s.params for s in wins], family.lower, family.upper),
                               "crash_kinds": crash_kinds([s.collision for s in wins if s.collision])},
        **({"nearest_traffic_m": nearest} if nearest is not None else {}),
        **({"without_attack": {"episodes": without.played, "crashed": without.crashed, "kinds": dict(without.kinds),
                               "traffics_doing": dict(without.traffics)}} if without is not None else {}),
        "best": None if top is None else {
            "sample_id": top.id, "index": top.index, "robustness": top.robustness, "outcome": top.outcome,
            "params": list(top.params), "collision": top.collision,
        },
    }
    return result, nearest, without


def _say_falsify(args: argparse.Namespace, campaign, summary, counts, nearest, without, distinct: dict) -> None:
    """The summary in words."""
    top = summary.best
    config = campaign.config
    attack = f"{config.maneuver}, {campaign.attack}" if config.maneuver_class.lateral else campaign.attack
    if campaign.lie:
        attack += " with " + campaign.lie
    where = f"lane {config.lane}, " if config.lane is not None else ""
    sensing = f"radar {config.radar.label}, " if config.radar else ""
    sensing += f"{config.world_label}, " if config.traffic else ""
    print(f"campaign {summary.campaign_id} ({attack}, {where}{sensing}{campaign.optimizer}, seed {campaign.seed}) in {args.db}: "
          f"{len(summary.samples)} samples")
    print("  " + ", ".join(f"{k} {v}" for k, v in counts.items()))
    if counts.get("success"):
        from ..results.analysis import distinct_text

        print("  " + distinct_text(distinct["attacks"], distinct["crash_kinds"]))
    if campaign.boundary:
        from ..search.situation import locating

        spent = [s for s in summary.samples if locating(s.index, campaign.boundary)]
        wins = sum(s.outcome == "success" for s in spent)
        print(f"  locating the boundary: {len(spent)} of the samples, a random attack each, {wins} of them successes "
              f"(d4sumo plot map {args.db} --out map.png draws it from them)")
    if config.traffic is not None:
        from ..results.analysis import TRAFFIC_MEETS_M, traffic_nearness_text

        from ..results.baseline import baseline_text

        text, met = traffic_nearness_text(nearest)
        print(f"  {text}")
        print("  " + (baseline_text(without) if without is not None else "without the attack: each sample met traffic of "
                      "its own (traffic.per_sample); `d4sumo report` plays each crash's without it"))
        if not met:  # labelled traffic, played alone: said (its demand's vehicles drive elsewhere, or later)
            print(f"d4sumo: note: the traffic never came within {TRAFFIC_MEETS_M:g} m of a car of the platoon in "
                  f"{len(summary.samples)} samples: this campaign played as if alone (place the platoon where the "
                  "demand drives: scenario.route, traffic.warmup_s)", file=sys.stderr)
    if campaign.formula is not None:  # the outcomes count crashes; a formula of one's own is falsified where rho < 0
        broken = sum(s.robustness is not None and s.robustness < 0 for s in summary.samples)
        print(f"  formula falsified (robustness < 0) by {broken} of {len(summary.samples)} samples")
    if top is not None:
        print(f"  best: sample {top.id} ({top.outcome}), robustness {top.robustness:.4f}")
        if top.collision:
            print(f"  first collision: {collision_text(top.collision)}")
        print(f"  params: {params_text(campaign.family(), top.params, campaign.situation)}")
        print(f"  replay it: d4sumo replay {args.db} {top.id} --fcd sample_{top.id}.xml")


def params_text(family, params, searched: tuple = ()) -> str:
    """A sample's parameters: the pedal family's values, then what a maneuver or a lie adds, each by its name
    (a lie's offset and start are no knots), then the situation it played (``searched``: the campaign's)."""
    from ..search.situation import values

    own = len(getattr(family, "longitudinal", family).parameters)
    mine = len(family.parameters) - len(searched)  # the attack's
    added = [f"{name} {v:.3f}" for name, v in zip(family.names[own:mine], params[own:mine])]
    added += [f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in values(searched, params[mine:]).items()]
    return ", ".join(f"{v:.3f}" for v in params[:own]) + (f"; {', '.join(added)}" if added else "")


def cmd_sweep(args: argparse.Namespace) -> int:
    from tqdm import tqdm

    from ..sweep import Sweep, check_dask_address, run_sweep
    from ..sweep.grid import part_text

    if args.workers is not None and not 1 <= args.workers <= 1024:
        raise ConfigError("--workers", args.workers, "a whole number in [1, 1024]")
    if args.dask is not None:
        check_dask_address(args.dask)
    check_number("--dask-timeout", args.dask_timeout, 0.0, 3600.0, "seconds", low_open=True)
    if args.dask is None and args.dask_proposals is not None:
        print("d4sumo: note: --dask-proposals is unused: it says where a Dask sweep's optimisers run (--dask), and "
              "local workers run on this machine", file=sys.stderr)
    check_batch(args.batch)
    sweep = Sweep.load(args.sweep)
    if args.part is not None:
        sweep = sweep.part_of(args.part)
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
                           dask_proposals=args.dask_proposals or "client",
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
    print(f"sweep {sweep.name}{part_text(sweep.part)}: {result.campaigns} campaigns, {result.samples} samples, {result.successes} successes "
          f"in {result.wall_s:.1f} s -> {args.db}")
    print(f"  report: d4sumo report {args.db} --out report/")
    return 0
