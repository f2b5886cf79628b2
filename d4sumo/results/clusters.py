"""Clusters of successful knot vectors: which knots can have shaped an attack before its collision,
k-means over those knots (the elbow rule chooses k) and DBSCAN, and the conditions to cluster.

Pure computations on records (no SUMO, no plotting, no database): `figures` draws a clustering.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np

from ..model.attacks.pedals import FAMILY_CLASSES, make_attack
from .analysis import group, run_label, runs
from .records import Record

#: A knot's per-cluster statistic resting on fewer attacks than this is drawn greyed out.
FEW_ATTACKS = 3


def knot_families() -> tuple[str, ...]:
    """The attack families whose parameters are knots in time, to cluster (each says so: `AttackFamily.knots_in_time`;
    one registered from Python too)."""
    return tuple(name for name, cls in FAMILY_CLASSES.items() if cls.knots_in_time)


KNOT_FAMILIES = knot_families()  # d4sumo's own


def relevant_knots(knot_times_s: np.ndarray, collision_s: float, attack: str = "knots") -> np.ndarray:
    """Which knots can have shaped the attack before its collision (True); ``collision_s`` is t_c, the
    collision time counted from the attack's start, and knot k sits at t_k = k * delta.

    Only commands before t_c matter: a step's command acts during that step, so none given at t >= t_c
    can have caused the collision. PCHIP (``knots``) takes the slope at a knot from that knot and its
    two neighbours (at the ends, scipy's slope uses the first or last three knots), so the cubic on
    [t_j, t_{j+1}] depends on knots j-1 .. j+2, and knot k shapes u(t) only on (t_{k-2}, t_{k+2}) (the
    last knot also holds u after the horizon, which only lengthens its reach). The attack starts at
    t = 0, so knot k is irrelevant iff max(t_{k-2}, 0) >= t_c; for t_c > 0 that is k >= 2 and
    t_{k-2} >= t_c. The clipped global cubic spline (``spline``) lets every knot shape u at every time,
    so there no knot is masked (unless the collision came before the attack started). Commands are
    sampled once a step, so the rule may keep a knot whose reach before t_c is shorter than a step.
    """
    knot_times_s = np.asarray(knot_times_s, dtype=float)
    if not getattr(FAMILY_CLASSES.get(attack), "local_knots", False) or knot_times_s.size < 2:  # a global spline: every knot reaches
        return np.full(knot_times_s.shape, collision_s > 0.0)
    delta_s = knot_times_s[1] - knot_times_s[0]
    return np.maximum(knot_times_s - 2.0 * delta_s, 0.0) < collision_s


@dataclass(frozen=True)
class ClusterStats:
    """One k-means cluster: its knots' mean and std over the members whose knot mattered, and its
    members' collision times (from the attack's start)."""

    label: int
    size: int
    mean: np.ndarray  # per knot; NaN where no member's knot mattered
    std: np.ndarray
    counts: np.ndarray  # per knot: the members whose knot mattered, what mean and std rest on
    collision_times_s: np.ndarray

    @property
    def median_collision_s(self) -> float:
        return float(np.median(self.collision_times_s))

    @property
    def collision_quartiles_s(self) -> tuple[float, float]:
        q1, q3 = np.percentile(self.collision_times_s, [25, 75])
        return float(q1), float(q3)


@dataclass(frozen=True)
class Clustering:
    condition: str
    knot_times_s: np.ndarray  # from the attack's start
    vectors: np.ndarray  # successes x knots, as searched
    relevant: np.ndarray  # successes x knots: the knot came early enough to shape the attack (relevant_knots)
    collision_times_s: np.ndarray  # from the attack's start
    inertias: tuple[float, ...]  # k-means inertia over the relevant knots for k = 1..
    k: int  # chosen by the elbow rule
    labels: np.ndarray  # k-means labels
    dbscan_labels: np.ndarray  # -1: noise

    @property
    def dbscan_clusters(self) -> int:
        return int(len(set(self.dbscan_labels.tolist()) - {-1}))

    @property
    def dbscan_noise(self) -> int:
        return int(np.sum(self.dbscan_labels == -1))

    def cluster_stats(self) -> list[ClusterStats]:
        """Per k-means cluster, largest first; each knot's statistic over its relevant values only."""
        stats = []
        masked = np.where(self.relevant, self.vectors, np.nan)
        for c in range(self.k):
            members = masked[self.labels == c]
            counts = np.sum(~np.isnan(members), axis=0)
            some = counts > 0
            mean = np.full(members.shape[1], np.nan)
            std = np.full(members.shape[1], np.nan)
            mean[some] = np.nanmean(members[:, some], axis=0)
            std[some] = np.nanstd(members[:, some], axis=0)
            stats.append(ClusterStats(c, len(members), mean, std, counts, self.collision_times_s[self.labels == c]))
        return sorted(stats, key=lambda s: (-s.size, s.label))


def elbow(inertias: Sequence[float]) -> int:
    """k at the elbow: the point farthest from the chord between the first and last inertia."""
    y = np.asarray(inertias, dtype=float)
    if y.size <= 2:
        return int(y.size)
    x = np.arange(1, y.size + 1, dtype=float)
    x_n = (x - x[0]) / (x[-1] - x[0])
    span = y[0] - y[-1]
    y_n = (y - y[-1]) / span if span > 0 else np.zeros_like(y)
    distance = np.abs(1.0 - x_n - y_n)  # distance to the chord from (0, 1) to (1, 0)
    return int(x[int(np.argmax(distance))])


def kmeans_masked(X: np.ndarray, relevant: np.ndarray, k: int, seed: int = 0,
                  max_iter: int = 100) -> tuple[np.ndarray, np.ndarray, float]:
    """k-means that ignores the masked entries (k-POD): fill them from the centroid their vector is
    assigned to and refit until the assignment stops changing. A filled entry equals its centroid, so it
    adds nothing to the inertia and does not move the centroid. Returns labels, centroids and the
    inertia over the relevant entries."""
    from sklearn.cluster import KMeans

    masked = np.where(relevant, X, np.nan)
    counts = relevant.sum(axis=0)
    column_mean = np.divide(np.nansum(masked, axis=0), counts, out=np.zeros(X.shape[1]), where=counts > 0)
    fit = KMeans(n_clusters=k, n_init=10, random_state=seed).fit(np.where(relevant, X, column_mean))
    labels = fit.labels_
    for _ in range(max_iter):
        fit = KMeans(n_clusters=k, init=fit.cluster_centers_, n_init=1).fit(np.where(relevant, X, fit.cluster_centers_[labels]))
        if np.array_equal(fit.labels_, labels):
            break
        labels = fit.labels_
    centers = fit.cluster_centers_
    inertia = float(np.sum(np.where(relevant, X - centers[labels], 0.0) ** 2))
    return labels, centers, inertia


def cluster_knots(records: Sequence[Record], condition: str, max_k: int = 6, seed: int = 0) -> Clustering | None:
    """Cluster the successful knot vectors of one condition (k-means with the elbow rule, and DBSCAN),
    each on the knots that can have shaped the attack before its collision only (relevant_knots)."""
    from sklearn.cluster import DBSCAN
    from sklearn.metrics.pairwise import nan_euclidean_distances

    wins = [r for r in records if r.outcome == "success" and r.attack in knot_families()
            and r.time_from_attack_start_s is not None and r.time_from_attack_start_s > 0]  # else no knot mattered
    if len(wins) < 4 or len({(len(r.params), r.attack, r.delta_s, len(r.signal_params)) for r in wins}) != 1:
        return None
    # the knots only: what a maneuver adds (a lane change time, a swerving attacker's lanes) is no knot
    X = np.array([r.signal_params for r in wins], dtype=float)
    delta_s = wins[0].delta_s  # knots every delta_s; the coded knots where their family puts them
    knot_times_s = (np.arange(X.shape[1]) * delta_s if delta_s
                    else np.asarray(make_attack(wins[0].attack).knot_times_s, dtype=float))
    collision_times_s = np.array([r.time_from_attack_start_s for r in wins], dtype=float)
    relevant = np.array([relevant_knots(knot_times_s, t, wins[0].attack) for t in collision_times_s])
    distinct = len(np.unique(np.where(relevant, X, np.inf), axis=0))  # k-means finds no more clusters than these
    ks = range(1, min(max_k, len(wins) - 1, distinct) + 1)
    fits = [kmeans_masked(X, relevant, k, seed) for k in ks]
    inertias = tuple(f[2] for f in fits)
    k = elbow(inertias)
    # DBSCAN on distances over the knots relevant to both vectors (scaled up for the ones left out)
    distances = nan_euclidean_distances(np.where(relevant, X, np.nan))
    finite = np.isfinite(distances)
    distances[~finite] = 10.0 * (distances[finite].max() + 1.0)  # no knot in common: never neighbours
    min_samples = min(4, len(wins) - 1)
    eps = float(np.median(np.sort(distances, axis=1)[:, min_samples - 1])) or 1e-3  # self is the first neighbour
    db_labels = DBSCAN(eps=eps, min_samples=min_samples, metric="precomputed").fit(distances).labels_
    return Clustering(
        condition=condition,
        knot_times_s=knot_times_s,
        vectors=X,
        relevant=relevant,
        collision_times_s=collision_times_s,
        inertias=inertias,
        k=k,
        labels=fits[k - 1][0],
        dbscan_labels=db_labels,
    )


def richest_conditions(records: Sequence[Record]) -> list[tuple[str, list[Record]]]:
    """For each (scenario, system,) attack, optimiser and start of knot campaigns, the setpoint and speed with
    the most successes."""
    out = []
    knots = [r for r in records if r.attack in knot_families()]
    for key, rs in runs(knots, "attack", "optimizer", "start")[1].items():
        *scenario_system, attack, optimizer, start = key
        conditions = group(rs, "network", "setpoint_m", "speed_mps")
        (_, d, v), best = max(conditions.items(), key=lambda kv: sum(r.outcome == "success" for r in kv[1]))
        lead = run_label(tuple(scenario_system))
        lead = f"{lead}: " if lead else ""
        out.append((f"{lead}{attack} {optimizer}, {start}, setpoint {d:g} m, {v:g} m/s", best))
    return out
