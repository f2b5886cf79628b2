"""Sweep throughput against worker count and batch size, measured in one run: the same sweeps into
fresh databases.

Usage: python tools/bench_sweep.py [SWEEP.toml ...] [--workers 1 2] [--batch 32] [--baseline]
       python tools/bench_sweep.py examples/sweeps/paper_*.toml --workers 2 --batch 1 64
       python tools/bench_sweep.py examples/sweeps/paper_*.toml --workers 2 --baseline   # against d4sumo 0.2's engine
       python tools/bench_sweep.py examples/sweeps/paper_*.toml --set search.bo.batch_size=5   # a fixed value changed
Prints the wall time per (workers, batch), samples per second, the peak resident memory of a worker and of
the client so far, and the speed-up over the first;
checks that every run stored the same samples (the result depends on neither). ``--baseline`` first
runs the sweeps as d4sumo 0.2 did (one episode per SUMO, BO one point per score on scikit-optimize's GP,
ce without noise: `--batch 1 --set search.bo.gp_version=1 --set search.bo.batch_size=1 --set
search.ce.noise_fraction=0`) with the largest worker count, and prints the speed-up of every run over it
(its samples differ where bo's GP and ce's noise do, so it is left out of the check).
"""

from __future__ import annotations

import resource
import tempfile
import time
from pathlib import Path

from d4sumo.inputs import with_overrides
from d4sumo.engine.scenarios import MAX_COPIES
from d4sumo.errors import refusal
from d4sumo.model.stepping.batch import DEFAULT_BATCH
from d4sumo.tomlfiles import read_toml, toml_value
from d4sumo.search.campaign import open_store
from d4sumo.sweep import Sweep, run_sweep
from toolargs import Parser, run_main

HERE = Path(__file__).resolve().parent.parent


def signature(db: Path) -> list:
    with open_store(db, create=False) as store:
        keys = {c.id: c.key for c in store.campaigns()}
        return sorted((keys[s.campaign_id], s.index, s.params, s.robustness) for s in store.samples())


def load(path: str, overrides: dict) -> Sweep:
    doc = read_toml(path, "SWEEP")
    head = {k: doc.pop(k) for k in ("name", "grid") if k in doc}
    return Sweep.from_dict({**head, **with_overrides(doc, overrides)}, default_name=Path(path).stem)


def peak_rss() -> str:
    """The largest resident memory so far of a worker process (those that ended) and of this one (the client, and
    the worker itself with one worker): Linux gives KiB."""
    workers = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss / 1024
    return f"peak resident memory: a worker {workers:.0f} MiB, this process {resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024:.0f} MiB"


def main() -> None:
    parser = Parser(__doc__)
    parser.add_argument("sweeps", nargs="*", default=[str(HERE / "examples" / "sweeps" / "small.toml")])
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2])
    parser.add_argument("--batch", type=int, nargs="+", default=[DEFAULT_BATCH])
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="change a fixed value of every sweep (TOML value), e.g. search.bo.batch_size=5")
    parser.add_argument("--baseline", action="store_true", help="first run the sweeps as d4sumo 0.2 did, and compare")
    args = parser.parse_args()
    for workers in args.workers:  # the bounds `d4sumo sweep` has
        parser.check_counts({"--workers": (workers, 1, 1024)})
    for batch in args.batch:
        parser.check_counts({"--batch": (batch, 1, MAX_COPIES)})
    for item in args.set:
        if "=" not in item:
            parser.error(refusal("--set", item, "KEY=VALUE, e.g. search.bo.batch_size=5"))
    overrides = {k: toml_value(v) for k, v in (item.split("=", 1) for item in args.set)}
    sweeps = [load(path, overrides) for path in args.sweeps]
    print(", ".join(f"sweep {s.name}: {len(s.campaigns)} campaigns, {s.samples} samples" for s in sweeps))
    times, results = {}, {}
    runs = [(n, b) for n in args.workers for b in args.batch]
    before = (max(args.workers), "0.2")  # one episode per SUMO, scikit-optimize's GP

    def timed(run, sweeps, tmp):
        n, b = run
        t0 = time.perf_counter()
        samples = successes = 0
        signatures = []
        for i, sweep in enumerate(sweeps):
            db = Path(tmp) / f"w{n}-b{b}-{i}.sqlite"
            result = run_sweep(sweep, db, workers=n, batch=1 if b == "0.2" else b)
            samples += result.samples
            successes += result.successes
            signatures.append(signature(db))
        times[run] = time.perf_counter() - t0
        label = "as d4sumo 0.2 (batch 1, scikit-optimize's GP, ce without noise)" if b == "0.2" else f"batch {b:>2}"
        print(f"  {n} worker(s), {label}: {times[run]:6.1f} s  ({samples / times[run]:.0f} samples/s, {successes} successes; "
              f"{peak_rss()})", flush=True)
        return signatures

    with tempfile.TemporaryDirectory() as tmp:
        if args.baseline:
            as_before = {**overrides, "search.bo.gp_version": 1, "search.bo.batch_size": 1, "search.ce.noise_fraction": 0.0}
            timed(before, [load(path, as_before) for path in args.sweeps], tmp)
        for run in runs:
            results[run] = timed(run, sweeps, tmp)
    if args.baseline:
        for run in runs:
            print(f"  speed-up of {run[0]} worker(s), batch {run[1]} over d4sumo 0.2's engine: {times[before] / times[run]:.2f}x")
    base = runs[0]
    for run in runs[1:]:
        print(f"  speed-up of {run[0]} worker(s), batch {run[1]} over {base[0]} worker(s), batch {base[1]}: {times[base] / times[run]:.2f}x")
    same = all(results[run] == results[base] for run in runs)
    print(f"  identical samples for every run: {same}")


if __name__ == "__main__":
    run_main(main)
