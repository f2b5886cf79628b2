"""Falsification costs and effectiveness, measured in one run (SPEC section 7).

1. rtamt scoring against the episode it scores (target: <= 0.25).
2. BO's own time per sample (ask + tell) against the simulation time per sample, 100 samples,
   9 knots (target: <= 1), for d4sumo's BO and for scikit-optimize's Optimizer with its defaults
   (with --skopt-defaults: it takes a few minutes), with the successes each found.
3. Successes of bo, ce and random on the default scenario (7 m, 25 m/s, rest, knots, 100 samples),
   3 seeds each.

Usage: python tools/bench_falsify.py [--seeds 3] [--samples 100] [--skopt-defaults]
"""

from __future__ import annotations

import argparse
import statistics
import time
import warnings

import numpy as np

from d4sumo.campaign import Campaign, Evaluator, run_campaign
from d4sumo.optimizers import Optimizer
from d4sumo.simulation import simulate


class SkoptDefaults(Optimizer):
    """scikit-optimize's Optimizer as it comes (GP, gp_hedge, lbfgs acquisition), for comparison."""

    name = "skopt-defaults"

    def __init__(self, lower, upper, budget, rng):
        from skopt import Optimizer as SkOpt

        super().__init__(lower, upper, budget, rng)
        self.opt = SkOpt(list(zip(lower, upper)), random_state=int(rng.integers(2**31 - 1)))

    def ask(self):
        return np.array(self.opt.ask())

    def tell(self, x, score):
        super().tell(x, score)
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            self.opt.tell(list(map(float, x)), -score)


def rtamt_ratio(repeats: int = 20) -> None:
    campaign = Campaign()
    ev = Evaluator(campaign)
    rng = np.random.default_rng(0)
    t_sim, t_spec = [], []
    for _ in range(repeats):
        u = ev.signal(rng.uniform(-1, 1, ev.family.dimension))
        t0 = time.perf_counter()
        episode = simulate(campaign.config, u, road=ev.road)
        t1 = time.perf_counter()
        ev.spec.robustness(episode.trace)
        t2 = time.perf_counter()
        t_sim.append(t1 - t0)
        t_spec.append(t2 - t1)
    sim, spec = sum(t_sim), sum(t_spec)
    print(f"[rtamt] {repeats} random knot episodes: simulation {sim / repeats * 1e3:.2f} ms, "
          f"rtamt scoring {spec / repeats * 1e3:.2f} ms per episode; ratio {spec / sim:.3f} (target <= 0.25)")


def bo_overhead(samples: int, with_defaults: bool) -> None:
    import d4sumo.optimizers as optimizers

    variants = [("d4sumo bo", optimizers.BayesianOptimization)]
    if with_defaults:
        variants.append(("skopt defaults", SkoptDefaults))
    for label, cls in variants:
        saved = optimizers._FACTORIES["bo"]
        optimizers._FACTORIES["bo"] = cls
        try:
            t0 = time.perf_counter()
            summary = run_campaign(Campaign(optimizer="bo", samples=samples, seed=0))
            wall = time.perf_counter() - t0
        finally:
            optimizers._FACTORIES["bo"] = saved
        sim = sum(s.wall_s for s in summary.samples)
        own = wall - sim
        print(f"[bo] {label:15s}: {samples} samples in {wall:.1f} s; simulation {sim / samples * 1e3:.1f} ms/sample, "
              f"optimiser {own / samples * 1e3:.1f} ms/sample; ratio {own / sim:.2f} (target <= 1); "
              f"successes {summary.count('success')}")


def effectiveness(seeds: int, samples: int) -> None:
    for optimizer in ("bo", "ce", "random"):
        counts = []
        for seed in range(seeds):
            s = run_campaign(Campaign(optimizer=optimizer, samples=samples, seed=seed))
            counts.append((s.count("success"), s.count("attacker_crash"), s.count("no_crash")))
        succ = [c[0] for c in counts]
        print(f"[effectiveness] {optimizer:6s}: successes per seed {succ} (mean {statistics.mean(succ):.1f}); "
              f"attacker crashes {[c[1] for c in counts]}; no crash {[c[2] for c in counts]}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--samples", type=int, default=100)
    parser.add_argument("--skopt-defaults", action="store_true")
    args = parser.parse_args()
    print("default scenario: highway_4lane, 3 followers, setpoint 7 m, 25 m/s, rest, knots (9), 0.05 s steps")
    rtamt_ratio()
    bo_overhead(args.samples, args.skopt_defaults)
    effectiveness(args.seeds, args.samples)


if __name__ == "__main__":
    main()
