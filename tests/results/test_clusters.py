"""Clusters of successful knot vectors: which knots count, k-means with the elbow rule and DBSCAN."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from d4sumo.model.attacks.pedals import make_attack
from d4sumo.results.clusters import cluster_knots, elbow, relevant_knots, richest_conditions
from d4sumo.results.records import Record, load_records


def _record(params, time_s=10.0, **changes):
    r = Record("db", 0, 0, "n", 3, 7.0, 25.0, "rest", "knots", "bo", 0, 6.0, tuple(params), 0.1, "success",
               "v1-v2", time_s, 100.0, 10.0, param_names=tuple(f"m{i}" for i in range(len(params))))
    return dataclasses.replace(r, **changes)


@pytest.mark.sumo
def test_one_condition_to_cluster_per_start_mode(small_db):
    assert len(richest_conditions(load_records([small_db]))) == 2


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


def test_the_coded_knot_attacks_cluster_on_their_own_knot_times_every_knot_relevant():
    """knots-coded (the authors' 8 knots over 40 s, one global cubic spline): clustered like the knots, its
    knot times its family's, and every knot can have shaped an attack (a global spline reaches everywhere)."""
    rng = np.random.default_rng(0)
    records = [_record(rng.uniform(-1, 1, 8), time_s=12.0, sample_id=i, attack="knots-coded", delta_s=None)
               for i in range(12)]
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
