"""Sweep throughput against worker count, measured in one run: the same sweep into fresh databases.

Usage: python tools/bench_sweep.py [SWEEP.toml] [--workers 1 2]
Prints the wall time per worker count, samples per second, and the speed-up over one worker; checks
that every run stored the same samples (the result does not depend on the worker count).
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

from d4sumo.store import Store
from d4sumo.sweep import Sweep, run_sweep

HERE = Path(__file__).resolve().parent.parent


def signature(db: Path) -> list:
    with Store(db, create=False) as store:
        keys = {c.id: c.key for c in store.campaigns()}
        return sorted((keys[s.campaign_id], s.index, s.params, s.robustness) for s in store.samples())


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("sweep", nargs="?", default=str(HERE / "examples" / "sweeps" / "small.toml"))
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    args = parser.parse_args()
    sweep = Sweep.load(args.sweep)
    print(f"sweep {sweep.name}: {len(sweep.campaigns)} campaigns, {sweep.samples} samples")
    times, results = {}, {}
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.workers:
            db = Path(tmp) / f"w{n}.sqlite"
            t0 = time.perf_counter()
            result = run_sweep(sweep, db, workers=n)
            times[n] = time.perf_counter() - t0
            results[n] = signature(db)
            print(f"  {n} worker(s): {times[n]:6.1f} s  ({result.samples / times[n]:.0f} samples/s, {result.successes} successes)")
    base = args.workers[0]
    for n in args.workers[1:]:
        print(f"  speed-up {n} vs {base} worker(s): {times[base] / times[n]:.2f}x")
    same = all(results[n] == results[base] for n in args.workers)
    print(f"  identical samples for every worker count: {same}")


if __name__ == "__main__":
    main()
