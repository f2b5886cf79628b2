"""Sweeps on a Dask distributed cluster: the client connects, sends tasks, and stays the only writer."""

from __future__ import annotations

import contextlib
import logging
import math
import os
import re
import signal
import threading
import time
import traceback

from ..errors import ConfigError, D4sumoError
from ..search.runner import CampaignRunner
from .tasks import (
    Play, _accept_gang, _Active, _after_failure, _evaluator, _gangs, _share, _task, play_chunks, run_chunks)
from .workers import quiet_resource_tracker

log = logging.getLogger(__name__)

def check_dask_address(address: str) -> str:
    """``local``, or a scheduler address such as tcp://10.0.0.5:8786; anything else is a ConfigError."""
    if address == "local":
        return address
    m = _DASK_ADDRESS.match(address.strip()) if isinstance(address, str) else None
    if not m or not 1 <= int(m.group(3)) <= 65535:
        raise ConfigError("--dask", address, "'local' or a scheduler address PROTOCOL://HOST:PORT, e.g. tcp://10.0.0.5:8786")
    return address.strip() if m.group(1) else f"tcp://{address.strip()}"

_DASK_ADDRESS = re.compile(r"^(?:(tcp|tls|ws|wss|ucx)://)?(\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9_.-]+):(\d{1,5})$")



def _interrupted_sync(record: logging.LogRecord) -> bool:
    """False for the NameError distributed's ``sync`` logs when Ctrl-C lands before the call it waits for
    has started (its ``cancel`` reads a future not made yet): a traceback after the one line the
    interruption gets, about nothing the user did wrong."""
    exc = record.exc_info[1] if record.exc_info else None
    if not isinstance(exc, NameError) or exc.__traceback__ is None:
        return True
    last = traceback.extract_tb(exc.__traceback__)[-1]
    return not (last.name == "cancel" and last.filename.endswith(os.path.join("distributed", "utils.py")))


@contextlib.contextmanager
def _dask_client(address: str, timeout_s: float, workers: int):
    """A Dask client of the scheduler at ``address``, or of a local cluster of ``workers`` processes."""
    try:
        from distributed import Client, LocalCluster
    except ImportError:  # pragma: no cover - a core dependency
        raise D4sumoError("--dask needs the distributed package (pip install 'dask[distributed]')") from None
    with contextlib.ExitStack() as stack:
        try:
            if address == "local":
                quiet_resource_tracker()
                logging.getLogger("distributed").setLevel(logging.WARNING)  # not a page of start-up messages
                logging.getLogger("tornado.application").addFilter(_interrupted_sync)
                # the workers' warnings (a task cancelled by Ctrl-C) are not the user's business; errors are
                with _signals_deferred():  # a cluster cut short while it starts cannot be closed cleanly
                    cluster = LocalCluster(n_workers=workers, threads_per_worker=1, processes=True, host="127.0.0.1",
                                           dashboard_address=":0", silence_logs=logging.ERROR, preload=[__name__])
                    stack.callback(cluster.close, timeout=5)
                log.warning("local Dask cluster of %d workers; dashboard at %s", workers, cluster.dashboard_link)
                address = cluster.scheduler_address
            try:
                client = Client(address, timeout=timeout_s)
            except (OSError, TimeoutError) as exc:
                raise D4sumoError(f"--dask: no Dask scheduler answered at {address} within {timeout_s:g} s ({exc})") from None
            stack.enter_context(client)
            yield client
        finally:
            # a close cut short by Ctrl-C left Python's exit waiting 10 s for Dask to close the cluster again
            with _signals_deferred(ignored=True):
                stack.close()


def dask_setup(worker) -> None:
    """Run by each worker of a local cluster as it starts (its ``preload``): it ignores Ctrl-C. The terminal
    sends Ctrl-C to the whole process group, the workers with it; the sweep takes it and closes them in
    order, where each worker's own KeyboardInterrupt printed pages of tracebacks. And it does not log the
    scheduler it lost: a local cluster's scheduler is the sweep's process, which a kill -9 ends before its
    workers (on a loaded machine one lived to print the heartbeat it could not send, with its traceback)."""
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    logging.getLogger("distributed.worker").addFilter(_scheduler_lost)


def _scheduler_lost(record: logging.LogRecord) -> bool:
    """False for a local worker's log of the scheduler it can no longer reach."""
    return "communicate with scheduler" not in record.getMessage()


class DaskCluster:
    """A cluster as a sweep's client uses it: ``submit(function, *args, pure=False)`` a task, ``nthreads()`` (worker ->
    threads) and ``as_completed()`` (the tasks as they finish, more added as they are submitted). This one is a
    Dask client's; tools/bench_client.py has one of simulated workers."""

    def __init__(self, client):
        self.client = client

    def submit(self, function, *args, pure: bool = False):
        return self.client.submit(function, *args, pure=pure)

    def nthreads(self) -> dict:
        return self.client.nthreads()

    def as_completed(self):
        from distributed import as_completed

        return as_completed()


def _run_dask(todo: list[_Active], store_results, cluster: DaskCluster) -> None:
    """The sweep with each campaign's optimiser stepped on the workers, its state carried from task to task."""
    def task(gang: list[_Active]):
        return run_chunks, (_task(gang),), None

    def accept(gang: list[_Active], _, result) -> list[_Active]:
        return _accept_gang(gang, result, store_results)

    _schedule(todo, cluster, task, accept)


def _run_dask_proposing(todo: list[_Active], store_results, cluster: DaskCluster, where: str) -> None:
    """The sweep with every campaign's optimiser on the client and only episodes on the workers: each
    campaign asks and is told on one machine, so its samples are, bit for bit, the ones it gives alone
    on the client's, whatever mix of CPUs and libraries the workers have. A task plays the next batch
    of a gang of campaigns; the client tells their optimisers and sends the next."""
    runners = {id(a): CampaignRunner(a.campaign, _evaluator(_task([a])[0]), stored=a.stored, batch=a.batch,
                                     where=f"{where}: campaign {a.campaign_id}") for a in todo}

    def task(gang: list[_Active]):
        owners, plays = [], []
        for a in gang:  # the same points again after a failure: nothing was told
            for first, xs in runners[id(a)].pending():
                owners.append(a)
                plays.append(Play(a.campaign, a.network, first, tuple(xs), a.fmus))
        return play_chunks, (tuple(plays), gang[0].batch), owners

    def accept(gang: list[_Active], owners: list[_Active], result) -> list[_Active]:
        played: dict[int, dict] = {id(a): {} for a in gang}
        for owner, results in zip(owners, result):
            played[id(owner)].update((r.index, r) for r in results)
        for a in gang:
            results = runners[id(a)].accept(played[id(a)])
            a.numerics_differ_at = runners[id(a)].numerics_differ_at  # found at the start, or past a gap
            store_results(a, results)
            a.failures = 0
        return [a for a in gang if runners[id(a)].done < a.campaign.samples]

    _schedule(todo, cluster, task, accept)


def _threads(cluster: DaskCluster, every_s: float = 1.0):
    """The cluster's thread count, asked of its scheduler at most every ``every_s`` (workers join and leave
    rarely, and each ask is a round trip: 0.35 ms on a local cluster, asked twice a task)."""
    asked = [-math.inf, 1]

    def threads() -> int:
        now = time.monotonic()
        if now - asked[0] >= every_s:
            asked[:] = [now, max(1, sum(cluster.nthreads().values()))]
        return asked[1]

    return threads


IN_FLIGHT_PER_THREAD = 2


def _schedule(todo: list[_Active], cluster: DaskCluster, task, accept) -> None:
    """Gangs of campaigns on the cluster (a `DaskCluster`), a task at a time each, twice as many in flight as it
    has threads: each thread has the next task waiting as it finishes one, rather than waiting for the client
    to take its result and send another (with one task a thread and one spare, 50 simulated workers of 1 ms
    episodes played 63 % of the time, with a client busy 46 %: tools/bench_client.py). ``task(gang)``: the
    function, its arguments and what ``accept(gang, that, result)`` needs to take the result, which gives the
    gang's campaigns not complete yet."""
    threads = _threads(cluster)
    queue = _gangs(todo, threads())
    running: dict = {}
    futures = cluster.as_completed()

    def slots() -> int:
        return IN_FLIGHT_PER_THREAD * threads()

    def submit(gang: list[_Active]) -> None:
        function, args, context = task(gang)
        # pure=False: the same task sent again after a failure is run again, not looked up
        future = cluster.submit(function, *args, pure=False)
        running[future] = gang, context
        futures.add(future)

    while queue and len(running) < slots():
        submit(queue.pop(0))
    for future in futures:
        gang, context = running.pop(future)
        if future.status == "error":
            exc = future.exception()
            if isinstance(exc, D4sumoError):
                raise exc
            for part in _after_failure(gang, f"{type(exc).__name__}: {exc}"):
                submit(part)
            continue
        result = future.result()
        future.release()
        gang = accept(gang, context, result)
        if gang:
            submit(_share(gang, queue, len(running) + 1, threads()))
        while queue and len(running) < slots():
            submit(queue.pop(0))


@contextlib.contextmanager
def _signals_deferred(*, ignored: bool = False):
    """Ctrl-C and SIGTERM kept out of a block: taken at its end (the start of a local cluster, about a
    second: one cut short cannot be closed cleanly), by the command's own handler, in place of what the
    block raised, if anything; or ``ignored`` (its closing, bounded by its timeout)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    caught: list[int] = []
    handler = signal.SIG_IGN if ignored else (lambda sig, frame: caught.append(sig))
    held = {sig: signal.signal(sig, handler) for sig in (signal.SIGINT, signal.SIGTERM)}
    try:
        yield
    finally:
        for sig, previous in held.items():
            signal.signal(sig, previous)
        if caught:
            signal.raise_signal(caught[0])
