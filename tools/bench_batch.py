"""Samples per second with episodes played side by side in one SUMO (batched) against one episode per
SUMO (unbatched), on one core, measured in one run (SPEC section 7: ratio >= 1.8).

The same campaigns run both ways, interleaved so machine noise hits both; each stores nothing and
is scored as usual (simulation, specification, optimiser: a whole sample). A batch is what the
optimiser proposes together: a cross-entropy generation (`ce`, 10 by default), a CMA-ES population,
or up to --batch random points. The results are checked to be identical both ways.

Usage: python tools/bench_batch.py [--samples 200] [--repeats 3] [--batch 64] [--optimizers random ce cmaes]
                                   [--situation [KEY ...]]
The last line is the ratio of the first optimiser's campaigns on the paper's default scenario
(7 m, 25 m/s, from rest, knots).

``--situation`` measures instead what searching the situation costs a sample (`search.situation`): the same
attack points played by a campaign whose setpoint and speed are fixed and by one that searches them, each sample
within nanometres of the same values (the same episodes but for rounding: what differs is the situation's own
work, a configuration per sample),
batched and one at a time, interleaved; it prints the ratio of their costs per sample. It searches the setpoint
and speed, or the keys named (``--situation controller.acc_kp``: a key a batch holds for all its episodes, so that
each sample plays in a batch of its own configuration).
"""

from __future__ import annotations

import os
import statistics
import time

import numpy as np

from d4sumo.model.stepping.batch import DEFAULT_BATCH
from d4sumo.model.config import EpisodeConfig
from d4sumo.search import situation
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
    parser.add_argument("--situation", nargs="*", metavar="KEY", help="what searching the setpoint and speed (or these keys, "
                                                                      "each from its value up a tenth) costs a sample")
    args = parser.parse_args()
    parser.check_counts({"--samples": (args.samples, 1), "--repeats": (args.repeats, 1), "--batch": (args.batch, 1)})
    parser.check_optimizers(args.optimizers)
    try:
        os.sched_setaffinity(0, {min(os.sched_getaffinity(0))})  # one core, both ways
    except (AttributeError, OSError):
        pass
    config = EpisodeConfig(start=args.start)
    if args.situation is not None:
        return situation_cost(config, args)
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


def situation_cost(config: EpisodeConfig, args) -> None:
    """The same attack points played by a campaign with its setpoint and speed fixed and by one that searches them
    (ranges from the fixed values up), each point within a few nanometres and nanometres a second of the fixed values
    (each a configuration of its own, as in a search, playing the same episodes to the eye: their outcomes and
    collisions are counted alike), so what differs is the situation's own work."""
    ranges = (("setpoint_m", config.setpoint_m, config.setpoint_m + 3.0), ("speed_mps", config.speed_mps, config.speed_mps + 5.0))
    if args.situation:
        values = {key: situation.played(config, key) for key in args.situation}
        for key, value in values.items():
            if not isinstance(value, float):
                raise SystemExit(f"--situation: got {key!r}; allowed: a key of [scenario], [controller] or [vehicle] that holds "
                                 "a real number in the default configuration")
        ranges = tuple((key, value, value * 1.1) for key, value in values.items())
    fixed = Campaign(config=config, optimizer="random", samples=args.samples, seed=0)
    searched = fixed.replace(situation=ranges)
    family = fixed.family()
    points = np.random.default_rng(0).uniform(family.lower, family.upper, size=(args.samples, family.dimension))
    nudge = 1e-9 * np.arange(args.samples)[:, None]  # each sample a situation of its own, as in a search: its own configuration
    at = np.concatenate([points, np.tile([lo for _, lo, _ in searched.situation], (args.samples, 1)) + nudge], axis=1)
    print(f"{args.samples} samples, {config.setpoint_m:g} m and {config.speed_mps:g} m/s fixed, against a campaign searching "
          f"{', '.join(f'{k} [{lo:g}, {hi:g}]' for k, lo, hi in ranges)} played at the same values; best of {args.repeats} "
          "interleaved runs, one core")
    evaluators = {"fixed": (Evaluator(fixed), points), "searched": (Evaluator(searched), at)}
    for batch in (args.batch, 1):
        times: dict = {"fixed": [], "searched": []}
        results = {}
        for _ in range(args.repeats):
            for name, (evaluator, xs) in evaluators.items():
                t0 = time.perf_counter()
                played = [r for first in range(0, len(xs), batch) for r in evaluator.batch(first, xs[first:first + batch])]
                times[name].append(time.perf_counter() - t0)
                results[name] = [(r.robustness, r.outcome, r.collision, r.min_gaps) for r in played]
        same = sum(a[1] == b[1] and (a[2] or {}).get("pair") == (b[2] or {}).get("pair") and (a[2] or {}).get("time_s") == (b[2] or {}).get("time_s")
                   for a, b in zip(results["fixed"], results["searched"]))  # outcome, and pair and time of the collision
        tf, ts = min(times["fixed"]), min(times["searched"])
        print(f"  {'batched' if batch > 1 else 'one at a time':<13} fixed {1e3 * tf / args.samples:6.2f} ms/sample   "
              f"situation searched {1e3 * ts / args.samples:6.2f} ms/sample   ratio {ts / tf:4.2f}   "
              f"(the same outcome, colliding pair and time: {same} of {args.samples})")

if __name__ == "__main__":
    run_main(main)
