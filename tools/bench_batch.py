"""Samples per second with episodes played side by side in one SUMO (batched) against one episode per
SUMO (unbatched), on one core, measured in one run (SPEC section 7: ratio >= 1.8).

The same campaigns run both ways, interleaved so machine noise hits both; each stores nothing and
is scored as usual (simulation, specification, optimiser: a whole sample). A batch is what the
optimiser proposes together: a cross-entropy generation (`ce`, 10 by default), a CMA-ES population,
or up to --batch random points. The results are checked to be identical both ways.

Usage: python tools/bench_batch.py [--samples 200] [--repeats 3] [--batch 64] [--optimizers random ce cmaes]
The last line is the ratio of the first optimiser's campaigns on the paper's default scenario
(7 m, 25 m/s, from rest, knots).
"""

from __future__ import annotations

import os
import statistics
import time

from d4sumo.model.stepping.batch import DEFAULT_BATCH
from d4sumo.model.config import EpisodeConfig
from d4sumo.search.campaign import Campaign
from d4sumo.search.runner import Evaluator, run_campaign
from toolargs import Parser, run_main


def timed(campaign: Campaign, evaluator: Evaluator, batch: int) -> tuple[float, list]:
    t0 = time.perf_counter()
    summary = run_campaign(campaign, evaluator=evaluator, batch=batch)
    return time.perf_counter() - t0, [(s.params, s.robustness, s.outcome) for s in summary.samples]


def main() -> None:
    parser = Parser(__doc__)
    parser.add_argument("--samples", type=int, default=200)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--batch", type=int, default=DEFAULT_BATCH)
    parser.add_argument("--optimizers", nargs="+", default=["random", "ce", "cmaes"])
    parser.add_argument("--start", default="rest", choices=["rest", "steady"])
    args = parser.parse_args()
    parser.check_counts({"--samples": (args.samples, 1), "--repeats": (args.repeats, 1), "--batch": (args.batch, 1)})
    parser.check_optimizers(args.optimizers)
    try:
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core, both ways
    except (AttributeError, OSError):
        pass
    config = EpisodeConfig(start=args.start)
    print(f"{args.samples} samples per campaign, {config.setpoint_m:g} m, {config.speed_mps:g} m/s, from {config.start}, "
          f"knots; best of {args.repeats} interleaved runs, one core")
    ratios = {}
    for name in args.optimizers:
        campaign = Campaign(config=config, optimizer=name, samples=args.samples, seed=0)
        evaluator = Evaluator(campaign)
        timed(campaign.replace(samples=12), Evaluator(campaign.replace(samples=12)), args.batch)  # build and cache the roads
        alone, batched = [], []
        for _ in range(args.repeats):
            t, a = timed(campaign, evaluator, 1)
            alone.append(t)
            t, b = timed(campaign, evaluator, args.batch)
            batched.append(t)
            assert a == b, f"{name}: batched samples differ from unbatched ones"
        ta, tb = min(alone), min(batched)
        ratios[name] = ta / tb
        print(f"  {name:<7} unbatched {args.samples / ta:6.1f} samples/s   batched {args.samples / tb:6.1f} samples/s   "
              f"ratio {ta / tb:4.2f}   (median ratio {statistics.median(alone) / statistics.median(batched):4.2f})")
    print(f"ratio batched/unbatched: {ratios[args.optimizers[0]]:.2f}")


if __name__ == "__main__":
    run_main(main)
