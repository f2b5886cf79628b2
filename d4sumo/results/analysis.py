"""The paper's analysis of stored samples: its Tables 1-3, the success grids, the most severe attacks,
and how many of a set of attacks are distinct.

Pure computations on records (`records` reads them from the databases; no SUMO, no plotting):
`clusters` groups knot vectors, `figures` draws, `report` assembles.
"""

from __future__ import annotations

from collections import defaultdict
from dataclasses import dataclass
from typing import Callable, Iterable, Sequence

import numpy as np

from .records import Record


def group(records: Iterable[Record], *fields: str) -> dict[tuple, list[Record]]:
    return _grouped(records, lambda r: tuple(getattr(r, f) for f in fields))


def _grouped(records: Iterable[Record], key: Callable[[Record], tuple]) -> dict[tuple, list[Record]]:
    out: dict[tuple, list[Record]] = defaultdict(list)
    for r in records:
        out[key(r)].append(r)
    return dict(sorted(out.items(), key=lambda kv: tuple(str(k) for k in kv[0])))


def scenario_labels(records: Iterable[Record]) -> dict[tuple, str]:
    """Each scenario of the records named by what sets it apart from the others: the keys it holds whose
    values differ among the scenarios that hold them ("route=[A0B0 B0C0], duration_s=80"). A key a scenario
    does not hold has no effect there (warmup_s without a warm-up) and sets nothing apart, so that two
    scenarios may share a name: they are one scenario to the tables. Scenarios alike in every key are ""."""
    scenarios = list(dict.fromkeys(r.scenario for r in records))
    values: dict[str, set] = defaultdict(set)
    for s in scenarios:
        for k, v in s:
            values[k].add(_hashable(v))
    # a path by its file's name where that tells the values apart (a network, a demand file): labels stay readable
    short = {k: len({_short(v) for v in vs}) == len(vs) for k, vs in values.items()}
    return {s: ", ".join(f"{k}={_value_text(_short(v) if short[k] else v)}" for k, v in s if len(values[k]) > 1)
            for s in scenarios}


def _short(value):
    if isinstance(value, (list, tuple)):
        return tuple(_short(v) for v in value)
    name = value.rsplit("/", 1)[-1] if isinstance(value, str) else ""
    return name if "." in name else value  # a file's (corridor.net.xml), not a rate's (1800 veh/h/lane)


def _hashable(value):
    return tuple(value) if isinstance(value, list) else value


def _value_text(value) -> str:
    if isinstance(value, (list, tuple)):
        return "[" + " ".join(map(str, value)) + "]"
    return f"{value:g}" if isinstance(value, float) else str(value)


def runs(records: Sequence[Record], *fields: str) -> tuple[tuple[str, ...], dict[tuple, list[Record]]]:
    """Group by ``fields``, led by the scenario (by its name in `scenario_labels`) and the system under test
    when the records hold more than one: campaigns on two roads, routes or durations are never pooled. An
    attack is its family with its lie, if any ("knots with a lie (offset on its speed)"): nor are campaigns
    with and without one."""
    labels = scenario_labels(records)
    lead = (("scenario",) if len(set(labels.values())) > 1 else ()) + (
        ("system",) if len({r.system for r in records}) > 1 else ())

    def value(r: Record, f: str):
        if f == "scenario":
            return labels[r.scenario]
        if f == "attack":
            return attack_label(r)
        return getattr(r, f)

    return lead + fields, _grouped(records, lambda r: tuple(value(r, f) for f in (*lead, *fields)))


def attack_label(record: Record) -> str:
    """The attack of a record's campaign: its family, with its lie where it has one."""
    return f"{record.attack} with {record.lie}" if record.lie else record.attack


def run_label(key: tuple) -> str:
    """A group's key as words; a scenario named "" (the one the others are set apart from) says nothing."""
    return " ".join(str(k) for k in key if k != "")


def count_noun(count: int, singular: str, plural: str | None = None) -> str:
    """'1 cluster', '2 clusters', '0 successes': the count with the noun in the right number."""
    return f"{count} {singular if count == 1 else plural or singular + 's'}"


def _mean_std(values: list[float]) -> str:
    if not values:
        return "-"
    return f"{np.mean(values):.1f} ({np.std(values):.1f})"


@dataclass(frozen=True)
class Table:
    title: str
    header: tuple[str, ...]
    rows: tuple[tuple[str, ...], ...]

    def to_text(self, width: int = 100) -> str:
        """The table as text, its lines at most ``width`` characters where the columns allow: a table
        wider than that (a sweep of many systems) goes on in blocks of columns, each led by the first."""
        widths = [max(len(str(x)) for x in col) for col in zip(self.header, *self.rows)]
        blocks: list[list[int]] = [[]]
        used = widths[0]
        for i in range(1, len(widths)):
            if blocks[-1] and used + 2 + widths[i] > width:
                blocks.append([])
                used = widths[0]
            blocks[-1].append(i)
            used += 2 + widths[i]
        out = []
        for b, columns in enumerate(blocks):
            shown = [0, *columns]
            line = lambda cells: "  ".join(  # noqa: E731
                str(cells[i]).rjust(widths[i]) if i else str(cells[i]).ljust(widths[i]) for i in shown).rstrip()
            title = self.title if b == 0 else f"{self.title} (continued, {b + 1} of {len(blocks)})"
            out.append("\n".join([title, line(self.header), *(line(r) for r in self.rows)]))
        return "\n\n".join(out)


def table_success_statistics(records: Sequence[Record]) -> Table:
    """The paper's Table 1: per attack and optimiser, the successes and their collisions."""
    rows = []
    for key, rs in runs(records, "attack", "optimizer")[1].items():
        wins = [r for r in rs if r.outcome == "success"]
        v12 = sum(1 for r in wins if r.pair == "v1-v2")
        rows.append((
            run_label(key), str(len(rs)), str(len(wins)),
            f"{v12} ({100 * v12 / len(wins):.0f}%)" if wins else "0",
            _mean_std([r.time_from_attack_start_s for r in wins]), _mean_std([r.position_m for r in wins]),
            _mean_std([r.speed_diff_kmh for r in wins]),
        ))
    return Table(
        "Table 1: successful attacks (followers collide, attacker untouched)",
        ("attack", "samples", "successes", "v1-v2 crashes", "time from attack start to collision s, mean (std)",
         "collision location m, mean (std)", "speed difference km/h, mean (std)"),
        tuple(rows),
    )


def table_attacker_crashes(records: Sequence[Record]) -> Table:
    """The paper's Table 2: per setpoint, attacker crashes / no-crash samples of each attack and optimiser."""
    groups = runs(records, "attack", "optimizer")[1]
    rows = []
    for d in sorted({r.setpoint_m for r in records}):
        cells = [f"{d:g} m"]
        for rs in groups.values():
            sub = [r for r in rs if r.setpoint_m == d]
            crashes = sum(r.outcome == "attacker_crash" for r in sub)
            cells.append(f"{crashes} / {sum(r.outcome == 'no_crash' for r in sub)}" if sub else "-")
        rows.append(tuple(cells))
    header = ("setpoint", *[run_label(key) for key in groups])
    return Table("Table 2: attacker crashes / no-crash samples per setpoint", header, tuple(rows))


def table_by_speed(records: Sequence[Record]) -> Table:
    """The paper's Table 3: successes per optimiser and start mode, split by target speed; with several
    speeds, each with its share of the row's successes (how they split by speed, not a success rate)."""
    speeds = sorted({r.speed_mps for r in records})
    rows = []
    for key, rs in runs(records, "attack", "optimizer", "start")[1].items():
        wins = [r for r in rs if r.outcome == "success"]
        cells = [run_label(key), str(len(wins))]
        for v in speeds:
            n = sum(1 for r in wins if r.speed_mps == v)
            cells.append(f"{n} ({100 * n / len(wins):.1f}%)" if wins and len(speeds) > 1 else str(n))
        rows.append(tuple(cells))
    title = "Table 3: successes by target speed"
    if len(speeds) > 1:
        title += " (in brackets: the share of the row's successes at that speed)"
    return Table(title, ("attack", "successes", *[f"{v:g} m/s" for v in speeds]), tuple(rows))


def table_systems(records: Sequence[Record]) -> Table:
    """Per system under test (and scenario, when the records hold several): how often an attacker made it
    crash, where, and how hard."""
    labels = scenario_labels(records)
    rows = []
    for key, rs in _grouped(records, lambda r: (labels[r.scenario], r.system)).items():
        wins = [r for r in rs if r.outcome == "success"]
        setpoints = sorted({r.setpoint_m for r in wins})
        rows.append((
            run_label(key), str(len(rs)), f"{len(wins)} ({100 * len(wins) / len(rs):.1f}%)",
            str(sum(r.outcome == "attacker_crash" for r in rs)),
            ", ".join(f"{d:g}" for d in setpoints) or "none",
            f"{max(r.speed_diff_kmh for r in wins):.1f}" if wins else "-",
            _mean_std([r.time_from_attack_start_s for r in wins]),
        ))
    return Table("Systems under test: successful attacks",
                 ("system", "samples", "successes", "attacker crashes", "setpoints with a success m",
                  "worst speed difference km/h", "time from attack start to collision s, mean (std)"), tuple(rows))


#: the kinds of first collision among traffic, by who ran into whom (`crash_kind`)
CRASH_KINDS = ("followers", "follower into traffic", "traffic into follower", "attacker and a follower",
               "attacker into traffic", "traffic into attacker")


def crash_kind(pair: str) -> str:
    """What a first collision ``leader-follower`` was: between followers, a follower and a traffic car
    (which ran into which), or the attacker's."""
    leader, _, follower = pair.partition("-")
    traffic = lambda vid: not (vid[:1] == "v" and vid[1:].isdigit())  # noqa: E731 (ids of traffic are SUMO's)
    if "v0" in (leader, follower):
        return ("attacker into traffic" if traffic(leader) else "traffic into attacker" if traffic(follower)
                else "attacker and a follower")
    return "follower into traffic" if traffic(leader) else "traffic into follower" if traffic(follower) else "followers"


def has_traffic(records: Sequence[Record]) -> bool:
    return any(dict(r.scenario).get("traffic", "none") != "none" for r in records)


def table_crash_kinds(records: Sequence[Record]) -> Table:
    """Among traffic: per run, the samples whose first collision was of each kind (`crash_kind`). The
    first three are successes (the followers crashed, the attacker untouched), the last three attacker crashes."""
    rows = []
    for key, rs in runs(records, "attack", "optimizer")[1].items():
        kinds = [crash_kind(r.pair) for r in rs if r.pair and r.outcome in ("success", "attacker_crash")]
        rows.append((run_label(key), str(len(rs)), *(str(kinds.count(k)) for k in CRASH_KINDS)))
    return Table("Crashes among traffic: who ran into whom first (successes: the first three kinds)",
                 ("attack", "samples", *CRASH_KINDS), tuple(rows))


#: Two successes closer than this in every parameter (as a fraction of its range) are one attack.
DISTINCT_RADIUS = 0.05


def distinct_count(params: Sequence[Sequence[float]], lower: Sequence[float], upper: Sequence[float],
                   radius: float = DISTINCT_RADIUS) -> int:
    """How many of the given attacks are distinct: in order, an attack counts unless an attack already
    counted lies within ``radius`` of its parameter range in every parameter (an optimiser that
    resamples its best attack with tiny changes finds one attack, not many)."""
    lower, upper = np.asarray(lower, float), np.asarray(upper, float)
    span = np.where(upper > lower, upper - lower, 1.0)
    kept: list[np.ndarray] = []
    for p in params:
        z = (np.asarray(p, float) - lower) / span
        if all(np.max(np.abs(z - k)) > radius for k in kept):
            kept.append(z)
    return len(kept)


#: two crashes of one pair are one kind where their times fall in one bin of this many seconds and their speed
#: differences in one of this many km/h (`crash_kinds`)
CRASH_TIME_S, CRASH_SPEED_KMH = 2.0, 10.0


def crash_kinds(collisions: Sequence[dict]) -> int:
    """How many kinds of crash these first collisions are: which pair collided, when (in buckets of `CRASH_TIME_S`)
    and how hard (in buckets of `CRASH_SPEED_KMH` of speed difference)."""
    return len({(c["pair"], int(c["time_s"] // CRASH_TIME_S), int(c["speed_diff_kmh"] // CRASH_SPEED_KMH))
                for c in collisions})


def distinct_text(distinct: int, kinds: int) -> str:
    """A campaign's distinct successes in words."""
    return (f"distinct successes: {distinct} attack{'s' * (distinct != 1)} (parameters more than "
            f"{DISTINCT_RADIUS:.0%} of their range apart), {kinds} kind{'s' * (kinds != 1)} of crash (by the pair, the "
            f"time in {CRASH_TIME_S:g} s bins and the speed difference in {CRASH_SPEED_KMH:g} km/h bins)")


def success_grid(records: Sequence[Record], setpoints: Sequence[float] | None = None,
                 speeds: Sequence[float] | None = None) -> tuple[list[float], list[float], np.ndarray]:
    """Successes over setpoint (rows) x speed (columns); the axes default to the values in ``records``."""
    setpoints = sorted({r.setpoint_m for r in records}) if setpoints is None else list(setpoints)
    speeds = sorted({r.speed_mps for r in records}) if speeds is None else list(speeds)
    grid = np.zeros((len(setpoints), len(speeds)), dtype=int)
    for r in records:
        if r.outcome == "success":
            grid[setpoints.index(r.setpoint_m), speeds.index(r.speed_mps)] += 1
    return setpoints, speeds, grid


def most_severe(records: Sequence[Record], count: int = 3) -> list[Record]:
    """The ``count`` successes with the largest speed difference at the first collision, no two of one
    configuration (`Record.configuration`: campaigns that differ in their seed alone are one): each
    configuration's most severe success competes, so that one campaign's near-copies of its best attack
    do not fill the list."""
    wins = [r for r in records if r.outcome == "success" and r.speed_diff_kmh is not None]
    chosen: dict[tuple, Record] = {}
    for r in sorted(wins, key=lambda r: (-r.speed_diff_kmh, r.db, r.sample_id)):
        if len(chosen) == count:
            break
        chosen.setdefault(r.configuration, r)
    return list(chosen.values())



#: traffic this near a car of the platoon is traffic it meets [m]: within what its ACC and the attacker's careful
#: driver react to (a 1.5 s time gap at 40 m/s is 60 m; the radars d4sumo draws reach 60 to 150 m)
TRAFFIC_MEETS_M = 100.0


def nearest_traffic(min_gaps: Iterable[dict[str, float]], cars: Sequence[str]) -> dict[str, float]:
    """Each car of the platoon's nearest traffic car over the samples' minimum gaps [m] (``traffic-v0``: a traffic car
    ahead of v0; ``v3-traffic``: one behind v3); a car no traffic car ever followed or led is left out."""
    nearest: dict[str, float] = {}
    for gaps in min_gaps:
        for pair, gap in gaps.items():
            leader, _, follower = pair.partition("-")
            car = follower if leader == "traffic" else leader if follower == "traffic" else None
            if car in cars and gap < nearest.get(car, float("inf")):
                nearest[car] = gap
    return {car: nearest[car] for car in cars if car in nearest}


def traffic_nearness_text(nearest: dict[str, float]) -> tuple[str, bool]:
    """How near the traffic came to each car of the platoon (`nearest_traffic`), in a line; and whether it ever
    came within `TRAFFIC_MEETS_M` of one (else the campaign played as if alone)."""
    if not nearest:
        return "traffic: none ever ahead of or behind a car of the platoon, in its lane", False
    parts = ", ".join(f"{car} {gap:.1f} m" if gap >= 0 else f"{car} collided with it" for car, gap in nearest.items())
    return f"traffic: nearest to {parts}", min(nearest.values()) < TRAFFIC_MEETS_M
