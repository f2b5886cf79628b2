"""The commands about one episode: scenarios, simulate, replay."""

from __future__ import annotations

import argparse
import json
import sys

from .. import __version__
from ..errors import ConfigError, check_number
from ..model.config import EpisodeConfig
from ..model.attacks.messages import lie_label
from ..model.world.sensing import RadarParams
from ..model.world.traffic import TrafficParams
from .common import EXIT_DIFFERS, check_display, check_output_file, document, note_unused_flags


def cmd_scenarios(args: argparse.Namespace) -> int:
    from ..engine.networks import SCENARIOS_DIR, list_scenarios
    from ..engine.scenarios import build_road

    names = list_scenarios()
    if not names:
        raise ConfigError("sumo_scenarios", str(SCENARIOS_DIR), "a folder of scenario variants")
    print(f"{'name':24s} {'lanes':>5s} {'length_m':>9s} {'limit_mps':>9s}  net")
    for name in names:
        road = build_road(name)
        print(f"{name:24s} {road.lanes:5d} {road.length_m:9.0f} {road.speed_limit_mps:9.2f}  {road.net_file}")
    return 0


def cmd_build_fmu(args: argparse.Namespace) -> int:
    from ..fmus import build_switching_fmu

    out = build_switching_fmu(args.out, args.fmi)
    print(f"{out}: the paper's switching controller, FMI {args.fmi}.0 co-simulation, built for this machine; "
          f"d4sumo simulate --controller fmu:{out}")
    return 0


def cmd_simulate(args: argparse.Namespace) -> int:
    from ..engine.scenarios import build_road
    from ..engine.simulation import simulate
    from ..inputs import attack_of, episode_config, link_collision_distance
    from ..search.spec import Specification

    from ..presets import apply_preset

    doc = apply_preset(link_collision_distance(document(args)[0]))  # the spec's values too
    config = episode_config(doc)
    family, params = attack_of(doc)
    spec_table = doc.get("spec", {})
    note_unused_flags(args, config, family, spec_table.get("formula"))
    d_safe = check_number("spec.d_safe_m", spec_table.get("d_safe_m", 0.0), -1e3, 1e3, "m")
    formula = spec_table.get("formula")
    spec = None
    if formula is not None or config.followers >= 2 or config.maneuver_class.lateral or config.traffic is not None:
        spec = Specification(followers=config.followers, step_s=config.step_s, formula=formula, d_safe_m=d_safe,
                             duration_s=config.duration_s, start_step=config.attack_start_step,
                             maneuver=config.maneuver, traffic=config.traffic is not None)  # as a campaign scores
    fcd = check_output_file("--fcd", args.fcd)
    check_display(args.gui)
    road = build_road(config.network, route=config.route, lane=config.lane, whole=config.whole_network, given=config.network_given)
    plan = episode_plan(family, params, config)
    episode = simulate(config, plan, road=road, fcd_path=fcd, gui=args.gui)
    robustness = spec.robustness(episode.trace) if spec else None
    summary = episode_summary(config, family, params, plan, episode, robustness, d_safe, fcd)
    summary["formula"] = formula
    _report(summary, road.name, args.json)
    return 0


def cmd_replay(args: argparse.Namespace) -> int:
    from ..search.campaign import Campaign, open_store
    from ..search.runner import Evaluator

    fcd = check_output_file("--fcd", args.fcd)
    check_display(args.gui)
    if args.network is not None and args.openscenario is None:
        raise ConfigError("--network", str(args.network), "a road for an exported scenario's replay (with --openscenario)")
    with open_store(args.db, create=False) as store:
        row = store.sample(args.sample)
        stored_campaign = store.campaign(row.campaign_id)
        campaign = Campaign.from_definition(stored_campaign.definition, where=f"{args.db}: campaign {row.campaign_id}",
                                            imports=True)
    if row.outcome == "error":
        print(f"d4sumo: note: sample {row.id} was stored as errored ({row.error}); replaying it", file=sys.stderr)
    if args.openscenario is not None:
        return _replay_openscenario(args, row, campaign, fcd)
    evaluator = Evaluator(campaign)
    plan = evaluator.plan(row.params)
    if row.outcome == "error":  # what the campaign stored was how it failed: the replay fails the same way, or not
        try:
            evaluator.simulate(row.index, row.params, fcd_path=fcd, gui=args.gui)
        except Exception as exc:  # a user's controller's, or SUMO's
            again = evaluator.failure(exc)
        else:
            again = None
        if again == row.error:
            print(f"reproduces the stored sample exactly: it fails again, {again}")
            return 0
        print(f"differs from the stored sample: it failed ({row.error}); replayed, " + (f"it fails otherwise ({again})" if again else "it plays"))
        return EXIT_DIFFERS
    episode = evaluator.simulate(row.index, row.params, fcd_path=fcd, gui=args.gui)
    rho = evaluator.spec.robustness(episode.trace)
    summary = episode_summary(evaluator.config_for(row.params), evaluator.family, row.params, plan, episode, rho,
                              campaign.d_safe_m, fcd)
    # the whole verdict, compared exactly: what was stored is what this episode gives
    replayed = {"robustness": rho, "outcome": episode.outcome,
                "collision": episode.first_collision_record(),
                "min_gaps": evaluator.min_gaps(episode)}
    stored = {"robustness": row.robustness, "outcome": row.outcome, "collision": row.collision, "min_gaps": row.min_gaps}
    # d4sumo 0.11 and before stored a warm-up's minimum gaps over the whole episode, warm-up included: a
    # campaign it began holds samples of either meaning
    if (row.min_gaps != replayed["min_gaps"] and campaign.config.attack_start_step
            and _version(stored_campaign.version) < (0, 12) and row.min_gaps == episode.min_gaps_with_warmup_m()):
        replayed["min_gaps"] = row.min_gaps
    differs = [k for k in stored if stored[k] != replayed[k]]
    summary.update(sample_id=row.id, campaign_id=row.campaign_id, formula=campaign.formula,
                   stored_robustness=row.robustness, stored_outcome=row.outcome, stored_collision=row.collision,
                   reproduced=not differs, differs=differs)
    _report(summary, evaluator.road.name, args.json)
    if not args.json:
        print("reproduces the stored sample exactly" if not differs else
              "differs from the stored sample: " + "; ".join(f"{k}: stored {stored[k]}, replayed {replayed[k]}" for k in differs))
    return 0 if not differs else EXIT_DIFFERS


def _replay_openscenario(args, row, campaign, fcd) -> int:
    """The stored sample with the attacker driving the exported scenario's trajectory (on ``--network``, the
    exported road.xodr imported back, or any road): the same crash, pair and time within a step, or exit 1."""
    import dataclasses

    import numpy as np

    from ..engine.layout import route_lanes
    from ..engine.networks import opendrive_network
    from ..model.attacks.maneuvers import lane_changes, maneuver_of
    from ..results.openscenario import read_motion
    from ..search.runner import Evaluator
    from ..search.store import campaign_key

    stored = Evaluator(campaign)  # the sample as stored: its road, its pedals
    config = stored.config_for(row.params)  # in the situation it played
    key = campaign_key(campaign.definition())  # the campaign an export of this sample names
    if args.network is not None:
        network = opendrive_network(args.network) if args.network.suffix == ".xodr" else args.network
        config = dataclasses.replace(config, network=str(network), network_sha256=None, route=(), lane=None)
        campaign = campaign.replace(config=config)
    evaluator = Evaluator(campaign)
    plan = evaluator.plan(row.params)
    road = evaluator.road  # the positions measured along its lanes, as SUMO counts them
    lanes = route_lanes(road.net_file, road.route_edges, road.platoon_path)
    plan = dataclasses.replace(plan, motion=read_motion(args.openscenario, "v0", config.step_s, config.steps, row.id, key,
                                                        changes_lanes=bool(lane_changes(plan, maneuver_of(config))),
                                                        lanes=lanes))
    from ..engine.simulation import simulate

    episode = simulate(config, plan, road=evaluator.road, fcd_path=fcd, gui=args.gui)
    first, was = episode.first_collision, row.collision
    same = ((first is None and was is None) or (first is not None and was is not None and first.pair == was["pair"]
                                                 and abs(first.time_s - was["time_s"]) <= config.step_s + 1e-9))
    original = stored.simulate(row.index, row.params)
    n = min(len(original.trace), len(episode.trace))
    moved = {f"v{i}": float(np.max(np.abs(original.trace[f"pos_v{i}"][:n] - episode.trace[f"pos_v{i}"][:n])))
             for i in range(config.followers + 1)}
    summary = {"sample_id": row.id, "network": config.network, "outcome": episode.outcome,
               "collision": episode.first_collision_record(), "stored_collision": was, "reproduced": same,
               "largest_position_difference_m": moved}
    if args.json:
        print(json.dumps(summary, indent=2))
    else:
        said = lambda c: "no collision" if c is None else f"{c['pair']} at {c['time_s']:.2f} s"  # noqa: E731
        print(f"sample {row.id}, the attacker driving {args.openscenario} on {evaluator.road.name}: "
              f"{said(episode.first_collision_record())} (stored: {said(was)})")
        print("positions along the road against the stored episode's, at most: "
              + ", ".join(f"{k} {v:.3g} m" for k, v in moved.items()))
        print("reproduces the stored crash" if same else "does not reproduce the stored crash")
    return 0 if same else EXIT_DIFFERS


def _version(text: str) -> tuple[int, ...]:
    """A d4sumo version as numbers ("0.11.0" -> (0, 11, 0)); an unreadable one as the oldest."""
    try:
        return tuple(int(part) for part in text.split(".")[:3])
    except ValueError:
        return (0,)


def episode_plan(family, params, config: EpisodeConfig):
    """The attacker's command at every step's start (NaN, cruise, before the attack or with none) and its lane change."""
    from ..model.attacks.maneuvers import attack_plan

    return attack_plan(family, params, config)


def episode_summary(config, family, params, plan, episode, robustness, d_safe, fcd) -> dict:
    from ..model.attacks.maneuvers import attack_of, lane_changes, maneuver_of
    from ..search.situation import played as searched_value

    played = len(episode.trace) - 1  # steps played: a change planned after the episode ended did not happen
    attack, params = attack_of(family, params) if family is not None else (None, params)
    # a situation searched with the attack: the configuration holds its values
    situation = ({p.name: searched_value(config, p.name) for p in family.parameters[len(attack.parameters):]}
                 if attack is not family else {})
    family = attack
    return {
        "d4sumo": __version__,
        "config": config.to_dict(),
        "attack": None if family is None else {**family.describe(), "values": [float(v) for v in params]},
        **({"situation": situation} if situation else {}),
        # the attacker's lane changes as played: when each began [s], the lane (0 the platoon's, 1 to its left)
        "lane_changes": [{"time_s": k * config.step_s, "lane": lane}
                         for k, lane in lane_changes(plan, maneuver_of(config)) if k < played],
        "outcome": episode.outcome,
        "first_collision": episode.first_collision_record(),
        "collisions": [c.to_dict() for c in episode.collisions],
        # unrounded: a gap a hair under the collision distance stays under; from the attack's start, as the
        # outcome and robustness, and a warm-up's apart
        "min_gaps_m": episode.min_gaps_m(),
        "warmup_min_gaps_m": episode.warmup_min_gaps and dict(episode.warmup_min_gaps),
        # among traffic: SUMO's collisions of two traffic cars (in no verdict)
        "traffic_collisions": [{"time_s": t, "pair": f"{a}-{b}"} for t, a, b in episode.traffic_collisions],
        "attack_start_s": config.attack_start_s,
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


def _gap_text(gap_m: float, collision_m: float) -> str:
    """A gap to 2 decimals, or to as many as it takes to stay on its side of the collision distance
    (-0.0000089 m is no "-0.00" beside an overlap, 0.049969 m no "0.05" beside a 0.05 m collision gap)."""
    for digits in (2, 4, 6, 9):
        text = f"{gap_m:.{digits}f}"
        if (float(text) < collision_m) == (gap_m < collision_m):
            return text
    return repr(gap_m)


def collision_text(c: dict) -> str:
    """A first collision in words, each number labelled: its pair, time (simulation time), position along
    the road and speed difference."""
    return (f"{c['pair']} collided at t = {c['time_s']:.2f} s, {c['position_m']:.1f} m along the road, "
            f"speed difference {c['speed_diff_kmh']:.1f} km/h")


def _print_summary(s: dict, road_name: str) -> None:
    sc = s["config"]["scenario"]
    attack = s["attack"]
    what = "no attack (the attacker cruises)" if attack is None else f"{attack['family']} {attack['values']}"
    if attack is not None and attack.get("message"):
        lie = lie_label(attack["message"], attack["message_field"], attack.get("message_sender", 0))
        what = f"{attack['family']} with {lie} {attack['values']}"
    maneuver = f", {sc['maneuver']}" if "maneuver" in sc else ""
    radar = s["config"].get("radar")
    sensing = f", radar {RadarParams.from_table(radar).label}" if radar else ""
    traffic = s["config"].get("traffic")
    sensing += f", traffic {TrafficParams.from_table(traffic).label}" if traffic else ""
    print(f"{road_name}: {sc['followers']} followers, setpoint {sc['setpoint_m']:g} m, {sc['speed_mps']:g} m/s, "
          f"start {sc['start']}{maneuver}{sensing}; {what}")
    if s["lane_changes"]:
        print("attacker's lane changes: " + ", ".join(f"to lane {c['lane']} at {c['time_s']:.2f} s" for c in s["lane_changes"]))
    c = s["first_collision"]
    if c is None:
        print(f"outcome: {s['outcome']} in {s['simulated_s']:.2f} s")
    else:
        print(f"outcome: {s['outcome']}: {collision_text(c)}")
    collision_m = s["config"]["scenario"].get("collision_gap_m", 0.0)
    def gaps(minima: dict) -> str:
        return ", ".join(f"{k} {_gap_text(v, collision_m)} m" for k, v in minima.items())

    if s.get("warmup_min_gaps_m") is None:
        print("min gaps: " + gaps(s["min_gaps_m"]))
    else:  # the window the outcome and robustness speak of, and the warm-up's apart
        print(f"min gaps from the attack's start at {s['attack_start_s']:.2f} s: " + gaps(s["min_gaps_m"]))
        print("min gaps in the warm-up before it: " + gaps(s["warmup_min_gaps_m"]))
    if s.get("traffic_collisions"):
        print("collisions among the traffic (in no verdict): " + ", ".join(
            f"{c['pair']} at {c['time_s']:.2f} s" for c in s["traffic_collisions"][:5])
              + (f" and {len(s['traffic_collisions']) - 5} more" if len(s["traffic_collisions"]) > 5 else ""))
    if s["robustness"] is not None:
        what = "the formula" if s.get("formula") else f"psi (d_safe {s['d_safe_m']:g} m)"
        print(f"robustness of {what}: {s['robustness']:.4f}")
    if s["fcd"]:
        print(f"FCD written to {s['fcd']}")
