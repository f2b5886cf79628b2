"""One HTML report of stored results: the paper's tables, heatmaps, time-space diagrams, accelerations
and clusters. The time-space diagrams replay the most severe attacks through SUMO into FCD files.

Also the single figures of ``d4sumo plot``: ``plot_figure`` checks where the figure goes before any
work and writes nothing but the figure (and the FCD, only where one is asked for).
"""

from __future__ import annotations

import hashlib
import html
import logging
import os
import shutil
import tempfile
from pathlib import Path
from typing import Callable, Sequence

from .. import __version__
from ..errors import ConfigError, NotSimulable
from ..files import part_of, remove_stale_parts
from ..search.store import collision_dict
from . import figures, paper, timespace
from .analysis import (
    Table, attack_label, count_noun, has_traffic, most_severe, scenario_labels, table_attacker_crashes, table_by_speed,
    table_crash_kinds, table_success_statistics, table_systems)
from .baseline import table_without_attack
from .clusters import cluster_knots, richest_conditions
from .failure_map import MOST_PANELS, failure_maps
from .records import Record, load_records
from .replays import evaluator_of, replay_to_fcd  # noqa: F401 (importable from here, where they were)

log = logging.getLogger(__name__)

PLOT_KINDS = ("time-space", "accel", "heatmap", "clusters", "map")
SEVERITY = "largest speed difference between the colliding cars at the first collision"


def collision_of(record: Record) -> dict | None:
    """The stored first collision, its time in simulation time (the FCD's clock)."""
    return collision_dict(record.pair, record.time_s, record.position_m, record.speed_diff_kmh)


def describe(record: Record) -> str:
    scenario = dict(record.scenario)
    where = (f"{record.network}, " if record.network != "highway_4lane" else "") + (
        f"route [{' '.join(scenario['route'])}], " if scenario.get("route") else "") + (
        f"lane {scenario['lane']}, " if scenario.get("lane") is not None else "") + (
        f"{record.followers} followers, " if record.followers != 3 else "") + (
        f"duration {scenario['duration_s']:g} s, " if scenario.get("duration_s", 60.0) != 60.0 else "") + (
        f"traffic {scenario['traffic']}, " if scenario.get("traffic", "none") != "none" else "")
    start = f"warmup {record.attack_start_s:g} s" if record.start == "warmup" else record.start
    system = f"{record.system}, " if record.system != "switching" else ""
    maneuver = f"{record.maneuver} " if record.maneuver != "inlane" else ""
    played = {"setpoint_m": record.setpoint_m, "speed_mps": record.speed_mps, **dict(record.situation)}  # its own, searched
    head = (f"sample {record.sample_id}: {system}{maneuver}{attack_label(record)} {record.optimizer}, {where}{start}, "
            f"setpoint {played['setpoint_m']:g} m, {played['speed_mps']:g} m/s")
    if record.pair is None:
        return f"{head}; {record.outcome.replace('_', ' ')}"
    return (f"{head}; {record.pair} collided {record.time_from_attack_start_s:.1f} s after the attack started, "
            f"{record.speed_diff_kmh:.1f} km/h")


def _sample_figure(record: Record, kind: str, fcd: dict, out: Path, speed_max_mps: float | None = None) -> Path:
    title = describe(record)
    moments = dict(attack_start_s=record.attack_start_s, lane_change_s=record.lane_changes_at_s)
    if kind == "time-space":
        return timespace.time_space(fcd, title, out, collision_of(record), speed_max_mps=speed_max_mps, **moments)
    return timespace.accelerations(fcd, title, out, collision_of(record), **moments)


def _check_kind(kind: str, allowed: Sequence[str]) -> None:
    if kind not in allowed:
        raise ConfigError("kind", kind, f"one of {', '.join(allowed)}")


def plot_sample(record: Record, kind: str, out: str | Path, fcd_path: str | Path | None = None) -> Path:
    """A time-space or acceleration figure of one stored sample, replayed through SUMO. The FCD goes to
    ``fcd_path`` when given, else to a temporary folder that is removed afterwards."""
    _check_kind(kind, ("time-space", "accel"))
    out = figures.check_figure_path(out, "--out")
    if fcd_path is not None:
        fcd_path = Path(fcd_path)
        if not fcd_path.parent.is_dir() or fcd_path.is_dir():
            raise ConfigError("--fcd", str(fcd_path), "a file in an existing folder")
        return _sample_figure(record, kind, replay_to_fcd(record, fcd_path), out)
    with tempfile.TemporaryDirectory(prefix="d4sumo-fcd-") as folder:
        fcd = replay_to_fcd(record, Path(folder) / "fcd.xml")
    return _sample_figure(record, kind, fcd, out)


def plot_selection(records: Sequence[Record], kind: str, out: str | Path, label: str = "all samples", *,
                   keys: tuple[str, ...] | None = None) -> Path:
    """A heatmap (one panel per attack, optimiser and start mode, one colour range), the map of where the system
    fails (over ``keys``, searched keys; none: the first two) or the clusters of the successful knot vectors of
    ``records``."""
    _check_kind(kind, ("heatmap", "clusters", "map"))
    out = figures.check_figure_path(out, "--out")
    if kind == "heatmap":
        return figures.heatmap(records, f"Successful attacks over setpoint and target speed: {label}", out)
    if kind == "map":
        found = failure_maps(records, keys)
        if not found:
            raise ConfigError("db", label, "samples of campaigns that search their situation (a range such as "
                                           "scenario.setpoint_m = [3, 10]): a map is drawn over it")
        return figures.failure_map(found, f"Where the system fails: {label}", out)
    clustering = cluster_knots(records, label)
    if clustering is None:
        raise ConfigError("filters", label, "a selection with at least 4 successful knot attacks")
    return figures.clusters(clustering, out)


def plot_figure(dbs: Sequence[str | Path], kind: str, out: str | Path, *, sample: int | None = None,
                fcd_path: str | Path | None = None, attack: str | None = None, optimizer: str | None = None,
                start: str | None = None, setpoint_m: float | None = None, speed_mps: float | None = None,
                keys: str | None = None) -> str:
    """``d4sumo plot``: one figure into ``out`` (checked first: a file in an existing folder); a sample
    (time-space, accel) or a selection (heatmap, clusters). Returns the line to print."""
    _check_kind(kind, PLOT_KINDS)
    out = figures.check_figure_path(out, "--out")
    if keys is not None and kind != "map":
        raise ConfigError("--keys", keys, "keys only with a map: the searched keys it is drawn over")
    if fcd_path is not None and kind not in ("time-space", "accel"):
        raise ConfigError("--fcd", str(fcd_path), "an FCD file only with a time-space or accel plot")
    if kind in ("time-space", "accel") and sample is None:
        raise ConfigError("--sample", "none given", f"a sample id: {'an' if kind[0] in 'aeiou' else 'a'} {kind} plot draws one stored sample")
    records = load_records(dbs)
    if kind in ("time-space", "accel"):
        matches = [r for r in records if r.sample_id == sample]
        if not matches:
            ids = [r.sample_id for r in records]
            raise ConfigError("--sample", sample, f"a sample id of {', '.join(map(str, dbs))} "
                                                  f"({f'{min(ids)} .. {max(ids)}' if ids else 'it holds none'})")
        plot_sample(matches[0], kind, out, fcd_path)
        return f"{kind} plot written to {out}" + (f" (FCD: {fcd_path})" if fcd_path is not None else "")
    filters = {"attack": attack, "optimizer": optimizer, "start": start, "setpoint_m": setpoint_m, "speed_mps": speed_mps}
    chosen = [r for r in records if all(v is None or getattr(r, k) == v for k, v in filters.items())]
    if not chosen:
        raise ConfigError("filters", {k: v for k, v in filters.items() if v is not None}, "values that match stored samples")
    label = ", ".join(f"{k} {v:g}" if isinstance(v, float) else f"{v}" for k, v in filters.items() if v is not None) or "all samples"
    plot_selection(chosen, kind, out, label, keys=None if keys is None else tuple(k.strip() for k in keys.split(",")))
    return f"{kind} plot written to {out}"


def build_report(
    dbs: Sequence[str | Path], out_dir: str | Path, *, severe: int = 3, progress: Callable[[str], None] | None = None
) -> Path:
    """Write ``index.html`` and its figures into ``out_dir``; returns the HTML path. The report is built in a
    folder beside it and moved in at the end, the page last: a report refused, failed or interrupted midway
    leaves ``out_dir`` as it was."""
    out = Path(out_dir)
    records = load_records(dbs)
    remove_stale_parts(out.resolve())  # resolved: "." has no name to put a part beside
    staging = part_of(out.resolve())
    shutil.rmtree(staging, ignore_errors=True)  # this process's own, from a report it made before
    staging.mkdir()
    try:
        _write_report(records, dbs, staging, out, severe, progress or (lambda what: log.info("%s", what)))
        for f in sorted(staging.rglob("*"), key=lambda f: f.name == "index.html"):
            if f.is_file():
                target = out / f.relative_to(staging)
                target.parent.mkdir(parents=True, exist_ok=True)
                os.replace(f, target)
    finally:
        shutil.rmtree(staging, ignore_errors=True)
    return out / "index.html"


def _write_report(records: list[Record], dbs: Sequence[str | Path], out: Path, final: Path, severe: int,
                  step: Callable[[str], None]) -> None:
    """The report into ``out``, a folder beside ``final`` that will be moved there (the FCD files name
    themselves as they will be): its sections in order, then the page."""
    (out / "fcd").mkdir()
    db_names = [str(db) for db in dbs]

    def stem(r: Record) -> str:  # sample ids repeat across databases
        return f"sample_{r.sample_id}" if len(set(db_names)) == 1 else f"db{db_names.index(r.db) + 1}_sample_{r.sample_id}"

    systems = sorted({r.system for r in records})
    compare_systems = systems != ["switching"]
    parts = _tables_section(records, out, compare_systems, step) + _heatmaps_section(records, out, step)
    parts += _paper_section(records)
    if compare_systems:
        parts += _worst_section(records, systems, out, final, stem, step)
    parts += _severe_section(records, severe, out, final, stem, step) + _clusters_section(records, out, step)
    (out / "index.html").write_text(_page(records, db_names, parts), encoding="utf-8")


def _tables_section(records: list[Record], out: Path, compare_systems: bool, step: Callable[[str], None]) -> list[str]:
    """The tables (and tables.txt), among traffic with the traffic's own doing, the attack left out."""
    step("tables")
    parts: list[str] = []
    tables = [table_success_statistics(records), table_attacker_crashes(records), table_by_speed(records)]
    if compare_systems:
        tables.insert(0, table_systems(records))
    if has_traffic(records):
        tables.append(table_crash_kinds(records))
        played = [0]

        def one_more() -> None:
            played[0] += 1
            step(f"tables: the traffic without the attack, episode {played[0]}")

        step("tables: the traffic without the attack")
        tables.append(table_without_attack(records, evaluator_of, one_more))
    for t in tables:
        parts.append(_table_html(t))
    # a table of a few columns whole (its headers say much), a sweep of many systems in blocks of columns
    (out / "tables.txt").write_text("\n\n".join(t.to_text(width=TEXT_WIDTH) for t in tables) + "\n")
    parts.append("<p>The tables as text: <a href='tables.txt'>tables.txt</a>. Times count from the attack's start "
                 "(after the warm-up drive for start mode warmup).</p>")
    return parts


def _heatmaps_section(records: list[Record], out: Path, step: Callable[[str], None]) -> list[str]:
    step("heatmaps")
    parts: list[str] = []
    panels = figures.heatmap_panels(records)
    parts.append("<h2>Successful attacks over setpoint and target speed</h2>"
                 f"<p>One panel per {'scenario, ' if len(set(scenario_labels(records).values())) > 1 else ''}"
                 f"attack, optimiser and start mode ({count_noun(len(panels), 'panel')}"
                 f"{'; a row per system under test' if panels and isinstance(panels[0][0], tuple) else ''}), "
                 "all on one colour range; grey cells were not run.</p>")
    figures.heatmaps(panels, "Successful attacks over setpoint and target speed", out / "heatmaps.png",
                     columns=figures.heatmap_columns(records))
    parts.append(_img("heatmaps.png", "successes per setpoint and target speed"))
    found = failure_maps(records)
    if found:  # campaigns that searched their situation
        parts.append("<h2>Where the system fails</h2><p>Over the situation the campaigns searched with the attack: the "
                     "success rate at each point, estimated from the samples near it (a Gaussian weight of a tenth of "
                     "each range; a uniform prior: the mean and standard deviation of a Beta), and the line where it "
                     "crosses one half, the boundary between the situations where the attacks mostly failed and those "
                     f"where they mostly succeeded. A row per system and start ({count_noun(len(found), 'row')}; "
                     f"at most {MOST_PANELS}, those with the most samples), its attacks and optimisers pooled. Blank: "
                     "too far from any sample to say.</p>")
        figures.failure_map(found, "Where the system fails", out / "failure_map.png")
        parts.append(_img("failure_map.png", "the success rate over the searched situation"))
    return parts


def _paper_section(records: list[Record]) -> list[str]:
    """The paper's tables with ours under each row, where these databases cover its grids."""
    parts: list[str] = []
    compared = paper.comparisons(records)
    if compared:
        parts.append("<h2>Compare with the paper</h2><p>The paper's tables (typed in from its source) with ours under "
                     "each of its rows, for the parts of its grids these databases cover (the paper's controller only). "
                     "<span class='far'>Highlighted</span>: ours more than twice or less than half the paper's. "
                     "docs/paper.md discusses each difference.</p>")
        parts += [_comparison_html(c) for c in compared]
    return parts


def _worst_section(records: list[Record], systems: list[str], out: Path, final: Path, stem: Callable[[Record], str],
                   step: Callable[[str], None]) -> list[str]:
    """Each system's worst counterexample, replayed through SUMO."""
    parts: list[str] = []
    step("worst counterexample per system")
    parts.append("<h2>Worst counterexample per system under test</h2><p>For each system, its successful attack "
                 f"with the {SEVERITY}, replayed through SUMO; a system without one is named with its budget.</p>")
    for system in systems:
        rs = [r for r in records if r.system == system]
        worst = most_severe(rs, 1)
        if not worst:
            parts.append(f"<h3>{html.escape(system)}</h3><p>No successful attack in {count_noun(len(rs), 'sample')} "
                         f"({sum(r.outcome == 'attacker_crash' for r in rs)} attacker crashes).</p>")
            continue
        r = worst[0]
        try:
            fcd = replay_to_fcd(r, out / "fcd" / f"worst_{stem(r)}.xml", final / "fcd" / f"worst_{stem(r)}.xml")
        except NotSimulable as exc:  # read, not replayed: the page says why
            parts.append(f"<h3>{html.escape(system)}</h3><p>{html.escape(describe(r))}; not replayed here: "
                         f"{html.escape(str(exc))}</p>")
            continue
        ts = _sample_figure(r, "time-space", fcd, out / f"worst_time_space_{stem(r)}.png")
        parts.append(f"<h3>{html.escape(system)}</h3><p>{html.escape(describe(r))}; replay: "
                     f"<code>d4sumo replay {html.escape(r.db)} {r.sample_id} --gui</code></p>{_img(ts.name, 'time-space diagram')}")
    return parts


def _severe_section(records: list[Record], severe: int, out: Path, final: Path, stem: Callable[[Record], str],
                    step: Callable[[str], None]) -> list[str]:
    """The most severe attacks, each replayed: its time-space diagram and its accelerations."""
    step("time-space diagrams")
    parts: list[str] = []
    top = most_severe(records, severe)
    parts.append("<h2>Most severe attacks</h2>" + (
        f"<p>{html.escape(severe_rule(records, top, severe))} Each is replayed through SUMO; its time-space diagram "
        "shows every car's position over time coloured by speed (one scale for all diagrams), and beside it (below it "
        "in a narrow window) every car's acceleration.</p>" if top else "<p>No successful attack.</p>"))
    fcds = [_replayed(r, out / "fcd" / f"{stem(r)}.xml", final / "fcd" / f"{stem(r)}.xml") for r in top]
    speed_max_mps = max((float(d["speed"].max()) for fcd in fcds if isinstance(fcd, dict) for d in fcd.values()
                         if len(d["speed"])), default=None)
    for r, fcd in zip(top, fcds):
        if not isinstance(fcd, dict):  # read, not replayed (its controller cannot be had here): the page says why
            parts.append(f"<h3>{html.escape(describe(r))}</h3><p>attack parameters: "
                         f"{html.escape(', '.join(f'{v:.3f}' for v in r.params))}; not replayed here: {html.escape(fcd)}</p>")
            continue
        ts = _sample_figure(r, "time-space", fcd, out / f"time_space_{stem(r)}.png", speed_max_mps)
        acc = _sample_figure(r, "accel", fcd, out / f"accel_{stem(r)}.png")
        parts.append(f"<h3>{html.escape(describe(r))}</h3><p>attack parameters: "
                     f"{html.escape(', '.join(f'{v:.3f}' for v in r.params))}; FCD: "
                     f"<a href='fcd/{stem(r)}.xml'><code>fcd/{stem(r)}.xml</code></a>; {_openscenario_links(r, out, stem(r), out / 'fcd' / f'{stem(r)}.xml')}"
                     f"replay: <code>d4sumo replay {html.escape(r.db)} {r.sample_id} --gui</code></p><div class='row'>"
                     f"{_img(ts.name, 'time-space diagram')}{_img(acc.name, 'accelerations')}</div>")
    return parts


def _clusters_section(records: list[Record], out: Path, step: Callable[[str], None]) -> list[str]:
    """The clusters of successful knot vectors, per condition with the most successes."""
    step("clusters")
    parts: list[str] = []
    parts.append("<h2>Clusters of successful knot vectors</h2><p>For each attack, optimiser and start mode, the "
                 "configuration with the most successes. A knot counts only if it can have shaped the attack before "
                 "the collision (with PCHIP, knot k reaches back to the time of knot k-2); k-means and DBSCAN ignore "
                 "the others, and each knot's mean and standard deviation rest on the attacks shown above it.</p>")
    found = False
    for condition, rs in richest_conditions(records):
        c = cluster_knots(rs, condition)
        if c is None:
            continue
        found = True
        name = figure_name("clusters", condition)
        figures.clusters(c, out / name)
        parts.append(f"<h3>{html.escape(condition)}</h3><p>{html.escape(clusters_caption(c))}</p>{_img(name, condition)}")
    if not found:
        parts.append("<p>No knot campaign with at least 4 successes.</p>")
    return parts


def _page(records: list[Record], db_names: list[str], parts: list[str]) -> str:
    return (
        "<!doctype html><html><head><meta charset='utf-8'><title>d4sumo report</title><style>"
        "body{font-family:sans-serif;margin:2em;max-width:1400px}table{border-collapse:collapse;margin:1em 0}"
        "td,th{border:1px solid #bbb;padding:3px 8px;text-align:right;font-size:13px}td:first-child,th:first-child{text-align:left}"
        ".row{display:flex;flex-wrap:wrap;gap:12px;align-items:flex-start}.row img{flex:1 1 0;min-width:min(440px,100%)}"
        "img{max-width:100%;border:1px solid #eee}.far{background:#ffe08a}"
        "</style></head><body>"
        f"<h1>d4sumo report</h1><p>{count_noun(len(records), 'sample')} from {html.escape(', '.join(db_names))}; "
        f"d4sumo {__version__}.</p>" + "".join(parts) + "</body></html>"
    )


def _replayed(record: Record, fcd_path: Path, name: Path) -> dict | str:
    """`replay_to_fcd`, or why it cannot be (a controller that cannot be had here: a module that does not
    import, an FMU missing or changed), for a report that shows what it can of the rest."""
    try:
        return replay_to_fcd(record, fcd_path, name)
    except NotSimulable as exc:
        return str(exc)


#: the widest line tables.txt holds before a table goes on in blocks of columns
TEXT_WIDTH = 200


def _openscenario_links(record: Record, out: Path, name: str, fcd: Path) -> str:
    """The sample as OpenSCENARIO on its road as OpenDRIVE (`openscenario`), written beside the report, as links;
    a sample this version does not export (a message attack's) says so."""
    from .openscenario import NotExported, export_openscenario

    folder = f"openscenario/{name}"
    try:
        export_openscenario(record, out / folder, fcd)  # from the FCD the report replayed it into
    except NotExported as exc:  # says what the campaign has, not what it would need
        return f"not exported as OpenSCENARIO ({html.escape(exc.why)}); "
    except ConfigError as exc:
        return f"not exported as OpenSCENARIO ({html.escape(exc.allowed)}); "
    return (f"OpenSCENARIO: <a href='{folder}/scenario.xosc'><code>{folder}/scenario.xosc</code></a> on "
            f"<a href='{folder}/road.xodr'><code>road.xodr</code></a>; ")


def severe_rule(records: Sequence[Record], top: Sequence[Record], severe: int) -> str:
    """How the most severe attacks were chosen, with the counts that say why there are this many."""
    configurations = {r.configuration for r in records}
    found = {r.configuration for r in records if r.outcome == "success" and r.speed_diff_kmh is not None}
    return (f"An attack's severity is the {SEVERITY}. A configuration is one scenario, setpoint, target speed, start "
            "mode, system under test, attack and optimiser (campaigns that differ in their seed alone are one). Each "
            "configuration gives at most one attack, its most severe, so that one campaign's near-copies of its best "
            f"attack do not fill the list: of the {count_noun(len(found), 'configuration')} that found a successful "
            f"attack (of {len(configurations)}), the {len(top)} with the most severe are shown (--severe {severe}).")


#: the longest figure name a report writes: a condition names its road's and its demand's paths, and file systems
#: take at most 255 bytes a name
FIGURE_NAME_CHARS = 120


def figure_name(kind: str, condition: str) -> str:
    """A figure's file name from what it shows: its words, shortened past `FIGURE_NAME_CHARS` and told apart by a
    digest of the whole."""
    words = "".join(ch if ch.isalnum() else "_" for ch in condition)
    if len(words) > FIGURE_NAME_CHARS:
        words = words[:FIGURE_NAME_CHARS] + "_" + hashlib.sha256(condition.encode()).hexdigest()[:12]
    return f"{kind}_{words}.png"


def clusters_caption(c) -> str:
    """One sentence on a clustering: k-means clusters with their sizes and own collision times, DBSCAN."""
    sizes = ", ".join(f"{count_noun(s.size, 'attack')} colliding at {s.median_collision_s:.1f} s" for s in c.cluster_stats())
    return (f"{count_noun(len(c.vectors), 'success', 'successes')}. k-means with the elbow rule: "
            f"{count_noun(c.k, 'cluster')} ({sizes}; median times from the attack's start). DBSCAN: "
            f"{count_noun(c.dbscan_clusters, 'cluster')}, {count_noun(c.dbscan_noise, 'noise point')}.")


def _comparison_html(c) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in c.header)
    body = "".join(
        "<tr>" + f"<td>{html.escape(label)}</td><td>{html.escape(who)}</td>"
        + "".join(f"<td class='far'>{html.escape(cell)}</td>" if far else f"<td>{html.escape(cell)}</td>"
                  for cell, far in zip(cells, flags)) + "</tr>"
        for label, who, cells, flags in c.rows)
    return f"<h3>{html.escape(c.title)}</h3><table><tr>{head}</tr>{body}</table>"


def _table_html(t: Table) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in t.header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in t.rows)
    return f"<h2>{html.escape(t.title)}</h2><table><tr>{head}</tr>{body}</table>"


def _img(name: str, alt: str) -> str:
    return f"<img src='{html.escape(name)}' alt='{html.escape(alt)}'>"
