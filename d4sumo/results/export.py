"""Stored samples as CSV: each with its campaign's settings (read through the one reader of stored
campaigns, nothing imported), its scenario, its outcome and collision, the minimum gap of every pair of
cars that followed each other, and one column per attack parameter."""

from __future__ import annotations

import csv
import dataclasses
from typing import Any, TextIO

from ..model.config import EpisodeConfig
from ..model.definition import IDENTITY_KEYS
from ..search import situation
from ..search.campaign import Campaign
from ..search.store import Store
from .records import system_label

#: the scenario's columns every export has; any other [scenario] key a campaign of the database stores
#: (warmup_s, the maneuver's settings, collision_gap_m, ...) gets a column of its own after them, empty
#: for a campaign where it has no effect
SCENARIO = ["network", "followers", "setpoint_m", "speed_mps", "start", "maneuver", "route", "step_s", "duration_s"]
#: the columns after the scenario's: the campaign's system, attack (and its lie, `messages.lie_label`) and search, the sample's result
RESULT = ["system", "attack", "lie", "optimizer", "seed", "robustness", "outcome", "pair", "time_s", "position_m",
          "speed_diff_kmh", "wall_s", "error"]
_SCENARIO_KEYS = [f.name for f in dataclasses.fields(EpisodeConfig)]  # in the order of the config


def pair_order(pair: str) -> tuple:
    """Pairs front to back as the cars are named (v0-v1 before v1-v2 before v10-v11), others after."""
    cars = pair.split("-")
    return tuple((0, int(c[1:]), "") if c[1:].isdigit() and c[0] == "v" else (1, 0, c) for c in cars)


def _cell(value: Any) -> Any:
    """A scenario value as a CSV cell: a route as its edges separated by spaces."""
    return " ".join(value) if isinstance(value, (list, tuple)) else value


def write_csv(store: Store, out: TextIO, campaign_id: int | None = None) -> int:
    """Write the samples (of one campaign, or all) to ``out``; returns how many."""
    campaigns = {c.id: Campaign.from_definition(c.definition, where=f"{store.path}: campaign {c.id}")
                 for c in store.campaigns()}
    families = {cid: c.family() for cid, c in campaigns.items()}
    names = {cid: family.names for cid, family in families.items()}
    systems = {cid: system_label(c.config.to_dict()) for cid, c in campaigns.items()}
    scenarios = {cid: c.config.to_dict()["scenario"] for cid, c in campaigns.items()}
    own = sorted({k for sc in scenarios.values() for k in sc} - set(SCENARIO) - set(IDENTITY_KEYS), key=_SCENARIO_KEYS.index)
    searched = {e[0] for c in campaigns.values() for e in c.situation}  # each sample's own, in the scenario's columns
    own += sorted(k for k in searched if "." in k)  # a searched key of another table (v2v.loss): a column of its own
    columns = list(dict.fromkeys(n for cid in campaigns for n in names[cid] if n not in searched))
    pairs = sorted({p for s in store.iter_samples(campaign_id) for p in s.min_gaps}, key=pair_order)
    writer = csv.writer(out)
    writer.writerow(["sample_id", "campaign_id", "index", *SCENARIO, *own, *RESULT]
                    + [f"min_gap_{p}_m" for p in pairs] + columns)
    rows = 0
    for s in store.iter_samples(campaign_id):
        c = campaigns[s.campaign_id]
        cfg = c.config
        params = dict(zip(names[s.campaign_id], s.params))
        scenario = {**{k: getattr(cfg, k) for k in SCENARIO}, **scenarios[s.campaign_id]}
        if c.situation:  # the sample's own
            played = c.config_for(s.params, families[s.campaign_id])
            scenario.update((e[0], situation.played(played, e[0])) for e in c.situation)
        writer.writerow([s.id, s.campaign_id, s.index, *(_cell(scenario.get(k, "")) for k in (*SCENARIO, *own)),
                         systems[s.campaign_id], c.attack, c.lie, c.optimizer, c.seed, s.robustness, s.outcome, s.pair, s.time_s,
                         s.position_m, s.speed_diff_kmh, round(s.wall_s, 6), s.error]
                        + [s.min_gaps.get(p, "") for p in pairs] + [params.get(n, "") for n in columns])
        rows += 1
    return rows
