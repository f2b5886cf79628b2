"""How many workers one sweep client feeds: the client of a Dask sweep (its optimisers on the client, as by
default) against simulated workers whose episodes cost a fixed time and run no SUMO, from 1 to 1,000
workers; and, at the small end, a real Dask cluster of local processes playing the same episodes.

The client is d4sumo's own, whole: `sweep.run.run_sweep` with its optimisers proposing, the database
storing every sample, the tasks built and their results taken (`dask_cluster._schedule`). Only the cluster
is simulated (`SimulatedCluster`): each worker plays one task at a time, each episode of it costing
``--episode-ms``; time is simulated, except the client's own work, which advances the clock by what it
really took. So the sweep's simulated wall time is what a cluster of that many workers would take if
neither the network nor Dask's scheduler cost anything; the real cluster's line shows what they add.

For each number of workers it prints the episodes per second, the workers' utilisation (the share of their
time spent playing), the client's busy share, and where the client's time went: proposals (the optimisers'
ask and tell), storage (the database's writes), and the rest (tasks built, results taken, bookkeeping). The
client saturates where its busy share reaches 1: the last line names what took most of its time there, and
the most workers it feeds at the utilisation given (--utilisation, 0.9).

With ``--proposals workers`` the optimisers step on the workers (`sweep --dask-proposals workers`): their
real time is the workers', and the client only stores and sends.

Usage: python tools/bench_client.py [--workers 1 10 100 1000] [--episode-ms 1] [--campaigns 2000]
                                    [--samples 300] [--optimizer random] [--proposals client workers]
                                    [--dask 1 2 4] [--clients N]

With ``--clients N`` the sweep is shared by N clients (`sweep --part K/N`), each with its share of the workers
and its own database, as on machines of their own: each part is simulated in turn, and the sweep's episodes per
second and utilisation are those of all the workers together.
"""

from __future__ import annotations

import heapq
import itertools
import tempfile
import time
from contextlib import ExitStack
from pathlib import Path
from unittest import mock

import numpy as np

from d4sumo.errors import refusal
from d4sumo.search.campaign import SampleResult
from d4sumo.search.runner import CampaignRunner
from d4sumo.search.store import Store
from d4sumo.sweep import Sweep, run_sweep
from d4sumo.sweep.run import DASK_PROPOSALS
from d4sumo.sweep.tasks import play_chunks, run_chunks
from toolargs import Parser, run_main


def synthetic(first: int, points, episode_s: float) -> list[SampleResult]:
    """What playing ``points`` as samples ``first``, ``first`` + 1, ... gives, without SUMO: each point's
    robustness a smooth function of it (a success where it is positive, with its collision), the minimum gap
    of each pair of a platoon of three followers, each episode's cost ``episode_s``."""
    results = []
    for i, x in enumerate(points):
        robustness = 0.3 - float(np.mean((np.asarray(x) - 0.5) ** 2))
        gaps = {"v0-v1": 5.0 + robustness, "v1-v2": 3.0 + robustness, "v2-v3": -robustness}
        collision = {"pair": "v2-v3", "time_s": 8.15, "position_m": 67.4, "speed_diff_kmh": 29.6} if robustness > 0 else None
        results.append(SampleResult(first + i, tuple(float(v) for v in x), robustness,
                                    "success" if robustness > 0 else "no_crash", collision, gaps, episode_s))
    return results


ON_A_WORKER = [False]  # a simulated worker's optimisers stepping: not the client's time


def synthetic_chunks(chunks, episode_s: float) -> tuple[list, int]:
    """`tasks.run_chunks` (the optimisers stepped where it runs) with synthetic episodes: its result, and how
    many episodes it played."""
    played = [0]

    def play_pending(jobs, batch=None, on_result=None):
        played[0] += sum(len(xs) for _, _, xs in jobs)
        return [synthetic(first, xs, episode_s) for _, first, xs in jobs]

    ON_A_WORKER[0] = True
    try:
        with mock.patch("d4sumo.search.runner.play_pending", play_pending):
            return run_chunks(chunks), played[0]
    finally:
        ON_A_WORKER[0] = False


def on_a_worker(function, args, episode_s: float):
    """A real worker's task: the synthetic episodes of a task, after sleeping their cost."""
    if function is play_chunks:
        plays, _ = args
        time.sleep(episode_s * sum(len(p.points) for p in plays))
        return [synthetic(p.first, p.points, episode_s) for p in plays]
    result, episodes = synthetic_chunks(args[0], episode_s)
    time.sleep(episode_s * episodes)
    return result


class _Done:
    """A finished task, as a Dask future looks to the client."""

    status = "finished"

    def __init__(self, result):
        self._result = result

    def result(self):
        return self._result

    def exception(self):
        return None

    def release(self) -> None:
        self._result = None


class SimulatedCluster:
    """``workers`` simulated workers behind the client's cluster seam (`dask_cluster.DaskCluster`): submit,
    nthreads, as_completed. A task starts on the first worker free, at the simulated time it was submitted,
    and ends its episodes' cost later; the client's time between taking a result and asking for the next is
    real, measured, and added to the simulated clock, with a scheduler's round trip for each ask of its
    threads (`ASK_S`)."""

    #: what asking a scheduler for its workers' threads costs the client: a round trip, measured on a local
    #: Dask cluster of 2 workers (`client.nthreads()`, 0.35 ms)
    ASK_S = 0.00035

    def __init__(self, workers: int, episode_s: float, task_overhead_s: float = 0.0):
        self.workers, self.episode_s, self.task_overhead_s = workers, episode_s, task_overhead_s
        self.asks = 0
        self.now = 0.0  # simulated seconds
        self.free = [(0.0, w) for w in range(workers)]  # (when free, worker)
        self.finishing: list = []  # (when, order, future)
        self.order = itertools.count()
        self.worker_busy_s = 0.0
        self.client_busy_s = 0.0
        self.tasks = 0
        self.episodes = 0
        self._mark = None  # real time the client was handed a result
        self._excluded = 0.0  # real time spent making a simulated task's results: the workers', not the client's
        self.ended = None  # real time the last result was taken

    def _clock(self) -> float:
        if self._mark is None:
            return self.now
        return self.now + time.perf_counter() - self._mark - self._excluded

    def nthreads(self) -> dict:
        if self._mark is None:  # the client asks first as its tasks begin (its set-up done): its work counts from here
            self._mark = time.perf_counter()
        self._excluded -= self.ASK_S  # the round trip to the scheduler: the client's time
        self.asks += 1
        return dict.fromkeys(range(self.workers), 1)

    def submit(self, function, *args, pure: bool = False):
        t0 = time.perf_counter()
        if function is play_chunks:  # episodes only: the optimisers are on the client
            plays, _ = args
            results = [synthetic(p.first, p.points, self.episode_s) for p in plays]
            episodes, proposing_s = sum(len(p.points) for p in plays), 0.0
        elif function is run_chunks:  # the optimisers on the workers: their real time is the workers'
            results, episodes = synthetic_chunks(args[0], self.episode_s)
            proposing_s = time.perf_counter() - t0
        else:
            raise ValueError(f"the simulated cluster plays sweeps' tasks, not {function.__name__}")
        self._excluded += time.perf_counter() - t0
        free_at, worker = heapq.heappop(self.free)
        start = max(self._clock(), free_at)
        cost = episodes * self.episode_s + proposing_s + self.task_overhead_s
        heapq.heappush(self.free, (start + cost, worker))
        future = _Done(results)
        heapq.heappush(self.finishing, (start + cost, next(self.order), future))
        self.worker_busy_s += cost
        self.tasks += 1
        self.episodes += episodes
        return future

    def as_completed(self):
        cluster = self

        class Completed:
            def add(self, future) -> None:  # submit queued it already
                pass

            def __iter__(self):
                while cluster.finishing:
                    if cluster._mark is not None:  # the client's work since it was handed the last result (or began)
                        now = cluster._clock()
                        cluster.client_busy_s += now - cluster.now
                        cluster.now = now
                    when, _, future = heapq.heappop(cluster.finishing)
                    cluster.now = max(cluster.now, when)
                    cluster._mark, cluster._excluded = time.perf_counter(), 0.0
                    yield future
                now = cluster._clock()
                cluster.client_busy_s += now - cluster.now
                cluster.now = now
                cluster.ended = time.perf_counter()

        return Completed()


class RealCluster:
    """A real Dask cluster of local processes behind the same seam, its tasks the synthetic episodes."""

    def __init__(self, client, episode_s: float):
        from d4sumo.sweep.dask_cluster import DaskCluster

        self.cluster, self.episode_s = DaskCluster(client), episode_s

    def submit(self, function, *args, pure: bool = False):
        return self.cluster.submit(on_a_worker, function, args, self.episode_s, pure=pure)

    def nthreads(self) -> dict:
        return self.cluster.nthreads()

    def as_completed(self):
        return self.cluster.as_completed()


class Split:
    """Real seconds the client spent proposing (its optimisers' ask and tell) and storing (a simulated worker's
    proposals are not the client's)."""

    def __init__(self):
        self.proposals_s = self.storage_s = 0.0

    def timed(self, attribute: str, function):
        def wrapper(*args, **kwargs):
            if ON_A_WORKER[0]:
                return function(*args, **kwargs)
            t0 = time.perf_counter()
            try:
                return function(*args, **kwargs)
            finally:
                setattr(self, attribute, getattr(self, attribute) + time.perf_counter() - t0)
        return wrapper

    def patches(self, stack: ExitStack) -> None:
        for name in ("pending", "accept"):
            stack.enter_context(mock.patch.object(CampaignRunner, name, self.timed("proposals_s", getattr(CampaignRunner, name))))
        stack.enter_context(mock.patch.object(Store, "add_samples_of", self.timed("storage_s", Store.add_samples_of)))


RUNS = itertools.count()  # each run its own database


def sweep_file(folder: Path, campaigns: int, samples: int, optimizer: str) -> Path:
    path = folder / "scale.toml"
    path.write_text(f'name = "scale"\n\n[grid]\noptimizer = ["{optimizer}"]\nseed = {list(range(campaigns))}\n\n'
                    f"[search]\nsamples = {samples}\n")
    return path


def run_simulated(sweep: Sweep, folder: Path, workers: int, episode_s: float, proposals: str = "client") -> dict:
    split, cluster = Split(), SimulatedCluster(workers, episode_s)
    db = folder / f"simulated-{workers}-{next(RUNS)}.sqlite"
    t0 = time.perf_counter()
    with ExitStack() as stack:
        split.patches(stack)
        run_sweep(sweep, db, cluster=cluster, dask_proposals=proposals)
    real_s = time.perf_counter() - t0
    tail_s = time.perf_counter() - cluster.ended  # the last results written, the database closed
    cluster.now += tail_s
    cluster.client_busy_s += tail_s
    return {"workers": workers, "db": db, "wall_s": cluster.now, "episodes": cluster.episodes, "tasks": cluster.tasks,
            "asks": cluster.asks,
            "utilisation": cluster.worker_busy_s / (workers * cluster.now), "client": cluster.client_busy_s / cluster.now,
            "proposals_s": split.proposals_s, "storage_s": split.storage_s, "client_s": cluster.client_busy_s, "real_s": real_s}


def run_parts(sweep: Sweep, folder: Path, workers: int, clients: int, episode_s: float, proposals: str = "client") -> dict:
    """``clients`` clients, each running its part of the sweep (`sweep --part K/N`) into its own database with
    its share of the workers, on machines of their own: each simulated in turn, their figures added up (the
    sweep's wall time the slowest part's)."""
    shares = [workers // clients + (k < workers % clients) for k in range(clients)]
    parts = [run_simulated(sweep.part_of(f"{k + 1}/{clients}"), folder, n, episode_s, proposals)
             for k, n in enumerate(shares) if n]
    wall_s = max(r["wall_s"] for r in parts)
    busy_s = sum(r["utilisation"] * r["workers"] * r["wall_s"] for r in parts)
    total = {key: sum(r[key] for r in parts) for key in ("episodes", "proposals_s", "storage_s", "client_s")}
    return {**total, "workers": workers, "dbs": [r["db"] for r in parts], "wall_s": wall_s, "utilisation": busy_s / (workers * wall_s),
            "client": max(r["client"] for r in parts)}


def run_real(sweep: Sweep, folder: Path, workers: int, episode_s: float, proposals: str = "client") -> dict:
    from d4sumo.sweep.dask_cluster import _dask_client

    db = folder / f"dask-{workers}-{next(RUNS)}.sqlite"
    with _dask_client("local", 60.0, workers) as client:
        client.submit(sum, [1]).result()  # the workers up before the clock starts
        t0 = time.perf_counter()
        run_sweep(sweep, db, cluster=RealCluster(client, episode_s), dask_proposals=proposals)
        wall_s = time.perf_counter() - t0
    episodes = sweep.samples
    return {"workers": workers, "wall_s": wall_s, "episodes": episodes, "utilisation": episodes * episode_s / (workers * wall_s)}


def main() -> None:
    parser = Parser(__doc__)
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 10, 100, 1000])
    parser.add_argument("--episode-ms", type=float, default=1.0)
    parser.add_argument("--campaigns", type=int, default=2000)
    parser.add_argument("--samples", type=int, default=300)
    parser.add_argument("--optimizer", default="random")
    parser.add_argument("--proposals", nargs="+", choices=DASK_PROPOSALS, default=["client"],
                        help="where the optimisers run (sweep --dask-proposals)")
    parser.add_argument("--clients", type=int, default=1,
                        help="clients sharing the sweep (sweep --part K/N), each with its share of the workers")
    parser.add_argument("--dask", type=int, nargs="*", default=[1, 2, 4], help="local Dask workers, real (none: skip)")
    parser.add_argument("--dask-campaigns", type=int, default=64)
    parser.add_argument("--utilisation", type=float, default=0.9)
    args = parser.parse_args()
    parser.check_counts({"--campaigns": (args.campaigns, 1), "--samples": (args.samples, 1),
                         "--dask-campaigns": (args.dask_campaigns, 1)})
    for n in (*args.workers, *args.dask):
        parser.check_counts({"--workers": (n, 1, 100_000)})
    parser.check_counts({"--clients": (args.clients, 1, min(args.campaigns, *args.workers))})  # each a campaign, a worker
    if not 0 < args.episode_ms <= 10_000:
        parser.error(refusal("--episode-ms", args.episode_ms, "a time in (0, 10000] ms"))
    if not 0 < args.utilisation <= 1:
        parser.error(refusal("--utilisation", args.utilisation, "a share in (0, 1]"))
    parser.check_optimizers([args.optimizer])
    episode_s = args.episode_ms / 1000
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        sweep = Sweep.load(sweep_file(folder, args.campaigns, args.samples, args.optimizer))
        real = Sweep.load(sweep_file(folder, args.dask_campaigns, args.samples, args.optimizer)) if args.dask else None
        for proposals in args.proposals:
            print(f"{args.campaigns} campaigns of {args.samples} samples ({args.optimizer}, optimisers on the {proposals}), "
                  f"episodes of {args.episode_ms:g} ms, simulated workers")
            print(f"{'workers':>8} {'episodes/s':>11} {'utilisation':>11} {'client busy':>11} {'proposals':>9} "
                  f"{'storage':>8} {'rest':>6} {'client us/episode':>17}")
            if args.clients > 1:
                print(f"{args.clients} clients, each its part of the sweep (sweep --part K/N) with its share of the workers; "
                      "client busy: the busiest's")
            rows = [run_simulated(sweep, folder, n, episode_s, proposals) if args.clients == 1
                    else run_parts(sweep, folder, n, args.clients, episode_s, proposals) for n in args.workers]
            for r in rows:
                rest = r["client_s"] - r["proposals_s"] - r["storage_s"]
                print(f"{r['workers']:>8} {r['episodes'] / r['wall_s']:>11.0f} {r['utilisation']:>11.2f} {r['client']:>11.2f} "
                      f"{r['proposals_s'] / r['client_s']:>9.0%} {r['storage_s'] / r['client_s']:>8.0%} "
                      f"{rest / r['client_s']:>6.0%} {1e6 * r['client_s'] / r['episodes']:>17.1f}")
            per_episode_s = min(r["client_s"] / r["episodes"] for r in rows)
            last = rows[-1]
            parts = {"proposals": last["proposals_s"], "storage": last["storage_s"],
                     "tasks and results": last["client_s"] - last["proposals_s"] - last["storage_s"]}
            print(f"{'one client' if args.clients == 1 else f'each of {args.clients} clients'} feeds about "
                  f"{int(args.utilisation * episode_s / per_episode_s)} workers at "
                  f"{args.utilisation:.0%} utilisation with {args.episode_ms:g} ms episodes (its {1e6 * per_episode_s:.1f} us "
                  f"per episode); at {last['workers']} workers most of its time went to {max(parts, key=parts.get)}")
            if real is not None:
                print(f"real local Dask cluster, {args.dask_campaigns} campaigns of {args.samples} samples, the same episodes:")
                for n in args.dask:
                    r, s = run_real(real, folder, n, episode_s, proposals), run_simulated(real, folder, n, episode_s, proposals)
                    print(f"{n:>8} workers: {r['episodes'] / r['wall_s']:>8.0f} episodes/s, episodes {r['utilisation']:.0%} of "
                          f"the workers' time (simulated: {s['episodes'] / s['wall_s']:.0f} episodes/s, utilisation "
                          f"{s['utilisation']:.2f})")


if __name__ == "__main__":
    run_main(main)
