"""Local worker processes that never outlive the process that started them: sweeps' workers, and the
benchmark scripts' in tools/."""

from __future__ import annotations

import os
import signal
from concurrent.futures import ProcessPoolExecutor
from multiprocessing import get_context

from ..processes import die_with_parent


def usable_cores() -> int:
    """The cores this process may run on (its CPU affinity: a container's cpuset, taskset's), not the
    machine's: as many workers as that, and none wait for a core. (A CPU quota, as Docker's cpus option sets, is not an
    affinity: --workers says it.)"""
    try:
        return len(os.sched_getaffinity(0)) or 1
    except (AttributeError, OSError):  # no affinity where the system has none to say (macOS)
        return os.cpu_count() or 1


def new_pool(workers: int) -> ProcessPoolExecutor:
    """``workers`` local processes, spawned clean (libsumo keeps one simulation per process), that ignore
    Ctrl-C (the caller's to handle) and die with the caller."""
    quiet_resource_tracker()
    return ProcessPoolExecutor(max_workers=workers, mp_context=get_context("spawn"), initializer=_worker_init,
                               initargs=(os.getpid(),))


#: multiprocessing's resource tracker, a process of the caller's, removes the semaphores of its worker
#: processes (a pool's, a local Dask cluster's) if the caller cannot (killed by SIGKILL): once the workers
#: are gone too, a few tenths of a second later, it warns "There appear to be 5 leaked semaphore objects
#: to clean up at shutdown" on the terminal, often in the middle of the next command. Nothing leaks
#: (removing them is its job), so it is told to say nothing.
_TRACKER_QUIET = "ignore::UserWarning:multiprocessing.resource_tracker"


def quiet_resource_tracker() -> None:
    """Start multiprocessing's resource tracker (once a process, unless it has died) with its warnings off
    (it reads them from the environment it starts with), before any worker process is started."""
    from multiprocessing import resource_tracker

    given = os.environ.get("PYTHONWARNINGS")
    os.environ["PYTHONWARNINGS"] = f"{given},{_TRACKER_QUIET}" if given else _TRACKER_QUIET
    try:
        resource_tracker.ensure_running()
    finally:
        if given is None:
            del os.environ["PYTHONWARNINGS"]
        else:
            os.environ["PYTHONWARNINGS"] = given


def kill_pool(pool: ProcessPoolExecutor) -> None:
    """Stop a pool now: queued tasks are dropped and running ones killed (workers leave writing to the
    caller, so nothing half-written is left); waits until the processes are gone."""
    processes = list((getattr(pool, "_processes", None) or {}).values())
    pool.shutdown(wait=False, cancel_futures=True)
    for p in processes:
        if p.is_alive():
            p.kill()
    for p in processes:
        p.join(timeout=5)
    manager = getattr(pool, "_executor_manager_thread", None)
    if manager is not None:  # gone, its wake-up pipe closed, before Python's exit wakes it: CPython 3.11 races there
        manager.join(timeout=5)  # (a closed pipe written to: "Exception ignored ... Bad file descriptor" at exit)


def _worker_init(parent_pid: int) -> None:
    """A local worker: Ctrl-C is the client's to handle, and the worker dies with the client."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    signal.signal(signal.SIGTERM, signal.SIG_DFL)
    die_with_parent(parent_pid)
