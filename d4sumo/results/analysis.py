"""The paper's analysis of stored samples: its Tables 1-3, success grids, clusters of knot vectors.

Pure data work on the results databases (no SUMO, no plotting): `figures` draws, `report` assembles.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from pathlib import Path
from typing import Iterable, Sequence

import numpy as np

from ..errors import ConfigError
from ..model.attacks import make_attack
from ..model.config import EpisodeConfig
from ..model.control import names_only
from ..model.maneuvers import LANE_CHANGE_PARAMETER, MANEUVERS, lane_change_steps

#: the scenario keys of the lane-changing maneuvers (not the maneuver's name): what sets two such campaigns apart
MANEUVER_SETTINGS = tuple(dict.fromkeys(k for m in MANEUVERS.values() for k in m.settings if k != "maneuver"))


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
    attack_start_s: float = 0.0  # simulation time at which the attack starts (after a warm-up, else 0)
    system: str = "switching"  # the system under test: its controller(s), see EpisodeConfig.system_label
    maneuver: str = "inlane"  # the attacker's maneuver: inlane (the paper's), cutin or cutout
    maneuver_settings: str = ""  # its settings ("cutin_follower=2, cutin_offset_m=0.0, lane_change_s=2.0")
    step_s: float = 0.05
    end_s: float = 60.0  # when the episode ends without a collision (warm-up included)
    param_names: tuple[str, ...] = ()  # the attack parameters' names, as the family (and maneuver) name them

    @property
    def time_from_attack_start_s(self) -> float | None:
        """The collision time counted from the attack's start: what the attack had to cause it."""
        return None if self.time_s is None else self.time_s - self.attack_start_s

    @property
    def lane_change_at_s(self) -> float | None:
        """When the attacker began its lane change, in simulation time (None: the paper's maneuver, or an
        episode that ended before the change began)."""
        if LANE_CHANGE_PARAMETER not in self.param_names:
            return None
        t_lc_s = self.params[self.param_names.index(LANE_CHANGE_PARAMETER)]
        at = self.attack_start_s + lane_change_steps(t_lc_s, self.step_s) * self.step_s  # as played
        return None if at >= (self.end_s if self.time_s is None else self.time_s) else at

    @property
    def configuration(self) -> tuple:
        """What makes two campaigns different experiments (the seed does not)."""
        return (self.network, self.followers, self.setpoint_m, self.speed_mps, self.start, self.attack_start_s,
                self.system, self.maneuver, self.maneuver_settings, self.attack, self.optimizer)


def system_label(config: dict) -> str:
    """The system under test of a stored campaign config, as EpisodeConfig.system_label names it (a
    user's controller by its name: nothing is imported)."""
    with names_only():
        return EpisodeConfig.from_dict(config).system_label


def load_records(paths: Sequence[str | Path]) -> list[Record]:
    """Every stored sample of the databases with its campaign's settings, read through the one reader of
    stored campaigns (`Campaign.from_definition`: its defaults, nothing imported)."""
    from ..search.campaign import Campaign, open_store

    records: list[Record] = []
    for path in paths:
        with open_store(path, create=False) as store:
            campaigns = {c.id: Campaign.from_definition(c.definition, where=f"{path}: campaign {c.id}")
                         for c in store.campaigns()}
            rows = {}
            for cid, c in campaigns.items():
                cfg = c.config
                start_s = cfg.warmup_s if cfg.start == "warmup" else 0.0
                settings = ", ".join(f"{k}={v}" for k, v in cfg.to_dict()["scenario"].items() if k in MANEUVER_SETTINGS)
                rows[cid] = (cfg.network, cfg.followers, cfg.setpoint_m, cfg.speed_mps, cfg.start, c.attack, c.optimizer,
                             c.seed, dict(c.attack_options).get("delta_s"), start_s, cfg.system_label,
                             cfg.maneuver, settings, cfg.step_s, start_s + cfg.duration_s, c.family().names)
            for s in store.iter_samples():
                (network, followers, setpoint, speed, start, attack, optimizer, seed, delta_s, start_s, system, maneuver,
                 settings, step_s, end_s, names) = rows[s.campaign_id]
                records.append(Record(
                    str(path), s.id, s.campaign_id, network, followers, setpoint, speed, start, attack, optimizer, seed,
                    delta_s, s.params, s.robustness, s.outcome, s.pair, s.time_s, s.position_m, s.speed_diff_kmh,
                    start_s, system, maneuver, settings, step_s, end_s, names,
                ))
    if not records:
        raise ConfigError("DB", ", ".join(map(str, paths)), "databases holding at least one sample")
    return records


def group(records: Iterable[Record], *fields: str) -> dict[tuple, list[Record]]:
    out: dict[tuple, list[Record]] = defaultdict(list)
    for r in records:
        out[tuple(getattr(r, f) for f in fields)].append(r)
    return dict(sorted(out.items(), key=lambda kv: tuple(str(k) for k in kv[0])))


def runs(records: Sequence[Record], *fields: str) -> tuple[tuple[str, ...], dict[tuple, list[Record]]]:
    """Group by ``fields``, led by the maneuver and the system under test when the records hold more than one."""
    lead = tuple(f for f in ("maneuver", "maneuver_settings", "system") if len({getattr(r, f) for r in records}) > 1)
    return lead + fields, group(records, *lead, *fields)


def run_label(key: tuple) -> str:
    return " ".join(str(k) for k in key)


def count_noun(count: int, singular: str, plural: str | None = None) -> str:
    """'1 cluster', '2 clusters', '0 successes': the count with the noun in the right number."""
    return f"{count} {singular if count == 1 else plural or singular + 's'}"


def _mean_std(values: list[float]) -> str:
    if not values:
        return "-"
    return f"{np.mean(values):.1f} ({np.std(values):.1f})"


@dataclass(frozen=True)
class Table:
    title: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]

    def to_text(self, width: int = 100) -> str:
        """The table as text, its lines at most ``width`` characters where the columns allow: a table
        wider than that (a sweep of many systems) goes on in blocks of columns, each led by the first."""
        widths = [max(len(str(x)) for x in col) for col in zip(self.header, *self.rows)]
        blocks: list[list[int]] = [[]]
        used = widths[0]
        for i in range(1, len(widths)):
            if blocks[-1] and used + 2 + widths[i] > width:
                blocks.append([])
                used = widths[0]
            blocks[-1].append(i)
            used += 2 + widths[i]
        out = []
        for b, columns in enumerate(blocks):
            shown = [0, *columns]
            line = lambda cells: "  ".join(  # noqa: E731
                str(cells[i]).rjust(widths[i]) if i else str(cells[i]).ljust(widths[i]) for i in shown).rstrip()
            title = self.title if b == 0 else f"{self.title} (continued, {b + 1} of {len(blocks)})"
            out.append("\n".join([title, line(self.header), *(line(r) for r in self.rows)]))
        return "\n\n".join(out)


def table_success_statistics(records: Sequence[Record]) -> Table:
    """The paper's Table 1: per attack and optimiser, the successes and their collisions."""
    rows = []
    for key, rs in runs(records, "attack", "optimizer")[1].items():
        wins = [r for r in rs if r.outcome == "success"]
        v12 = sum(1 for r in wins if r.pair == "v1-v2")
        rows.append((
            run_label(key), str(len(rs)), str(len(wins)),
            f"{v12} ({100 * v12 / len(wins):.0f}%)" if wins else "0",
            _mean_std([r.time_from_attack_start_s for r in wins]), _mean_std([r.position_m for r in wins]),
            _mean_std([r.speed_diff_kmh for r in wins]),
        ))
    return Table(
        "Table 1: successful attacks (followers collide, attacker untouched)",
        ("attack", "samples", "successes", "v1-v2 crashes", "time from attack start to collision s, mean (std)",
         "collision location m, mean (std)", "speed difference km/h, mean (std)"),
        tuple(rows),
    )


def table_attacker_crashes(records: Sequence[Record]) -> Table:
    """The paper's Table 2: per setpoint, attacker crashes / no-crash samples of each attack and optimiser."""
    groups = runs(records, "attack", "optimizer")[1]
    rows = []
    for d in sorted({r.setpoint_m for r in records}):
        cells = [f"{d:g} m"]
        for rs in groups.values():
            sub = [r for r in rs if r.setpoint_m == d]
            crashes = sum(r.outcome == "attacker_crash" for r in sub)
            cells.append(f"{crashes} / {sum(r.outcome == 'no_crash' for r in sub)}" if sub else "-")
        rows.append(tuple(cells))
    header = ("setpoint", *[run_label(key) for key in groups])
    return Table("Table 2: attacker crashes / no-crash samples per setpoint", header, tuple(rows))


def table_by_speed(records: Sequence[Record]) -> Table:
    """The paper's Table 3: successes per optimiser and start mode, split by target speed; with several
    speeds, each with its share of the row's successes (how they split by speed, not a success rate)."""
    speeds = sorted({r.speed_mps for r in records})
    rows = []
    for key, rs in runs(records, "attack", "optimizer", "start")[1].items():
        wins = [r for r in rs if r.outcome == "success"]
        cells = [run_label(key), str(len(wins))]
        for v in speeds:
            n = sum(1 for r in wins if r.speed_mps == v)
            cells.append(f"{n} ({100 * n / len(wins):.1f}%)" if wins and len(speeds) > 1 else str(n))
        rows.append(tuple(cells))
    title = "Table 3: successes by target speed"
    if len(speeds) > 1:
        title += " (in brackets: the share of the row's successes at that speed)"
    return Table(title, ("attack", "successes", *[f"{v:g} m/s" for v in speeds]), tuple(rows))


def table_systems(records: Sequence[Record]) -> Table:
    """Per system under test: how often an attacker made it crash, where, and how hard."""
    rows = []
    for (system,), rs in group(records, "system").items():
        wins = [r for r in rs if r.outcome == "success"]
        setpoints = sorted({r.setpoint_m for r in wins})
        rows.append((
            system, str(len(rs)), f"{len(wins)} ({100 * len(wins) / len(rs):.1f}%)",
            str(sum(r.outcome == "attacker_crash" for r in rs)),
            ", ".join(f"{d:g}" for d in setpoints) or "none",
            f"{max(r.speed_diff_kmh for r in wins):.1f}" if wins else "-",
            _mean_std([r.time_from_attack_start_s for r in wins]),
        ))
    return Table("Systems under test: successful attacks",
                 ("system", "samples", "successes", "attacker crashes", "setpoints with a success m",
                  "worst speed difference km/h", "time from attack start to collision s, mean (std)"), tuple(rows))


#: Two successes closer than this in every parameter (as a fraction of its range) are one attack.
DISTINCT_RADIUS = 0.05


def distinct_count(params: Sequence[Sequence[float]], lower: Sequence[float], upper: Sequence[float],
                   radius: float = DISTINCT_RADIUS) -> int:
    """How many of the given attacks are distinct: in order, an attack counts unless an attack already
    counted lies within ``radius`` of its parameter range in every parameter (an optimiser that
    resamples its best attack with tiny changes finds one attack, not many)."""
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    span = np.where(upper > lower, upper - lower, 1.0)
    kept: list[np.ndarray] = []
    for p in params:
        z = (np.asarray(p, float) - lower) / span
        if all(np.max(np.abs(z - k)) > radius for k in kept):
            kept.append(z)
    return len(kept)


def success_grid(records: Sequence[Record], setpoints: Sequence[float] | None = None,
                 speeds: Sequence[float] | None = None) -> tuple[list[float], list[float], np.ndarray]:
    """Successes over setpoint (rows) x speed (columns); the axes default to the values in ``records``."""
    setpoints = sorted({r.setpoint_m for r in records}) if setpoints is None else list(setpoints)
    speeds = sorted({r.speed_mps for r in records}) if speeds is None else list(speeds)
    grid = np.zeros((len(setpoints), len(speeds)), dtype=int)
    for r in records:
        if r.outcome == "success":
            grid[setpoints.index(r.setpoint_m), speeds.index(r.speed_mps)] += 1
    return setpoints, speeds, grid


def most_severe(records: Sequence[Record], count: int = 3) -> list[Record]:
    """The successes with the largest speed difference at the first collision, at most one per
    configuration (network, followers, setpoint, speed, start, system, attack, optimiser), so that one
    campaign's near-copies of its best attack do not fill the list."""
    wins = [r for r in records if r.outcome == "success" and r.speed_diff_kmh is not None]
    chosen: dict[tuple, Record] = {}
    for r in sorted(wins, key=lambda r: (-r.speed_diff_kmh, r.db, r.sample_id)):
        if len(chosen) == count:
            break
        chosen.setdefault(r.configuration, r)
    return list(chosen.values())


# --- clusters of successful knot vectors ---------------------------------------------------------


#: A knot's per-cluster statistic resting on fewer attacks than this is drawn greyed out.
FEW_ATTACKS = 3


#: the attack families whose parameters are knots in time, to cluster
KNOT_FAMILIES = ("knots", "spline", "knots-coded")


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
    if attack != "knots" or knot_times_s.size < 2:  # a global cubic spline (spline, knots-coded): every knot reaches
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

    wins = [r for r in records if r.outcome == "success" and r.attack in KNOT_FAMILIES
            and r.time_from_attack_start_s is not None and r.time_from_attack_start_s > 0]  # else no knot mattered
    if len(wins) < 4 or len({(len(r.params), r.attack, r.delta_s, r.maneuver == "inlane") for r in wins}) != 1:
        return None
    # the knots only: a lane-changing attack's last parameter is its lane change time, not a knot
    X = np.array([r.params if r.maneuver == "inlane" else r.params[:-1] for r in wins], dtype=float)
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
    """For each (system,) attack, optimiser and start of knot campaigns, the condition with the most successes."""
    out = []
    knots = [r for r in records if r.attack in KNOT_FAMILIES]
    for key, rs in runs(knots, "attack", "optimizer", "start")[1].items():
        *system, attack, optimizer, start = key
        conditions = group(rs, "network", "setpoint_m", "speed_mps")
        (network, d, v), best = max(conditions.items(), key=lambda kv: sum(r.outcome == "success" for r in kv[1]))
        lead = f"{system[0]}: " if system else ""
        out.append((f"{lead}{attack} {optimizer}, {start}, setpoint {d:g} m, {v:g} m/s", best))
    return out
