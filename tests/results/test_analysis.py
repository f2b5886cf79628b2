"""The paper's tables and the most severe attacks, from a small real database and from synthetic data."""

from __future__ import annotations

import dataclasses
import itertools

import pytest

from d4sumo.model.config import EpisodeConfig
from d4sumo.results.analysis import (
    count_noun, most_severe, success_grid, table_attacker_crashes, table_by_speed, table_success_statistics)
from d4sumo.results.records import Record, load_records


@pytest.mark.sumo
def test_tables_count_what_the_database_holds(small_db):
    records = load_records([small_db])
    assert len(records) == 96
    wins = [r for r in records if r.outcome == "success"]
    t1 = table_success_statistics(records)
    assert t1.rows[0][0] == "knots random" and t1.rows[0][1] == "96" and t1.rows[0][2] == str(len(wins))
    v12 = sum(r.pair == "v1-v2" for r in wins)
    assert t1.rows[0][3].startswith(f"{v12} (")
    t2 = table_attacker_crashes(records)
    assert t2.header == ("setpoint", "knots random") and [row[0] for row in t2.rows] == ["5 m", "7 m"]
    crashes, no_crash = (int(v) for v in t2.rows[0][1].split(" / "))
    assert crashes == sum(r.outcome == "attacker_crash" and r.setpoint_m == 5.0 for r in records)
    assert no_crash == sum(r.outcome == "no_crash" and r.setpoint_m == 5.0 for r in records)
    t3 = table_by_speed(records)
    assert [row[0] for row in t3.rows] == ["knots random rest", "knots random steady"]
    assert sum(int(row[1]) for row in t3.rows) == len(wins)
    assert "Table 1" in t1.to_text()
    assert all(r.attack_start_s == 0.0 and r.time_from_attack_start_s == r.time_s for r in wins)  # rest and steady


@pytest.mark.sumo
def test_success_grid_and_most_severe(small_db):
    records = load_records([small_db])
    setpoints, speeds, grid = success_grid(records)
    assert setpoints == [5.0, 7.0] and speeds == [20.0, 25.0]
    assert grid.sum() == sum(r.outcome == "success" for r in records)
    top = most_severe(records, 3)
    assert len(top) == 3 and top[0].speed_diff_kmh >= top[1].speed_diff_kmh >= top[2].speed_diff_kmh
    assert all(r.outcome == "success" for r in top)
    assert len({r.configuration for r in top}) == 3 and len({r.campaign_id for r in top}) == 3


def _record(params, time_s=10.0, **changes):
    names = tuple(f"m{i}" for i in range(9)) + (("t_lc_s",) if len(params) == 10 else ())  # a lane change time: by name
    r = Record("db", 0, 0, "n", 3, 7.0, 25.0, "rest", "knots", "bo", 0, 6.0, tuple(params), 0.1, "success",
               "v1-v2", time_s, 100.0, 10.0, param_names=names[:len(params)])
    return dataclasses.replace(r, **changes)


# --- time from the attack's start, Table 1 ----------------------------------------------------------


def test_table_1_counts_collision_time_from_the_attack_start():
    records = [_record([0] * 9, time_s=25.0, start="warmup", attack_start_s=15.0),
               _record([0] * 9, time_s=35.0, start="warmup", attack_start_s=15.0)]
    assert [r.time_from_attack_start_s for r in records] == [10.0, 20.0]
    t1 = table_success_statistics(records)
    column = t1.header.index("time from attack start to collision s, mean (std)")
    assert t1.rows[0][column] == "15.0 (5.0)"  # not 30.0: the warm-up is not the attack's doing


# --- most severe attacks ------------------------------------------------------------------------------


def test_most_severe_are_picked_across_configurations():
    # one campaign holds the five largest speed differences; the others are milder
    strong = [_record([0] * 9, sample_id=i, speed_diff_kmh=80.0 - i) for i in range(5)]
    other_setpoint = [_record([0] * 9, sample_id=10 + i, setpoint_m=5.0, speed_diff_kmh=50.0 - i) for i in range(3)]
    other_optimizer = [_record([0] * 9, sample_id=20, optimizer="ce", speed_diff_kmh=60.0)]
    other_start = [_record([0] * 9, sample_id=30, start="steady", speed_diff_kmh=40.0)]
    failed = [_record([0] * 9, sample_id=40, start="steady", setpoint_m=9.0, outcome="attacker_crash", speed_diff_kmh=99.0)]
    top = most_severe(strong + other_setpoint + other_optimizer + other_start + failed, 3)
    assert [r.sample_id for r in top] == [0, 20, 10]  # the best of each configuration, most severe first
    assert len({r.configuration for r in top}) == 3
    assert [r.sample_id for r in most_severe(strong, 3)] == [0]  # one configuration: one attack


@pytest.mark.parametrize("count, words", [(0, "0 clusters"), (1, "1 cluster"), (2, "2 clusters")])
def test_count_noun(count, words):
    assert count_noun(count, "cluster") == words
    assert count_noun(count, "success", "successes") == words.replace("clusters", "successes").replace("cluster", "success")


# --- systems under test --------------------------------------------------------------------------------


def test_tables_split_by_system_when_several_were_attacked():
    from d4sumo.results.analysis import table_systems

    paper = [_record([0] * 9, sample_id=i, speed_diff_kmh=20.0 + i) for i in range(3)]
    acc = [_record([0] * 9, sample_id=10 + i, system="sumo:ACC", outcome="no_crash", pair=None, time_s=None,
                   speed_diff_kmh=None) for i in range(4)]
    t = table_systems(paper + acc)
    rows = {row[0]: row for row in t.rows}
    assert rows["switching"][2] == "3 (100.0%)" and rows["switching"][4] == "7"
    assert rows["sumo:ACC"][2] == "0 (0.0%)" and rows["sumo:ACC"][4] == "none"  # said plainly
    assert [row[0] for row in table_success_statistics(paper + acc).rows] == ["sumo:ACC knots bo", "switching knots bo"]
    assert [row[0] for row in table_success_statistics(paper).rows] == ["knots bo"]  # one system: as the paper
    assert len(most_severe(paper + acc, 3)) == 1  # one configuration with successes


def test_near_copies_of_one_attack_count_once():
    from d4sumo.results.analysis import distinct_count

    lower, upper = [-1.0, -1.0], [1.0, 1.0]
    same = [[0.5, 0.5], [0.55, 0.45], [0.59, 0.5]]  # within 5% of the range (0.1) of the first in every parameter
    assert distinct_count(same, lower, upper) == 1
    assert distinct_count(same + [[0.5, 0.75]], lower, upper) == 2  # 0.25 away in one parameter: another attack
    assert distinct_count([], lower, upper) == 0


def _sample(i, **changes):
    r = Record("db", i, 0, "n", 3, 7.0, 25.0, "rest", "knots", "bo", 0, 6.0, (0.0,) * 9, 0.1, "success",
               "v1-v2", 20.0, 100.0, 10.0)
    return dataclasses.replace(r, **changes)


def test_the_tables_of_a_sweep_of_many_systems_fit_in_100_characters_a_line():
    """tables.txt had lines of about 600 characters for the systems sweep: wide tables go on in blocks."""
    systems = [f"sumo:ACC(tau={t}, speedControlGainSpeed={g})" for t in (0.5, 1.0, 1.5, 2.0) for g in (0.5, 1.0, 1.5)]
    records = [_sample(i, system=system, optimizer=optimizer, setpoint_m=d, outcome=outcome)
               for i, (system, optimizer, d, outcome) in enumerate(itertools.product(
                   systems, ("bo", "ce"), (3.0, 5.0, 7.0, 9.0, 11.0, 13.0), ("success", "attacker_crash", "no_crash")))]
    t2 = table_attacker_crashes(records)
    assert len(t2.header) == 25
    text = t2.to_text()
    assert max(len(line) for line in text.splitlines()) <= 100
    blocks = text.split("\n\n")
    assert len(blocks) > 1 and blocks[1].startswith("Table 2: attacker crashes / no-crash samples per setpoint (continued, 2 of")
    for column in t2.header[1:]:  # every run's column is in one block, each block led by the setpoints
        assert sum(column in block.splitlines()[1] for block in blocks) == 1
    assert all(block.splitlines()[2].startswith("3 m") for block in blocks)


def test_table_3_gives_shares_of_a_rows_successes_only_across_several_speeds():
    one_speed = [_sample(i, outcome="success" if i % 2 else "no_crash") for i in range(10)]
    t3 = table_by_speed(one_speed)
    assert t3.rows == (("knots bo rest", "5", "5"),) and "share" not in t3.title  # once "5 (100.0%)"
    two = one_speed + [_sample(10 + i, speed_mps=30.0) for i in range(15)]
    t3 = table_by_speed(two)
    assert t3.rows == (("knots bo rest", "20", "5 (25.0%)", "15 (75.0%)"),)
    assert "the share of the row's successes" in t3.title


# --- campaigns of different scenarios ------------------------------------------------------------------


def _two_roads(path):
    """Two campaigns on one network, on two routes with two durations, their successes far apart."""
    from d4sumo.search.campaign import Campaign, open_store
    from d4sumo.search.store import collision_dict

    with open_store(path) as store:
        for route, duration_s, position_m in ((("A0B0", "B0C0"), 80.0, 100.0), (("A1B1", "B1C1"), 60.0, 500.0)):
            config = EpisodeConfig(network="grid.net.xml", route=route, duration_s=duration_s)
            cid = store.open_campaign(Campaign(config=config, optimizer="random").definition(), 2)
            for i in range(2):
                store.add_sample(cid, i, (0.0,) * 9, 0.5, "success", collision_dict("v1-v2", 20.0, position_m, 10.0),
                                 {"v0-v1": 3.0, "v1-v2": -0.1, "v2-v3": 4.0}, 0.1)
    return load_records([path])


def test_campaigns_on_two_routes_of_one_network_are_never_pooled(tmp_path):
    """Regression: two campaigns on one network, on different routes and durations, were one row of
    Table 1, its collision location the mean over both roads (300 m, a place neither crash was near)."""
    from d4sumo.results.analysis import scenario_labels

    records = _two_roads(tmp_path / "r.sqlite")
    t1 = table_success_statistics(records)
    location = t1.header.index("collision location m, mean (std)")
    assert [(row[0], row[location]) for row in t1.rows] == [
        ("route=[A0B0 B0C0], duration_s=80 knots random", "100.0 (0.0)"),
        ("route=[A1B1 B1C1], duration_s=60 knots random", "500.0 (0.0)")]
    assert len(table_attacker_crashes(records).header) == 3 and len(table_by_speed(records).rows) == 2
    assert len(most_severe(records, 3)) == 2  # two configurations
    assert sorted(scenario_labels(records).values()) == ["route=[A0B0 B0C0], duration_s=80",
                                                         "route=[A1B1 B1C1], duration_s=60"]
    assert scenario_labels(records[:2]) == {records[0].scenario: ""}  # one scenario: nothing to set apart


def test_heatmap_panels_and_clusters_name_the_scenario_they_show(tmp_path):
    from d4sumo.results.clusters import richest_conditions
    from d4sumo.results.figures import heatmap_panels

    records = _two_roads(tmp_path / "r.sqlite")
    names = [name for name, _ in heatmap_panels(records)]
    assert names == ["route=[A0B0 B0C0], duration_s=80: knots, RANDOM, start rest",
                     "route=[A1B1 B1C1], duration_s=60: knots, RANDOM, start rest"]
    assert [c for c, _ in richest_conditions(records)] == [
        "route=[A0B0 B0C0], duration_s=80: knots random, rest, setpoint 7 m, 25 m/s",
        "route=[A1B1 B1C1], duration_s=60: knots random, rest, setpoint 7 m, 25 m/s"]
    several = [dataclasses.replace(r, system="sumo:ACC") for r in records[:2]] + records
    assert [name for name, _ in heatmap_panels(several)][0] == ("route=[A0B0 B0C0], duration_s=80 sumo:ACC",
                                                                "knots, RANDOM, start rest")


def test_a_key_without_effect_sets_no_scenario_apart_and_one_left_out_at_zero_does(tmp_path):
    """A sweep over start modes stores warmup_s for its warm-up campaigns alone: still one scenario, as
    before. collision_gap_m is stored only where set, yet a campaign at 0 m and one at 0.05 m are two."""
    from d4sumo.results.analysis import scenario_labels
    from d4sumo.results.records import scenario_of

    starts = [EpisodeConfig(start=start) for start in ("rest", "steady", "warmup")]
    assert len({scenario_of(c) for c in starts}) == 2  # warmup_s is the warm-up's alone
    records = [_record_of(c, i) for i, c in enumerate(starts)]
    assert set(scenario_labels(records).values()) == {""}
    assert [row[0] for row in table_success_statistics(records).rows] == ["knots bo"]
    gaps = [_record_of(EpisodeConfig(collision_gap_m=g), i) for i, g in enumerate((0.0, 0.05))]
    assert sorted(scenario_labels(gaps).values()) == ["collision_gap_m=0", "collision_gap_m=0.05"]
    assert len(table_success_statistics(gaps).rows) == 2
    maneuvers = [_record_of(EpisodeConfig(maneuver=m, start="steady"), i) for i, m in enumerate(("inlane", "cutin"))]
    assert [row[0] for row in table_success_statistics(maneuvers).rows] == ["maneuver=cutin knots bo",
                                                                           "maneuver=inlane knots bo"]


def _record_of(config, i):
    from d4sumo.results.records import scenario_of

    return _record([0] * 9, sample_id=i, start=config.start, scenario=scenario_of(config))



# --- crashes among traffic --------------------------------------------------------------------------


@pytest.mark.parametrize("pair, kind", [("v1-v2", "followers"), ("traffic.0.3-v2", "follower into traffic"),
                                        ("v3-traffic.ramp.12", "traffic into follower"), ("v0-v1", "attacker and a follower"),
                                        ("traffic.1.0-v0", "attacker into traffic"), ("v0-traffic.1.0", "traffic into attacker")])
def test_a_first_collision_among_traffic_says_who_ran_into_whom(pair, kind):
    from d4sumo.results.analysis import crash_kind

    assert crash_kind(pair) == kind


def test_campaigns_alone_and_among_traffic_are_other_scenarios_and_their_crashes_are_told_apart():
    from d4sumo.results.analysis import has_traffic, scenario_labels, table_crash_kinds
    from d4sumo.results.records import scenario_of

    alone = EpisodeConfig(start="steady")
    busy = dataclasses.replace(alone, traffic={"vehicles_per_hour": 1500})
    records = [_record([0] * 9, sample_id=0, scenario=scenario_of(alone)),
               _record([0] * 9, sample_id=1, scenario=scenario_of(busy), pair="traffic.0.4-v2"),
               _record([0] * 9, sample_id=2, scenario=scenario_of(busy), pair="v3-traffic.0.9"),
               _record([0] * 9, sample_id=3, scenario=scenario_of(busy), pair="traffic.0.1-v0", outcome="attacker_crash")]
    labels = scenario_labels(records)
    assert labels[scenario_of(alone)] == "traffic=none" and labels[scenario_of(busy)] == "traffic=1500 veh/h/lane, seed 0"
    assert has_traffic(records) and not has_traffic(records[:1])
    table = table_crash_kinds(records)
    rows = {row[0]: row[1:] for row in table.rows}
    busy_row = next(v for k, v in rows.items() if "1500" in k)
    assert busy_row == ("3", "0", "1", "1", "0", "1", "0")  # samples, then each kind in CRASH_KINDS' order


def test_how_near_the_traffic_came_to_each_car_of_the_platoon_and_whether_it_ever_met_it():
    from d4sumo.results.analysis import TRAFFIC_MEETS_M, nearest_traffic, traffic_nearness_text

    cars = ("v0", "v1", "v2", "v3")
    samples = [{"traffic-v0": 40.0, "v0-v1": 3.0, "v3-traffic": 250.0}, {"traffic-v0": 25.5, "v1-traffic": 80.0, "traffic-v2": 12.0}]
    assert nearest_traffic(samples, cars) == {"v0": 25.5, "v1": 80.0, "v2": 12.0, "v3": 250.0}
    text, met = traffic_nearness_text(nearest_traffic(samples, cars))
    assert text == "traffic: nearest to v0 25.5 m, v1 80.0 m, v2 12.0 m, v3 250.0 m" and met
    far = [{"traffic-v0": TRAFFIC_MEETS_M + 805.0}]  # a demand that departs far from the platoon (issue 48: 905 m)
    assert traffic_nearness_text(nearest_traffic(far, cars)) == ("traffic: nearest to v0 905.0 m", False)
    assert traffic_nearness_text(nearest_traffic([{"v0-v1": 3.0}], cars))[1] is False
    assert traffic_nearness_text(nearest_traffic([{"traffic-v0": -0.04}], cars)) == ("traffic: nearest to v0 collided with it", True)


@pytest.mark.sumo
def test_falsify_among_traffic_that_never_meets_the_platoon_says_so(tmp_path, capsys):
    from d4sumo.cli import main

    assert main(["falsify", "--start", "steady", "--duration", "10", "--set", "traffic.vehicles_per_hour=1",
                 "--set", "traffic.warmup_s=5", "--optimizer", "random", "--samples", "2", "--db", str(tmp_path / "r.sqlite"),
                 "--quiet"]) == 0
    captured = capsys.readouterr()
    assert "traffic: none ever ahead of or behind a car of the platoon" in captured.out
    assert "the traffic never came within 100 m of a car of the platoon in 2 samples: this campaign played as if alone" in captured.err



def test_the_report_keeps_a_table_of_a_few_columns_whole_in_tables_txt():
    """Issue 48: tables.txt split Table 1 of a single campaign (7 columns, long headers) into "continued" blocks."""
    from d4sumo.results.analysis import table_success_statistics
    from d4sumo.results.report import TEXT_WIDTH

    text = table_success_statistics([_sample(i) for i in range(4)]).to_text(width=TEXT_WIDTH)
    assert "continued" not in text


def test_crashes_are_told_apart_by_pair_time_and_how_hard():
    from d4sumo.results.analysis import crash_kinds, distinct_text

    crash = {"pair": "v1-v2", "time_s": 8.1, "position_m": 60.0, "speed_diff_kmh": 21.0}
    alike = [crash, {**crash, "time_s": 9.9, "speed_diff_kmh": 29.9}, {**crash, "position_m": 99.0}]
    assert crash_kinds(alike) == 1
    assert crash_kinds([*alike, {**crash, "pair": "v2-v3"}, {**crash, "time_s": 10.0}, {**crash, "speed_diff_kmh": 30.0}]) == 4
    assert crash_kinds([]) == 0
    assert distinct_text(1, 1).startswith("distinct successes: 1 attack (parameters more than 5% of their range apart), 1 kind ")
