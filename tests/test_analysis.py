"""The paper's tables and clusters, from a small real database and from synthetic data."""

from __future__ import annotations

import numpy as np
import pytest

from d4sumo.analysis import (
    Record,
    cluster_knots,
    elbow,
    load_records,
    most_severe,
    richest_conditions,
    success_grid,
    table_attacker_crashes,
    table_by_speed,
    table_success_statistics,
)

pytestmark = pytest.mark.sumo


def test_tables_count_what_the_database_holds(small_db):
    records = load_records([small_db])
    assert len(records) == 96
    wins = [r for r in records if r.outcome == "success"]
    t1 = table_success_statistics(records)
    assert t1.rows[0][0] == "knots random" and t1.rows[0][1] == "96" and t1.rows[0][2] == str(len(wins))
    v12 = sum(r.pair == "v1-v2" for r in wins)
    assert t1.rows[0][3].startswith(f"{v12} (")
    t2 = table_attacker_crashes(records)
    assert t2.header == ("setpoint", "knots random") and [row[0] for row in t2.rows] == ["5 m", "7 m"]
    crashes, no_crash = (int(v) for v in t2.rows[0][1].split(" / "))
    assert crashes == sum(r.outcome == "attacker_crash" and r.setpoint_m == 5.0 for r in records)
    assert no_crash == sum(r.outcome == "no_crash" and r.setpoint_m == 5.0 for r in records)
    t3 = table_by_speed(records)
    assert [row[0] for row in t3.rows] == ["knots random rest", "knots random steady"]
    assert sum(int(row[1]) for row in t3.rows) == len(wins)
    assert "Table 1" in t1.to_text()


def test_success_grid_and_most_severe(small_db):
    records = load_records([small_db])
    setpoints, speeds, grid = success_grid(records)
    assert setpoints == [5.0, 7.0] and speeds == [20.0, 25.0]
    assert grid.sum() == sum(r.outcome == "success" for r in records)
    top = most_severe(records, 3)
    assert len(top) == 3 and top[0].speed_diff_kmh >= top[1].speed_diff_kmh >= top[2].speed_diff_kmh
    assert all(r.outcome == "success" for r in top)
    assert len(richest_conditions(records)) == 2  # one per start mode


def _record(params, time_s=10.0):
    return Record("db", 0, 0, "n", 3, 7.0, 25.0, "rest", "knots", "bo", 0, 6.0, tuple(params), 0.1, "success",
                  "v1-v2", time_s, 100.0, 10.0)


@pytest.mark.parametrize("inertias, k", [([100, 20, 15, 12, 10], 2), ([100, 80, 20, 15, 12, 10], 3), ([5.0], 1)])
def test_the_elbow_rule(inertias, k):
    assert elbow(inertias) == k


def test_two_maneuvers_are_found_as_two_clusters():
    rng = np.random.default_rng(0)
    brake_throttle_brake = np.array([-1, 1, -1, 0, 0, 0, 0, 0, 0], dtype=float)
    throttle_then_brake = np.array([1, 1, 1, 1, 1, -1, 1, -1, 0], dtype=float)
    vectors = [np.clip(m + rng.normal(0, 0.08, 9), -1, 1) for m in [brake_throttle_brake] * 12 + [throttle_then_brake] * 8]
    c = cluster_knots([_record(v) for v in vectors], "synthetic")
    assert c.k == 2 and c.dbscan_clusters == 2
    (n1, mean1, _), (n2, mean2, _) = c.cluster_stats()
    assert (n1, n2) == (12, 8)
    assert np.allclose(mean1, brake_throttle_brake, atol=0.1) and np.allclose(mean2, throttle_then_brake, atol=0.1)
    assert list(c.knot_times_s) == [0, 6, 12, 18, 24, 30, 36, 42, 48]
