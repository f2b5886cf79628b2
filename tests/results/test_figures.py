"""The figures: what a reader of them must be able to rely on (shared colour scales, labels that do
not overprint, lanes, per-cluster statistics, wording), and that ``d4sumo plot`` writes only the figure."""

from __future__ import annotations

import dataclasses
import itertools
import os
import re
import tempfile

import numpy as np
import pytest

from d4sumo.errors import ConfigError
from d4sumo.results import figures, timespace
from d4sumo.results.analysis import most_severe
from d4sumo.results.clusters import cluster_knots, richest_conditions
from d4sumo.results.records import Record, load_records

PNG = b"\x89PNG\r\n\x1a\n"
PLURAL_AFTER_ONE = re.compile(r"\b1 (attacks|clusters|noise points|successes|samples|panels)\b")


def is_image(path):
    data = path.read_bytes()
    return data.startswith(PNG) and len(data) > 10_000


def _record(i, **changes):
    r = Record("db", i, 0, "n", 3, 7.0, 25.0, "rest", "knots", "bo", 0, 6.0, (0.0,) * 9, 0.1, "success",
               "v1-v2", 20.0, 100.0, 10.0)
    return dataclasses.replace(r, **changes)


# --- time-space diagrams ------------------------------------------------------------------------------


def _platoon_fcd(lane_change: bool) -> dict:
    """Four cars closing up (their lines end within a metre: labels there would overprint); with
    ``lane_change`` v2 drives in lane 1 from 5 s to 12 s. v1-v2 collide at 20 s in lane 0."""
    t = np.round(np.arange(0.0, 20.0001, 0.1), 6)
    fcd = {}
    for i in range(4):
        gap = 11.0 * i * (1.0 - t / 20.0) + 0.3 * i
        speed = 20.0 + 2.0 * i * np.sin(t / 3.0)
        lane = np.full(t.size, "highway_0", dtype="<U16")
        if lane_change and i == 2:
            lane[(t >= 5.0) & (t < 12.0)] = "highway_1"
        fcd[f"v{i}"] = {"time": t, "pos": 100.0 + 20.0 * t - gap, "speed": speed, "acceleration": np.gradient(speed, t),
                        "lane": lane}
    return fcd


COLLISION = {"pair": "v1-v2", "time_s": 20.0, "position_m": 499.7, "speed_diff_kmh": 30.0}


def _speed_collections(ax):
    from matplotlib.collections import LineCollection

    if ax.get_label() == "<colorbar>":
        return []
    return [c for c in ax.collections if isinstance(c, LineCollection)]


def _labels_overlap(fig) -> list[tuple[str, str]]:
    from matplotlib.text import Text

    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    # the text itself (an annotation's own extent also holds its leader line)
    texts = [(t.get_text(), Text.get_window_extent(t, renderer)) for ax in fig.axes for t in ax.texts]
    return [(a, b) for (a, ba), (b, bb) in itertools.combinations(texts, 2) if ba.overlaps(bb)]


def test_time_space_with_two_lanes_has_a_panel_per_lane_one_speed_scale_and_one_colour_bar():
    fcd = _platoon_fcd(lane_change=True)
    fig = timespace.time_space_figure(fcd, "two lanes", COLLISION)
    panels = [ax for ax in fig.axes if _speed_collections(ax)]
    assert [ax.get_title(loc="left") for ax in panels] == ["lane 1 (highway_1)", "lane 0 (highway_0)"]  # leftmost on top
    assert panels[0].get_shared_x_axes().joined(*panels) and panels[0].get_shared_y_axes().joined(*panels)
    norms = {(c.norm.vmin, c.norm.vmax) for ax in panels for c in _speed_collections(ax)}
    fastest = max(float(d["speed"].max()) for d in fcd.values())
    assert len(norms) == 1 and norms.pop() == (0.0, pytest.approx(fastest))
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert len(bars) == 1 and bars[0].get_ylabel() == "speed [m/s]"
    # lane 1 holds only v2's detour (5 s to 12 s); lane 0 everything else
    lane1_times = np.concatenate([c.get_segments() for c in _speed_collections(panels[0])])[:, :, 0]
    assert lane1_times.min() == pytest.approx(5.0) and lane1_times.max() == pytest.approx(11.9)
    # the collision is marked in the lane where it happened, and only there
    marks = [[line for line in ax.lines if line.get_marker() == "X"] for ax in panels]
    assert [len(m) for m in marks] == [0, 1] and marks[1][0].get_xdata()[0] == 20.0
    labels = [[t.get_text() for t in ax.texts] for ax in panels]
    assert labels[0] == ["v2"] and sorted(labels[1]) == ["v0 attacker", "v1", "v2", "v3"]
    assert _labels_overlap(fig) == []


def test_time_space_labels_do_not_overprint_where_the_lines_end_together():
    fig = timespace.time_space_figure(_platoon_fcd(lane_change=False), "one lane", COLLISION)
    (panel,) = [ax for ax in fig.axes if _speed_collections(ax)]
    assert sorted(t.get_text() for t in panel.texts) == ["v0 attacker", "v1", "v2", "v3"]
    assert _labels_overlap(fig) == []
    assert len([ax for ax in fig.axes if ax.get_label() == "<colorbar>"]) == 1


def test_time_axes_end_with_the_episode_and_the_labels_stay_in_the_figure():
    """Regression: the time axes ran on past the episode's end (to 28 s for a 24 s episode), the room
    for the vehicle labels being made inside the time-space diagram's axes."""
    fcd = _platoon_fcd(lane_change=True)  # the episode ends with the collision at 20 s
    fig = timespace.time_space_figure(fcd, "two lanes", COLLISION)
    panels = [ax for ax in fig.axes if _speed_collections(ax)]
    assert all(ax.get_xlim() == (0.0, 20.0) for ax in panels)
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    (bar,) = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    for text in (t for ax in panels for t in ax.texts):
        box = text.get_window_extent(renderer)
        assert fig.bbox.contains(box.x0, box.y0) and fig.bbox.contains(box.x1, box.y1), text.get_text()
        assert box.x1 < bar.get_window_extent(renderer).x0, text.get_text()  # clear of the colour bar
    ended = [t for t in panels[1].texts if t.get_text() == "v3"][0]  # its line ends with the episode: labelled beyond
    assert ended.get_window_extent(renderer).x0 > panels[1].get_window_extent(renderer).x1
    acc = timespace.accelerations_figure(fcd, "accelerations", COLLISION)
    assert acc.axes[0].get_xlim() == (0.0, 20.0)


def test_time_space_uses_a_given_speed_scale():
    fig = timespace.time_space_figure(_platoon_fcd(lane_change=False), "one lane", speed_max_mps=40.0)
    assert {(c.norm.vmin, c.norm.vmax) for ax in fig.axes for c in _speed_collections(ax)} == {(0.0, 40.0)}


FCD_TEXT = """<?xml version="1.0" encoding="UTF-8"?>
<fcd-export xmlns:xsi="http://www.w3.org/2001/XMLSchema-instance" xsi:noNamespaceSchemaLocation="http://sumo.dlr.de/xsd/fcd_file.xsd">
    <timestep time="0.00">
        <vehicle id="v0" x="49.000000" y="-11.200000" angle="90.000000" type="d4car" speed="1.000000" pos="49.000000" lane="highway_0" slope="0.000000" acceleration="0.500000"/>
        <vehicle id="v1" x="37.500000" y="-11.200000" angle="90.000000" type="d4car" speed="2.000000" pos="37.500000" lane="highway_0" slope="0.000000" acceleration="0.000000"/>
    </timestep>
    <timestep time="0.05">
        <vehicle id="v0" x="49.100000" y="-8.000000" angle="90.000000" type="d4car" speed="1.500000" pos="49.100000" lane="highway_1" slope="0.000000" acceleration="-0.500000"/>
        <vehicle id="v1" x="37.600000" y="-11.200000" angle="90.000000" type="d4car" speed="2.000000" pos="37.600000" lane="highway_0" slope="0.000000" acceleration="0.000000"/>
    </timestep>
</fcd-export>
"""


def test_read_fcd_reads_lanes_in_sumo_attribute_order(tmp_path):
    path = tmp_path / "fcd.xml"
    path.write_text(FCD_TEXT)
    fcd = timespace.read_fcd(path)
    assert list(fcd) == ["v0", "v1"]
    assert fcd["v0"]["lane"].tolist() == ["highway_0", "highway_1"]
    assert fcd["v0"]["time"].tolist() == [0.0, 0.05] and fcd["v0"]["pos"].tolist() == [49.0, 49.1]
    assert fcd["v0"]["speed"].tolist() == [1.0, 1.5] and fcd["v0"]["acceleration"].tolist() == [0.5, -0.5]
    assert timespace.lanes(fcd) == ["highway_1", "highway_0"]
    without_lanes = tmp_path / "old.xml"
    without_lanes.write_text(re.sub(r' lane="[^"]*"', "", FCD_TEXT))
    assert timespace.read_fcd(without_lanes)["v0"]["pos"].tolist() == [49.0, 49.1]


MANY_EDGES_FCD = """<?xml version="1.0" encoding="UTF-8"?>
<fcd-export>
    <timestep time="0.00">
        <vehicle id="v0" x="1999.0" y="-1.6" angle="90.0" type="d4car" speed="20.0" pos="1999.000000" lane="e1_1" slope="0.0" acceleration="0.0" odometer="0.000000"/>
    </timestep>
    <timestep time="0.05">
        <vehicle id="v0" x="2000.0" y="-1.6" angle="90.0" type="d4car" speed="20.0" pos="0.050000" lane=":b_0_1" slope="0.0" acceleration="0.0" odometer="1.000000"/>
    </timestep>
    <timestep time="0.10">
        <vehicle id="v0" x="2001.0" y="-1.6" angle="90.0" type="d4car" speed="20.0" pos="0.950000" lane="e2_1" slope="0.0" acceleration="0.0" odometer="2.000000"/>
    </timestep>
</fcd-export>
"""


def test_read_fcd_gives_positions_along_a_route_of_many_edges_and_lanes_by_index(tmp_path):
    """A lane position starts again at 0 on each edge and junction: the position along the route is
    the start plus SUMO's odometer; a junction's internal lane is the lane the car came from."""
    path = tmp_path / "fcd.xml"
    path.write_text(MANY_EDGES_FCD)
    fcd = timespace.read_fcd(path)
    assert fcd["v0"]["pos"].tolist() == [1999.0, 2000.0, 2001.0]
    assert fcd["v0"]["lane"].tolist() == ["1", "1", "1"]
    assert timespace.lanes(fcd) == ["1"]


# --- heatmaps -----------------------------------------------------------------------------------------


def _panel_records(start: str, optimizer: str, successes: dict[tuple[float, float], int], samples: int = 10):
    out = []
    for (d, v), wins in successes.items():
        for i in range(samples):
            out.append(_record(len(out), start=start, optimizer=optimizer, setpoint_m=d, speed_mps=v,
                               outcome="success" if i < wins else "no_crash"))
    return out


def test_heatmap_panels_share_one_colour_range_and_numbers_read_well():
    few = _panel_records("rest", "bo", {(5.0, 20.0): 1, (5.0, 25.0): 2, (7.0, 20.0): 0, (7.0, 25.0): 3})
    many = _panel_records("steady", "bo", {(5.0, 20.0): 9, (5.0, 25.0): 4, (7.0, 20.0): 7, (7.0, 25.0): 10})
    other = _panel_records("rest", "ce", {(5.0, 20.0): 5})  # ran one cell only
    panels = figures.heatmap_panels(few + many + other)
    assert [name for name, _ in panels] == ["knots, BO, start rest", "knots, BO, start steady", "knots, CE, start rest"]
    fig = figures.heatmaps_figure(panels, "successes")
    images = [ax.images[0] for ax in fig.axes if ax.images]
    assert len(images) == 3 and {im.get_clim() for im in images} == {(0.0, 10.0)}  # not (0, 3) for the first
    bars = [ax for ax in fig.axes if ax.get_label() == "<colorbar>"]
    assert len(bars) == 1
    assert "10 samples per cell" in fig.get_suptitle()
    for im in images:
        ax = im.axes
        values = np.ma.getdata(im.get_array())
        texts = {(round(t.get_position()[0]), round(t.get_position()[1])): t for t in ax.texts}
        assert len(texts) == np.sum(~np.ma.getmaskarray(im.get_array()))  # a number in every cell that ran
        for (j, i), t in texts.items():
            assert int(t.get_text()) == values[i, j] and t.get_fontsize() >= 8
            assert figures.contrast_ratio(im.cmap(im.norm(values[i, j])), t.get_color()) >= 4.5
    # the CE panel's untested cells show no number, and are not coloured as zero
    assert np.ma.getmaskarray(images[2].get_array()).sum() == 3


def test_heatmap_cells_with_different_budgets_show_successes_of_samples():
    rs = _panel_records("rest", "bo", {(5.0, 20.0): 1}, samples=10) + _panel_records("rest", "bo", {(7.0, 20.0): 2}, samples=4)
    fig = figures.heatmaps_figure(figures.heatmap_panels(rs), "successes")
    assert sorted(t.get_text() for ax in fig.axes for t in ax.texts) == ["1/10", "2/4"]
    (image,) = [ax.images[0] for ax in fig.axes if ax.images]
    assert image.get_clim() == (0.0, 50.0)  # coloured by share: 2 of 4 is more than 1 of 10


def _texts_apart_and_inside(fig) -> None:
    """No two titles or axis labels overprint each other, and every one is inside the figure."""
    fig.canvas.draw()
    renderer = fig.canvas.get_renderer()
    whole = fig.bbox
    boxes = []
    for ax in fig.axes:
        if not ax.get_visible():
            continue
        for text in (ax.title, ax.yaxis.label, ax.xaxis.label):
            if text.get_text():
                box = text.get_window_extent(renderer)
                assert whole.x0 - 1 <= box.x0 and box.x1 <= whole.x1 + 1 and whole.y0 - 1 <= box.y0 and box.y1 <= whole.y1 + 1, text.get_text()
                boxes.append((text.get_text(), box))
    for i, (a, box_a) in enumerate(boxes):
        for b, box_b in boxes[i + 1:]:
            assert not box_a.overlaps(box_b), (a, b)


def test_heatmaps_of_many_systems_are_a_grid_with_each_name_once_and_nothing_overprinted():
    """The systems sweep's report had 48 panels whose titles (system: run) overprinted each other."""
    systems = [f"sumo:ACC(tau={t}, speedControlGainSpeed={g})" for t in (0.5, 1.0, 1.5, 2.0) for g in (0.5, 1.0, 1.5)]
    rs = [_record(i, system=system, start=start, optimizer=optimizer, setpoint_m=d, speed_mps=v,
                  outcome="success" if i % 3 == 0 else "no_crash")
          for i, (system, start, optimizer, d, v) in enumerate(
              itertools.product(systems, ("rest", "steady"), ("bo", "ce"), (3.0, 7.0, 11.0), (20.0, 30.0)))]
    panels = figures.heatmap_panels(rs)
    assert len(panels) == 48 and panels[0][0] == (systems[0], "knots, BO, start rest")
    fig = figures.heatmaps_figure(panels, "successes", columns=figures.heatmap_columns(rs))
    visible = [ax for ax in fig.axes if ax.images]
    assert len(visible) == 48
    titles = [ax.get_title() for ax in visible if ax.get_title()]
    assert [t.replace("\n", " ") for t in titles] == ["knots, BO, start rest", "knots, BO, start steady",
                                                      "knots, CE, start rest", "knots, CE, start steady"]
    labels = " ".join(ax.get_ylabel().replace("\n", " ") for ax in visible)
    assert all(labels.count(system) == 1 for system in systems) and fig.get_supylabel() == "setpoint [m]"
    _texts_apart_and_inside(fig)


def test_a_heatmap_of_one_cell_keeps_its_title_inside_its_panel():
    rs = [_record(i, attack="intermittent", optimizer="ce-bucket", start="warmup", system="sumo:ACC(tau=0.5)")
          for i in range(5)] + [_record(i, attack="intermittent", optimizer="ce-bucket", start="warmup") for i in range(5)]
    for records in (rs, rs[5:]):
        fig = figures.heatmaps_figure(figures.heatmap_panels(records), "Successful attacks over setpoint and target speed")
        _texts_apart_and_inside(fig)
        for ax in fig.axes:
            if ax.images and ax.get_title():
                box = ax.title.get_window_extent(fig.canvas.get_renderer())
                assert box.width <= ax.get_window_extent().width + 1


@pytest.mark.parametrize("background", [(0, 0, 0), (1, 1, 1), (0.27, 0.0, 0.33), (0.99, 0.9, 0.14), (0.13, 0.57, 0.55)])
def test_text_colour_reads_on_any_cell(background):
    assert figures.contrast_ratio(background, figures.text_colour(background)) >= 4.5


# --- clusters -----------------------------------------------------------------------------------------


def _figure_text(fig) -> str:
    parts = [fig.get_suptitle()] + [t.get_text() for t in fig.texts]
    for ax in fig.axes:
        parts += [ax.get_title(), ax.get_xlabel(), ax.get_ylabel()] + [t.get_text() for t in ax.texts]
        if ax.get_legend():
            parts += [t.get_text() for t in ax.get_legend().get_texts()]
    for legend in fig.legends:
        parts += [t.get_text() for t in legend.get_texts()]
    return "\n".join(parts)


def test_clusters_figure_shows_each_clusters_own_collision_time_and_counts_right():
    rng = np.random.default_rng(4)
    maneuver = np.array([-1, 1, -1, 0.5, 0.5, 0, 0, 0, 0], dtype=float)
    vectors = [np.clip(maneuver + rng.normal(0, 0.03, 9), -1, 1) for _ in range(8)] + [-maneuver]
    times = [10.0, 11.0, 12.0, 13.0, 14.0, 15.0, 16.0, 17.0, 40.0]
    records = [_record(i, params=tuple(v), time_s=t) for i, (v, t) in enumerate(zip(vectors, times))]
    c = cluster_knots(records, "one outlier")
    assert c.k == 2 and (c.dbscan_clusters, c.dbscan_noise) == (1, 1)
    fig = figures.clusters_figure(c)
    text = _figure_text(fig)
    assert "cluster 2: 1 attack;" in text and "DBSCAN: 1 cluster, 1 noise point" in text
    assert PLURAL_AFTER_ONE.search(text) is None
    from d4sumo.results.report import clusters_caption

    caption = clusters_caption(c)
    assert "1 attack colliding at 40.0 s" in caption and "DBSCAN: 1 cluster, 1 noise point." in caption
    assert PLURAL_AFTER_ONE.search(caption) is None
    panels = [ax for ax in fig.axes if ax.get_title().startswith("cluster ")]
    medians = [[line.get_xdata()[0] for line in ax.lines if line.get_linestyle() == "--"] for ax in panels]
    assert medians == [[13.5], [40.0]]  # each cluster's own, not the median of all (14.0)
    counts = [[label.get_text() for label in ax.child_axes[0].get_xticklabels()] for ax in panels]
    assert counts[0] == ["8", "8", "8", "8", "5", "0", "0", "0", "0"]  # knot k counts where t_(k-2) < t_c


# --- where figures go -----------------------------------------------------------------------------------


def test_a_figure_in_a_missing_folder_is_refused_and_the_folder_not_created(tmp_path):
    from d4sumo.results.report import plot_figure

    out = tmp_path / "missing" / "fig.png"
    for kind, extra in [("heatmap", {}), ("time-space", {"sample": 1})]:
        with pytest.raises(ConfigError) as err:  # before any work: the database does not even exist
            plot_figure([tmp_path / "no.sqlite"], kind, out, **extra)
        assert err.value.field == "--out" and err.value.allowed == f"a file in an existing folder ({out.parent} does not exist)"
    with pytest.raises(ConfigError):
        figures.heatmap([_record(0)], "successes", out)
    assert not (tmp_path / "missing").exists()
    with pytest.raises(ConfigError) as err:
        plot_figure([tmp_path / "no.sqlite"], "heatmap", tmp_path / "fig.nope")
    assert err.value.field == "--out" and ".png" in err.value.allowed
    assert list(tmp_path.iterdir()) == []


# --- from a small real database ---------------------------------------------------------------------------


@pytest.mark.sumo
def test_time_space_and_accelerations_from_a_replayed_fcd(small_db, tmp_path):
    from d4sumo.results.report import collision_of, describe, replay_to_fcd

    r = most_severe(load_records([small_db]), 1)[0]
    fcd = replay_to_fcd(r, tmp_path / "fcd.xml")
    assert set(fcd) == {"v0", "v1", "v2", "v3"}
    assert timespace.lanes(fcd) == ["highway_0"]  # today every car stays in lane 0
    last = fcd["v0"]["time"][-1]
    assert last == pytest.approx(r.time_s)  # the replay ends at the stored collision
    assert is_image(timespace.time_space(fcd, describe(r), tmp_path / "ts.png", collision_of(r)))
    assert is_image(timespace.accelerations(fcd, "acc", tmp_path / "acc.png", collision_of(r)))


@pytest.mark.sumo
def test_clusters(small_db, tmp_path):
    condition, records = richest_conditions(load_records([small_db]))[0]
    clustering = cluster_knots(records, condition)
    assert clustering is not None
    assert is_image(figures.clusters(clustering, tmp_path / "c.png"))


@pytest.mark.sumo
def test_plot_sample_writes_the_figure_only_and_the_fcd_only_when_asked(small_db, tmp_path):
    from d4sumo.results.report import plot_figure

    before = set(os.listdir(tempfile.gettempdir()))
    out = tmp_path / "fig.png"
    message = plot_figure([small_db], "time-space", out, sample=1)
    assert list(tmp_path.iterdir()) == [out] and is_image(out) and "FCD" not in message
    after = set(os.listdir(tempfile.gettempdir()))
    assert not [name for name in after - before if name.startswith("d4sumo-fcd-")]  # the replay's folder is gone
    fcd = tmp_path / "replay.xml"
    plot_figure([small_db], "accel", tmp_path / "acc.png", sample=1, fcd_path=fcd)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["acc.png", "fig.png", "replay.xml"]
    assert set(timespace.read_fcd(fcd)) == {"v0", "v1", "v2", "v3"}
    with pytest.raises(ConfigError) as err:
        plot_figure([small_db], "accel", tmp_path / "acc2.png", sample=1, fcd_path=tmp_path / "nope" / "f.xml")
    assert err.value.field == "--fcd" and not (tmp_path / "nope").exists()


@pytest.mark.sumo
@pytest.mark.parametrize("kind, extra", [("time-space", {"sample": 1}), ("accel", {"sample": 1}),
                                         ("heatmap", {"start": "rest"}), ("clusters", {})])
def test_plot_draws_one_figure(small_db, tmp_path, kind, extra):
    from d4sumo.results.report import plot_figure

    out = tmp_path / f"{kind}.png"
    assert plot_figure([small_db], kind, out, **extra) == f"{kind} plot written to {out}"
    assert is_image(out) and list(tmp_path.iterdir()) == [out]


@pytest.mark.sumo
@pytest.mark.parametrize("extra, field", [({}, "--sample"), ({"sample": 99999}, "--sample"),
                                          ({"optimizer": "nope"}, "filters")])
def test_plot_bad_input_names_the_option(small_db, tmp_path, extra, field):
    from d4sumo.results.report import plot_figure

    kind = "heatmap" if "optimizer" in extra else "time-space"
    with pytest.raises(ConfigError) as err:
        plot_figure([small_db], kind, tmp_path / "x.png", **extra)
    assert err.value.field == field and list(tmp_path.iterdir()) == []


@pytest.mark.sumo
def test_the_plot_command_refuses_a_missing_out_folder(small_db, tmp_path, capsys):
    from d4sumo.cli import main

    out = tmp_path / "missing" / "fig.png"
    assert main(["plot", "heatmap", str(small_db), "--out", str(out)]) == 2
    err = capsys.readouterr().err.strip()
    assert "--out" in err and "existing folder" in err and err.count("\n") == 0
    assert not (tmp_path / "missing").exists()
