"""The paper's numbers beside ours: pure data, synthetic records."""

from __future__ import annotations

import dataclasses

from d4sumo.results.records import Record
from d4sumo.results.paper import PART, TABLE_1, comparisons, table_1, table_2, table_3, to_markdown


def record(**changes) -> Record:
    r = Record("db", 0, 0, "highway_4lane", 3, 5.0, 20.0, "steady", "persistent", "bo", 0, None, (0.5, 0.1, 2.0), 0.2,
               "success", "v1-v2", 20.0, 100.0, 9.0)
    return dataclasses.replace(r, **changes)


def test_the_paper_tables_come_only_for_the_grids_the_records_cover():
    assert comparisons([record(attack="knots", optimizer="random", start="rest")]) == []  # not one of the paper's rows
    assert comparisons([record(speed_mps=25.0)]) == []  # the paper's parametric runs were at 20 m/s
    assert comparisons([record(system="sumo:ACC")]) == []  # nor another system under test
    # nor a campaign that searched its situation: its samples' cells are no campaigns of the grid
    assert comparisons([record(situation=(("setpoint_m", 5.3), ("speed_mps", 20.4)))]) == []
    titles = [c.title for c in comparisons([record()])]
    assert titles == ["Table 1: successful parametric attacks (steady state, 20 m/s)",
                      "Table 2: attacker crashes / no-crash samples at 2-5 m"]


def test_our_rows_sit_under_the_papers_and_far_cells_are_flagged():
    records = [record(sample_id=i, setpoint_m=float(2 + i % 8)) for i in range(600)]  # 600 successes against 246: far
    records += [record(sample_id=1000 + i, setpoint_m=2.0, outcome="attacker_crash", pair="v0-v1") for i in range(100)]
    t1 = table_1(records)
    (label, who, cells, far), (_, ours, our_cells, our_far) = t1.rows
    assert (label, who, cells[0]) == ("persistent BO", "paper", str(TABLE_1[("persistent", "bo")][0]))
    assert ours == "ours" and our_cells[0] == "600" and our_far[0] is True
    assert our_cells[1] == "600 (100%)" and our_far[1] is True  # 600 v1-v2 crashes against 155
    assert our_cells[4] == "9.0 (0.0)" and our_far[4] is False  # 9.0 km/h against 8.9
    t2 = table_2(records)
    assert t2.rows[1][2][0] == "100 / 0" and t2.rows[1][3][0] is False  # 100 attacker crashes at 2 m, as the paper
    assert "**600**" in "\n".join(to_markdown(t1))


def test_a_grid_that_covers_part_of_the_papers_flags_nothing_and_shows_what_did_not_run():
    """Regression: a report of a sweep at 25 m/s only showed 0 successes at 20 and 30 m/s in bold, as if
    we had contradicted the paper there, and compared its totals with the paper's whole grid."""
    knots = [record(sample_id=i, attack="knots", start="rest", speed_mps=25.0, setpoint_m=float(5 + 2 * (i % 2)))
             for i in range(300)]
    (_, _, _, _), (_, who, cells, far) = table_3(knots).rows
    assert who == PART and cells == ("300", "-", "300", "-") and far == (False,) * 4
    (_, _, _, _), (_, who, _, far) = table_1([record(sample_id=i) for i in range(600)]).rows  # at 5 m only
    assert who == PART and far == (False,) * 5


def test_a_share_by_speed_is_given_only_where_a_row_ran_every_speed_as_the_paper_did():
    """Regression: a sweep at 25 m/s alone showed "229 (100.0%)" beside the paper's "473 (29.7%)": the
    paper's share of its row's successes at 20, 25 and 30 m/s, ours of one speed, 100% by construction."""
    one = [record(sample_id=i, attack="knots", start="rest", speed_mps=25.0) for i in range(229)]
    t3 = table_3(one)
    (_, _, paper_cells, _), (_, _, cells, _) = t3.rows
    assert paper_cells[2] == "473 (29.7%)" and cells == ("229", "-", "229", "-")
    assert "share of the row's successes at that speed" in t3.title
    every = one + [record(sample_id=1000 + i, attack="knots", start="rest", speed_mps=v) for i, v in
                   enumerate([20.0] * 100 + [30.0] * 171)]
    assert table_3(every).rows[1][2] == ("500", "100 (20.0%)", "229 (45.8%)", "171 (34.2%)")


def test_each_scenario_is_set_beside_the_paper_on_its_own():
    """Two roads are never pooled: a collision location means something else on each."""
    records = [record(sample_id=i, scenario=(("network", "highway_4lane"),)) for i in range(3)]
    records += [record(sample_id=10 + i, network="mine", scenario=(("network", "mine"),), position_m=900.0)
                for i in range(3)]
    compared = comparisons(records)
    assert [c.title for c in compared] == [
        "Table 1: successful parametric attacks (steady state, 20 m/s): network=highway_4lane",
        "Table 2: attacker crashes / no-crash samples at 2-5 m: network=highway_4lane",
        "Table 1: successful parametric attacks (steady state, 20 m/s): network=mine",
        "Table 2: attacker crashes / no-crash samples at 2-5 m: network=mine"]
    assert [c.rows[1][2][3] for c in compared if c.title.startswith("Table 1")] == ["100.0 (0.0)", "900.0 (0.0)"]
