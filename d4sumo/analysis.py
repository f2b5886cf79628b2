"""The paper's analysis of stored samples: its Tables 1-3, success grids, clusters of knot vectors.

Pure data work on the results databases (no SUMO, no plotting): `figures` draws, `report` assembles.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from .errors import ConfigError
from .store import Store


@dataclass(frozen=True)
class Record:
    """One stored sample with the campaign settings it ran under."""

    db: str
    sample_id: int
    campaign_id: int
    network: str
    followers: int
    setpoint_m: float
    speed_mps: float
    start: str
    attack: str
    optimizer: str
    seed: int
    delta_s: float | None
    params: tuple[float, ...]
    robustness: float | None
    outcome: str
    pair: str | None
    time_s: float | None
    position_m: float | None
    speed_diff_kmh: float | None


def load_records(paths: Sequence[str | Path]) -> list[Record]:
    records: list[Record] = []
    for path in paths:
        with Store(path, create=False) as store:
            campaigns = {c.id: c.definition for c in store.campaigns()}
            for s in store.iter_samples():
                d = campaigns[s.campaign_id]
                sc = d["config"]["scenario"]
                records.append(Record(
                    str(path), s.id, s.campaign_id, sc["network"], sc["followers"], float(sc["setpoint_m"]),
                    float(sc["speed_mps"]), sc["start"], d["attack"]["family"], d["optimizer"], d["seed"],
                    d["attack"].get("delta_s"), s.params, s.robustness, s.outcome, s.pair, s.time_s, s.position_m,
                    s.speed_diff_kmh,
                ))
    if not records:
        raise ConfigError("DB", ", ".join(map(str, paths)), "databases holding at least one sample")
    return records


def group(records: Iterable[Record], *fields: str) -> dict[tuple, list[Record]]:
    out: dict[tuple, list[Record]] = defaultdict(list)
    for r in records:
        out[tuple(getattr(r, f) for f in fields)].append(r)
    return dict(sorted(out.items(), key=lambda kv: tuple(str(k) for k in kv[0])))


def _mean_std(values: list[float]) -> str:
    if not values:
        return "-"
    return f"{np.mean(values):.1f} ({np.std(values):.1f})"


@dataclass(frozen=True)
class Table:
    title: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]

    def to_text(self) -> str:
        widths = [max(len(str(x)) for x in col) for col in zip(self.header, *self.rows)]
        line = lambda cells: "  ".join(str(c).rjust(w) if i else str(c).ljust(w) for i, (c, w) in enumerate(zip(cells, widths)))
        return "\n".join([self.title, line(self.header), *(line(r) for r in self.rows)])


def table_success_statistics(records: Sequence[Record]) -> Table:
    """The paper's Table 1: per attack and optimiser, the successes and their collisions."""
    rows = []
    for (attack, optimizer), rs in group(records, "attack", "optimizer").items():
        wins = [r for r in rs if r.outcome == "success"]
        v12 = sum(1 for r in wins if r.pair == "v1-v2")
        rows.append((
            f"{attack} {optimizer}", str(len(rs)), str(len(wins)),
            f"{v12} ({100 * v12 / len(wins):.0f}%)" if wins else "0",
            _mean_std([r.time_s for r in wins]), _mean_std([r.position_m for r in wins]),
            _mean_std([r.speed_diff_kmh for r in wins]),
        ))
    return Table(
        "Table 1: successful attacks (followers collide, attacker untouched)",
        ("attack", "samples", "successes", "v1-v2 crashes", "time to collision s, mean (std)",
         "collision location m, mean (std)", "speed difference km/h, mean (std)"),
        tuple(rows),
    )


def table_attacker_crashes(records: Sequence[Record]) -> Table:
    """The paper's Table 2: per setpoint, attacker crashes / no-crash samples of each attack and optimiser."""
    groups = group(records, "attack", "optimizer")
    rows = []
    for d in sorted({r.setpoint_m for r in records}):
        cells = [f"{d:g} m"]
        for rs in groups.values():
            sub = [r for r in rs if r.setpoint_m == d]
            crashes = sum(r.outcome == "attacker_crash" for r in sub)
            cells.append(f"{crashes} / {sum(r.outcome == 'no_crash' for r in sub)}" if sub else "-")
        rows.append(tuple(cells))
    header = ("setpoint", *[f"{a} {o}" for a, o in groups])
    return Table("Table 2: attacker crashes / no-crash samples per setpoint", header, tuple(rows))


def table_by_speed(records: Sequence[Record]) -> Table:
    """The paper's Table 3: successes per optimiser and start mode, split by target speed."""
    speeds = sorted({r.speed_mps for r in records})
    rows = []
    for (attack, optimizer, start), rs in group(records, "attack", "optimizer", "start").items():
        wins = [r for r in rs if r.outcome == "success"]
        cells = [f"{attack} {optimizer} {start}", str(len(wins))]
        for v in speeds:
            n = sum(1 for r in wins if r.speed_mps == v)
            cells.append(f"{n} ({100 * n / len(wins):.1f}%)" if wins else "0")
        rows.append(tuple(cells))
    return Table("Table 3: successes by target speed", ("attack", "successes", *[f"{v:g} m/s" for v in speeds]), tuple(rows))


def success_grid(records: Sequence[Record]) -> tuple[list[float], list[float], np.ndarray]:
    """Successes over setpoint (rows) x speed (columns)."""
    setpoints = sorted({r.setpoint_m for r in records})
    speeds = sorted({r.speed_mps for r in records})
    grid = np.zeros((len(setpoints), len(speeds)), dtype=int)
    for r in records:
        if r.outcome == "success":
            grid[setpoints.index(r.setpoint_m), speeds.index(r.speed_mps)] += 1
    return setpoints, speeds, grid


def most_severe(records: Sequence[Record], count: int = 3) -> list[Record]:
    """The successes with the largest speed difference at collision."""
    wins = [r for r in records if r.outcome == "success" and r.speed_diff_kmh is not None]
    return sorted(wins, key=lambda r: (-r.speed_diff_kmh, r.sample_id))[:count]


# --- clusters of successful knot vectors ---------------------------------------------------------


@dataclass(frozen=True)
class Clustering:
    condition: str
    knot_times_s: np.ndarray
    vectors: np.ndarray  # successes x knots
    collision_times_s: np.ndarray
    inertias: tuple[float, ...]  # k-means inertia for k = 1..
    k: int  # chosen by the elbow rule
    labels: np.ndarray  # k-means labels
    dbscan_clusters: int
    dbscan_noise: int

    def cluster_stats(self) -> list[tuple[int, np.ndarray, np.ndarray]]:
        """(size, mean, std) per k-means cluster, largest first."""
        stats = []
        for c in range(self.k):
            members = self.vectors[self.labels == c]
            stats.append((len(members), members.mean(axis=0), members.std(axis=0)))
        return sorted(stats, key=lambda s: -s[0])


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


def cluster_knots(records: Sequence[Record], condition: str, max_k: int = 6, seed: int = 0) -> Clustering | None:
    """Cluster the successful knot vectors of one condition (k-means with the elbow rule, and DBSCAN)."""
    from sklearn.cluster import DBSCAN, KMeans
    from sklearn.neighbors import NearestNeighbors

    wins = [r for r in records if r.outcome == "success" and r.attack in ("knots", "spline")]
    if len(wins) < 4 or len({len(r.params) for r in wins}) != 1:
        return None
    X = np.array([r.params for r in wins])
    delta = wins[0].delta_s or 6.0
    ks = range(1, min(max_k, len(wins) - 1) + 1)
    fits = [KMeans(n_clusters=k, n_init=10, random_state=seed).fit(X) for k in ks]
    inertias = tuple(float(f.inertia_) for f in fits)
    k = elbow(inertias)
    min_samples = min(4, len(wins) - 1)
    distances, _ = NearestNeighbors(n_neighbors=min_samples).fit(X).kneighbors(X)
    eps = float(np.median(distances[:, -1])) or 1e-3
    db_labels = DBSCAN(eps=eps, min_samples=min_samples).fit(X).labels_
    return Clustering(
        condition=condition,
        knot_times_s=np.arange(X.shape[1]) * delta,
        vectors=X,
        collision_times_s=np.array([r.time_s for r in wins]),
        inertias=inertias,
        k=k,
        labels=fits[k - 1].labels_,
        dbscan_clusters=int(len(set(db_labels) - {-1})),
        dbscan_noise=int(np.sum(db_labels == -1)),
    )


def richest_conditions(records: Sequence[Record]) -> list[tuple[str, list[Record]]]:
    """For each (attack, optimiser, start) of knot campaigns, the condition with the most successes."""
    out = []
    knots = [r for r in records if r.attack in ("knots", "spline")]
    for (attack, optimizer, start), rs in group(knots, "attack", "optimizer", "start").items():
        conditions = group(rs, "network", "setpoint_m", "speed_mps")
        (network, d, v), best = max(conditions.items(), key=lambda kv: sum(r.outcome == "success" for r in kv[1]))
        out.append((f"{attack} {optimizer}, {start}, setpoint {d:g} m, {v:g} m/s", best))
    return out
