"""Figures of one episode from SUMO's FCD: the time-space diagram (every car's position along the route over
time, coloured by speed, a panel per lane; SUMO's traffic around the platoon in light grey; under a
message attack, what the lying car's beacons said, dashed) and every platoon car's acceleration; and the
FCD read as positions along the route."""

from __future__ import annotations

from pathlib import Path
from typing import Mapping, Sequence

import numpy as np

from ..model.world.traffic import is_traffic
from .figures import LABEL_FONT_PT, SPEED_CMAP, _figure, _save, check_figure_path, wrap_title

#: traffic cars: lighter than the platoon, whose speeds the colours tell
TRAFFIC_COLOR = "0.75"
#: under a message attack, what the liar's beacons said (``vK said``), drawn dashed beside where it was
SAID = " said"


class Tracks(dict):
    """An FCD read as {vehicle id: track} (`read_fcd`), with what else its figures draw: ``signals``, each traffic light's
    stop line along the route [m], its id, and its state at each step (`Episode.signals`)."""

    signals: tuple[tuple[float, str, str], ...] = ()


#: a signal's state letters (SUMO's) as the colour a time-space diagram draws its stop line in
SIGNAL_COLORS = {**dict.fromkeys("rRu", "#d62728"), **dict.fromkeys("yY", "#ffbf00"), **dict.fromkeys("GgsoO", "#2ca02c")}


def _draw_signals(ax, signals, start_s: float, step_s: float) -> None:
    """Each signal's stop line at its place along the route, in the colour of its state over time: a red light
    the platoon stopped before shows as the cars' lines flat below a red band."""
    from matplotlib.collections import LineCollection

    first = True
    for line_m, tls, states in signals:
        segments, colors = [], []
        start = 0
        for k in range(1, len(states) + 1):
            if k == len(states) or states[k] != states[start]:
                segments.append([(start_s + start * step_s, line_m), (start_s + k * step_s, line_m)])
                colors.append(SIGNAL_COLORS.get(states[start], "0.5"))
                start = k
        ax.add_collection(LineCollection(segments, colors=colors, linewidths=3.5, zorder=1.2, capstyle="butt",
                                         label="traffic light at its stop line" if first else None))
        first = False


def said_track(trace, fcd: Mapping[str, Mapping[str, np.ndarray]]) -> tuple[str, dict[str, np.ndarray]] | None:
    """What the liar's beacons said at each sample (the trace's ``sent_*_vK``, from its first beacon on), as
    an FCD track beside the liar's own (its lanes), with its id (``vK said``); None without a message attack."""
    sent = next((name for name in trace.signals if name.startswith("sent_pos_v")), None)
    liar = sent and sent[len("sent_pos_"):]
    if sent is None or liar not in fcd:
        return None
    own = fcd[liar]
    n = min(len(trace), len(own["time"]))
    said = ~np.isnan(trace[sent][:n])
    return liar + SAID, {"time": own["time"][:n][said], "pos": trace[sent][:n][said],
                         "speed": trace[f"sent_speed_{liar}"][:n][said], "acceleration": trace[f"sent_accel_{liar}"][:n][said],
                         "lane": own["lane"][:n][said]}


def read_fcd(path: str | Path, platoon_lanes: Mapping[str, int] | None = None) -> dict[str, dict[str, np.ndarray]]:
    """SUMO FCD as {vehicle id: {time, pos, speed, acceleration, lane}}; ``pos`` is the position along
    the route, ``lane`` the lane the car drives in. ``platoon_lanes``: the platoon's lane on each edge
    where its index changes along the route (`Road.platoon_lanes`); lanes are then counted from it.

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
    platoon = [vid for vid in rows if not is_traffic(vid)]
    edges = {lane.rpartition("_")[0] for vid in platoon for *_, lane, _ in rows[vid] if lane and not lane.startswith(":")}
    many_edges = len(edges) > 1
    # With traffic SUMO's clock ran through the traffic's warm-up first: the episode's starts with the platoon
    t0 = min((rows[vid][0][0] for vid in platoon), default=0.0) if len(platoon) < len(rows) else 0.0
    offsets: dict[str, float] = {}  # each edge's start along the route, as the platoon drove it
    out = Tracks()
    for vid in sorted(rows, key=_vehicle_order):
        time, pos, speed, accel, lane, odometer = zip(*rows[vid])
        pos = np.array(pos)
        if many_edges and not is_traffic(vid):
            odometer = np.array(odometer)
            along = pos[0] - odometer[0] + odometer  # every car of the platoon starts on the route's first edge
            for edge_lane, p, a in zip(lane, pos, along):
                offsets.setdefault(edge_lane.rpartition("_")[0], a - p)
            pos = along
        elif many_edges:  # a traffic car: along the route where it drives an edge of it, else not drawn
            pos = np.array([offsets.get(ln.rpartition("_")[0], np.nan) + p for ln, p in zip(lane, pos)])
        if many_edges:
            lane = _lane_indices(lane, platoon_lanes or {})
        out[vid] = {"time": np.array(time) - t0, "pos": pos, "speed": np.array(speed),
                    "acceleration": np.array(accel), "lane": np.array(lane, dtype=str)}
    return out


def _lane_indices(lane_ids: Sequence[str], platoon_lanes: Mapping[str, int]) -> list[str]:
    """Lane ids as their index across the road, counted from the platoon's lane on each edge (an on-ramp
    shifts the indices, not the lane the platoon drives); a junction's internal lane as the lane before it."""
    out, last = [], ""
    for lane in lane_ids:
        if not lane.startswith(":"):
            edge, _, index = lane.rpartition("_")
            last = str(int(index) - platoon_lanes.get(edge, 0)) if index.isdigit() else index
        out.append(last)
    return out


def _vehicle_order(vid: str):
    """The platoon front to back (traffic cars last: they are drawn first, under it)."""
    return (0, int(vid[1:]), "") if vid[1:].isdigit() else (2, 0, vid) if is_traffic(vid) else (1, 0, vid)


def _vehicle_label(vid: str) -> str:
    return vid + " attacker" if vid == "v0" else "what " + vid if vid.endswith(SAID) else vid


def lanes(fcd: dict) -> list[str]:
    """The lanes the platoon's cars use, leftmost first (SUMO counts lanes from the right: lane 0 is the
    rightmost), so that stacked panels look like the road seen from above."""
    used = {str(lane) for vid, d in fcd.items() if not is_traffic(vid) for lane in d.get("lane", [""])}

    def key(lane: str):
        edge, _, index = lane.rpartition("_")
        return (edge, -int(index)) if index.isdigit() else (lane, 0)

    return sorted(used, key=key)


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
    pixels, then kept in data units so that they scale with the saved file's dpi. A line that ends with
    the episode is labelled right of the axes, in the room `_reserve_label_room` kept there."""
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
            ax.plot([end[0], at[0]], [end[1], at[1]], color="0.35", linewidth=0.6, zorder=2.5, clip_on=False)
        texts.append(ax.text(at[0], at[1], text, va="center", ha="left", fontsize=LABEL_FONT_PT, zorder=6,
                             bbox=dict(boxstyle="square,pad=0.1", facecolor="white", edgecolor="none", alpha=0.85)))
    return texts


def _reserve_label_room(fig, ax, labels: list[tuple[str, float, float]]) -> list:
    """Invisible copies of the widest label just right of the axes, so that the layout keeps room there
    for the labels of the lines that end with the episode; remove them once the layout is frozen."""
    from matplotlib.transforms import offset_copy

    if not labels:
        return []
    widest = max((text for text, _, _ in labels), key=len)
    at = offset_copy(ax.transAxes, fig=fig, x=8.0, units="points")
    return [ax.text(1.0, y, widest, transform=at, fontsize=LABEL_FONT_PT, alpha=0.0) for y in (0.0, 1.0)]


def _collision_lane(fcd: dict, collision: dict, lane_ids: list[str]) -> str:
    """The lane in which the pair collided: the lane of the pair's first car at the collision time."""
    for vid in str(collision.get("pair", "")).split("-"):
        d = fcd.get(vid)
        if d is not None and len(d["time"]) and "lane" in d:
            i = int(np.argmin(np.abs(d["time"] - float(collision["time_s"]))))
            return str(d["lane"][i])
    return lane_ids[0]


def _mark_moments(ax, attack_start_s: float, lane_change_s: float | Sequence[float] | None) -> None:
    """The attack's start after a warm-up, and the moments the attacker began its lane changes (one, or a
    swerving attacker's several)."""
    if attack_start_s > 0:
        ax.axvline(attack_start_s, color="0.3", linestyle=":", linewidth=1, label=f"attack starts at {attack_start_s:g} s")
    times = [] if lane_change_s is None else [lane_change_s] if isinstance(lane_change_s, (int, float)) else list(lane_change_s)
    for i, t in enumerate(times):
        label = (f"attacker changes lane at {', '.join(f'{x:.2f}' for x in times)} s" if i == 0 else None)
        ax.axvline(t, color="0.1", linestyle="-.", linewidth=1, label=label)


def time_space_figure(fcd: dict, title: str, collision: dict | None = None, *, speed_max_mps: float | None = None,
                      attack_start_s: float = 0.0, lane_change_s: float | None = None):
    """Position over time of every car, coloured by speed on one scale for the whole figure (0 to
    ``speed_max_mps``, default the fastest car), one panel per lane when the cars use several, the
    collision marked; returns the laid-out Figure."""
    from matplotlib.cm import ScalarMappable
    from matplotlib.collections import LineCollection
    from matplotlib.colors import Normalize

    lane_ids = lanes(fcd)
    signals = getattr(fcd, "signals", ())
    if signals:  # the platoon's own steps: the FCD's, as read (its clock starts with the platoon)
        platoon_times = next(d["time"] for vid, d in fcd.items() if not is_traffic(vid))
        step_s = float(platoon_times[1] - platoon_times[0]) if len(platoon_times) > 1 else 1.0
        start_s = float(platoon_times[0])
    vmax = speed_max_mps or max((float(d["speed"].max()) for d in fcd.values() if len(d["speed"])), default=0.0) or 1.0
    # the scale starts at 0, or lower where a liar said it drove backwards (else its lie would be clipped)
    vmin = min((float(d["speed"].min()) for vid, d in fcd.items() if vid.endswith(SAID) and len(d["speed"])), default=0.0)
    norm = Normalize(min(0.0, vmin), vmax)
    fig = _figure(figsize=(8.0, 1.6 + 3.0 * len(lane_ids)) if len(lane_ids) > 1 else (8.0, 4.6))
    axes = fig.subplots(len(lane_ids), 1, sharex=True, sharey=True, squeeze=False)[:, 0]
    crash_lane = _collision_lane(fcd, collision, lane_ids) if collision else None
    ends: dict[int, list[tuple[str, float, float]]] = {i: [] for i in range(len(lane_ids))}
    traffic_drawn = [False] * len(lane_ids)
    for i, (ax, lane) in enumerate(zip(axes, lane_ids)):
        for vid, d in fcd.items():
            inside = np.asarray(d.get("lane", np.full(len(d["time"]), "")), dtype=str) == lane
            if is_traffic(vid):  # lighter, under the platoon, unlabelled
                for a, b in _runs(inside):
                    ax.plot(d["time"][a:b], d["pos"][a:b], color=TRAFFIC_COLOR, linewidth=0.9, zorder=1.5,
                            label="traffic" if not traffic_drawn[i] else None)
                    traffic_drawn[i] = True
                continue
            for a, b in _runs(inside):
                points = np.column_stack([d["time"][a:b], d["pos"][a:b]]).reshape(-1, 1, 2)
                if b - a >= 2:
                    lines = LineCollection(np.concatenate([points[:-1], points[1:]], axis=1), cmap=SPEED_CMAP, norm=norm,
                                           linewidths=2.4 if vid == "v0" else 1.5,
                                           linestyles="dashed" if vid.endswith(SAID) else "solid")
                    lines.set_array(d["speed"][a:b - 1])
                    ax.add_collection(lines)
                else:
                    ax.scatter(d["time"][a:b], d["pos"][a:b], c=d["speed"][a:b], cmap=SPEED_CMAP, norm=norm, s=4)
            last = np.flatnonzero(inside)
            if last.size:
                ends[i].append((_vehicle_label(vid), float(d["time"][last[-1]]), float(d["pos"][last[-1]])))
        if signals:
            _draw_signals(ax, signals, start_s, step_s)
        _mark_moments(ax, attack_start_s, lane_change_s)
        if collision and lane == crash_lane:
            ax.plot([collision["time_s"]], [collision["position_m"]], marker="X", color="red", markeredgecolor="white",
                    markersize=10, linestyle="none", zorder=4, clip_on=False,
                    label=f"collision {collision['pair']}: {collision['speed_diff_kmh']:.1f} km/h at {collision['time_s']:.1f} s")
        if len(lane_ids) > 1:
            ax.set_title(_lane_title(lane), fontsize=9, loc="left")
        ax.set_ylabel("position along the road [m]")
        ax.grid(alpha=0.25)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(loc="upper left", fontsize=8)
    platoon = [d for vid, d in fcd.items() if not is_traffic(vid)] or list(fcd.values())  # the axes hold the platoon
    times = np.concatenate([d["time"] for d in platoon])
    positions = np.concatenate([d["pos"] for d in platoon])
    t0, t1 = float(times.min()), float(times.max())
    p0, p1 = float(np.nanmin(positions)), float(np.nanmax(positions))
    axes[0].set_xlim(t0, _episode_end_s(t1, collision))  # the axis ends with the episode; the labels go beyond it
    axes[0].set_ylim(p0 - 0.04 * (p1 - p0 or 1.0), p1 + 0.06 * (p1 - p0 or 1.0))
    axes[-1].set_xlabel("time [s]")
    fig.suptitle(wrap_title(title), fontsize=9)
    fig.colorbar(ScalarMappable(norm, SPEED_CMAP), ax=list(axes), label="speed [m/s]", shrink=0.9 if len(axes) > 1 else 1.0)
    room = [t for i, ax in enumerate(axes) for t in _reserve_label_room(fig, ax, ends[i])]
    fig.canvas.draw()  # lay out, then freeze it so the labels placed in pixels stay put
    fig.set_layout_engine("none")
    for t in room:
        t.remove()
    for i, ax in enumerate(axes):
        _place_labels(fig, ax, ends[i])
    return fig


def _episode_end_s(last_s: float, collision: dict | None) -> float:
    """When the episode ended: its last recorded step (the collision's, when one ended it)."""
    return max(last_s, float(collision["time_s"])) if collision else last_s


def time_space(fcd: dict, title: str, path: str | Path, collision: dict | None = None, *,
               speed_max_mps: float | None = None, attack_start_s: float = 0.0, lane_change_s: float | None = None) -> Path:
    """Position over time of every car, coloured by speed, the collision marked (see time_space_figure)."""
    check_figure_path(path)
    return _save(time_space_figure(fcd, title, collision, speed_max_mps=speed_max_mps, attack_start_s=attack_start_s,
                                   lane_change_s=lane_change_s), path)


def accelerations_figure(fcd: dict, title: str, collision: dict | None = None, *, attack_start_s: float = 0.0,
                         lane_change_s: float | None = None):
    """Every car's acceleration over time; under a message attack also every car's speed above it, what the
    liar said dashed in its colour beside what it did (a lie about its speed shows only there)."""
    fcd = {vid: d for vid, d in fcd.items() if not is_traffic(vid)}  # the platoon's
    lying = any(vid.endswith(SAID) for vid in fcd)
    fields = (("speed", "speed [m/s]"), ("acceleration", "acceleration [m/s²]")) if lying else (("acceleration", "acceleration [m/s²]"),)
    fig = _figure(figsize=(8.0, 6.4 if lying else 3.8))
    axes = fig.subplots(len(fields), 1, sharex=True, squeeze=False)[:, 0]
    cycle = iter(plt_colors())
    colors = {vid: "black" if vid == "v0" else next(cycle) for vid in fcd if not vid.endswith(SAID)}
    for ax, (field, label) in zip(axes, fields):
        for vid, d in fcd.items():
            said = vid.endswith(SAID)
            ax.plot(d["time"], d[field], label=_vehicle_label(vid), linewidth=1.9 if vid == "v0" or said else 1.1,
                    color=colors.get(vid[:-len(SAID)] if said else vid), zorder=3 if vid == "v0" else 2,
                    linestyle="--" if said else "-")
        _mark_moments(ax, attack_start_s, lane_change_s)
        if collision:
            ax.axvline(collision["time_s"], color="red", linestyle="--", linewidth=1, label=f"collision {collision['pair']}")
        ax.set_ylabel(label)
        ax.grid(alpha=0.3)
    times = np.concatenate([d["time"] for d in fcd.values()])
    axes[0].set_xlim(float(times.min()), _episode_end_s(float(times.max()), collision))  # the axis ends with the episode
    axes[-1].set_xlabel("time [s]")
    axes[0].set_title(wrap_title(title), fontsize=9)
    axes[0].legend(fontsize=8, loc="upper left", bbox_to_anchor=(1.01, 1.0), borderaxespad=0)
    return fig


def plt_colors() -> list[str]:
    """Matplotlib's colour cycle, as many times over as a long platoon needs."""
    import matplotlib

    return matplotlib.rcParams["axes.prop_cycle"].by_key()["color"] * 4


def accelerations(fcd: dict, title: str, path: str | Path, collision: dict | None = None, *, attack_start_s: float = 0.0,
                  lane_change_s: float | None = None) -> Path:
    check_figure_path(path)
    return _save(accelerations_figure(fcd, title, collision, attack_start_s=attack_start_s, lane_change_s=lane_change_s), path)
