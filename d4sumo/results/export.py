"""Stored samples as CSV: each with its campaign's settings (read through the one reader of stored
campaigns, nothing imported), its outcome and collision, the minimum gap of every pair of cars that
followed each other, and one column per attack parameter."""

from __future__ import annotations

import csv
from typing import TextIO

from ..search.campaign import Campaign
from ..search.store import Store
from .records import system_label

HEADER = ["sample_id", "campaign_id", "index", "network", "followers", "setpoint_m", "speed_mps", "start", "maneuver",
          "system", "attack", "optimizer", "seed", "robustness", "outcome", "pair", "time_s", "position_m",
          "speed_diff_kmh", "wall_s", "error"]


def pair_order(pair: str) -> tuple:
    """Pairs front to back as the cars are named (v0-v1 before v1-v2 before v10-v11), others after."""
    cars = pair.split("-")
    return tuple((0, int(c[1:]), "") if c[1:].isdigit() and c[0] == "v" else (1, 0, c) for c in cars)


def write_csv(store: Store, out: TextIO, campaign_id: int | None = None) -> int:
    """Write the samples (of one campaign, or all) to ``out``; returns how many."""
    campaigns = {c.id: Campaign.from_definition(c.definition, where=f"{store.path}: campaign {c.id}")
                 for c in store.campaigns()}
    names = {cid: c.family().names for cid, c in campaigns.items()}
    systems = {cid: system_label(c.config.to_dict()) for cid, c in campaigns.items()}
    columns = list(dict.fromkeys(n for cid in campaigns for n in names[cid]))
    pairs = sorted({p for s in store.iter_samples(campaign_id) for p in s.min_gaps}, key=pair_order)
    writer = csv.writer(out)
    writer.writerow(HEADER + [f"min_gap_{p}_m" for p in pairs] + columns)
    rows = 0
    for s in store.iter_samples(campaign_id):
        c = campaigns[s.campaign_id]
        cfg = c.config
        params = dict(zip(names[s.campaign_id], s.params))
        writer.writerow([s.id, s.campaign_id, s.index, cfg.network, cfg.followers, cfg.setpoint_m, cfg.speed_mps, cfg.start,
                         cfg.maneuver, systems[s.campaign_id], c.attack, c.optimizer, c.seed, s.robustness, s.outcome,
                         s.pair, s.time_s, s.position_m, s.speed_diff_kmh, round(s.wall_s, 6), s.error]
                        + [s.min_gaps.get(p, "") for p in pairs] + [params.get(n, "") for n in columns])
        rows += 1
    return rows
