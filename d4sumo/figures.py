"""Figures of the paper's analysis, drawn with matplotlib (headless) into image files."""

from __future__ import annotations

from pathlib import Path
from typing import Sequence

import numpy as np

from .analysis import Clustering, Record, success_grid


def _plt():
    import matplotlib

    matplotlib.use("Agg")  # files only: works without a display
    import matplotlib.pyplot as plt

    return plt


def read_fcd(path: str | Path) -> dict[str, dict[str, np.ndarray]]:
    """SUMO FCD as {vehicle id: {time, pos, speed, acceleration}} (attributes read in file order)."""
    from sumolib.xml import parse_fast_nested

    rows: dict[str, list[tuple[float, float, float, float]]] = {}
    for step, v in parse_fast_nested(str(path), "timestep", ["time"], "vehicle", ["id", "speed", "pos", "acceleration"]):
        rows.setdefault(v.id, []).append((float(step.time), float(v.pos), float(v.speed), float(v.acceleration)))
    out = {}
    for vid in sorted(rows, key=lambda s: int(s[1:]) if s[1:].isdigit() else s):
        a = np.array(rows[vid])
        out[vid] = {"time": a[:, 0], "pos": a[:, 1], "speed": a[:, 2], "acceleration": a[:, 3]}
    return out


def heatmap(records: Sequence[Record], title: str, path: str | Path) -> Path:
    """Successes over setpoint x target speed."""
    plt = _plt()
    setpoints, speeds, grid = success_grid(records)
    fig, ax = plt.subplots(figsize=(1.6 + 1.3 * len(speeds), 1.4 + 0.38 * len(setpoints)))
    im = ax.imshow(grid, cmap="viridis", aspect="auto", origin="lower")
    for i in range(len(setpoints)):
        for j in range(len(speeds)):
            ax.text(j, i, str(grid[i, j]), ha="center", va="center", color="w" if grid[i, j] < grid.max() / 2 else "k", fontsize=8)
    ax.set_xticks(range(len(speeds)), [f"{v:g}" for v in speeds])
    ax.set_yticks(range(len(setpoints)), [f"{d:g}" for d in setpoints])
    ax.set_xlabel("target speed [m/s]")
    ax.set_ylabel("setpoint distance [m]")
    ax.set_title(title, fontsize=9)
    fig.colorbar(im, ax=ax, label="successful attacks")
    return _save(fig, path)


def time_space(fcd: dict, title: str, path: str | Path, collision: dict | None = None) -> Path:
    """Position over time of every car, coloured by speed, the collision marked."""
    plt = _plt()
    from matplotlib.collections import LineCollection

    fig, ax = plt.subplots(figsize=(7.5, 4.5))
    vmax = max(float(d["speed"].max()) for d in fcd.values()) or 1.0
    for vid, d in fcd.items():
        points = np.column_stack([d["time"], d["pos"]]).reshape(-1, 1, 2)
        segments = np.concatenate([points[:-1], points[1:]], axis=1)
        lines = LineCollection(segments, cmap="turbo", norm=plt.Normalize(0, vmax), linewidths=2.2 if vid == "v0" else 1.4)
        lines.set_array(d["speed"][:-1])
        ax.add_collection(lines)
        ax.annotate(vid + (" (attacker)" if vid == "v0" else ""), (d["time"][-1], d["pos"][-1]), fontsize=7,
                    xytext=(3, 0), textcoords="offset points")
    if collision:
        ax.plot([collision["time_s"]], [collision["position_m"]], marker="X", color="red", markersize=12, linestyle="none",
                label=f"collision {collision['pair']}, {collision['speed_diff_kmh']:.1f} km/h")
        ax.legend(loc="upper left", fontsize=8)
    ax.autoscale()
    ax.margins(x=0.12)  # room for the vehicle labels at the lines' ends
    ax.set_xlabel("time [s]")
    ax.set_ylabel("position along the road [m]")
    ax.set_title(title, fontsize=9)
    fig.colorbar(lines, ax=ax, label="speed [m/s]")
    return _save(fig, path)


def accelerations(fcd: dict, title: str, path: str | Path, collision: dict | None = None) -> Path:
    """Every car's acceleration over time."""
    plt = _plt()
    fig, ax = plt.subplots(figsize=(7.5, 3.6))
    for vid, d in fcd.items():
        ax.plot(d["time"], d["acceleration"], label=vid + (" (attacker)" if vid == "v0" else ""), linewidth=1.8 if vid == "v0" else 1.1)
    if collision:
        ax.axvline(collision["time_s"], color="red", linestyle="--", linewidth=1, label=f"collision {collision['pair']}")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("acceleration [m/s²]")
    ax.set_title(title, fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7, ncol=3)
    return _save(fig, path)


def clusters(c: Clustering, path: str | Path) -> Path:
    """Each k-means cluster's mean and standard deviation over knot time, the median collision time,
    and the elbow curve that chose k."""
    plt = _plt()
    stats = c.cluster_stats()
    fig, axes = plt.subplots(1, len(stats) + 1, figsize=(3.4 * (len(stats) + 1), 3.2), squeeze=False)
    axes = axes[0]
    median_t = float(np.median(c.collision_times_s))
    for ax, (i, (size, mean, std)) in zip(axes, enumerate(stats, start=1)):
        ax.fill_between(c.knot_times_s, mean - std, mean + std, alpha=0.25, label="mean ± std")
        ax.plot(c.knot_times_s, mean, marker="o", label="mean")
        ax.axvline(median_t, color="red", linestyle="--", linewidth=1, label=f"median collision {median_t:.1f} s")
        ax.axhline(0, color="grey", linewidth=0.5)
        ax.set_ylim(-1.1, 1.1)
        ax.set_xlabel("knot time [s]")
        ax.set_ylabel("command u (−1 brake, +1 throttle)")
        ax.set_title(f"cluster {i}: {size} attacks", fontsize=9)
        ax.legend(fontsize=6, loc="lower left")
    ax = axes[-1]
    ax.plot(range(1, len(c.inertias) + 1), c.inertias, marker="o")
    ax.axvline(c.k, color="red", linestyle="--", linewidth=1, label=f"elbow: k = {c.k}")
    ax.set_xlabel("clusters k")
    ax.set_ylabel("k-means inertia")
    ax.set_title(f"elbow rule; DBSCAN: {c.dbscan_clusters} clusters, {c.dbscan_noise} noise", fontsize=8)
    ax.legend(fontsize=7)
    fig.suptitle(f"Successful knot vectors: {c.condition}", fontsize=9)
    return _save(fig, path)


def _save(fig, path: str | Path) -> Path:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    import matplotlib.pyplot as plt

    plt.close(fig)
    return path
