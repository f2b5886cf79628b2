"""Figures of the paper's analysis, drawn with matplotlib (headless) into image files: heatmaps of
successes and clusters of knot attacks here, one episode's time-space diagram in `timespace`.

Each figure has a ``*_figure`` function that returns the drawn matplotlib Figure (laid out, ready to
inspect) and a function of the plain name that writes it to a file.
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Sequence

import numpy as np

from ..errors import ConfigError
from .analysis import count_noun, run_label, runs, success_grid
from .clusters import FEW_ATTACKS, Clustering
from .failure_map import FailureMap
from .records import Record

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
    if path.is_dir():
        raise ConfigError(option, str(path), "a file name (this is a folder)")
    if not path.parent.is_dir():
        raise ConfigError(option, str(path), f"a file in an existing folder ({path.parent} does not exist)")
    formats = FigureCanvasBase.get_supported_filetypes()
    if path.suffix.lower().lstrip(".") not in formats:
        raise ConfigError(option, str(path), "an image file: " + ", ".join(f".{f}" for f in sorted(formats)))
    return path


def _save(fig, path: str | Path) -> Path:
    path = check_figure_path(path)
    fig.savefig(path, dpi=110)
    return path


# --- FCD: time-space diagrams and accelerations --------------------------------------------------


def wrap_title(title: str, width: int = 100) -> str:
    """A long title on as many lines as it needs: a system's name and parameters can make one long."""
    import textwrap

    return "\n".join(textwrap.wrap(title, width)) or title


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
    systems under test a panel's name is (system, "attack, OPTIMISER, start ..."): a row per system
    (per scenario and system, with several scenarios); with several scenarios and one system, the
    scenario leads the panel's title."""
    fields, groups = runs(records, "attack", "optimizer", "start")
    lead = len(fields) - 3
    panels = []
    for key, rs in groups.items():
        run = f"{key[-3]}, {key[-2].upper()}, start {key[-1]}"
        label = run_label(key[:lead])
        if "system" in fields:
            panels.append(((label, run), rs))
        else:
            panels.append((f"{label}: {run}" if label else run, rs))
    return panels


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
    from matplotlib.ticker import MaxNLocator

    setpoints, speeds, grids, values, norm, same_budget, note, label = _success_values(panels)
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


def _success_values(panels):
    """Each panel's successes and samples per (setpoint, target speed) cell over the axes every panel shares, the
    values its colours show (counts where every cell ran alike, else shares) on one colour range, and what they are."""
    from matplotlib.colors import Normalize

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
    return setpoints, speeds, grids, values, norm, same_budget, note, label


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


# --- where the system fails, over the searched situation ---------------------------------------------


def failure_map_figure(maps: Sequence[tuple[str, FailureMap]], title: str):
    """For each panel's samples (`failure_map.failure_maps`: a system and start), the estimated success rate over the
    searched situation, the boundary where it crosses one half, and the samples (a cross: a success); beside it, the
    estimate's standard deviation. Blank: too far from any sample."""
    fig = _figure(figsize=(11.0, 0.6 + 3.8 * len(maps)))
    axes = fig.subplots(len(maps), 2, squeeze=False)
    for (label, m), (left, right) in zip(maps, axes):
        _draw_map(fig, left, right, m, label)
    fig.suptitle(wrap_title(f"{title}: the success rate estimated from the samples (crosses: successes; the line: where "
                            "it crosses one half)"), fontsize=10)
    return fig


def _draw_map(fig, left, right, m: FailureMap, label: str) -> None:
    wins, other = m.points[m.successes], m.points[~m.successes]
    left.set_title(f"{label}: {count_noun(len(m.points), 'sample')}", fontsize=9)
    if len(m.keys) == 1:
        x = m.axes[0]
        left.fill_between(x, np.clip(m.rate - 2 * m.std, 0, 1), np.clip(m.rate + 2 * m.std, 0, 1), alpha=0.25,
                          label="two standard deviations")
        left.plot(x, m.rate, label="success rate")
        left.axhline(0.5, color="grey", linestyle="--", linewidth=1)
        left.plot(wins[:, 0], np.ones(len(wins)), "x", color="red", label="a success")
        left.plot(other[:, 0], np.zeros(len(other)), "o", mfc="none", color="black", markersize=4, label="no success")
        left.set(xlabel=m.label(0), ylabel="success rate", ylim=(-0.05, 1.05))
        left.legend(fontsize=LABEL_FONT_PT)
        right.plot(x, m.std)
        right.set(xlabel=m.label(0), ylabel="standard deviation of the rate")
        return
    x, y = m.axes
    for ax, values, name, cmap in ((left, m.rate, "success rate", SUCCESS_CMAP), (right, m.std, "its standard deviation", "magma")):
        mesh = ax.pcolormesh(x, y, values.T, shading="auto", cmap=cmap, vmin=0.0, vmax=1.0 if ax is left else None)
        fig.colorbar(mesh, ax=ax, label=name)
        if np.nanmin(m.rate) < 0.5 < np.nanmax(m.rate):
            ax.contour(x, y, m.rate.T, levels=[0.5], colors="white", linewidths=1.5)
        ax.plot(wins[:, 0], wins[:, 1], "x", color="red", markersize=4)
        ax.plot(other[:, 0], other[:, 1], "o", mfc="none", color="white", markersize=3, alpha=0.7)
        ax.set(xlabel=m.label(0), ylabel=m.label(1))


def failure_map(maps: Sequence[tuple[str, FailureMap]], title: str, path: str | Path) -> Path:
    check_figure_path(path)
    return _save(failure_map_figure(maps, title), path)
