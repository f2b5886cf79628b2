"""Sweeps: a grid of campaigns, run on local worker processes or on a Dask distributed cluster.

A sweep file is TOML:

    name = "paper-nonparametric"      # optional; the file's stem by default
    [grid]                            # lists; the sweep is every combination
    network = ["highway_4lane"]
    setpoint_m = [3, 5, 7]
    speed_mps = [20, 25, 30]
    start = ["rest", "steady"]
    maneuver = ["inlane", "cutin"]      # optional, and its settings: cutin_follower, cutin_offset_m, lane_change_s, ...
                                        # (a setting another maneuver does not read gives it one campaign)
    controller = ["switching", "timegap", "sumo:ACC", {class = "sumo:IDM", tau = 1.5}]   # optional
    attack = ["knots"]
    optimizer = ["bo", "ce"]
    seed = [0]
    [search]  samples = 100           # and [search.bo], [search.ce]: the optimisers' options
    [scenario], [vehicle], [controller], [attack], [spec]: fixed values, as in a config file

Every campaign is built and checked before anything runs. Workers send every few samples back to
the client, which alone writes the database, so killing the sweep loses nothing it stored; running
it again skips complete campaigns and resumes the others.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hashlib
import itertools
import json
import logging
import os
import re
import signal
import threading
import time
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass, field
from multiprocessing import get_context
from pathlib import Path
from typing import Any, Callable

from .model.batch import DEFAULT_BATCH, batch_key
from .search.campaign import Campaign, SampleResult, open_store
from .search.runner import CampaignRunner, Evaluator, step_together, stored_results
from .model.config import read_toml
from .inputs import campaign_of, check_document, with_overrides
from .errors import ConfigError, D4sumoError
from .model.maneuvers import MANEUVERS
from .search.optimizers import EARLIER_OPTIONS
from .engine.scenarios import NetworkSource, build_road, network_source
from .engine.simulation import check_episode
from .search.store import Store, StoreError, campaign_key

log = logging.getLogger(__name__)

SCENARIO_GRID_KEYS = ("network", "followers", "setpoint_m", "speed_mps", "start",
                      *dict.fromkeys(k for m in MANEUVERS.values() for k in m.settings))  # maneuver, cutin_follower, ...
GRID_KEYS = (*SCENARIO_GRID_KEYS, "controller", "attack", "optimizer", "seed")
#: a grid axis -> the document key it sets (a controller replaces the whole [controller]: a name, a
#: table, or a list of them for a mixed platoon)
GRID_TO_KEY = {**{k: f"scenario.{k}" for k in SCENARIO_GRID_KEYS}, "controller": "controller", "attack": "attack.family",
               "optimizer": "search.optimizer", "seed": "search.seed"}


def _unused_settings_only(a: dict, b: dict, campaign: Campaign) -> bool:
    """Whether two grid points differ only in maneuver settings the campaign's maneuver does not read
    (a cut-in's offset for the in-lane attack): the same campaign, counted once."""
    used = set(campaign.config.maneuver_class.settings)
    settings = {f"scenario.{k}" for m in MANEUVERS.values() for k in m.settings}
    differ = {k for k in a if a[k] != b[k]}
    return bool(differ) and all(k in settings and k.removeprefix("scenario.") not in used for k in differ)


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

    def as_run_before(self, optimizer: str, earlier: dict) -> "Sweep":
        """The sweep with ``earlier`` options (`optimizers.EARLIER_OPTIONS`) for every ``optimizer`` campaign."""
        return dataclasses.replace(self, campaigns=tuple(
            c.replace(optimizer_options=tuple({**dict(c.optimizer_options), **earlier}.items()))
            if c.optimizer == optimizer else c for c in self.campaigns))

    @classmethod
    def load(cls, path: str | Path) -> "Sweep":
        path = Path(path)
        doc = read_toml(path, "SWEEP")
        return cls.from_dict(doc, default_name=path.stem, source=path.name)

    @classmethod
    def from_dict(cls, doc: dict[str, Any], default_name: str = "sweep", source: str = "sweep") -> "Sweep":
        check_document(doc, source, extra_keys=("name", "grid"))
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
        base = {k: v for k, v in doc.items() if k not in ("name", "grid")}
        if "controller" in grid and "controller" in base:
            raise ConfigError(f"{source}: [controller]", base["controller"],
                              "no [controller] beside grid.controller: give each controller's values in the grid")
        campaigns, points, merged = [], {}, []
        for values in itertools.product(*grid.values()):
            point = {GRID_TO_KEY[k]: v for k, v in zip(grid, values)}
            campaign = campaign_of(with_overrides(base, point))
            key = campaign_key(campaign.definition())
            if key in points:
                if _unused_settings_only(points[key], point, campaign):  # inlane x cutin_offset_m: one inlane campaign
                    merged.append((points[key], point))
                    continue
                # e.g. a controller's defaults written out, or one table per follower alike
                raise ConfigError(f"{source}: [grid]", f"{points[key]} and {point}", "grid points that are different campaigns")
            points[key] = point
            campaigns.append(campaign)
        read = {f"scenario.{k}" for c in campaigns for k in c.config.maneuver_class.settings}
        for a, b in merged:  # an axis no maneuver of the grid reads changes nothing at all: a mistake
            if any(a[k] != b[k] and k not in read for k in a):
                raise ConfigError(f"{source}: [grid]", f"{a} and {b}", "grid points that are different campaigns")
        return cls(name=name.strip(), campaigns=tuple(campaigns))

    def check(self) -> None:
        """Build every road and check every campaign fits it, and every formula parses: before running."""
        roads = {}
        for c in self.campaigns:
            if c.config.network not in roads:
                roads[c.config.network] = build_road(c.config.network)
            check_episode(c.config, roads[c.config.network])
        seen = set()
        for c in self.campaigns:
            key = (c.config.followers, c.config.step_s, c.config.total_s, c.formula, c.d_safe_m, c.config.maneuver)
            if key not in seen:
                seen.add(key)
                c.specification()


# --- running ---------------------------------------------------------------------------------
#
# The client (the process that runs `d4sumo sweep`) is the only process that opens the database.
# Workers, local processes or Dask workers, run campaigns a chunk of samples at a time, up to
# GANG_SIZE campaigns in one task whose episodes share SUMO instances: a task carries, per campaign,
# the campaign, its road's XML and the optimiser's state, and returns each one's chunk of samples and
# new state. The client stores each chunk in one transaction and sends the next task. A worker that
# dies loses only its unfinished task, which the client sends again (split in two, so that a campaign
# that kills its worker every time is found alone); workers need nothing but the installed package.

def claim(store: Store, sweep: Sweep) -> None:
    """Mark the database as this sweep's, refusing one written by anything else."""
    meta = store.meta()
    mine = {"name": sweep.name, "fingerprint": sweep.fingerprint()}
    if "sweep" in meta:
        try:
            theirs = json.loads(meta["sweep"])
            theirs["name"], theirs["fingerprint"]
        except (ValueError, TypeError, KeyError):
            raise StoreError(f"{store.path}: damaged results database (its sweep record {meta['sweep']!r})") from None
        if theirs != mine:
            hint = "Use another --db, or the sweep file that wrote it"
            names = list(EARLIER_OPTIONS)
            # each optimiser as now or as an earlier version ran it, in every combination (bo's and ce's both changed)
            for choice in itertools.product(*[(None, *EARLIER_OPTIONS[o]) for o in names]):
                changed = [(o, e) for o, e in zip(names, choice) if e is not None]
                before = sweep
                for optimizer, earlier in changed:
                    before = before.as_run_before(optimizer, earlier)
                if changed and theirs["name"] == sweep.name and theirs["fingerprint"] == before.fingerprint():
                    tables = "; ".join(", ".join(f"`{k} = {v}`" for k, v in e.items()) + f" in [search.{o}]" for o, e in changed)
                    hint = f"It was run by an earlier d4sumo: set {tables} of the sweep file to go on with it, or use another --db"
                    break
            raise StoreError(
                f"{store.path}: holds sweep {theirs['name']!r} (grid {theirs['fingerprint']}), not {sweep.name!r} "
                f"(grid {mine['fingerprint']}); nothing was changed. {hint}"
            )
    else:
        others = store.campaigns()
        if others:
            held = f"{len(others)} campaign{'s' if len(others) != 1 else ''}"
            raise StoreError(f"{store.path}: holds {held} not run by this sweep; nothing was changed. Use another --db")
        store.set_meta("sweep", json.dumps(mine))


def stored_counts(store: Store, sweep_name: str) -> tuple[int, int]:
    """(samples stored, successes stored) for the sweep's campaigns."""
    row = store.db.execute(
        "SELECT COUNT(*), COALESCE(SUM(s.outcome = 'success'), 0) FROM sample s JOIN campaign c ON s.campaign_id = c.id "
        "WHERE c.sweep = ?",
        (sweep_name,),
    ).fetchone()
    return int(row[0]), int(row[1])


CHUNK_SAMPLES = 10  # a task returns once each of its campaigns has this many samples (a batch is played whole) ...
CHUNK_WALL_S = 2.0  # ... or after this long, so results reach the client often
MAX_TASK_FAILURES = 3  # a chunk that fails this often (a bug, not a lost worker) stops the sweep
#: a task steps up to this many campaigns together, their episodes side by side in one SUMO: a
#: campaign that proposes one point per score (the paper's BO) then still plays in batches
GANG_SIZE = 32


@dataclass(frozen=True)
class Chunk:
    """A task's share of one campaign: continue ``campaign`` from ``state`` (None: from the ``stored``
    samples) for a chunk."""

    campaign: Campaign
    network: NetworkSource
    stored: tuple[SampleResult, ...]
    state: tuple | None
    batch: int = DEFAULT_BATCH  # episodes side by side in one SUMO, at most


_EVALUATORS: dict[str, Evaluator] = {}  # per worker process: roads built and formulas parsed once


def _evaluator(chunk: Chunk) -> Evaluator:
    key = campaign_key(chunk.campaign.definition())
    evaluator = _EVALUATORS.get(key)
    if evaluator is None:
        if len(_EVALUATORS) >= 8 * GANG_SIZE:
            _EVALUATORS.clear()
        evaluator = _EVALUATORS[key] = Evaluator(chunk.campaign, road=build_road(chunk.network), network=chunk.network)
    return evaluator


def run_chunks(chunks: tuple[Chunk, ...]) -> list[tuple[list[SampleResult], tuple]]:
    """Worker task: the next samples of several campaigns (at least one each), stepped together so
    that their episodes share SUMO instances (`campaign.step_together`), and each optimiser's state
    after them. Each campaign's samples are the ones it gives run alone."""
    from threadpoolctl import threadpool_limits

    # One BLAS thread per task: the GP's matrices are small, and a BLAS pool per worker process
    # oversubscribes the cores (two workers on two cores ran no faster than one).
    with threadpool_limits(limits=1):
        runners = [CampaignRunner(c.campaign, _evaluator(c), stored=c.stored, state=c.state,
                                  where=f"campaign {campaign_key(c.campaign.definition())}", batch=c.batch)
                   for c in chunks]
        results: list[list[SampleResult]] = [[] for _ in chunks]
        t0 = time.monotonic()
        while True:
            going = [i for i, r in enumerate(runners) if r.done < r.campaign.samples and len(results[i]) < CHUNK_SAMPLES]
            if not going:
                break
            for i, new in zip(going, step_together([runners[i] for i in going], batch=chunks[0].batch)):
                results[i].extend(new)
            if time.monotonic() - t0 > CHUNK_WALL_S:
                break
    return [(r, runner.state) for r, runner in zip(results, runners)]


@dataclass
class SweepResult:
    campaigns: int
    samples: int
    successes: int
    wall_s: float


@dataclass
class _Active:
    """The client's view of one running campaign."""

    campaign: Campaign
    campaign_id: int
    network: NetworkSource
    stored: tuple[SampleResult, ...]
    state: tuple | None = None
    done: int = 0
    failures: int = 0
    batch: int = DEFAULT_BATCH
    added: set = field(default_factory=set)  # indices stored by this sweep run (a stored campaign may have gaps)

    def chunk(self) -> Chunk:
        # the stored samples travel only until a state exists
        return Chunk(self.campaign, self.network, self.stored if self.state is None else (), self.state, self.batch)


def run_sweep(
    sweep: Sweep,
    db_path: str | Path,
    *,
    workers: int | None = None,
    dask_address: str | None = None,
    dask_timeout_s: float = 30.0,
    progress: Callable[[int, int, int], None] | None = None,
    batch: int = DEFAULT_BATCH,
) -> SweepResult:
    """Run every campaign of the sweep not yet complete in ``db_path``. ``progress(done, total, successes)``
    is called as samples are stored. ``dask_address``: a scheduler's address, or "local" for a local
    Dask cluster of ``workers`` processes. ``batch``: at most this many episodes of a campaign side by
    side in one SUMO (1: one at a time); the results do not depend on it."""
    sweep.check()
    if dask_address is not None:
        dask_address = check_dask_address(dask_address)
    workers = workers or os.cpu_count() or 1
    t0 = time.perf_counter()
    sources: dict[str, NetworkSource] = {}
    with contextlib.ExitStack() as stack:
        # the cluster first: an unreachable scheduler leaves no database behind
        client = stack.enter_context(_dask_client(dask_address, dask_timeout_s, workers)) if dask_address else None
        store = stack.enter_context(open_store(db_path))
        claim(store, sweep)
        todo: list[_Active] = []
        for c in sweep.campaigns:
            cid = store.open_campaign(c.definition(), c.samples, sweep.name)
            stored = stored_results(store, cid, c.samples)
            if len(stored) < c.samples:
                if c.config.network not in sources:
                    sources[c.config.network] = network_source(c.config.network)
                todo.append(_Active(c, cid, sources[c.config.network], tuple(stored), done=len(stored), batch=batch))
        total = sweep.samples
        counts = list(stored_counts(store, sweep.name))

        def store_results(active: _Active, results: list[SampleResult]) -> None:
            store.add_samples(active.campaign_id, [(r.index, r.params, r.robustness, r.outcome, r.collision, r.min_gaps,
                                                    r.wall_s, r.error) for r in results])
            active.done += len(results)
            counts[0] += len(results)
            counts[1] += sum(r.outcome == "success" for r in results)
            if progress:
                progress(min(counts[0], total), total, counts[1])

        if progress:
            progress(min(counts[0], total), total, counts[1])
        if todo:
            log.info("sweep %s: %d of %d campaigns to run", sweep.name, len(todo), len(sweep.campaigns))
            if client is not None:
                _run_dask(todo, store_results, client)
            elif workers == 1:
                _run_inline(todo, store_results)
            else:
                _run_local(todo, store_results, workers)
    return SweepResult(len(sweep.campaigns), counts[0], counts[1], time.perf_counter() - t0)


def _accept(active: _Active, chunk_result: tuple[list[SampleResult], tuple], store_results) -> bool:
    """Store a finished chunk; True when its campaign is complete."""
    results, state = chunk_result
    indices = [r.index for r in results]
    stored = {r.index for r in active.stored} | active.added
    if (indices != sorted(set(indices)) or any(i in stored or not 0 <= i < active.campaign.samples for i in indices)):
        raise D4sumoError(f"campaign {active.campaign_id}: a worker returned samples out of order or stored already; "
                          "nothing of them was stored")
    store_results(active, results)
    active.added.update(indices)
    active.state = state
    active.failures = 0
    return active.done >= active.campaign.samples


def _gangs(todo: list[_Active], workers: int) -> list[list[_Active]]:
    """The campaigns in tasks of up to GANG_SIZE that step together: ones whose episodes may share
    SUMO (one `batch.batch_key` and road) and that propose alike (one optimiser and batch size), so
    that they keep pace. Smaller tasks where there are few campaigns, to keep every worker busy."""
    size = max(1, min(GANG_SIZE, -(-len(todo) // (2 * workers))))
    groups: dict[tuple, list[_Active]] = {}
    for a in todo:
        c = a.campaign
        key = (batch_key(c.config), a.network, c.optimizer, dict(c.optimizer_options).get("batch_size"))
        groups.setdefault(key, []).append(a)
    gangs = []
    for g in groups.values():  # near-equal gangs: 78 campaigns in gangs of 32 at most are 26, 26, 26
        count = -(-len(g) // size)
        gangs += [g[i * len(g) // count:(i + 1) * len(g) // count] for i in range(count)]
    return gangs


def _share(gang: list[_Active], queue: list, busy: int, slots: int) -> list[_Active]:
    """Near the sweep's end, when a worker would idle, the gang goes on as two tasks: its half."""
    if not queue and busy < slots and len(gang) > 1:
        first, second = _halves(gang)
        queue.append(second)
        return first
    return gang


def _halves(gang: list[_Active]) -> list[list[_Active]]:
    return [gang[:len(gang) // 2], gang[len(gang) // 2:]]


def _task(gang: list[_Active]) -> tuple[Chunk, ...]:
    return tuple(a.chunk() for a in gang)


def _accept_gang(gang: list[_Active], chunk_results: list, store_results) -> list[_Active]:
    """Store a finished task's chunks; the gang's campaigns not complete yet."""
    if len(chunk_results) != len(gang):
        raise D4sumoError(f"a worker returned {len(chunk_results)} chunks for {len(gang)} campaigns; nothing of them was stored")
    return [a for a, result in zip(gang, chunk_results) if not _accept(a, result, store_results)]


def _run_inline(todo: list[_Active], store_results) -> None:
    for gang in _gangs(todo, 1):
        while gang:
            gang = _accept_gang(gang, run_chunks(_task(gang)), store_results)


def _run_local(todo: list[_Active], store_results, workers: int) -> None:
    """Chunks on local worker processes (spawned clean: libsumo keeps one simulation per process).
    Campaigns run a few tasks at a time, so an interrupted sweep leaves few of them half done.

    A worker that dies breaks the whole pool, and every task in flight fails with it: which one killed
    it is unknown. Those tasks are suspects and run again one at a time, alone in the pool, until each
    has either finished (cleared) or died alone (`_after_failure`: a gang splits, a single campaign
    counts a failure)."""
    queue = _gangs(todo, workers)
    suspects: list[list[_Active]] = []
    running: dict[Future, list[_Active]] = {}
    pool = _new_pool(workers)
    try:
        while queue or running or suspects:
            if suspects:
                if not running:
                    running[pool.submit(run_chunks, _task(suspects[0]))] = suspects[0]
            else:
                while queue and len(running) < workers + 1:
                    gang = queue.pop(0)
                    running[pool.submit(run_chunks, _task(gang))] = gang
            finished, _ = wait(running, timeout=1.0, return_when=FIRST_COMPLETED)
            for future in finished:
                gang = running.pop(future)
                alone = bool(suspects) and gang is suspects[0]  # it ran by itself
                try:
                    chunk_results = future.result()
                except BrokenProcessPool:
                    # a worker died (killed, out of memory): the tasks in flight run again
                    if alone:
                        suspects[:1] = _after_failure(gang, "its worker process died")
                    else:
                        suspects[:0] = [gang, *running.values()]
                    running.clear()
                    _kill_pool(pool)
                    pool = _new_pool(workers)
                    break
                if alone:
                    suspects.pop(0)
                gang = _accept_gang(gang, chunk_results, store_results)
                if gang and alone:
                    queue.insert(0, gang)
                elif gang:
                    gang = _share(gang, queue, len(running) + 1, workers)
                    running[pool.submit(run_chunks, _task(gang))] = gang
    finally:
        _kill_pool(pool)


def _after_failure(gang: list[_Active], why: str) -> list[list[_Active]]:
    """A task that failed runs again: a gang of several campaigns as two halves (the samples do not
    depend on the grouping, and a campaign that fails every time is found alone after a few
    failures), a single campaign as it was, until it has failed MAX_TASK_FAILURES times."""
    if len(gang) > 1:
        log.warning("a task of %d campaigns failed (%s); it runs again as two", len(gang), why)
        return _halves(gang)
    _check_failures(gang[0], why)
    return [gang]


def _check_failures(active: _Active, why: str) -> None:
    active.failures += 1
    if active.failures >= MAX_TASK_FAILURES:
        raise D4sumoError(f"campaign {active.campaign_id} failed {active.failures} times ({why}); every finished sample "
                          "is stored: run the same command to resume")
    log.warning("campaign %d: %s; running its chunk again", active.campaign_id, why)


def _new_pool(workers: int) -> ProcessPoolExecutor:
    return ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn"), initializer=_worker_init,
                               initargs=(os.getpid(),))


def _kill_pool(pool: ProcessPoolExecutor) -> None:
    """Stop a pool now: queued chunks are dropped and running ones killed (workers never write, so
    nothing half-written is left); waits until the processes are gone."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in processes:
        if p.is_alive():
            p.kill()
    for p in processes:
        p.join(timeout=5)


def _worker_init(parent_pid: int) -> None:
    """A local worker: Ctrl-C is the client's to handle, and the worker dies with the client."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    try:  # Linux: the kernel kills the worker when its parent dies, even by kill -9
        import ctypes

        PR_SET_PDEATHSIG = 1
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    except (OSError, AttributeError):
        pass
    if os.getppid() != parent_pid:  # the parent died before the line above took effect
        os._exit(1)

    def watch() -> None:  # everywhere else: notice within a second
        while True:
            time.sleep(1.0)
            if os.getppid() != parent_pid:
                os._exit(1)

    threading.Thread(target=watch, name="parent-watch", daemon=True).start()


# --- Dask --------------------------------------------------------------------------------------

_DASK_ADDRESS = re.compile(r"^(?:(tcp|tls|ws|wss|ucx)://)?(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(\d{1,5})$")


def check_dask_address(address: str) -> str:
    """``local``, or a scheduler address such as tcp://10.0.0.5:8786; anything else is a ConfigError."""
    if address == "local":
        return address
    m = _DASK_ADDRESS.match(address.strip()) if isinstance(address, str) else None
    if not m or not 1 <= int(m.group(3)) <= 65535:
        raise ConfigError("--dask", address, "'local' or a scheduler address PROTOCOL://HOST:PORT, e.g. tcp://10.0.0.5:8786")
    return address.strip() if m.group(1) else f"tcp://{address.strip()}"


@contextlib.contextmanager
def _dask_client(address: str, timeout_s: float, workers: int):
    """A Dask client of the scheduler at ``address``, or of a local cluster of ``workers`` processes."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - a core dependency
        raise D4sumoError("--dask needs the distributed package (pip install 'dask[distributed]')") from None
    with contextlib.ExitStack() as stack:
        if address == "local":
            logging.getLogger("distributed").setLevel(logging.WARNING)  # not a page of start-up messages
            cluster = stack.enter_context(LocalCluster(n_workers=workers, threads_per_worker=1, processes=True,
                                                       host="127.0.0.1", dashboard_address=":0", silence_logs=logging.WARNING))
            log.warning("local Dask cluster of %d workers; dashboard at %s", workers, cluster.dashboard_link)
            address = cluster.scheduler_address
        try:
            client = Client(address, timeout=timeout_s)
        except (OSError, TimeoutError) as exc:
            raise D4sumoError(f"--dask: no Dask scheduler answered at {address} within {timeout_s:g} s ({exc})") from None
        with client:
            yield client


def _run_dask(todo: list[_Active], store_results, client) -> None:
    from distributed import as_completed

    queue = _gangs(todo, max(1, sum(client.nthreads().values())))
    running: dict = {}
    futures = as_completed()

    def slots() -> int:
        return max(1, sum(client.nthreads().values())) + 1

    def submit(gang: list[_Active]) -> None:
        # pure=False: the same chunk sent again after a failure is run again, not looked up
        future = client.submit(run_chunks, _task(gang), pure=False)
        running[future] = gang
        futures.add(future)

    while queue and len(running) < slots():
        submit(queue.pop(0))
    for future in futures:
        gang = running.pop(future)
        if future.status == "error":
            exc = future.exception()
            if isinstance(exc, D4sumoError):
                raise exc
            for part in _after_failure(gang, f"{type(exc).__name__}: {exc}"):
                submit(part)
            continue
        result = future.result()
        future.release()
        gang = _accept_gang(gang, result, store_results)
        if gang:
            submit(_share(gang, queue, len(running) + 1, slots() - 1))
        while queue and len(running) < slots():
            submit(queue.pop(0))
