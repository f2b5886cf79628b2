"""The paper's own numbers, and our records set beside them (pure data: no SUMO, no plotting).

The numbers are typed in from the paper's LaTeX source: Table 1 (tab:res_statistics), Table 2
(tab:res_attack_crash) and Table 3 (tab:res_statistics_2). `comparisons` builds, for whichever of the
paper's grids the records cover, the same table with the paper's row and ours one under the other;
the report shows them, and `tools/paper_page.py` writes them into docs/paper.md.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass
from typing import Sequence

import numpy as np

from .analysis import scenario_labels
from .records import Record

#: Table 1, per row: crashes, v1-v2 crashes, time till collision mean (std) s, collision location
#: mean (std) m, speed difference mean (std) km/h. Parametric attacks, 2-9 m, 20 m/s, steady state.
TABLE_1 = {
    ("persistent", "bo"): (246, 155, (18.3, 3.6), (87.6, 55.6), (8.9, 4.0)),
    ("persistent", "ce"): (185, 112, (17.8, 2.9), (79.0, 40.7), (8.7, 3.3)),
    ("intermittent", "bo"): (178, 82, (17.1, 6.5), (70.6, 112.6), (6.7, 3.8)),
    ("intermittent", "ce"): (169, 83, (28.9, 10.4), (258.8, 166.2), (5.9, 4.7)),
}
#: Table 2: (attacker crashes, no crash) at setpoints 2, 3, 4, 5 m
TABLE_2_SETPOINTS = (2.0, 3.0, 4.0, 5.0)
TABLE_2 = {
    ("persistent", "bo"): ((100, 0), (100, 0), (100, 0), (9, 0)),
    ("persistent", "ce"): ((100, 0), (99, 1), (96, 3), (32, 4)),
    ("intermittent", "bo"): ((84, 9), (89, 11), (90, 8), (0, 11)),
    ("intermittent", "ce"): ((40, 38), (33, 27), (32, 36), (0, 32)),
}
#: Table 3: knot successes in all and at 20, 25, 30 m/s, by optimiser and start ("Stable": steady)
TABLE_3_SPEEDS = (20.0, 25.0, 30.0)
TABLE_3 = {
    ("bo", "rest"): (1594, (467, 473, 654)),
    ("ce", "rest"): (369, (122, 77, 170)),
    ("bo", "steady"): (1840, (664, 619, 557)),
    ("ce", "steady"): (869, (244, 281, 344)),
}
PARAMETRIC_SPEED_MPS = 20.0
#: the setpoints the paper's totals add up: Tables 1 (2-9 m) and 3 (3-15 m)
TABLE_1_SETPOINTS = tuple(float(d) for d in range(2, 10))
TABLE_3_SETPOINTS = tuple(float(d) for d in range(3, 16))
PART = "ours (part of the grid)"  # a row whose runs do not cover the paper's: its counts are not comparable


@dataclass(frozen=True)
class Comparison:
    """One of the paper's tables with our rows beside its rows: rows are (label, who, cells, far) where
    ``far`` flags each cell whose count is off the paper's by more than a factor of two."""

    title: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, str, tuple[str, ...], tuple[bool, ...]], ...]


def _wins(records: Sequence[Record], **where) -> list[Record]:
    return [r for r in records if r.outcome == "success" and all(getattr(r, k) == v for k, v in where.items())]


def _mean_std(values) -> str:
    return f"{np.mean(values):.1f} ({np.std(values):.1f})" if len(values) else "-"


def _far(ours: float, paper: float) -> bool:
    """More than a factor of two apart (counts of zero: any difference of more than 5)."""
    if min(ours, paper) <= 0:
        return abs(ours - paper) > 5
    return bool(max(ours, paper) / min(ours, paper) > 2.0)


def _parametric(records: Sequence[Record]) -> list[Record]:
    return [r for r in records if r.attack in ("persistent", "intermittent") and r.start == "steady"
            and r.speed_mps == PARAMETRIC_SPEED_MPS and r.system == "switching" and r.maneuver == "inlane"]


def _knots(records: Sequence[Record]) -> list[Record]:
    return [r for r in records if r.attack == "knots" and r.start in ("rest", "steady")
            and r.speed_mps in TABLE_3_SPEEDS and r.system == "switching" and r.maneuver == "inlane"]


def table_1(records: Sequence[Record]) -> Comparison | None:
    par = _parametric(records)
    if not par:
        return None
    rows = []
    for (attack, optimizer), paper in TABLE_1.items():
        if not any(r.attack == attack and r.optimizer == optimizer for r in par):
            continue
        label = f"{attack} {optimizer.upper()}"
        whole = {r.setpoint_m for r in par if r.attack == attack and r.optimizer == optimizer} >= set(TABLE_1_SETPOINTS)
        rows.append((label, "paper", (str(paper[0]), f"{paper[1]} ({100 * paper[1] / paper[0]:.0f}%)",
                                      *(f"{m:.1f} ({s:.1f})" for m, s in paper[2:])), (False,) * 5))
        ours = _wins(par, attack=attack, optimizer=optimizer)
        v12 = sum(r.pair == "v1-v2" for r in ours)
        cells = (str(len(ours)), f"{v12} ({100 * v12 / len(ours):.0f}%)" if ours else "0",
                 _mean_std([r.time_from_attack_start_s for r in ours]), _mean_std([r.position_m for r in ours]),
                 _mean_std([r.speed_diff_kmh for r in ours]))
        means = [float(np.mean(v)) if v else 0.0 for v in ([r.time_from_attack_start_s for r in ours],
                                                    [r.position_m for r in ours], [r.speed_diff_kmh for r in ours])]
        far = (_far(len(ours), paper[0]), _far(v12, paper[1]), *(_far(m, p[0]) for m, p in zip(means, paper[2:])))
        rows.append(("", "ours", cells, far) if whole else ("", PART, cells, (False,) * 5))
    return Comparison("Table 1: successful parametric attacks (steady state, 20 m/s)",
                      ("attack", "", "successes", "v1-v2 crashes", "time to collision s", "collision location m",
                       "speed difference km/h"), tuple(rows))


def table_2(records: Sequence[Record]) -> Comparison | None:
    par = [r for r in _parametric(records) if r.setpoint_m in TABLE_2_SETPOINTS]
    if not par:
        return None
    rows = []
    for (attack, optimizer), paper in TABLE_2.items():
        if not any(r.attack == attack and r.optimizer == optimizer for r in par):
            continue
        rows.append((f"{attack} {optimizer.upper()}", "paper", tuple(f"{a} / {n}" for a, n in paper), (False,) * 4))
        cells, far = [], []
        for d, (paper_crashes, _) in zip(TABLE_2_SETPOINTS, paper):
            rs = [r for r in par if r.attack == attack and r.optimizer == optimizer and r.setpoint_m == d]
            crashes = sum(r.outcome == "attacker_crash" for r in rs)
            cells.append(f"{crashes} / {sum(r.outcome == 'no_crash' for r in rs)}" if rs else "-")
            far.append(bool(rs) and _far(crashes, paper_crashes))
        rows.append(("", "ours", tuple(cells), tuple(far)))
    return Comparison("Table 2: attacker crashes / no-crash samples at 2-5 m",
                      ("attack", "", *(f"{d:g} m" for d in TABLE_2_SETPOINTS)), tuple(rows))


def table_3(records: Sequence[Record]) -> Comparison | None:
    knots = _knots(records)
    if not knots:
        return None
    rows = []
    for (optimizer, start), (total, by_speed) in TABLE_3.items():
        if not any(r.optimizer == optimizer and r.start == start for r in knots):
            continue
        label = f"knots {optimizer.upper()} {start}"
        rows.append((label, "paper", (str(total), *(f"{n} ({100 * n / total:.1f}%)" for n in by_speed)), (False,) * 4))
        run = [r for r in knots if r.optimizer == optimizer and r.start == start]
        speeds = {r.speed_mps for r in run}
        whole = speeds >= set(TABLE_3_SPEEDS) and {r.setpoint_m for r in run} >= set(TABLE_3_SETPOINTS)
        ours = _wins(run)
        counts = [sum(r.speed_mps == v for r in ours) for v in TABLE_3_SPEEDS]
        shares = ours and speeds >= set(TABLE_3_SPEEDS)  # a share of one speed's successes alone is 100%, always
        cells = (str(len(ours)), *((f"{n} ({100 * n / len(ours):.1f}%)" if shares else str(n)) if v in speeds else "-"
                                   for n, v in zip(counts, TABLE_3_SPEEDS)))
        far = (_far(len(ours), total), *(_far(n, p) for n, p in zip(counts, by_speed)))
        rows.append(("", "ours", cells, far) if whole else ("", PART, cells, (False,) * 4))
    return Comparison("Table 3: successful knot attacks by target speed (in brackets: the share of the row's successes "
                      "at that speed, as the paper gives it; ours only where the row ran all three speeds)",
                      ("attack", "", "successes", *(f"{v:g} m/s" for v in TABLE_3_SPEEDS)), tuple(rows))


def comparisons(records: Sequence[Record]) -> list[Comparison]:
    """The paper's tables that the records' grids cover, with our rows beside them; one set per scenario
    when the records hold several (never pooled: a collision location means something else on another
    road), each title naming its scenario."""
    records = [r for r in records if not r.situation]  # the paper's grid fixed each campaign's situation
    labels = scenario_labels(records)
    by_scenario: dict[str, list[Record]] = {}
    for r in records:
        by_scenario.setdefault(labels[r.scenario], []).append(r)
    out = []
    for name, rs in sorted(by_scenario.items()):
        for c in (table_1(rs), table_2(rs), table_3(rs)):
            if c is not None and c.rows:
                out.append(dataclasses.replace(c, title=f"{c.title}: {name}") if name else c)
    return out


def to_markdown(c: Comparison) -> list[str]:
    lines = ["| " + " | ".join(c.header) + " |", "|" + "---|" * len(c.header)]
    for label, who, cells, far in c.rows:
        shown = [f"**{cell}**" if f else cell for cell, f in zip(cells, far)]
        lines.append(f"| {label} | {who} | " + " | ".join(shown) + " |")
    return lines
