"""Running a sweep: the client alone writes the database; workers (local processes, or Dask's) play
chunks of campaigns and send their samples back."""

from __future__ import annotations

import contextlib
import itertools
import json
import logging
import time
from concurrent.futures import FIRST_COMPLETED, Future, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from pathlib import Path
from typing import Callable

from ..engine.scenarios import NetworkSource, network_source
from ..errors import ConfigError
from ..model.stepping.batch import DEFAULT_BATCH
from ..model.controllers.fmu import shipment
from ..search.campaign import SampleResult, open_store
from ..search.optimizers import EARLIER_DEFAULT_OPTIMIZER, EARLIER_OPTIONS
from ..search.runner import numerics_note, stored_results
from ..search.store import Store, StoreError
from .dask_cluster import DaskCluster, _dask_client, _run_dask, _run_dask_proposing, check_dask_address
from .grid import Sweep, part_text
from .tasks import _accept_gang, _Active, _after_failure, _gangs, _share, _task, run_chunks
from .workers import kill_pool, new_pool, usable_cores

log = logging.getLogger(__name__)

# --- running ---------------------------------------------------------------------------------
#
# The client (the process that runs `d4sumo sweep`) is the only process that opens the database.
# Workers, local processes or Dask workers, run campaigns a chunk of samples at a time, up to
# GANG_SIZE campaigns in one task whose episodes share SUMO instances: a task carries, per campaign,
# the campaign, its road's XML and the optimiser's state, and returns each one's chunk of samples and
# new state. The client stores each chunk in one transaction and sends the next task. A worker that
# dies loses only its unfinished task, which the client sends again (split in two, so that a campaign
# that kills its worker every time is found alone); workers need nothing but the installed package.

def _earlier_hint(sweep: Sweep, theirs: dict) -> str | None:
    """What to set in the sweep file to go on with a database an earlier d4sumo wrote for it: its optimisers as
    earlier versions ran them, its inputs as 0.16 and before did, in every combination; None: none of them."""
    if theirs["name"] != sweep.name:
        return None
    from ..search.campaign import INPUTS_CHANGED

    inputs = sweep.with_inputs_of_before()
    versions = {}  # version -> (the sweep as it ran it, the keys to set, what it did), where it ran it otherwise
    for version in INPUTS_CHANGED:
        then = {key: (value, did) for c in sweep.campaigns for key, value, did in c.changes_of(version)}
        keys = [f"`{key.partition('.')[2]} = {json.dumps(value) if value == 'ignore' else value}` in [{key.partition('.')[0]}]"
                for key, (value, _) in then.items()]
        if (before := sweep.with_inputs_of(version)) is not sweep and before not in [b for b, _, _ in versions.values()]:
            versions[version] = (before, keys, ", ".join(did for _, did in then.values()))
    oldest_then = {key: value for c in sweep.campaigns for key, value, _ in c.changes_of(INPUTS_CHANGED[-1])}
    oldest = [f"`{key.partition('.')[2]} = {json.dumps(value) if value == 'ignore' else value}` in [{key.partition('.')[0]}]"
              for key, value in oldest_then.items()]
    input_keys = [*(["`network_sha256 = \"\"` in [scenario]"] if any(c.config.network_sha256 for c in sweep.campaigns) else []),
                  *(["`insertion_checks = false` in [traffic] (or in each table of grid.traffic)"]
                    if any(c.config.traffic for c in sweep.campaigns) else []), *oldest]
    for base, keys in [(sweep, []), *((b, k) for b, k, _ in versions.values()),
                       *([(inputs, input_keys)] if inputs is not sweep else [])]:
        names = list(EARLIER_OPTIONS)
        # each optimiser as now or as an earlier version ran it, in every combination (bo's and ce's both changed)
        for choice in itertools.product(*[(None, *EARLIER_OPTIONS[o]) for o in names]):
            changed = [(o, e) for o, e in zip(names, choice) if e is not None]
            before = base
            for optimizer, earlier in changed:
                before = before.as_run_before(optimizer, earlier)
            if (changed or keys) and theirs["fingerprint"] == before.fingerprint():
                tables = [", ".join(f"`{k} = {v}`" for k, v in e.items()) + f" in [search.{o}]" for o, e in changed]
                ran = next((f"d4sumo {v} or before ({did})" for v, (b, _, did) in versions.items() if b is base), None)
                version = ("an earlier d4sumo" if changed or not keys else ran if ran is not None else
                           "d4sumo 0.16 or before, which took a road of one's own as it found it, let traffic enter after "
                           "the warm-up unchecked, drove the platoon through red lights and played demand files one after "
                           "the other")
                wanted = "; ".join([*tables, *([" and ".join(keys)] if keys else [])])
                return f"It was run by {version}: set {wanted} of the sweep file to go on with it, or use another --db"
        default_before = base.with_default_of_before()
        earliers = ({}, *EARLIER_OPTIONS.get(EARLIER_DEFAULT_OPTIMIZER, ()))  # bo as each earlier version ran it
        for earlier in earliers if default_before is not base else ():
            if theirs["fingerprint"] == default_before.as_run_before(EARLIER_DEFAULT_OPTIMIZER, earlier).fingerprint():
                table = "".join(f", `{k} = {v}` in [search.{EARLIER_DEFAULT_OPTIMIZER}]" for k, v in earlier.items())
                table += "".join(f", {k}" for k in keys)  # and its inputs as it took them
                return (f"It was run by d4sumo 0.7 or before, whose default optimiser was {EARLIER_DEFAULT_OPTIMIZER}: set "
                        f"`optimizer = \"{EARLIER_DEFAULT_OPTIMIZER}\"`{table} in the sweep file to go on with it, or use another --db")
    return None


def claim(store: Store, sweep: Sweep) -> None:
    """Mark the database as this sweep's, refusing one written by anything else."""
    meta = store.meta()
    mine = {"name": sweep.name, "fingerprint": sweep.fingerprint(), **({"part": list(sweep.part)} if sweep.part else {})}
    if "sweep" in meta:
        try:
            theirs = json.loads(meta["sweep"])
            theirs["name"], theirs["fingerprint"]
        except (ValueError, TypeError, KeyError):
            raise StoreError(f"{store.path}: damaged results database (its sweep record {meta['sweep']!r})") from None
        if theirs != mine:
            hint = _earlier_hint(sweep, theirs) or "Use another --db, or the sweep file that wrote it"
            part = theirs.get("part")
            held = repr(theirs["name"]) + part_text(part if isinstance(part, list) and len(part) == 2 else None)
            raise StoreError(
                f"{store.path}: holds sweep {held} (grid {theirs['fingerprint']}), not {sweep.label} "
                f"(grid {mine['fingerprint']}); nothing was changed. {hint}"
            )
    else:
        others = store.campaigns()
        if others:
            held = f"{len(others)} campaign{'s' if len(others) != 1 else ''}"
            raise StoreError(f"{store.path}: holds {held} not run by this sweep; nothing was changed. Use another --db")
        store.set_meta("sweep", json.dumps(mine))


#: where a Dask sweep's optimisers run (`run_sweep`)
DASK_PROPOSALS = ("client", "workers")


@dataclass
class SweepResult:
    campaigns: int
    samples: int
    successes: int
    wall_s: float


def run_sweep(
    sweep: Sweep,
    db_path: str | Path,
    *,
    workers: int | None = None,
    dask_address: str | None = None,
    dask_timeout_s: float = 30.0,
    progress: Callable[[int, int, int], None] | None = None,
    batch: int = DEFAULT_BATCH,
    dask_proposals: str = "client",
    cluster=None,
) -> SweepResult:
    """Run every campaign of the sweep not yet complete in ``db_path``. ``progress(done, total, successes)``
    is called as samples are stored. ``dask_address``: a scheduler's address, or "local" for a local
    Dask cluster of ``workers`` processes. ``batch``: at most this many episodes of a campaign side by
    side in one SUMO (1: one at a time); the results do not depend on it. ``dask_proposals``: where a
    Dask sweep's optimisers run: on the ``client`` (the samples are the ones each campaign gives alone
    on the client's machine, whatever machines the workers are) or on the ``workers`` (the client's work
    spread, but a campaign proposes with the numerics of whichever worker steps it). ``cluster``: a cluster
    made already, in place of Dask's (`dask_cluster.DaskCluster`: tools/bench_client.py's simulated workers)."""
    sweep.check()
    if dask_proposals not in DASK_PROPOSALS:
        raise ConfigError("--dask-proposals", dask_proposals, f"one of {', '.join(DASK_PROPOSALS)}")
    if dask_address is not None:
        dask_address = check_dask_address(dask_address)
    workers = workers or usable_cores()
    t0 = time.perf_counter()
    sources: dict[str, NetworkSource] = {}
    with contextlib.ExitStack() as stack:
        # the cluster first: an unreachable scheduler leaves no database behind
        if cluster is None and dask_address:
            cluster = DaskCluster(stack.enter_context(_dask_client(dask_address, dask_timeout_s, workers)))
        store = stack.enter_context(open_store(db_path))
        claim(store, sweep)
        todo: list[_Active] = []
        for c in sweep.campaigns:
            cid = store.open_campaign(c.definition(), c.samples, sweep.name)
            stored = stored_results(store, cid, c.samples)
            if len(stored) < c.samples:
                key = c.config.network, c.config.route, c.config.whole_network, c.config.network_given
                if key not in sources:
                    sources[key] = network_source(c.config.network, route=() if c.config.whole_network else c.config.route,
                                                  given=c.config.network_given)
                fmus = shipment(c.config) if cluster is not None else ()  # local workers see the client's files
                todo.append(_Active(c, cid, sources[key], tuple(stored), done=len(stored), batch=batch, fmus=fmus))
        total = sweep.samples
        counts = list(store.sweep_counts(sweep.name))

        said = [False]  # a campaign begun where the numerics differ: said once a sweep
        writes = stack.enter_context(_Writes(store))

        def store_results(active: _Active, results: list[SampleResult]) -> None:
            if active.numerics_differ_at is not None and not said[0] and results:
                said[0] = True
                log.warning("%s (other campaigns resumed so are not named)",
                            numerics_note(f"{store.path}: campaign {active.campaign_id}", active.numerics_differ_at))
            writes.add(active.campaign_id, [(r.index, r.params, r.robustness, r.outcome, r.collision, r.min_gaps,
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
            if cluster is not None and dask_proposals == "client":
                _run_dask_proposing(todo, store_results, cluster, str(store.path))
            elif cluster is not None:
                _run_dask(todo, store_results, cluster)
            elif workers == 1:
                _run_inline(todo, store_results)
            else:
                _run_local(todo, store_results, workers)
    return SweepResult(len(sweep.campaigns), counts[0], counts[1], time.perf_counter() - t0)


class _Writes:
    """The samples a sweep's client stores, written together at most every FLUSH_S seconds (one transaction,
    one disk sync, for every campaign whose results came in meanwhile) and whatever is left when the sweep
    ends, is stopped or fails. A kill -9 loses at most the last FLUSH_S seconds of results, which the next
    run plays again, the same samples."""

    FLUSH_S = 0.1  # 0.5 s left 50 simulated workers of 1 ms episodes idle a quarter of the time while a write took its turn

    def __init__(self, store):
        self.store, self.pending, self.last = store, [], time.monotonic()

    def add(self, campaign_id: int, samples: list[tuple]) -> None:
        self.pending.append((campaign_id, samples))
        if time.monotonic() - self.last >= self.FLUSH_S:
            self.flush()

    def flush(self) -> None:
        if self.pending:
            pending, self.pending = self.pending, []
            self.store.add_samples_of(pending)
        self.last = time.monotonic()

    def __enter__(self) -> "_Writes":
        return self

    def __exit__(self, *exc) -> None:
        self.flush()


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
    pool = new_pool(workers)

    def submitted(gang: list[_Active]) -> bool:
        """Whether ``gang`` is on the pool. Not when a worker died since the last wait: the tasks in flight
        then fail with the pool (and run again); with none in flight, a new pool is made now."""
        nonlocal pool
        try:
            running[pool.submit(run_chunks, _task(gang))] = gang
            return True
        except BrokenProcessPool:
            if not running:
                kill_pool(pool)
                pool = new_pool(workers)
            return False

    try:
        while queue or running or suspects:
            if suspects:
                if not running:
                    submitted(suspects[0])  # if refused, tried again on the next turn
            else:
                while queue and len(running) < workers + 1:
                    gang = queue.pop(0)
                    if not submitted(gang):
                        queue.insert(0, gang)
                        break
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
                    kill_pool(pool)
                    pool = new_pool(workers)
                    break
                if alone:
                    suspects.pop(0)
                gang = _accept_gang(gang, chunk_results, store_results)
                if gang and alone:
                    queue.insert(0, gang)
                elif gang:
                    gang = _share(gang, queue, len(running) + 1, workers)
                    if not submitted(gang):
                        queue.insert(0, gang)
    finally:
        kill_pool(pool)


# --- Dask --------------------------------------------------------------------------------------

