"""The paper's tables and clusters, from a small real database and from synthetic data."""

from __future__ import annotations

import dataclasses
import itertools

import numpy as np
import pytest

from d4sumo.model.attacks import make_attack
from d4sumo.model.config import EpisodeConfig
from d4sumo.results.analysis import (Record, cluster_knots, count_noun, elbow, load_records, most_severe,
                                     relevant_knots, richest_conditions, success_grid, table_attacker_crashes,
                                     table_by_speed, table_success_statistics)


@pytest.mark.sumo
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
    assert all(r.attack_start_s == 0.0 and r.time_from_attack_start_s == r.time_s for r in wins)  # rest and steady


@pytest.mark.sumo
def test_success_grid_and_most_severe(small_db):
    records = load_records([small_db])
    setpoints, speeds, grid = success_grid(records)
    assert setpoints == [5.0, 7.0] and speeds == [20.0, 25.0]
    assert grid.sum() == sum(r.outcome == "success" for r in records)
    top = most_severe(records, 3)
    assert len(top) == 3 and top[0].speed_diff_kmh >= top[1].speed_diff_kmh >= top[2].speed_diff_kmh
    assert all(r.outcome == "success" for r in top)
    assert len({r.configuration for r in top}) == 3 and len({r.campaign_id for r in top}) == 3
    assert len(richest_conditions(records)) == 2  # one per start mode


def _record(params, time_s=10.0, **changes):
    names = tuple(f"m{i}" for i in range(9)) + (("t_lc_s",) if len(params) == 10 else ())  # a lane change time: by name
    r = Record("db", 0, 0, "n", 3, 7.0, 25.0, "rest", "knots", "bo", 0, 6.0, tuple(params), 0.1, "success",
               "v1-v2", time_s, 100.0, 10.0, param_names=names[:len(params)])
    return dataclasses.replace(r, **changes)


# --- time from the attack's start, Table 1 ----------------------------------------------------------


def test_records_read_stored_campaigns_through_the_one_reader_with_its_defaults(tmp_path):
    """A warm-up campaign stored without warmup_s (an earlier version's) starts its attack at the
    default 15 s, from EpisodeConfig's defaults, not from a copy of them here."""
    from d4sumo.search.campaign import Campaign, open_store

    definition = Campaign(config=EpisodeConfig(start="warmup", warmup_s=15.0, step_s=0.1)).definition()
    del definition["config"]["scenario"]["warmup_s"]
    with open_store(tmp_path / "r.sqlite") as store:
        cid = store.open_campaign(definition, 1)
        store.add_sample(cid, 0, (0.0,) * 9, -1.0, "no_crash", None, {"v0-v1": 7.0}, 0.1, None)
    (record,) = load_records([tmp_path / "r.sqlite"])
    assert (record.attack_start_s, record.end_s, record.step_s, record.start) == (15.0, 75.0, 0.1, "warmup")


def test_the_lane_change_is_marked_only_when_it_began_before_the_episode_ended():
    """Regression: figures marked the lane change at t_lc_s even when the crash had ended the episode first."""
    changed = _record([0] * 9 + [4.0], time_s=30.0, start="warmup", attack_start_s=15.0, maneuver="cutout")
    ended_first = _record([0] * 9 + [20.0], time_s=30.0, start="warmup", attack_start_s=15.0, maneuver="cutout")
    no_crash = _record([0] * 9 + [20.0], time_s=None, maneuver="cutout")
    assert changed.lane_change_at_s == 19.0 and ended_first.lane_change_at_s is None and no_crash.lane_change_at_s == 20.0
    # as played: 15.03 s after a 15 s warm-up is step 601 (30.05 s), after a collision at the end of step 600
    rounded = _record([0] * 9 + [15.03], time_s=30.05, start="warmup", attack_start_s=15.0, maneuver="cutout", end_s=75.0)
    assert rounded.lane_change_at_s is None
    assert _record([0] * 9 + [60.0], time_s=None, maneuver="cutout").lane_change_at_s is None  # past the episode
    assert _record([0] * 9, time_s=30.0).lane_change_at_s is None  # the paper's maneuver changes no lane


def test_table_1_counts_collision_time_from_the_attack_start():
    records = [_record([0] * 9, time_s=25.0, start="warmup", attack_start_s=15.0),
               _record([0] * 9, time_s=35.0, start="warmup", attack_start_s=15.0)]
    assert [r.time_from_attack_start_s for r in records] == [10.0, 20.0]
    t1 = table_success_statistics(records)
    column = t1.header.index("time from attack start to collision s, mean (std)")
    assert t1.rows[0][column] == "15.0 (5.0)"  # not 30.0: the warm-up is not the attack's doing


# --- most severe attacks ------------------------------------------------------------------------------


def test_most_severe_are_picked_across_configurations():
    # one campaign holds the five largest speed differences; the others are milder
    strong = [_record([0] * 9, sample_id=i, speed_diff_kmh=80.0 - i) for i in range(5)]
    other_setpoint = [_record([0] * 9, sample_id=10 + i, setpoint_m=5.0, speed_diff_kmh=50.0 - i) for i in range(3)]
    other_optimizer = [_record([0] * 9, sample_id=20, optimizer="ce", speed_diff_kmh=60.0)]
    other_start = [_record([0] * 9, sample_id=30, start="steady", speed_diff_kmh=40.0)]
    failed = [_record([0] * 9, sample_id=40, start="steady", setpoint_m=9.0, outcome="attacker_crash", speed_diff_kmh=99.0)]
    top = most_severe(strong + other_setpoint + other_optimizer + other_start + failed, 3)
    assert [r.sample_id for r in top] == [0, 20, 10]  # the best of each configuration, most severe first
    assert len({r.configuration for r in top}) == 3
    assert [r.sample_id for r in most_severe(strong, 3)] == [0]  # one configuration: one attack


# --- which knots count --------------------------------------------------------------------------------


def test_relevant_knots_rule():
    t = np.arange(9) * 6.0
    assert relevant_knots(t, 10.0).tolist() == [True] * 4 + [False] * 5  # t_2 = 12 >= 10: knot 4 on is masked
    assert relevant_knots(t, 12.0).tolist() == [True] * 4 + [False] * 5  # knot 4 acts only after t_2 = 12
    assert relevant_knots(t, 12.05).tolist() == [True] * 5 + [False] * 4
    assert relevant_knots(t, 0.05).tolist() == [True] * 3 + [False] * 6  # knot 2 shapes (t_0, t_1) already
    assert relevant_knots(t, 100.0).all()
    assert relevant_knots(t, 10.0, "spline").all()  # a global spline: every knot shapes every time
    assert not relevant_knots(t, 0.0).any() and not relevant_knots(t, -1.0, "spline").any()


@pytest.mark.parametrize("collision_s", [0.05, 5.0, 12.0, 13.0, 23.95, 30.0, 47.0])
def test_a_masked_knot_never_changes_the_command_before_the_collision(collision_s):
    family = make_attack("knots")
    t = np.arange(0.0, 60.0, 0.005)
    before = t < collision_s
    relevant = relevant_knots(family.knot_times_s, collision_s)
    rng = np.random.default_rng(1)
    for _ in range(40):
        x = rng.uniform(-1, 1, 9)
        for k in range(9):
            y = x.copy()
            y[k] = -x[k] if abs(x[k]) > 0.2 else x[k] + 0.5
            changed = np.any(np.abs(family.signal(x, t)[before] - family.signal(y, t)[before]) > 1e-12)
            if not relevant[k]:
                assert not changed, f"knot {k} masked at t_c = {collision_s} but changes u before it"
    # and the rule is tight: every knot it keeps can change the command before the collision (on rising
    # knots: PCHIP gives a local extremum a flat slope, which would hide a neighbour's influence)
    x = np.linspace(-0.8, 0.8, 9)
    for k in np.flatnonzero(relevant):
        y = x.copy()
        y[k] += 0.05
        assert np.any(np.abs(family.signal(x, t)[before] - family.signal(y, t)[before]) > 1e-12)


# --- clusters -----------------------------------------------------------------------------------------


@pytest.mark.parametrize("inertias, k", [([100, 20, 15, 12, 10], 2), ([100, 80, 20, 15, 12, 10], 3), ([5.0], 1)])
def test_the_elbow_rule(inertias, k):
    assert elbow(inertias) == k


def test_two_maneuvers_are_found_as_two_clusters():
    rng = np.random.default_rng(0)
    brake_throttle_brake = np.array([-1, 1, -1, 0, 0, 0, 0, 0, 0], dtype=float)
    throttle_then_brake = np.array([1, 1, 1, 1, 1, -1, 1, -1, 0], dtype=float)
    vectors = [np.clip(m + rng.normal(0, 0.08, 9), -1, 1) for m in [brake_throttle_brake] * 12 + [throttle_then_brake] * 8]
    c = cluster_knots([_record(v, time_s=60.0) for v in vectors], "synthetic")
    assert c.k == 2 and c.dbscan_clusters == 2
    first, second = c.cluster_stats()
    assert (first.size, second.size) == (12, 8)
    assert np.allclose(first.mean, brake_throttle_brake, atol=0.1) and np.allclose(second.mean, throttle_then_brake, atol=0.1)
    assert list(c.knot_times_s) == [0, 6, 12, 18, 24, 30, 36, 42, 48]


def _groups_differing_after_the_collision(collision_s: float):
    """Groups A and B share their first knots and differ only from knot 4 on; group C differs early."""
    rng = np.random.default_rng(3)
    early = np.array([0.8, -0.8, 0.8, -0.8])
    a = np.concatenate([early, np.ones(5)])
    b = np.concatenate([early, -np.ones(5)])
    c = np.concatenate([-early, np.zeros(5)])
    vectors = [np.clip(m + rng.normal(0, 0.05, 9), -1, 1) for m in [a] * 8 + [b] * 8 + [c] * 8]
    group = np.array([0] * 8 + [1] * 8 + [2] * 8)
    return [_record(v, time_s=collision_s) for v in vectors], group


def test_knots_after_the_collision_do_not_split_clusters():
    records, group = _groups_differing_after_the_collision(10.0)  # knots 4.. act from t_2 = 12 s on: masked
    c = cluster_knots(records, "masked")
    assert not c.relevant[:, 4:].any() and c.relevant[:, :4].all()
    assert c.k == 2
    labels = c.labels
    assert len(set(labels[group < 2])) == 1 and len(set(labels[group == 2])) == 1 and labels[0] != labels[-1]
    assert c.dbscan_clusters == 2
    core = c.dbscan_labels != -1  # DBSCAN may leave a few points as noise; none splits A from B
    assert len(set(c.dbscan_labels[(group < 2) & core])) == 1 and set(c.dbscan_labels[(group == 2) & core]).isdisjoint(
        c.dbscan_labels[(group < 2) & core])
    # the same knots with a late collision all count, and A and B come apart: the test above can fail
    late = cluster_knots(_groups_differing_after_the_collision(60.0)[0], "late")
    assert late.k == 3 and late.dbscan_clusters == 3


def test_cluster_statistics_rest_on_the_relevant_knots_only():
    # half the attacks collide at 10 s (knots 4.. masked), half at 35 s (only knot 8 masked)
    rng = np.random.default_rng(5)
    base = np.array([0.5, -0.5, 0.5, -0.5, 0.2, 0.2, 0.2, 0.2, 0.2])
    vectors, times = [], []
    for i in range(10):
        v = np.clip(base + rng.normal(0, 0.02, 9), -1, 1)
        if i < 5:
            v[4:] = -1.0  # after its collision: must not pull the mean down
        vectors.append(v)
        times.append(10.0 if i < 5 else 35.0)
    c = cluster_knots([_record(v, time_s=t) for v, t in zip(vectors, times)], "mixed", max_k=1)
    (s,) = c.cluster_stats()
    assert s.counts.tolist() == [10, 10, 10, 10, 5, 5, 5, 5, 0]
    X = np.array(vectors)
    assert np.allclose(s.mean[4:8], X[5:, 4:8].mean(axis=0)) and np.allclose(s.std[4:8], X[5:, 4:8].std(axis=0))
    assert np.allclose(s.mean[4:8], 0.2, atol=0.05) and np.isnan(s.mean[8])


def test_each_cluster_has_its_own_collision_times():
    rng = np.random.default_rng(2)
    early_brake = np.array([-1, -1, 1, 0, 0, 0, 0, 0, 0], dtype=float)
    late_brake = np.array([1, 1, 1, 1, -1, -1, 0, 0, 0], dtype=float)
    records = ([_record(np.clip(early_brake + rng.normal(0, 0.05, 9), -1, 1), time_s=t) for t in (9, 10, 11, 12, 13, 14)]
               + [_record(np.clip(late_brake + rng.normal(0, 0.05, 9), -1, 1), time_s=t) for t in (30, 31, 32, 33)])
    c = cluster_knots(records, "two")
    assert c.k == 2
    first, second = c.cluster_stats()
    assert (first.size, first.median_collision_s, first.collision_quartiles_s) == (6, 11.5, (10.25, 12.75))
    assert (second.size, second.median_collision_s) == (4, 31.5)
    assert np.median(c.collision_times_s) not in (first.median_collision_s, second.median_collision_s)


def test_clusters_use_the_time_from_the_attack_start():
    vectors = [np.full(9, 0.1 * i) for i in range(6)]
    records = [_record(v, time_s=25.0, start="warmup", attack_start_s=15.0) for v in vectors]
    c = cluster_knots(records, "warm-up")
    assert np.allclose(c.collision_times_s, 10.0)
    assert c.relevant[0].tolist() == relevant_knots(c.knot_times_s, 10.0).tolist()


@pytest.mark.parametrize("count, words", [(0, "0 clusters"), (1, "1 cluster"), (2, "2 clusters")])
def test_count_noun(count, words):
    assert count_noun(count, "cluster") == words
    assert count_noun(count, "success", "successes") == words.replace("clusters", "successes").replace("cluster", "success")


# --- systems under test --------------------------------------------------------------------------------


def test_tables_split_by_system_when_several_were_attacked():
    from d4sumo.results.analysis import system_label, table_systems

    paper = [_record([0] * 9, sample_id=i, speed_diff_kmh=20.0 + i) for i in range(3)]
    acc = [_record([0] * 9, sample_id=10 + i, system="sumo:ACC", outcome="no_crash", pair=None, time_s=None,
                   speed_diff_kmh=None) for i in range(4)]
    t = table_systems(paper + acc)
    rows = {row[0]: row for row in t.rows}
    assert rows["switching"][2] == "3 (100.0%)" and rows["switching"][4] == "7"
    assert rows["sumo:ACC"][2] == "0 (0.0%)" and rows["sumo:ACC"][4] == "none"  # said plainly
    assert [row[0] for row in table_success_statistics(paper + acc).rows] == ["sumo:ACC knots bo", "switching knots bo"]
    assert [row[0] for row in table_success_statistics(paper).rows] == ["knots bo"]  # one system: as the paper
    assert len(most_severe(paper + acc, 3)) == 1  # one configuration with successes
    assert system_label({"controller": [{"class": "sumo:ACC", "tau": 0.5}, {"class": "switching"}, "sumo:IDM"]}) \
        == "sumo:ACC(tau=0.5) / switching / sumo:IDM"
    # a user's controller by its name and parameters: nothing imported
    assert system_label({"controller": {"class": "nowhere.module:Ctl", "gain": 1}}) == "nowhere.module:Ctl(gain=1)"


def test_near_copies_of_one_attack_count_once():
    from d4sumo.results.analysis import distinct_count

    lower, upper = [-1.0, -1.0], [1.0, 1.0]
    same = [[0.5, 0.5], [0.55, 0.45], [0.59, 0.5]]  # within 5% of the range (0.1) of the first in every parameter
    assert distinct_count(same, lower, upper) == 1
    assert distinct_count(same + [[0.5, 0.75]], lower, upper) == 2  # 0.25 away in one parameter: another attack
    assert distinct_count([], lower, upper) == 0


def _sample(i, **changes):
    r = Record("db", i, 0, "n", 3, 7.0, 25.0, "rest", "knots", "bo", 0, 6.0, (0.0,) * 9, 0.1, "success",
               "v1-v2", 20.0, 100.0, 10.0)
    return dataclasses.replace(r, **changes)


def test_the_tables_of_a_sweep_of_many_systems_fit_in_100_characters_a_line():
    """tables.txt had lines of about 600 characters for the systems sweep: wide tables go on in blocks."""
    systems = [f"sumo:ACC(tau={t}, speedControlGainSpeed={g})" for t in (0.5, 1.0, 1.5, 2.0) for g in (0.5, 1.0, 1.5)]
    records = [_sample(i, system=system, optimizer=optimizer, setpoint_m=d, outcome=outcome)
               for i, (system, optimizer, d, outcome) in enumerate(itertools.product(
                   systems, ("bo", "ce"), (3.0, 5.0, 7.0, 9.0, 11.0, 13.0), ("success", "attacker_crash", "no_crash")))]
    t2 = table_attacker_crashes(records)
    assert len(t2.header) == 25
    text = t2.to_text()
    assert max(len(line) for line in text.splitlines()) <= 100
    blocks = text.split("\n\n")
    assert len(blocks) > 1 and blocks[1].startswith("Table 2: attacker crashes / no-crash samples per setpoint (continued, 2 of")
    for column in t2.header[1:]:  # every run's column is in one block, each block led by the setpoints
        assert sum(column in block.splitlines()[1] for block in blocks) == 1
    assert all(block.splitlines()[2].startswith("3 m") for block in blocks)


def test_table_3_gives_shares_of_a_rows_successes_only_across_several_speeds():
    one_speed = [_sample(i, outcome="success" if i % 2 else "no_crash") for i in range(10)]
    t3 = table_by_speed(one_speed)
    assert t3.rows == (("knots bo rest", "5", "5"),) and "share" not in t3.title  # once "5 (100.0%)"
    two = one_speed + [_sample(10 + i, speed_mps=30.0) for i in range(15)]
    t3 = table_by_speed(two)
    assert t3.rows == (("knots bo rest", "20", "5 (25.0%)", "15 (75.0%)"),)
    assert "the share of the row's successes" in t3.title


def test_the_coded_knot_attacks_cluster_on_their_own_knot_times_every_knot_relevant():
    """knots-coded (the authors' 8 knots over 40 s, one global cubic spline): clustered like the knots, its
    knot times its family's, and every knot can have shaped an attack (a global spline reaches everywhere)."""
    from d4sumo.results.analysis import cluster_knots

    rng = np.random.default_rng(0)
    records = [_sample(i, attack="knots-coded", delta_s=None, params=tuple(rng.uniform(-1, 1, 8)), time_s=12.0,
                       param_names=tuple(f"m{k}" for k in range(8))) for i in range(12)]
    clustering = cluster_knots(records, "knots-coded bo")
    assert clustering is not None and np.allclose(clustering.knot_times_s, np.linspace(0.0, 40.0, 8))
    assert clustering.relevant.all()


def test_k_means_tries_no_more_clusters_than_distinct_attacks():
    """Regression: a report of one database named twice (each attack twice) printed scikit-learn's
    ConvergenceWarning: k-means was asked for more clusters than there were distinct vectors."""
    import warnings

    rng = np.random.default_rng(3)
    vectors = [rng.uniform(-1, 1, 9) for _ in range(3)] * 4  # 12 successes, 3 distinct attacks
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        c = cluster_knots([_record(v, time_s=60.0) for v in vectors], "repeated")
    assert c is not None and c.k <= 3
