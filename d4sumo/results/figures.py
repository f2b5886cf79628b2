"""Figures of the paper's analysis, drawn with matplotlib (headless) into image files.

Each figure has a ``*_figure`` function that returns the drawn matplotlib Figure (laid out, ready to
inspect) and a function of the plain name that writes it to a file.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import ConfigError
from .analysis import FEW_ATTACKS, Clustering, Record, count_noun, runs, success_grid

SPEED_CMAP = "turbo"
SUCCESS_CMAP = "viridis"
LABEL_FONT_PT = 8.0


def _figure(**kwargs):
    """A Figure on the Agg canvas (files only: works without a display, no pyplot state to leak)."""
    from matplotlib.backends.backend_agg import FigureCanvasAgg
    from matplotlib.figure import Figure

    fig = Figure(layout="constrained", **kwargs)
    FigureCanvasAgg(fig)
    return fig


def check_figure_path(path: str | Path, option: str = "--out") -> Path:
    """``path`` if a figure can be written there: in an existing folder (none is created) and with an
    image format matplotlib writes; else a ConfigError naming ``option``."""
    from matplotlib.backend_bases import FigureCanvasBase

    path = Path(path)
    if not path.parent.is_dir() or path.is_dir():
        raise ConfigError(option, str(path), "a file in an existing folder")
    formats = FigureCanvasBase.get_supported_filetypes()
    if path.suffix.lower().lstrip(".") not in formats:
        raise ConfigError(option, str(path), "an image file: " + ", ".join(f".{f}" for f in sorted(formats)))
    return path


def _save(fig, path: str | Path) -> Path:
    path = check_figure_path(path)
    fig.savefig(path, dpi=110)
    return path


# --- FCD: time-space diagrams and accelerations --------------------------------------------------


def read_fcd(path: str | Path) -> dict[str, dict[str, np.ndarray]]:
    """SUMO FCD as {vehicle id: {time, pos, speed, acceleration, lane}}; ``pos`` is the position along
    the route, ``lane`` the lane the car drives in.

    parse_fast_nested matches attributes in the order SUMO writes them (id x y angle type speed pos
    lane slope acceleration odometer); an FCD without lanes reads as all in one lane "". On a route of
    many edges SUMO's lane position starts again at 0 on each edge: the position along the route is
    then where the car started plus its odometer, and a lane is named by its index across the road
    (a junction's internal lane counts as the lane the car came from).
    """
    from sumolib.xml import parse_fast_nested

    rows: dict[str, list[tuple]] = {}
    attributes = ["id", "speed", "pos", "lane", "acceleration", "odometer"]
    for step, v in parse_fast_nested(str(path), "timestep", ["time"], "vehicle", attributes):
        rows.setdefault(v.id, []).append((float(step.time), float(v.pos), float(v.speed), float(v.acceleration), v.lane,
                                          float(v.odometer)))
    if not rows:  # written before d4sumo asked SUMO for the odometer: a road of one edge
        for step, v in parse_fast_nested(str(path), "timestep", ["time"], "vehicle", attributes[:-1]):
            rows.setdefault(v.id, []).append((float(step.time), float(v.pos), float(v.speed), float(v.acceleration), v.lane,
                                              np.nan))
    if not rows:
        for step, v in parse_fast_nested(str(path), "timestep", ["time"], "vehicle", ["id", "speed", "pos", "acceleration"]):
            rows.setdefault(v.id, []).append((float(step.time), float(v.pos), float(v.speed), float(v.acceleration), "",
                                              np.nan))
    edges = {lane.rpartition("_")[0] for r in rows.values() for *_, lane, _ in r if lane and not lane.startswith(":")}
    many_edges = len(edges) > 1
    out = {}
    for vid in sorted(rows, key=_vehicle_order):
        time, pos, speed, accel, lane, odometer = zip(*rows[vid])
        pos = np.array(pos)
        if many_edges:
            pos = pos[0] + np.array(odometer)  # every car starts on the route's first edge
            lane = _lane_indices(lane)
        out[vid] = {"time": np.array(time), "pos": pos, "speed": np.array(speed),
                    "acceleration": np.array(accel), "lane": np.array(lane, dtype=str)}
    return out


def _lane_indices(lane_ids: Sequence[str]) -> list[str]:
    """Lane ids as their index across the road; a junction's internal lane as the lane before it."""
    out, last = [], ""
    for lane in lane_ids:
        if not lane.startswith(":"):
            last = lane.rpartition("_")[2]
        out.append(last)
    return out


def _vehicle_order(vid: str):
    return (0, int(vid[1:]), "") if vid[1:].isdigit() else (1, 0, vid)


def _vehicle_label(vid: str) -> str:
    return vid + " attacker" if vid == "v0" else vid


def lanes(fcd: dict) -> list[str]:
    """The lanes the cars use, leftmost first (SUMO counts lanes from the right: lane 0 is the
    rightmost), so that stacked panels look like the road seen from above."""
    used = {str(lane) for d in fcd.values() for lane in d.get("lane", [""])}

    def key(lane: str):
        edge, _, index = lane.rpartition("_")
        return (edge, -int(index)) if index.isdigit() else (lane, 0)

    return sorted(used, key=key)


def wrap_title(title: str, width: int = 100) -> str:
    """A long title on as many lines as it needs: a system's name and parameters can make one long."""
    import textwrap

    return "\n".join(textwrap.wrap(title, width)) or title


def _lane_title(lane: str) -> str:
    edge, _, index = lane.rpartition("_")
    return f"lane {index} ({lane})" if edge and index.isdigit() else f"lane {lane}"


def _runs(inside: np.ndarray) -> list[tuple[int, int]]:
    """[start, stop) index ranges where ``inside`` is True."""
    edges = np.diff(np.concatenate([[0], inside.astype(int), [0]]))
    return list(zip(np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)))


def _spread(anchors: Sequence[float], gap: float) -> list[float]:
    """Positions at least ``gap`` apart, as close to ``anchors`` (ascending) as possible: labels that
    would overlap are stacked as a group centred on their anchors."""
    groups = [[a] for a in anchors]  # each group's labels are stacked around its anchors' mean

    def bottom(g):
        return float(np.mean(g)) - (len(g) - 1) * gap / 2

    merged = True
    while merged:
        merged = False
        for i in range(len(groups) - 1):
            if bottom(groups[i + 1]) - (bottom(groups[i]) + (len(groups[i]) - 1) * gap) < gap:
                groups[i:i + 2] = [groups[i] + groups[i + 1]]
                merged = True
                break
    return [bottom(g) + j * gap for g in groups for j in range(len(g))]


def _place_labels(fig, ax, labels: list[tuple[str, float, float]]) -> list:
    """Label each line just right of its end, stacked so that no two labels overprint, with a thin
    leader line to the end when a label had to move. ``labels``: (text, time, position) in data units.
    Needs the final layout (call after drawing, with the layout frozen): positions are worked out in
    pixels, then kept in data units so that they scale with the saved file's dpi."""
    if not labels:
        return []
    to_pixels, to_data = ax.transData.transform, ax.transData.inverted().transform
    gap_px = LABEL_FONT_PT * fig.dpi / 72.0 * 1.3
    offset_px = 8.0 * fig.dpi / 72.0
    ends = sorted(((to_pixels((t, p)), text, (t, p)) for text, t, p in labels), key=lambda e: e[0][1])
    ys = _spread([xy[1] for xy, _, _ in ends], gap_px)
    box = ax.get_window_extent()
    shift = max(0.0, box.y0 + gap_px / 2 - min(ys)) - max(0.0, max(ys) - (box.y1 - gap_px / 2))
    texts = []
    for (xy, text, end), y in zip(ends, ys):
        at = to_data((xy[0] + offset_px, y + shift))
        if abs(y + shift - xy[1]) > 1.0:  # moved: leaders under every label, so none crosses a text
            ax.plot([end[0], at[0]], [end[1], at[1]], color="0.35", linewidth=0.6, zorder=2.5)
        texts.append(ax.text(at[0], at[1], text, va="center", ha="left", fontsize=LABEL_FONT_PT, zorder=6,
                             bbox=dict(boxstyle="square,pad=0.1", facecolor="white", edgecolor="none", alpha=0.85)))
    return texts


def _collision_lane(fcd: dict, collision: dict, lane_ids: list[str]) -> str:
    """The lane in which the pair collided: the lane of the pair's first car at the collision time."""
    for vid in str(collision.get("pair", "")).split("-"):
        d = fcd.get(vid)
        if d is not None and len(d["time"]) and "lane" in d:
            i = int(np.argmin(np.abs(d["time"] - float(collision["time_s"]))))
            return str(d["lane"][i])
    return lane_ids[0]


def _mark_moments(ax, attack_start_s: float, lane_change_s: float | None) -> None:
    """The attack's start after a warm-up, and the moment the attacker began its lane change."""
    if attack_start_s > 0:
        ax.axvline(attack_start_s, color="0.3", linestyle=":", linewidth=1, label=f"attack starts at {attack_start_s:g} s")
    if lane_change_s is not None:
        ax.axvline(lane_change_s, color="0.1", linestyle="-.", linewidth=1,
                   label=f"attacker changes lane at {lane_change_s:.2f} s")


def time_space_figure(fcd: dict, title: str, collision: dict | None = None, *, speed_max_mps: float | None = None,
                      attack_start_s: float = 0.0, lane_change_s: float | None = None):
    """Position over time of every car, coloured by speed on one scale for the whole figure (0 to
    ``speed_max_mps``, default the fastest car), one panel per lane when the cars use several, the
    collision marked; returns the laid-out Figure."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.collections import LineCollection
    from matplotlib.colors import Normalize

    lane_ids = lanes(fcd)
    vmax = speed_max_mps or max((float(d["speed"].max()) for d in fcd.values() if len(d["speed"])), default=0.0) or 1.0
    norm = Normalize(0.0, vmax)
    fig = _figure(figsize=(8.0, 1.6 + 3.0 * len(lane_ids)) if len(lane_ids) > 1 else (8.0, 4.6))
    axes = fig.subplots(len(lane_ids), 1, sharex=True, sharey=True, squeeze=False)[:, 0]
    crash_lane = _collision_lane(fcd, collision, lane_ids) if collision else None
    ends: dict[int, list[tuple[str, float, float]]] = {i: [] for i in range(len(lane_ids))}
    for i, (ax, lane) in enumerate(zip(axes, lane_ids)):
        for vid, d in fcd.items():
            inside = np.asarray(d.get("lane", np.full(len(d["time"]), "")), dtype=str) == lane
            for a, b in _runs(inside):
                points = np.column_stack([d["time"][a:b], d["pos"][a:b]]).reshape(-1, 1, 2)
                if b - a >= 2:
                    lines = LineCollection(np.concatenate([points[:-1], points[1:]], axis=1), cmap=SPEED_CMAP, norm=norm,
                                           linewidths=2.4 if vid == "v0" else 1.5)
                    lines.set_array(d["speed"][a:b - 1])
                    ax.add_collection(lines)
                else:
                    ax.scatter(d["time"][a:b], d["pos"][a:b], c=d["speed"][a:b], cmap=SPEED_CMAP, norm=norm, s=4)
            last = np.flatnonzero(inside)
            if last.size:
                ends[i].append((_vehicle_label(vid), float(d["time"][last[-1]]), float(d["pos"][last[-1]])))
        _mark_moments(ax, attack_start_s, lane_change_s)
        if collision and lane == crash_lane:
            ax.plot([collision["time_s"]], [collision["position_m"]], marker="X", color="red", markeredgecolor="white",
                    markersize=10, linestyle="none", zorder=4,
                    label=f"collision {collision['pair']}: {collision['speed_diff_kmh']:.1f} km/h at {collision['time_s']:.1f} s")
        if len(lane_ids) > 1:
            ax.set_title(_lane_title(lane), fontsize=9, loc="left")
        ax.set_ylabel("position along the road [m]")
        ax.grid(alpha=0.25)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper left", fontsize=8)
    times = np.concatenate([d["time"] for d in fcd.values()])
    positions = np.concatenate([d["pos"] for d in fcd.values()])
    t0, t1 = float(times.min()), float(times.max())
    p0, p1 = float(positions.min()), float(positions.max())
    axes[0].set_xlim(t0, t1 + 0.16 * (t1 - t0 or 1.0))  # room on the right for the vehicle labels
    axes[0].set_ylim(p0 - 0.04 * (p1 - p0 or 1.0), p1 + 0.06 * (p1 - p0 or 1.0))
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(wrap_title(title), fontsize=9)
    fig.colorbar(ScalarMappable(norm, SPEED_CMAP), ax=list(axes), label="speed [m/s]", shrink=0.9 if len(axes) > 1 else 1.0)
    fig.canvas.draw()  # lay out, then freeze it so the labels placed in pixels stay put
    fig.set_layout_engine("none")
    for i, ax in enumerate(axes):
        _place_labels(fig, ax, ends[i])
    return fig


def time_space(fcd: dict, title: str, path: str | Path, collision: dict | None = None, *,
               speed_max_mps: float | None = None, attack_start_s: float = 0.0, lane_change_s: float | None = None) -> Path:
    """Position over time of every car, coloured by speed, the collision marked (see time_space_figure)."""
    check_figure_path(path)
    return _save(time_space_figure(fcd, title, collision, speed_max_mps=speed_max_mps, attack_start_s=attack_start_s,
                                   lane_change_s=lane_change_s), path)


def accelerations_figure(fcd: dict, title: str, collision: dict | None = None, *, attack_start_s: float = 0.0,
                         lane_change_s: float | None = None):
    """Every car's acceleration over time."""
    fig = _figure(figsize=(8.0, 3.8))
    ax = fig.subplots()
    for vid, d in fcd.items():
        ax.plot(d["time"], d["acceleration"], label=_vehicle_label(vid), linewidth=1.9 if vid == "v0" else 1.1,
                color="black" if vid == "v0" else None, zorder=3 if vid == "v0" else 2)
    _mark_moments(ax, attack_start_s, lane_change_s)
    if collision:
        ax.axvline(collision["time_s"], color="red", linestyle="--", linewidth=1, label=f"collision {collision['pair']}")
    ax.set_xlabel("time [s]")
    ax.set_ylabel("acceleration [m/s²]")
    ax.set_title(wrap_title(title), fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    return fig


def accelerations(fcd: dict, title: str, path: str | Path, collision: dict | None = None, *, attack_start_s: float = 0.0,
                  lane_change_s: float | None = None) -> Path:
    check_figure_path(path)
    return _save(accelerations_figure(fcd, title, collision, attack_start_s=attack_start_s, lane_change_s=lane_change_s), path)


# --- heatmaps ---------------------------------------------------------------------------------------


def _luminance(colour) -> float:
    """WCAG relative luminance of a colour (any matplotlib colour)."""
    from matplotlib.colors import to_rgb

    linear = [c / 12.92 if c <= 0.04045 else ((c + 0.055) / 1.055) ** 2.4 for c in to_rgb(colour)]
    return 0.2126 * linear[0] + 0.7152 * linear[1] + 0.0722 * linear[2]


def contrast_ratio(a, b) -> float:
    """WCAG contrast ratio of two colours (1 to 21; 4.5 reads well for small text)."""
    la, lb = sorted((_luminance(a), _luminance(b)), reverse=True)
    return (la + 0.05) / (lb + 0.05)


def text_colour(background) -> str:
    """Black or white, whichever reads better on ``background``."""
    return "black" if contrast_ratio(background, (0, 0, 0)) >= contrast_ratio(background, (1, 1, 1)) else "white"


def heatmap_panels(records: Sequence[Record]) -> list[tuple[str | tuple[str, str], list[Record]]]:
    """One panel per attack, optimiser and start mode: the groups a reader compares. With several
    systems under test a panel's name is (system, "attack, OPTIMISER, start ..."): a row per system."""
    fields, groups = runs(records, "attack", "optimizer", "start")
    system = fields[0] == "system"
    return [((key[0], f"{key[-3]}, {key[-2].upper()}, start {key[-1]}") if system
             else f"{key[-3]}, {key[-2].upper()}, start {key[-1]}", rs) for key, rs in groups.items()]


def heatmap_columns(records: Sequence[Record]) -> int:
    """One column per start mode when every attack and optimiser ran them all (rows then compare
    optimisers, columns start modes), else up to four panels a row."""
    starts = {r.start for r in records}
    by_run = runs(records, "attack", "optimizer")[1]
    if 1 < len(starts) <= 4 and all({r.start for r in rs} == starts for rs in by_run.values()):
        return len(starts)
    return 4


#: a title's characters per inch of panel at 9 pt (DejaVu Sans averages about 0.55 em a character)
TITLE_CHARS_PER_IN = 72.0 / (0.55 * 9)


def _layout(panels: Sequence[tuple], columns: int) -> tuple[list[tuple[int, int]], list[str], list[str]]:
    """Where each panel goes (row, column), each row's label and each column's title: a grid of
    systems (rows) x runs (columns) when names are (system, run) pairs, else the panels in reading
    order, ``columns`` a row, each titled by its name."""
    names = [name for name, _ in panels]
    if names and all(isinstance(name, tuple) for name in names):
        rows = list(dict.fromkeys(name[0] for name in names))
        cols = list(dict.fromkeys(name[1] for name in names))
        return [(rows.index(r), cols.index(c)) for r, c in names], rows, cols
    return [(i // columns, i % columns) for i in range(len(names))], [], [str(name) for name in names]


def heatmaps_figure(panels: Sequence[tuple[str | tuple[str, str], Sequence[Record]]], title: str, *, columns: int = 4):
    """Successes over setpoint x target speed, one panel per (name, records), all on the same axes
    and one colour range (0 to the most of any panel) so that panels compare like with like; cells
    with no samples are left grey. When every cell ran the same number of samples the colour is the
    count of successes, as in the paper; else it is their share of the cell's samples. Names that are
    (system, run) pairs lay the panels out as a grid: a row per system, labelled once at its left, a
    column per run, titled once at the top; titles wrap to their panel's width."""
    import textwrap

    from matplotlib import colormaps
    from matplotlib.cm import ScalarMappable
    from matplotlib.colors import Normalize
    from matplotlib.ticker import MaxNLocator

    every = [r for _, rs in panels for r in rs]
    setpoints = sorted({r.setpoint_m for r in every})
    speeds = sorted({r.speed_mps for r in every})
    grids = []
    for _, rs in panels:
        _, _, wins = success_grid(rs, setpoints, speeds)
        samples = np.zeros_like(wins)
        for r in rs:
            samples[setpoints.index(r.setpoint_m), speeds.index(r.speed_mps)] += 1
        grids.append((wins, samples))
    budgets = {int(n) for _, samples in grids for n in samples.ravel() if n}
    same_budget = len(budgets) == 1
    if same_budget:  # counts compare like with like
        values = [wins.astype(float) for wins, _ in grids]
        norm = Normalize(0, max(1, max(int(w.max()) for w, _ in grids)))
        note, label = f"{count_noun(budgets.pop(), 'sample')} per cell", "successful attacks"
    else:  # counts of different budgets do not: colour the share
        values = [100.0 * np.divide(wins, samples, out=np.zeros(wins.shape), where=samples > 0) for wins, samples in grids]
        norm = Normalize(0, max(1.0, max(float(v.max()) for v in values)))
        note, label = "cells: successes/samples; cells ran different numbers of samples", "successful attacks [% of samples]"
    cmap = colormaps[SUCCESS_CMAP].with_extremes(bad="0.88")
    places, row_labels, column_titles = _layout(panels, max(1, min(columns, len(panels))))
    rows, columns = max(r for r, _ in places) + 1, max(c for _, c in places) + 1
    cell_w, cell_h = (0.75, 0.36) if same_budget else (1.05, 0.36)
    panel_w = max(1.9, 0.9 + cell_w * len(speeds))  # room for a title of two short lines
    width = int(panel_w * TITLE_CHARS_PER_IN)
    titles = [textwrap.fill(t, width, break_long_words=False) for t in column_titles]
    labels = [textwrap.fill(t, 24, break_long_words=False) for t in row_labels]
    title_h = 0.16 * max((t.count("\n") + 1 for t in titles), default=1)
    label_w = 1.6 if labels else 0.0
    panel_h = 0.55 + cell_h * len(setpoints) + (0.0 if labels else title_h)
    fig = _figure(figsize=(max(5.0, 1.4 + label_w + columns * panel_w), max(2.8, 0.9 + title_h + rows * panel_h)))
    axes = fig.subplots(rows, columns, sharex=True, sharey=True, squeeze=False)
    fontsize = 9 if same_budget else 8
    used = set(places)
    for (row, col), (wins, samples), value, index in zip(places, grids, values, range(len(places))):
        ax = axes[row, col]
        ax.imshow(np.ma.masked_where(samples == 0, value), cmap=cmap, norm=norm, aspect="auto", origin="lower")
        for i in range(len(setpoints)):
            for j in range(len(speeds)):
                if samples[i, j]:
                    text = str(wins[i, j]) if same_budget else f"{wins[i, j]}/{samples[i, j]}"
                    ax.text(j, i, text, ha="center", va="center", fontsize=fontsize, color=text_colour(cmap(norm(value[i, j]))))
        if not labels:
            ax.set_title(titles[index], fontsize=9)
        ax.set_xticks(range(len(speeds)), [f"{v:g}" for v in speeds])
        ax.set_yticks(range(len(setpoints)), [f"{d:g}" for d in setpoints])
    if labels:  # a grid: each run's title once, over its column; each system's name once, left of its row
        for col, t in enumerate(titles):
            axes[0, col].set_title(t, fontsize=9)
        for row, t in enumerate(labels):  # read across, beside the row's setpoints
            axes[row, 0].set_ylabel(t, fontsize=8, rotation=0, ha="right", va="center", labelpad=6)
        fig.supylabel("setpoint [m]", fontsize=10)
    else:
        for ax in axes[:, 0]:
            ax.set_ylabel("setpoint [m]")
    for row in range(rows):
        for col in range(columns):
            ax = axes[row, col]
            if (row, col) not in used:
                ax.set_visible(False)
            elif not any((r, col) in used for r in range(row + 1, rows)):  # the lowest panel of its column
                ax.xaxis.set_tick_params(labelbottom=True)
                ax.set_xlabel("target speed [m/s]")
    bar = fig.colorbar(ScalarMappable(norm, cmap), ax=axes.ravel().tolist(), label=label, shrink=min(1.0, 6.0 / rows + 0.2))
    if same_budget:
        bar.locator = MaxNLocator(integer=True)  # counts
        bar.update_ticks()
    fig.suptitle(textwrap.fill(f"{title} ({note})", int(fig.get_figwidth() * 72 / (0.55 * 10))), fontsize=10)
    return fig


def heatmaps(panels: Sequence[tuple[str, Sequence[Record]]], title: str, path: str | Path, *, columns: int = 4) -> Path:
    check_figure_path(path)
    return _save(heatmaps_figure(panels, title, columns=columns), path)


def heatmap(records: Sequence[Record], title: str, path: str | Path) -> Path:
    """Successes over setpoint x target speed, one panel per attack, optimiser and start mode."""
    return heatmaps(heatmap_panels(records), title, path, columns=heatmap_columns(records))


# --- clusters ---------------------------------------------------------------------------------------


def clusters_figure(c: Clustering, *, columns: int = 4):
    """Each k-means cluster's mean and standard deviation over knot time (each knot over the attacks
    whose collision came late enough for it to matter; greyed where fewer than FEW_ATTACKS), the
    cluster's own collision times, and the elbow curve that chose k."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch

    stats = c.cluster_stats()
    panels = len(stats) + 1
    columns = min(columns, panels)
    rows = math.ceil(panels / columns)
    fig = _figure(figsize=(3.5 * columns, 0.9 + 3.1 * rows))
    axes = fig.subplots(rows, columns, squeeze=False).ravel()
    t = c.knot_times_s
    for i, (ax, s) in enumerate(zip(axes, stats), start=1):
        enough = s.counts >= FEW_ATTACKS
        q1, q3 = s.collision_quartiles_s
        ax.axvspan(q1, q3, color="red", alpha=0.08, linewidth=0)
        ax.axvline(s.median_collision_s, color="red", linestyle="--", linewidth=1)
        band = np.where(s.counts >= 2, s.std, np.nan)  # one attack has no spread to show
        ax.fill_between(t, s.mean - band, s.mean + band, alpha=0.25, color="C0", linewidth=0)
        ax.plot(t, s.mean, color="C0", linewidth=1.2)
        ax.plot(t[enough], s.mean[enough], "o", color="C0", markersize=5)
        ax.plot(t[~enough], s.mean[~enough], "o", markerfacecolor="white", markeredgecolor="0.6", markersize=5)
        ax.axhline(0, color="grey", linewidth=0.5)
        ax.set_ylim(-1.15, 1.15)
        ax.set_xlabel("knot time from attack start [s]")
        ax.set_ylabel("command u (−1 brake, +1 throttle)", fontsize=8)
        ax.set_xticks(t, [f"{v:g}" for v in t], fontsize=7)
        top = ax.secondary_xaxis("top")
        top.set_xticks(t, [str(n) for n in s.counts], fontsize=7)
        top.set_xlabel("attacks behind each knot", fontsize=7)
        ax.set_title(f"cluster {i}: {count_noun(s.size, 'attack')}; collision at {s.median_collision_s:.1f} s "
                     f"(median)", fontsize=8.5)
    ax = axes[len(stats)]
    ax.plot(range(1, len(c.inertias) + 1), c.inertias, marker="o")
    ax.axvline(c.k, color="red", linestyle="--", linewidth=1, label=f"elbow: k = {c.k}")
    ax.set_xlabel("clusters k")
    ax.set_ylabel("k-means inertia (relevant knots)", fontsize=8)
    ax.set_title(f"elbow rule; DBSCAN: {count_noun(c.dbscan_clusters, 'cluster')}, "
                 f"{count_noun(c.dbscan_noise, 'noise point')}", fontsize=8.5)
    ax.legend(fontsize=8)
    for ax in axes[panels:]:
        ax.set_visible(False)
    handles = [
        Line2D([], [], color="C0", marker="o", label="cluster mean"),
        Patch(color="C0", alpha=0.25, label="mean ± std"),
        Line2D([], [], linestyle="none", marker="o", markerfacecolor="white", markeredgecolor="0.6",
               label=f"knot mean over fewer than {count_noun(FEW_ATTACKS, 'attack')}"),
        Line2D([], [], color="red", linestyle="--", label="cluster's median collision time"),
        Patch(color="red", alpha=0.08, label="its middle half (quartiles)"),
    ]
    fig.legend(handles=handles, loc="outside lower center", ncols=len(handles), fontsize=8, frameon=False)
    fig.suptitle(f"Successful knot vectors ({count_noun(len(c.vectors), 'success', 'successes')}): {c.condition}; "
                 f"knots after the collision left out", fontsize=9)
    return fig


def clusters(c: Clustering, path: str | Path) -> Path:
    check_figure_path(path)
    return _save(clusters_figure(c), path)
