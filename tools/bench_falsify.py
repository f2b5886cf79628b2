"""Falsification costs and effectiveness, measured in one run (SPEC section 7).

1. rtamt scoring against the episode it scores (target: <= 0.25).
2. BO's own time per sample (ask + tell) against the simulation time per sample, 100 samples,
   9 knots (target: <= 1), for d4sumo's BO and for scikit-optimize's Optimizer with its defaults
   (with --skopt-defaults: it takes a few minutes), with the successes each found.
3. For every optimiser: distinct successes per campaign (knot attacks, 100 samples, seeds 0..2) at four
   conditions: the paper's default (7 m, 25 m/s, from rest), a hard one (12 m, 20 m/s, steady), and
   two more (9 m, 30 m/s, from rest; 10 m, 25 m/s, steady); and the optimiser's own time per sample as a
   ratio to the episode's. Successes within 5% of each parameter's range of one already counted are one
   attack (`analysis.distinct_count`).

Usage: python tools/bench_falsify.py [--seeds 3] [--samples 100] [--skopt-defaults] [--optimizers ...]
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
        u = ev.plan(rng.uniform(-1, 1, ev.family.dimension))
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


CONDITIONS = (("7 m, 25 m/s, rest", 7.0, 25.0, "rest"), ("12 m, 20 m/s, steady (hard)", 12.0, 20.0, "steady"),
              ("9 m, 30 m/s, rest", 9.0, 30.0, "rest"), ("10 m, 25 m/s, steady", 10.0, 25.0, "steady"))


def effectiveness(seeds: int, samples: int, optimizers: list[str]) -> None:
    from d4sumo.analysis import distinct_count
    from d4sumo.config import EpisodeConfig

    table: dict[str, dict[str, float]] = {o: {} for o in optimizers}
    own: dict[str, list[float]] = {o: [] for o in optimizers}
    for label, setpoint, speed, start in CONDITIONS:
        config = EpisodeConfig(setpoint_m=setpoint, speed_mps=speed, start=start)
        for optimizer in optimizers:
            counts, raw = [], []
            for seed in range(seeds):
                campaign = Campaign(config=config, optimizer=optimizer, samples=samples, seed=seed)
                family = campaign.family()
                t0 = time.perf_counter()
                s = run_campaign(campaign)
                wall = time.perf_counter() - t0
                sim = sum(r.wall_s for r in s.samples)
                own[optimizer].append((wall - sim) / sim)
                wins = [r.params for r in s.samples if r.outcome == "success"]
                counts.append(distinct_count(wins, family.lower, family.upper))
                raw.append(len(wins))
            table[optimizer][label] = statistics.mean(counts)
            print(f"[effectiveness] {label:28s} {optimizer:9s}: distinct successes {counts} (raw {raw}); "
                  f"mean {statistics.mean(counts):.1f}", flush=True)
    print(f"\ndistinct successes per {samples} samples, mean of {seeds} seeds; optimiser's own time / episode time")
    print("optimizer  " + "".join(f"{c[0]:>30s}" for c in CONDITIONS) + "   own/episode")
    for o in optimizers:
        print(f"{o:10s} " + "".join(f"{table[o][c[0]]:30.1f}" for c in CONDITIONS) + f"   {statistics.mean(own[o]):11.2f}")
    hard = CONDITIONS[1][0]
    if "ce" in table:
        best = max((o for o in optimizers if o != "ce"), key=lambda o: table[o][hard], default=None)
        if best is not None and table["ce"][hard] > 0:
            print(f"ratio best/ce on the hard condition ({best}): {table[best][hard] / table['ce'][hard]:.2f}")
    if "random" in table:
        for o in optimizers:
            if o != "random":
                beaten = [c[0] for c in CONDITIONS if table[o][c[0]] <= table["random"][c[0]]]
                print(f"{o} beats random everywhere: {'yes' if not beaten else 'no (not at ' + '; '.join(beaten) + ')'}")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--samples", type=int, default=100)
    parser.add_argument("--skopt-defaults", action="store_true")
    parser.add_argument("--optimizers", nargs="+", default=["bo", "ce", "ce-bucket", "cmaes", "random"])
    args = parser.parse_args()
    print("default scenario: highway_4lane, 3 followers, setpoint 7 m, 25 m/s, rest, knots (9), 0.05 s steps")
    rtamt_ratio()
    bo_overhead(args.samples, args.skopt_defaults)
    effectiveness(args.seeds, args.samples, args.optimizers)


if __name__ == "__main__":
    main()
