"""The whole HTML report from a small real database: every figure and file it links exists, every table
has data, the severe attacks come from different configurations, and the wording counts right."""

from __future__ import annotations

import re
from html.parser import HTMLParser
from urllib.parse import urlparse

import numpy as np
import pytest

from d4sumo.results.analysis import most_severe
from d4sumo.results.records import load_records

pytestmark = pytest.mark.sumo

PNG = b"\x89PNG\r\n\x1a\n"


class _Page(HTMLParser):
    """The links and tables of a page: img src, a href, and the data rows (rows with td) of each table."""

    def __init__(self):
        super().__init__()
        self.images: list[str] = []
        self.links: list[str] = []
        self.tables: list[int] = []
        self._row_has_data = False
        self._in_table = False

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag == "img":
            self.images.append(attrs.get("src", ""))
        elif tag == "a" and "href" in attrs:
            self.links.append(attrs["href"])
        elif tag == "table":
            self.tables.append(0)
            self._in_table = True
        elif tag == "tr":
            self._row_has_data = False
        elif tag == "td" and self._in_table:
            self._row_has_data = True

    def handle_endtag(self, tag):
        if tag == "tr" and self._in_table and self._row_has_data:
            self.tables[-1] += 1
        elif tag == "table":
            self._in_table = False


def _local(ref: str) -> bool:
    parsed = urlparse(ref)
    return not parsed.scheme and not parsed.netloc and not ref.startswith("#")


@pytest.fixture(scope="module")
def report(small_db, tmp_path_factory):
    from d4sumo.results.report import build_report

    index = build_report([small_db], tmp_path_factory.mktemp("report") / "out", severe=3)
    page = _Page()
    text = index.read_text(encoding="utf-8")
    page.feed(text)
    return index, text, page


def test_every_linked_figure_and_file_exists_and_is_not_empty(report):
    index, _, page = report
    refs = [ref for ref in page.images + page.links if _local(ref)]
    assert len(page.images) >= 1 + 2 * 3 + 1  # heatmaps, time-space + accelerations of 3 attacks, clusters
    for ref in refs:
        path = index.parent / ref
        assert path.is_file() and path.stat().st_size > 0, ref
    for src in page.images:
        assert (index.parent / src).read_bytes().startswith(PNG), src
    assert any(ref.startswith("fcd/") for ref in page.links) and "tables.txt" in page.links


def test_every_table_has_data_rows(report):
    _, text, page = report
    assert len(page.tables) == 3 and all(rows >= 1 for rows in page.tables), page.tables
    for title in ("Table 1", "Table 2", "Table 3", "Most severe attacks", "Clusters"):
        assert title in text
    assert "time from attack start to collision" in text


def test_the_most_severe_attacks_come_from_different_configurations_and_say_why(report, small_db):
    index, text, page = report
    records = load_records([small_db])
    top = most_severe(records, 3)
    assert len(top) == 3 and len({(r.setpoint_m, r.speed_mps, r.start) for r in top}) == 3
    assert "largest speed difference between the colliding cars at the first collision" in text
    # said plainly, with the counts: once "at most one per configuration (...): 3 attacks" for 8 configurations
    found = len({r.configuration for r in records if r.outcome == "success"})
    assert "Each configuration gives at most one attack, its most severe" in text
    assert f"of the {found} configurations that found a successful attack (of 8), the 3 with the most severe are " \
           "shown (--severe 3)" in text
    shown = [int(m) for m in re.findall(r"time_space_sample_(\d+)\.png", " ".join(page.images))]
    assert shown == [r.sample_id for r in top]


def test_the_acceleration_plot_fits_beside_its_time_space_diagram_at_1400_px(report):
    """Regression: the text said the accelerations were beside the time-space diagram, yet at 1400 px
    they stacked below it (two figures of 880 px each kept their width and wrapped)."""
    index, text, _ = report
    assert "and beside it (below it in a narrow window) every car's acceleration" in text
    style = re.search(r"<style>(.*?)</style>", text).group(1)
    row = re.search(r"\.row\{([^}]*)\}", style).group(1)
    figure = re.search(r"\.row img\{([^}]*)\}", style).group(1)
    margin_px = 2 * 16 * 2  # body margin 2em each side
    gap_px = int(re.search(r"gap:(\d+)px", row).group(1))
    min_px = int(re.search(r"min-width:min\((\d+)px,100%\)", figure).group(1))
    assert "flex:1 1 0" in figure  # the two figures share the row, whatever their own width
    assert 2 * min_px + gap_px <= 1400 - margin_px  # and both fit in it at 1400 px
    assert re.findall(r"<div class='row'><img [^>]*time_space[^>]*><img [^>]*accel", text)


def test_the_reports_fcd_files_name_themselves_where_they_are(report):
    """Regression: an FCD file's header named the temporary file it was written as, in the folder the
    report was built in beside its own."""
    index, _, _ = report
    files = sorted((index.parent / "fcd").glob("*.xml"))
    assert len(files) == 3
    for fcd in files:
        head = fcd.read_text()[:4000]
        assert f'<fcd-output value="{fcd}"/>' in head and ".part" not in head, fcd


def test_each_most_severe_attack_links_its_openscenario_on_its_opendrive_road(report):
    index, text, page = report
    scenarios = [ref for ref in page.links if ref.endswith("scenario.xosc")]
    assert len(scenarios) == len(list((index.parent / "fcd").glob("*.xml"))) == 3
    for ref in scenarios:
        xosc = (index.parent / ref).read_text()
        assert (index.parent / ref).with_name("road.xodr").is_file() and '<LogicFile filepath="road.xodr"/>' in xosc
        assert 'name="d4sumo.outcome" value="success"' in xosc and "<CollisionCondition>" in xosc


def test_the_report_never_says_one_of_something_in_the_plural(report):
    _, text, _ = report
    assert re.search(r"\b1 (attacks|clusters|noise points|successes|samples|panels)\b", text) is None
    assert re.search(r"\b1 clusters\b", (report[0].parent / "tables.txt").read_text()) is None


def test_the_report_writes_only_into_its_folder(report):
    index, _, page = report
    written = {p.relative_to(index.parent).as_posix() for p in index.parent.rglob("*") if p.is_file()}
    linked = {ref for ref in page.images + page.links if _local(ref)} | {"index.html"}
    assert written == linked  # nothing the page does not show or link


def test_the_report_leaves_nothing_beside_its_folder(report):
    index, _, _ = report
    assert [p.name for p in index.parent.parent.iterdir()] == ["out"]  # the folder it was built in is gone


def test_a_report_refused_midway_keeps_the_earlier_report_and_leaves_no_part(report, small_db, tmp_path):
    """Regression: a sample refused while the report replayed it (here, a stored attack out of its box)
    left heatmaps.png, tables.txt and fcd/ in --out without index.html, over an earlier report."""
    import shutil
    import sqlite3

    from d4sumo.errors import ConfigError
    from d4sumo.results.report import build_report

    earlier = tmp_path / "out"
    shutil.copytree(report[0].parent, earlier)
    before = {p.relative_to(earlier): p.read_bytes() for p in earlier.rglob("*") if p.is_file()}
    bad = tmp_path / "bad.sqlite"
    shutil.copy(small_db, bad)
    with sqlite3.connect(bad) as con:  # the most severe success: the report replays it
        worst = con.execute("SELECT id FROM sample WHERE outcome = 'success' ORDER BY speed_diff_kmh DESC LIMIT 1").fetchone()[0]
        con.execute("UPDATE sample SET params = '[5, 5, 5, 5, 5, 5, 5, 5, 5]' WHERE id = ?", (worst,))
    for out in (earlier, tmp_path / "new"):
        with pytest.raises(ConfigError, match=f"{bad}: sample {worst}: attack parameters: m0"):
            build_report([bad], out, severe=3)
    assert {p.relative_to(earlier): p.read_bytes() for p in earlier.rglob("*") if p.is_file()} == before
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.sqlite", "out"]  # no "new", no part


def test_a_report_into_the_current_folder(small_db, tmp_path, monkeypatch):
    """Regression: --out . ended in "ValueError: PosixPath('.') has an empty name" (its part had no name)."""
    from d4sumo.results.report import build_report

    monkeypatch.chdir(tmp_path)
    index = build_report([small_db], ".", severe=1)
    assert (tmp_path / "index.html").is_file() and index.resolve() == tmp_path / "index.html"
    assert not [p for p in tmp_path.parent.iterdir() if p.name.endswith(".part")]


@pytest.mark.sumo
def test_a_replayed_message_attack_draws_what_the_attacker_said_beside_where_it_was(tmp_path):
    from d4sumo.model.config import ControllerConfig, EpisodeConfig
    from d4sumo.results import timespace
    from d4sumo.results.records import load_records
    from d4sumo.results.report import replay_to_fcd
    from d4sumo.search.campaign import Campaign, open_store
    from d4sumo.search.runner import run_campaign

    config = EpisodeConfig(controller=ControllerConfig("cacc"), start="steady", setpoint_m=5.0, duration_s=20.0)
    campaign = Campaign(config=config, optimizer="random", samples=2, message="offset", message_field="speed")
    db = tmp_path / "lies.sqlite"
    with open_store(db) as store:
        run_campaign(campaign, store)
    record = load_records([db])[1]
    value, start = record.params[9], record.params[10]
    fcd = replay_to_fcd(record, tmp_path / "fcd.xml")
    said, truth = fcd["v0" + timespace.SAID], fcd["v0"]
    late = said["time"] >= start + 0.1
    lie = said["speed"][late] - np.interp(said["time"][late], truth["time"], truth["speed"])
    assert np.median(lie) == pytest.approx(value, abs=0.05)  # the beacons' speed, held between them, less the truth
    fig = timespace.accelerations_figure(fcd, "lies")
    speed_panel, _ = fig.axes[:2]  # under a message attack the speeds too: a lie about its speed shows only there
    said_line, own_line = ({line.get_label(): line for line in speed_panel.get_lines()}[name] for name in ("what v0 said", "v0 attacker"))
    assert np.array_equal(said_line.get_ydata(), said["speed"]) and said_line.get_linestyle() == "--"
    assert said_line.get_color() == own_line.get_color()  # in the liar's colour


@pytest.mark.sumo
def test_campaigns_with_and_without_a_lie_are_never_pooled_and_every_output_names_the_lie(tmp_path):
    """A report of a cacc campaign with pedals alone and one with a lie about its speed showed one row,
    "knots random", crediting the lie's successes to the pedals; titles and the CSV said nothing of it."""
    import csv

    from d4sumo.model.config import ControllerConfig, EpisodeConfig
    from d4sumo.results.analysis import table_success_statistics
    from d4sumo.results.export import write_csv
    from d4sumo.results.figures import heatmap_panels
    from d4sumo.results.records import load_records
    from d4sumo.results.report import describe
    from d4sumo.search.campaign import Campaign, open_store
    from d4sumo.search.runner import run_campaign

    config = EpisodeConfig(controller=ControllerConfig("cacc"), start="steady", setpoint_m=5.0, duration_s=10.0)
    db = tmp_path / "mixed.sqlite"
    with open_store(db) as store:
        for message in ("", "offset"):
            run_campaign(Campaign(config=config, optimizer="random", samples=2, message=message, message_field="speed"), store)
    records = load_records([db])
    assert [r.lie for r in records] == ["", "", "a lie (offset on its speed)", "a lie (offset on its speed)"]
    rows = table_success_statistics(records).rows
    assert [(row[0], row[1]) for row in rows] == [("knots random", "2"), ("knots with a lie (offset on its speed) random", "2")]
    assert [name for name, _ in heatmap_panels(records)] == [
        "knots, RANDOM, start steady", "knots with a lie (offset on its speed), RANDOM, start steady"]
    assert "knots with a lie (offset on its speed) random" in describe(records[2]) and "lie" not in describe(records[0])
    out = tmp_path / "mixed.csv"
    with open_store(db, create=False) as store, open(out, "w", newline="") as f:
        write_csv(store, f)
    with open(out, newline="") as f:
        assert [row["lie"] for row in csv.DictReader(f)] == ["", "", "a lie (offset on its speed)", "a lie (offset on its speed)"]


@pytest.mark.sumo
def test_a_report_among_traffic_plays_each_crash_traffic_without_the_attack(tmp_path):
    """The report's table of the traffic's doing: each crashed sample's traffic (each its own) played with the attacker
    only cruising; none of these crashes without the attack."""
    from d4sumo.model.config import EpisodeConfig
    from d4sumo.results.baseline import table_without_attack
    from d4sumo.results.report import build_report, evaluator_of
    from d4sumo.search.campaign import Campaign, open_store
    from d4sumo.search.runner import run_campaign

    config = EpisodeConfig(network="highway_3lane_120kmh", start="steady", speed_mps=25.0, duration_s=15.0,
                           traffic={"vehicles_per_hour": 600, "warmup_s": 40.0, "per_sample": True})
    db = tmp_path / "traffic.sqlite"
    with open_store(db) as store:
        run_campaign(Campaign(config=config, optimizer="random", samples=4, seed=3), store)
    records = load_records([db])
    crashed = sum(r.outcome in ("success", "attacker_crash") for r in records)
    assert crashed  # the random attacks crash something: each crash's traffic is played
    ticks = []
    table = table_without_attack(records, evaluator_of, lambda: ticks.append(1))
    (row,) = table.rows
    assert row[1:4] == ("4", str(crashed), "0") and len(ticks) == crashed
    successes = sum(r.outcome == "success" for r in records)
    assert row[5] == f"0 of {successes}"
    page = build_report([db], tmp_path / "report")
    assert "Without the attack" in (tmp_path / "report" / "tables.txt").read_text() and page.exists()
