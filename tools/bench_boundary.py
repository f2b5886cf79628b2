"""How well a campaign locates the boundary between safe and unsafe situations (issue 52): the line where the
success rate of a random attack crosses one half, over the paper's domain (setpoint 3-15 m, speed 20-30 m/s).

A reference map is estimated from many random samples (--reference, one campaign). Then, for each seed, campaigns of
the same budget (--samples) draw their own map (`situation.kernel_estimate`, as the report's map does):

- ``random``: uniform attacks and situations;
- ``boundary``: every sample spent locating the boundary (``[search] boundary = 1``: a random attack in a situation
  chosen by the straddle rule);
- ``auto + boundary 0.5``: half the samples so, the other half the default optimiser's search for the worst attack.

Each map is scored against the reference on a grid of the domain, where the reference is sure of its side (its
rate at least --margin from one half): the share of the grid it puts on the wrong side of the boundary. A map is
drawn from a campaign's locating samples where it has any (the report's rule); the last column gives the samples it
was drawn from. Printed: the mean and the spread over the seeds, and the ratio to ``random``.

Usage: python tools/bench_boundary.py [--start rest] [--samples 300] [--seeds 5] [--reference 3000] [--margin 0.05]
"""

from __future__ import annotations

import statistics
import time

import numpy as np

from d4sumo.inputs import campaign_of
from d4sumo.search.runner import run_campaign
from d4sumo.search.situation import kernel_estimate, locating
from toolargs import Parser, run_main

LOW, HIGH = np.array([3.0, 20.0]), np.array([15.0, 30.0])
CELLS = 40


def campaign(start: str, samples: int, seed: int, optimizer: str, boundary: float):
    return campaign_of({"scenario": {"setpoint_m": [3, 15], "speed_mps": [20, 30], "start": start},
                        "search": {"optimizer": optimizer, "samples": samples, "seed": seed, "boundary": boundary}})


def played(c) -> tuple[np.ndarray, np.ndarray]:
    """The campaign's samples: their situations (unit square) and whether each succeeded; its locating samples alone
    where it has any."""
    results = run_campaign(c).samples
    if c.boundary:
        results = [r for r in results if locating(r.index, c.boundary)]
    points = np.array([r.params[-2:] for r in results], dtype=float)
    return (points - LOW) / (HIGH - LOW), np.array([r.outcome == "success" for r in results], dtype=float)


def rate_map(points: np.ndarray, successes: np.ndarray) -> np.ndarray:
    axis = np.linspace(0.0, 1.0, CELLS)
    grid = np.stack(np.meshgrid(axis, axis, indexing="ij"), axis=-1).reshape(-1, 2)
    return kernel_estimate(points, successes, grid)[0]


def main() -> None:
    parser = Parser(__doc__)
    parser.add_argument("--start", default="rest", choices=["rest", "steady"])
    parser.add_argument("--samples", type=int, default=300)
    parser.add_argument("--seeds", type=int, default=5)
    parser.add_argument("--reference", type=int, default=3000)
    parser.add_argument("--margin", type=float, default=0.05)
    args = parser.parse_args()
    parser.check_counts({"--samples": (args.samples, 8), "--seeds": (args.seeds, 1), "--reference": (args.reference, 100)})
    t0 = time.perf_counter()
    reference = rate_map(*played(campaign(args.start, args.reference, 10_000, "random", 0.0)))
    sure = np.abs(reference - 0.5) >= args.margin
    print(f"from {args.start}: reference of {args.reference} random samples ({time.perf_counter() - t0:.0f} s); its rate "
          f"{reference.min():.2f}-{reference.max():.2f}, sure of its side on {sure.mean():.0%} of the domain "
          f"(at least {args.margin:g} from one half)")
    arms = {"random": ("random", 0.0), "boundary": ("random", 1.0), "auto + boundary 0.5": ("auto", 0.5)}
    wrong: dict[str, list[float]] = {name: [] for name in arms}
    drawn: dict[str, int] = {}
    for seed in range(args.seeds):
        for name, (optimizer, share) in arms.items():
            points, successes = played(campaign(args.start, args.samples, seed, optimizer, share))
            estimate = rate_map(points, successes)
            wrong[name].append(float(np.mean((estimate[sure] > 0.5) != (reference[sure] > 0.5))))
            drawn[name] = len(points)
    base = statistics.mean(wrong["random"])
    print(f"{args.samples} samples a campaign, {args.seeds} seeds: the share of the domain on the wrong side of the boundary")
    for name, values in wrong.items():
        mean = statistics.mean(values)
        spread = statistics.stdev(values) if len(values) > 1 else 0.0
        print(f"  {name:<20} {mean:6.1%} +- {spread:5.1%}   ratio to random {mean / base if base else float('nan'):4.2f}   "
              f"(drawn from {drawn[name]} samples)")
    print(f"total {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    run_main(main)
