"""What a seed repeats on another machine: the same campaigns run here and under another numeric set-up,
compared sample by sample.

A set-up is a Python environment (its numpy, scipy and OpenBLAS builds) and its environment variables:
``OPENBLAS_CORETYPE=Prescott`` pins OpenBLAS to the kernel of another CPU (it runs on any x86-64 one),
``NPY_DISABLE_CPU_FEATURES`` turns off numpy's SIMD paths. For each optimiser it reports:
  points    how many samples' points are bit for bit the same, the first that differs, and how many are
            within 1e-12 (a point a model proposed, through BLAS, may differ; one the seed alone draws only
            in its last bits, where another scipy computes a distribution's quantiles otherwise);
  verdicts  of the samples whose points are the same, how many have the same robustness, outcome,
            collision record and minimum gaps, exactly (episodes involve no BLAS: expected all);
  replay    every sample stored there re-simulated here: how many give the stored verdict exactly;
  resume    the campaign stored there cut to half its samples and resumed here: whether it completes,
            and what it says.

Usage: python tools/cross_numerics.py --there-python /other/venv/bin/python [--there-env KEY=VALUE ...]
           [--here-env KEY=VALUE ...] [--optimizers random ce auto turbo] [--samples 100] [--seed 5] --out DIR
Run it by hand, on one machine: it measures this machine against another set-up of it, not a test.
"""

from __future__ import annotations

import os
import shutil
import sqlite3
import subprocess
import sys
from pathlib import Path

import numpy as np

from d4sumo.search.campaign import Campaign, open_store
from d4sumo.search.runner import Evaluator
from toolargs import Parser, run_main

CLI = "import sys; from d4sumo.cli import main; sys.exit(main(sys.argv[1:]))"


def environment(pairs: list[str]) -> dict[str, str]:
    env = dict(os.environ)
    for pair in pairs:
        key, _, value = pair.partition("=")
        env[key] = value
    return env


def falsify(python: str, env: dict, db: Path, optimizer: str, samples: int, seed: int) -> subprocess.CompletedProcess:
    return subprocess.run([python, "-c", CLI, "falsify", "--db", str(db), "--optimizer", optimizer, "--samples",
                           str(samples), "--seed", str(seed), "--quiet"], env=env, capture_output=True, text=True)


def rows(db: Path) -> list[tuple]:
    with open_store(db, create=False) as store:
        return [(s.index, s.params, s.robustness, s.outcome, s.collision, s.min_gaps) for s in store.samples()]


def numerics(python: str, env: dict) -> str:
    probe = ("import numpy, scipy, threadpoolctl; i = [x for x in threadpoolctl.threadpool_info() if x['user_api'] == 'blas'];"
             "print(f'numpy {numpy.__version__}, scipy {scipy.__version__}, ' + ', '.join(sorted({x['internal_api'] + ' ' "
             "+ str(x['version']) + ' ' + str(x.get('architecture')) for x in i})))")
    return subprocess.run([python, "-c", probe], env=env, capture_output=True, text=True).stdout.strip()


def replayed_here(db: Path) -> tuple[int, int]:
    """Every stored sample re-simulated in this process: (same verdict exactly, samples)."""
    with open_store(db, create=False) as store:
        stored = store.samples()
        campaign = Campaign.from_definition(store.campaign(stored[0].campaign_id).definition)
    evaluate = Evaluator(campaign)
    same = 0
    for s in stored:
        r = evaluate(s.index, np.array(s.params))
        same += (r.robustness, r.outcome, r.collision, r.min_gaps) == (s.robustness, s.outcome, s.collision, s.min_gaps)
    return same, len(stored)


def main() -> None:
    parser = Parser(__doc__)
    parser.add_argument("--there-python", required=True, help="the other set-up's Python (with d4sumo installed)")
    parser.add_argument("--there-env", nargs="*", default=[], help="KEY=VALUE for the other set-up")
    parser.add_argument("--here-env", nargs="*", default=[], help="KEY=VALUE for this one")
    parser.add_argument("--optimizers", nargs="+", default=["random", "ce", "auto", "turbo"])
    parser.add_argument("--samples", type=int, default=100)
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--out", type=Path, required=True)
    args = parser.parse_args()
    parser.check_optimizers(args.optimizers)
    parser.check_counts({"--samples": (args.samples, 2)})
    args.out.mkdir(parents=True, exist_ok=True)
    here, there = environment(args.here_env), environment(args.there_env)
    print(f"here:  {numerics(sys.executable, here)} {' '.join(args.here_env)}")
    print(f"there: {numerics(args.there_python, there)} {' '.join(args.there_env)}")
    for optimizer in args.optimizers:
        a, b = args.out / f"here-{optimizer}.sqlite", args.out / f"there-{optimizer}.sqlite"
        for db in (a, b):
            db.unlink(missing_ok=True)
        for python, env, db in ((sys.executable, here, a), (args.there_python, there, b)):
            done = falsify(python, env, db, optimizer, args.samples, args.seed)
            if done.returncode:
                sys.exit(f"{optimizer}: falsify failed: {done.stderr.strip()}")
        ra, rb = rows(a), rows(b)
        same_points = [x[1] == y[1] for x, y in zip(ra, rb)]
        close = sum(np.allclose(x[1], y[1], rtol=0, atol=1e-12) for x, y in zip(ra, rb))
        first = same_points.index(False) if not all(same_points) else None
        verdicts = [x[2:] == y[2:] for x, y, p in zip(ra, rb, same_points) if p]
        same, total = replayed_here(b)
        # resume: the campaign begun there, cut to half, resumed here
        cut = args.out / f"resume-{optimizer}.sqlite"
        shutil.copy(b, cut)
        with sqlite3.connect(cut) as db:
            db.execute("DELETE FROM sample WHERE idx >= ?", (args.samples // 2,))
        resumed = falsify(sys.executable, here, cut, optimizer, args.samples, args.seed)
        note = next((line for line in resumed.stderr.splitlines() if "numerics differ" in line or "error" in line), "")
        print(f"{optimizer}: points {sum(same_points)}/{len(ra)} bit for bit the same"
              + (f" (first differs at sample {first}), {close} to 1e-12" if first is not None else "")
              + f"; verdicts of those {sum(verdicts)}/{len(verdicts)} the same; replay here {same}/{total} exactly;"
              f" resumed here from {args.samples // 2}: exit {resumed.returncode}, {len(rows(cut))} samples"
              + (f"\n  says: {note.split(': ', 1)[-1]}" if note else ""))


if __name__ == "__main__":
    run_main(main)
