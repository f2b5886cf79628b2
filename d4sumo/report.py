"""One HTML report of stored results: the paper's tables, heatmaps, time-space diagrams, accelerations
and clusters. The time-space diagrams replay the most severe attacks through SUMO into FCD files."""

from __future__ import annotations

import html
import logging
from pathlib import Path
from typing import Callable, Sequence

from . import __version__, figures
from .analysis import (
    Record,
    Table,
    cluster_knots,
    group,
    load_records,
    most_severe,
    richest_conditions,
    table_attacker_crashes,
    table_by_speed,
    table_success_statistics,
)
from .campaign import Campaign, Evaluator
from .simulation import simulate
from .store import Store, collision_dict

log = logging.getLogger(__name__)


def replay_to_fcd(record: Record, fcd_path: str | Path) -> dict:
    """Re-simulate a stored sample into an FCD file; returns the parsed FCD."""
    with Store(record.db, create=False) as store:
        definition = store.campaign(record.campaign_id).definition
    campaign = Campaign.from_definition(definition)
    evaluator = Evaluator(campaign)
    simulate(campaign.config, evaluator.signal(record.params), road=evaluator.road, fcd_path=fcd_path)
    return figures.read_fcd(fcd_path)


def collision_of(record: Record) -> dict | None:
    return collision_dict(record.pair, record.time_s, record.position_m, record.speed_diff_kmh)


def describe(record: Record) -> str:
    return (f"sample {record.sample_id}: {record.attack} {record.optimizer}, {record.start}, setpoint {record.setpoint_m:g} m, "
            f"{record.speed_mps:g} m/s; {record.pair} at {record.time_s:.1f} s, {record.speed_diff_kmh:.1f} km/h")


def build_report(
    dbs: Sequence[str | Path], out_dir: str | Path, *, severe: int = 3, progress: Callable[[str], None] | None = None
) -> Path:
    """Write ``index.html`` and its figures into ``out_dir``; returns the HTML path."""
    out = Path(out_dir)
    (out / "fcd").mkdir(parents=True, exist_ok=True)
    records = load_records(dbs)
    step = progress or (lambda what: log.info("%s", what))
    parts: list[str] = []

    step("tables")
    tables = [table_success_statistics(records), table_attacker_crashes(records), table_by_speed(records)]
    for t in tables:
        parts.append(_table_html(t))
    (out / "tables.txt").write_text("\n\n".join(t.to_text() for t in tables) + "\n")

    step("heatmaps")
    parts.append("<h2>Successful attacks over setpoint and target speed</h2><div class='row'>")
    for (attack, optimizer, start), rs in group(records, "attack", "optimizer", "start").items():
        name = f"heatmap_{attack}_{optimizer}_{start}.png"
        figures.heatmap(rs, f"{attack}, {optimizer.upper()}, start {start}: successes", out / name)
        parts.append(_img(name, f"{attack} {optimizer} {start}"))
    parts.append("</div>")

    step("time-space diagrams")
    parts.append("<h2>Most severe attacks (largest speed difference at collision)</h2>")
    for r in most_severe(records, severe):
        fcd = replay_to_fcd(r, out / "fcd" / f"sample_{r.sample_id}.xml")
        c = collision_of(r)
        ts = figures.time_space(fcd, describe(r), out / f"time_space_{r.sample_id}.png", c)
        acc = figures.accelerations(fcd, f"accelerations, sample {r.sample_id}", out / f"accel_{r.sample_id}.png", c)
        parts.append(f"<h3>{html.escape(describe(r))}</h3><p>attack parameters: "
                     f"{html.escape(', '.join(f'{v:.3f}' for v in r.params))}; FCD: <code>fcd/sample_{r.sample_id}.xml</code>; "
                     f"replay: <code>d4sumo replay {html.escape(r.db)} {r.sample_id} --gui</code></p><div class='row'>"
                     f"{_img(ts.name, 'time-space')}{_img(acc.name, 'accelerations')}</div>")

    step("clusters")
    parts.append("<h2>Clusters of successful knot vectors</h2>")
    found = False
    for condition, rs in richest_conditions(records):
        c = cluster_knots(rs, condition)
        if c is None:
            continue
        found = True
        name = "clusters_" + "".join(ch if ch.isalnum() else "_" for ch in condition) + ".png"
        figures.clusters(c, out / name)
        sizes = ", ".join(str(size) for size, _, _ in c.cluster_stats())
        parts.append(f"<h3>{html.escape(condition)}</h3><p>{len(c.vectors)} successes; k-means elbow k = {c.k} "
                     f"(sizes {sizes}); DBSCAN: {c.dbscan_clusters} clusters, {c.dbscan_noise} noise points</p>{_img(name, condition)}")
    if not found:
        parts.append("<p>No knot campaign with at least 4 successes.</p>")

    page = (
        "<!doctype html><html><head><meta charset='utf-8'><title>d4sumo report</title><style>"
        "body{font-family:sans-serif;margin:2em;max-width:1400px}table{border-collapse:collapse;margin:1em 0}"
        "td,th{border:1px solid #bbb;padding:3px 8px;text-align:right;font-size:13px}td:first-child,th:first-child{text-align:left}"
        ".row{display:flex;flex-wrap:wrap;gap:12px}img{max-width:100%;border:1px solid #eee}</style></head><body>"
        f"<h1>d4sumo report</h1><p>{len(records)} samples from {html.escape(', '.join(map(str, dbs)))}; d4sumo {__version__}.</p>"
        + "".join(parts) + "</body></html>"
    )
    index = out / "index.html"
    index.write_text(page, encoding="utf-8")
    return index


def _table_html(t: Table) -> str:
    head = "".join(f"<th>{html.escape(h)}</th>" for h in t.header)
    body = "".join("<tr>" + "".join(f"<td>{html.escape(c)}</td>" for c in row) + "</tr>" for row in t.rows)
    return f"<h2>{html.escape(t.title)}</h2><table><tr>{head}</tr>{body}</table>"


def _img(name: str, alt: str) -> str:
    return f"<img src='{html.escape(name)}' alt='{html.escape(alt)}'>"
