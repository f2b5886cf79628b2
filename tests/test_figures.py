"""Every figure builder and the report produce real image files from a small real database."""

from __future__ import annotations

import re

import pytest

from d4sumo import figures
from d4sumo.analysis import cluster_knots, load_records, most_severe, richest_conditions
from d4sumo.cli import main
from d4sumo.report import build_report, collision_of, describe, replay_to_fcd

pytestmark = pytest.mark.sumo

PNG = b"\x89PNG\r\n\x1a\n"


def is_image(path):
    data = path.read_bytes()
    return data.startswith(PNG) and len(data) > 10_000


def test_heatmap(small_db, tmp_path):
    assert is_image(figures.heatmap(load_records([small_db]), "successes", tmp_path / "h.png"))


def test_time_space_and_accelerations_from_a_replayed_fcd(small_db, tmp_path):
    r = most_severe(load_records([small_db]), 1)[0]
    fcd = replay_to_fcd(r, tmp_path / "fcd.xml")
    assert set(fcd) == {"v0", "v1", "v2", "v3"}
    last = fcd["v0"]["time"][-1]
    assert last == pytest.approx(r.time_s)  # the replay ends at the stored collision
    assert is_image(figures.time_space(fcd, describe(r), tmp_path / "ts.png", collision_of(r)))
    assert is_image(figures.accelerations(fcd, "acc", tmp_path / "acc.png", collision_of(r)))


def test_clusters(small_db, tmp_path):
    condition, records = richest_conditions(load_records([small_db]))[0]
    clustering = cluster_knots(records, condition)
    assert clustering is not None
    assert is_image(figures.clusters(clustering, tmp_path / "c.png"))


def test_the_report_gathers_tables_and_figures(small_db, tmp_path):
    index = build_report([small_db], tmp_path / "report", severe=2)
    text = index.read_text()
    for title in ("Table 1", "Table 2", "Table 3", "Most severe attacks", "Clusters"):
        assert title in text
    images = re.findall(r"<img src='([^']+)'", text)
    assert len(images) >= 2 + 2 * 2 + 1  # heatmaps, time-space + accelerations, clusters
    assert all(is_image(index.parent / name) for name in images)


@pytest.mark.parametrize("kind, extra", [("time-space", ["--sample", "1"]), ("accel", ["--sample", "1"]),
                                         ("heatmap", ["--start", "rest"]), ("clusters", [])])
def test_plot_draws_one_figure(small_db, tmp_path, kind, extra, capsys):
    out = tmp_path / f"{kind}.png"
    assert main(["plot", kind, str(small_db), "--out", str(out), *extra]) == 0
    assert is_image(out)


@pytest.mark.parametrize("argv, message", [(["time-space"], "--sample"), (["time-space", "--sample", "99999"], "--sample"),
                                           (["heatmap", "--optimizer", "nope"], "filters")])
def test_plot_bad_input_is_one_line(small_db, tmp_path, argv, message, capsys):
    kind, *rest = argv
    assert main(["plot", kind, str(small_db), "--out", str(tmp_path / "x.png"), *rest]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and err.count("\n") == 0
