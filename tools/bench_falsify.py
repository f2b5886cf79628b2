"""Falsification costs and effectiveness, measured in one run (SPEC section 7).

1. rtamt scoring against the episode it scores (target: <= 0.25).
2. BO's own time per sample (ask + tell) against the rest of the campaign's time per sample (episodes,
   scoring, storing), 100 samples, 9 knots (target: <= 0.5), for d4sumo's bo (its own GP; with
   scikit-optimize's GP, gp_version 1), turbo, and scikit-optimize's Optimizer with its defaults (with
   --skopt-defaults: it takes a few minutes), with the successes each found.
3. For every optimiser: distinct successes per campaign (knot attacks, 100 samples, seeds 0..2) at four
   conditions: the paper's default (7 m, 25 m/s, from rest), a hard one (12 m, 20 m/s, steady), and
   two more (9 m, 30 m/s, from rest; 10 m, 25 m/s, steady); and the optimiser's own time per sample as a
   ratio to the episode's. Successes within 5% of each parameter's range of one already counted are one
   attack (`analysis.distinct_count`).

Usage: python tools/bench_falsify.py [--seeds 3] [--samples 100] [--skopt-defaults] [--optimizers ...]
An optimiser may carry options: --optimizers bo bo:batch_size=5 ce:batch_size=20
"""

from __future__ import annotations

import contextlib
import statistics
import time
import warnings

import numpy as np

from d4sumo.engine.simulation import simulate
from d4sumo.search.campaign import Campaign
from d4sumo.search.optimizers import Optimizer
from d4sumo.search.runner import Evaluator, run_campaign
from toolargs import Parser, optimizer_of, run_main


class SkoptDefaults(Optimizer):
    """scikit-optimize's Optimizer as it comes (GP, gp_hedge, lbfgs acquisition), for comparison."""

    name = "bo"  # it stands in for bo; bo's options do not apply to it

    def __init__(self, lower, upper, budget, rng, **options):
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
    import d4sumo.search.optimizers as optimizers

    variants = [("bo", "bo", {}), ("bo gp_version=1", "bo", {"gp_version": 1}), ("turbo", "turbo", {})]
    if with_defaults:
        variants.append(("skopt defaults", "bo", {}))
    for label, name, options in variants:
        saved = optimizers._FACTORIES["bo"]
        if label == "skopt defaults":
            optimizers._FACTORIES["bo"] = SkoptDefaults
        try:
            t0 = time.perf_counter()
            with timed_optimizer() as clock:
                summary = run_campaign(Campaign(optimizer=name, optimizer_options=options, samples=samples, seed=0))
            wall = time.perf_counter() - t0
        finally:
            optimizers._FACTORIES["bo"] = saved
        own = clock[0]
        sim = wall - own
        print(f"[bo] {label:15s}: {samples} samples in {wall:.1f} s; simulation {sim / samples * 1e3:.1f} ms/sample, "
              f"optimiser {own / samples * 1e3:.1f} ms/sample; ratio {own / sim:.2f} (target <= 0.5); "
              f"successes {summary.count('success')}")


CONDITIONS = (("7 m, 25 m/s, rest", 7.0, 25.0, "rest"), ("12 m, 20 m/s, steady (hard)", 12.0, 20.0, "steady"),
              ("9 m, 30 m/s, rest", 9.0, 30.0, "rest"), ("10 m, 25 m/s, steady", 10.0, 25.0, "steady"))


@contextlib.contextmanager
def timed_optimizer():
    """Time every ask and tell of the campaigns' optimisers: [seconds]."""
    import d4sumo.search.runner as campaign_module  # where campaigns make their optimisers

    clock = [0.0]
    real = campaign_module.make_optimizer

    def make(*args, **kwargs):
        opt = real(*args, **kwargs)
        for name in ("ask", "tell"):
            def timed(*a, _method=getattr(opt, name)):
                t0 = time.perf_counter()
                try:
                    return _method(*a)
                finally:
                    clock[0] += time.perf_counter() - t0
            setattr(opt, name, timed)
        return opt

    campaign_module.make_optimizer = make
    try:
        yield clock
    finally:
        campaign_module.make_optimizer = real


def effectiveness(seeds: int, samples: int, optimizers: list[str]) -> None:
    from d4sumo.model.config import EpisodeConfig
    from d4sumo.results.analysis import distinct_count

    table: dict[str, dict[str, float]] = {o: {} for o in optimizers}
    own: dict[str, list[float]] = {o: [] for o in optimizers}
    for label, setpoint, speed, start in CONDITIONS:
        config = EpisodeConfig(setpoint_m=setpoint, speed_mps=speed, start=start)
        for optimizer in optimizers:
            counts, raw = [], []
            name, options = optimizer_of(optimizer)
            for seed in range(seeds):
                campaign = Campaign(config=config, optimizer=name, optimizer_options=options, samples=samples, seed=seed)
                family = campaign.family()
                t0 = time.perf_counter()
                with timed_optimizer() as clock:
                    s = run_campaign(campaign)
                wall = time.perf_counter() - t0
                own[optimizer].append(clock[0] / (wall - clock[0]))
                wins = [r.params for r in s.samples if r.outcome == "success"]
                counts.append(distinct_count(wins, family.lower, family.upper))
                raw.append(len(wins))
            table[optimizer][label] = statistics.mean(counts)
            print(f"[effectiveness] {label:28s} {optimizer:16s}: distinct successes {counts} (raw {raw}); "
                  f"mean {statistics.mean(counts):.1f}", flush=True)
    print(f"\ndistinct successes per {samples} samples, mean of {seeds} seeds; the optimiser's own time (ask, tell) "
          "against the rest of the campaign's (episodes, scoring)")
    print("optimizer        " + "".join(f"{c[0]:>30s}" for c in CONDITIONS) + "   own/episode")
    for o in optimizers:
        print(f"{o:16s} " + "".join(f"{table[o][c[0]]:30.1f}" for c in CONDITIONS) + f"   {statistics.mean(own[o]):11.2f}")
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
    parser = Parser(__doc__)
    parser.add_argument("--seeds", type=int, default=3)
    parser.add_argument("--samples", type=int, default=100)
    parser.add_argument("--skopt-defaults", action="store_true")
    parser.add_argument("--optimizers", nargs="+", default=["bo", "turbo", "ce", "ce-bucket", "cmaes", "random"])
    args = parser.parse_args()
    parser.check_counts({"--seeds": (args.seeds, 1), "--samples": (args.samples, 1)})
    parser.check_optimizers(args.optimizers)
    print("default scenario: highway_4lane, 3 followers, setpoint 7 m, 25 m/s, rest, knots (9), 0.05 s steps")
    rtamt_ratio()
    bo_overhead(args.samples, args.skopt_defaults)
    effectiveness(args.seeds, args.samples, args.optimizers)


if __name__ == "__main__":
    run_main(main)
