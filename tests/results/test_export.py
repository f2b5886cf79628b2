"""Stored samples as CSV: what sets a campaign's scenario apart is in its columns."""

from __future__ import annotations

import csv
import io

from d4sumo.model.config import EpisodeConfig
from d4sumo.results.export import write_csv
from d4sumo.search.campaign import Campaign, open_store
from d4sumo.search.store import collision_dict


def test_the_route_duration_and_every_stored_scenario_key_are_columns(tmp_path):
    """Regression: two campaigns on one network, on two routes for two durations, exported as rows that
    nothing told apart but the campaign id (no route, no duration column)."""
    configs = [EpisodeConfig(network="grid.net.xml", route=("A0B0", "B0C0"), duration_s=80.0),
               EpisodeConfig(network="grid.net.xml", route=("A1B1", "B1C1"), duration_s=60.0),
               EpisodeConfig(start="warmup", warmup_s=10.0, collision_gap_m=0.05)]
    with open_store(tmp_path / "r.sqlite") as store:
        for config in configs:
            cid = store.open_campaign(Campaign(config=config, optimizer="random").definition(), 1)
            store.add_sample(cid, 0, (0.0,) * 9, 0.5, "success", collision_dict("v1-v2", 20.0, 100.0, 10.0),
                             {"v0-v1": 3.0, "v1-v2": -0.1, "v2-v3": 4.0}, 0.1)
        out = io.StringIO()
        assert write_csv(store, out) == 3
    rows = list(csv.DictReader(io.StringIO(out.getvalue())))
    header = out.getvalue().splitlines()[0].split(",")
    assert header[3:14] == ["network", "followers", "setpoint_m", "speed_mps", "start", "maneuver", "route", "step_s",
                            "duration_s", "warmup_s", "collision_gap_m"]  # the scenario, then the keys some campaign sets
    assert [(r["network"], r["route"], r["duration_s"]) for r in rows] == [
        ("grid.net.xml", "A0B0 B0C0", "80.0"), ("grid.net.xml", "A1B1 B1C1", "60.0"), ("highway_4lane", "", "60.0")]
    assert [(r["warmup_s"], r["collision_gap_m"]) for r in rows] == [("", ""), ("", ""), ("10.0", "0.05")]
