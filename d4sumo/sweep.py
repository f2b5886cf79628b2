"""Sweeps: a grid of campaigns, run on local worker processes or on a Dask distributed cluster.

A sweep file is TOML:

    name = "paper-nonparametric"      # optional; the file's stem by default
    [grid]                            # lists; the sweep is every combination
    network = ["highway_4lane"]
    setpoint_m = [3, 5, 7]
    speed_mps = [20, 25, 30]
    start = ["rest", "steady"]
    attack = ["knots"]
    optimizer = ["bo", "ce"]
    seed = [0]
    [search]  samples = 100
    [scenario], [vehicle], [controller], [attack], [spec]: fixed values, as in a config file

Every campaign is built and checked before anything runs. Each worker runs whole campaigns and
commits every sample to the database itself (SQLite, WAL), so killing the sweep loses nothing
finished; running it again skips complete campaigns and resumes the others.
"""

from __future__ import annotations

import hashlib
import itertools
import json
import logging
import os
import time
from concurrent.futures import FIRST_COMPLETED, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import Any, Callable

from .campaign import Campaign, run_campaign
from .config import EpisodeConfig, read_toml
from .errors import ConfigError, D4sumoError
from .scenarios import build_road
from .simulation import check_road
from .spec import Specification
from .store import Store, StoreError, campaign_key

log = logging.getLogger(__name__)

GRID_KEYS = ("network", "followers", "setpoint_m", "speed_mps", "start", "attack", "optimizer", "seed")
SCENARIO_GRID_KEYS = ("network", "followers", "setpoint_m", "speed_mps", "start")
TOP_LEVEL = ("name", "grid", "search", "scenario", "vehicle", "controller", "attack", "spec")


@dataclass(frozen=True)
class Sweep:
    name: str
    campaigns: tuple[Campaign, ...]

    @property
    def samples(self) -> int:
        return sum(c.samples for c in self.campaigns)

    def fingerprint(self) -> str:
        """Identifies the grid (not the budget): the same sweep may be resumed or extended."""
        keys = sorted(campaign_key(c.definition()) for c in self.campaigns)
        return hashlib.sha256(json.dumps(keys).encode()).hexdigest()[:20]

    @classmethod
    def load(cls, path: str | Path) -> "Sweep":
        path = Path(path)
        doc = read_toml(path, "SWEEP")
        return cls.from_dict(doc, default_name=path.stem, source=path.name)

    @classmethod
    def from_dict(cls, doc: dict[str, Any], default_name: str = "sweep", source: str = "sweep") -> "Sweep":
        for key in doc:
            if key not in TOP_LEVEL:
                raise ConfigError(f"{source}: {key}", doc[key], f"a key of a sweep file: {', '.join(TOP_LEVEL)}")
        name = doc.get("name", default_name)
        if not isinstance(name, str) or not name.strip():
            raise ConfigError(f"{source}: name", name, "a non-empty string")
        grid = doc.get("grid")
        if not isinstance(grid, dict) or not grid:
            raise ConfigError(f"{source}: [grid]", grid, f"a table of lists over {', '.join(GRID_KEYS)}")
        for key, values in grid.items():
            if key not in GRID_KEYS:
                raise ConfigError(f"grid.{key}", values, f"a key of [grid]: {', '.join(GRID_KEYS)}")
            if not isinstance(values, list) or not values:
                raise ConfigError(f"grid.{key}", values, "a non-empty list")
            if len(set(map(repr, values))) != len(values):
                raise ConfigError(f"grid.{key}", values, "a list without repeated values")
        search = dict(doc.get("search", {}))
        for key in search:
            if key not in ("samples", "optimizer", "seed"):
                raise ConfigError(f"search.{key}", search[key], "a key of [search]: samples, optimizer, seed")
        spec = dict(doc.get("spec", {}))
        attack = dict(doc.get("attack", {}))
        for key in attack:
            if key not in ("family", "delta_s", "horizon_s"):
                raise ConfigError(f"attack.{key}", attack[key], "a key of [attack] in a sweep: family, delta_s, horizon_s")
        base = {k: doc.get(k, {}) for k in ("scenario", "vehicle", "controller")}
        axes = {k: grid.get(k) for k in GRID_KEYS if k in grid}
        campaigns = []
        for values in itertools.product(*axes.values()):
            point = dict(zip(axes, values))
            overrides = {f"scenario.{k}": v for k, v in point.items() if k in SCENARIO_GRID_KEYS}
            config = EpisodeConfig.from_dict(base, overrides)
            campaigns.append(
                Campaign(
                    config=config,
                    attack=point.get("attack", attack.get("family", "knots")),
                    optimizer=point.get("optimizer", search.get("optimizer", "bo")),
                    samples=search.get("samples", 100),
                    seed=point.get("seed", search.get("seed", 0)),
                    d_safe_m=spec.get("d_safe_m", 0.0),
                    formula=spec.get("formula"),
                    delta_s=attack.get("delta_s", 6.0),
                    horizon_s=attack.get("horizon_s", 48.0),
                )
            )
        return cls(name=name.strip(), campaigns=tuple(campaigns))

    def check(self) -> None:
        """Build every road and check every campaign fits it, and every formula parses: before running."""
        roads = {}
        for c in self.campaigns:
            if c.config.network not in roads:
                roads[c.config.network] = build_road(c.config.network)
            check_road(c.config, roads[c.config.network])
        for followers, step_s, formula, d_safe in {(c.config.followers, c.config.step_s, c.formula, c.d_safe_m) for c in self.campaigns}:
            Specification(followers=followers, step_s=step_s, formula=formula, d_safe_m=d_safe)


# --- running ---------------------------------------------------------------------------------


def claim(store: Store, sweep: Sweep) -> None:
    """Mark the database as this sweep's, refusing one written by anything else."""
    meta = store.meta()
    mine = {"name": sweep.name, "fingerprint": sweep.fingerprint()}
    if "sweep" in meta:
        theirs = json.loads(meta["sweep"])
        if theirs != mine:
            raise StoreError(
                f"{store.path}: holds sweep {theirs['name']!r} (grid {theirs['fingerprint']}), not {sweep.name!r} "
                f"(grid {mine['fingerprint']}); nothing was changed. Use another --db, or the sweep file that wrote it"
            )
    else:
        others = store.campaigns()
        if others:
            raise StoreError(f"{store.path}: holds {len(others)} campaigns not run by this sweep; nothing was changed. Use another --db")
        store.set_meta("sweep", json.dumps(mine))


def stored_counts(store: Store, sweep_name: str) -> tuple[int, int]:
    """(samples stored, successes stored) for the sweep's campaigns."""
    row = store.db.execute(
        "SELECT COUNT(*), COALESCE(SUM(s.outcome = 'success'), 0) FROM sample s JOIN campaign c ON s.campaign_id = c.id "
        "WHERE c.sweep = ?",
        (sweep_name,),
    ).fetchone()
    return int(row[0]), int(row[1])


def run_one(campaign: Campaign, db_path: str, sweep_name: str) -> tuple[int, int]:
    """Worker task: run or resume one campaign into the database; returns (campaign id, successes).

    One BLAS thread per task: the GP's matrices are small, and a BLAS pool per worker process
    oversubscribes the cores (two workers on two cores ran no faster than one)."""
    from threadpoolctl import threadpool_limits

    with threadpool_limits(limits=1), Store(db_path) as store:
        summary = run_campaign(campaign, store, sweep=sweep_name)
    return summary.campaign_id, summary.count("success")


@dataclass
class SweepResult:
    campaigns: int
    samples: int
    successes: int
    wall_s: float
    interrupted: bool = False


def run_sweep(
    sweep: Sweep,
    db_path: str | Path,
    *,
    workers: int | None = None,
    dask_address: str | None = None,
    dask_timeout_s: float = 30.0,
    progress: Callable[[int, int, int], None] | None = None,
    poll_s: float = 0.5,
) -> SweepResult:
    """Run every campaign of the sweep not yet complete in ``db_path``. ``progress(done, total, successes)``
    is called as samples land in the database."""
    sweep.check()
    db_path = str(Path(db_path).resolve())
    t0 = time.perf_counter()
    with Store(db_path) as store:
        claim(store, sweep)
        todo = []
        for c in sweep.campaigns:
            cid = store.open_campaign(c.definition(), c.samples, sweep.name)
            if len(store.samples(cid)) < c.samples:
                todo.append(c)
        total = sweep.samples

        def report() -> tuple[int, int]:
            done, successes = stored_counts(store, sweep.name)
            if progress:
                progress(min(done, total), total, successes)
            return done, successes

        report()
        if todo:
            log.info("sweep %s: %d of %d campaigns to run", sweep.name, len(todo), len(sweep.campaigns))
            if dask_address:
                _run_dask(todo, db_path, sweep.name, dask_address, dask_timeout_s, report, poll_s)
            else:
                _run_local(todo, db_path, sweep.name, workers or os.cpu_count() or 1, report, poll_s)
        done, successes = report()
    return SweepResult(len(sweep.campaigns), done, successes, time.perf_counter() - t0)


def _run_local(todo, db_path, name, workers, report, poll_s) -> None:
    if workers == 1:
        for c in todo:
            run_one(c, db_path, name)
            report()
        return
    # spawn: workers start clean (libsumo keeps one simulation per process)
    with ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn")) as pool:
        pending = {pool.submit(run_one, c, db_path, name) for c in todo}
        try:
            while pending:
                finished, pending = wait(pending, timeout=poll_s, return_when=FIRST_COMPLETED)
                for f in finished:
                    f.result()
                report()
        except BrokenProcessPool:
            raise D4sumoError("a worker process died; every sample it had finished is stored: run the same command to resume") from None
        except BaseException:
            for f in pending:
                f.cancel()
            raise


def _run_dask(todo, db_path, name, address, timeout_s, report, poll_s) -> None:
    try:
        from distributed import Client
    except ImportError:  # pragma: no cover - a core dependency
        raise D4sumoError("--dask needs the distributed package (pip install 'dask[distributed]')") from None
    try:
        client = Client(address, timeout=timeout_s)
    except (OSError, TimeoutError) as exc:
        raise D4sumoError(f"--dask: no Dask scheduler answered at {address} ({exc})") from None
    with client:
        # pure=False: a resubmitted campaign runs again (it resumes from the database)
        futures = [client.submit(run_one, c, db_path, name, pure=False, retries=1) for c in todo]
        pending = list(futures)
        while pending:
            time.sleep(poll_s)
            for f in [f for f in pending if f.done()]:
                f.result()  # re-raises a campaign's error here
                pending.remove(f)
            report()
