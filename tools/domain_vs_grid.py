"""A campaign over the paper's whole domain against the paper's grid (issue 52): how many samples a campaign that
searches the setpoint and speed with the attack (`search.situation`) needs to find a success wherever the grid
of campaigns finds one, and both maps side by side.

The grid is `examples/sweeps/paper_nonparametric.toml`: setpoints 3-15 m by 1 m, speeds 20, 25 and 30 m/s, both
starts, knots (6 s apart, to 48 s), bo and ce, 100 samples a campaign: 7,800 samples a start. Its *cells* are
its (setpoint, speed) points; a cell is *found* where one of its samples succeeded. The domain campaigns search
setpoint [3, 15] and speed [20, 30] (one per start: the start mode is no range yet), with the same attack, and a
sample of theirs *finds* the grid cell nearest it (within half the grid's spacing: 0.5 m and 2.5 m/s) when it
succeeds. Printed per start and optimiser: the grid's found cells, how many of them the domain campaign found and
after how many samples it had found them all (or how many it found in its budget), the cells it found that the
grid did not, and the samples each spent.

Usage: python tools/domain_vs_grid.py [--samples 2000] [--optimizers auto ce] [--seed 0] [--workers 2]
                                      [--grid-db paper.sqlite] [--figure map.png]
``--grid-db``: a database of the grid, run before (`d4sumo sweep examples/sweeps/paper_nonparametric.toml`); else the
grid is run here first, into a temporary database (about a minute on 2 cores).
"""

from __future__ import annotations

import tempfile
import time
from pathlib import Path

import numpy as np

from d4sumo.errors import refusal
from d4sumo.inputs import campaign_of
from d4sumo.results.records import load_records
from d4sumo.search.runner import run_campaign
from d4sumo.sweep import Sweep, run_sweep
from toolargs import Parser, run_main

HERE = Path(__file__).resolve().parent.parent
GRID = HERE / "examples" / "sweeps" / "paper_nonparametric.toml"
SETPOINTS, SPEEDS = np.arange(3.0, 16.0), np.array([20.0, 25.0, 30.0])
HALF = (0.5, 2.5)  # half the grid's spacing: m, m/s


def grid_found(db: Path) -> dict[str, set]:
    """Per start, the grid's cells where a sample succeeded."""
    found: dict[str, set] = {"rest": set(), "steady": set()}
    for r in load_records([db]):
        if r.outcome == "success":
            found[r.start].add((r.setpoint_m, r.speed_mps))
    return found


def cell_of(setpoint_m: float, speed_mps: float) -> tuple[float, float] | None:
    """The grid cell a situation lies in (None: between cells, farther than half the spacing from any)."""
    s, v = SETPOINTS[np.argmin(abs(SETPOINTS - setpoint_m))], SPEEDS[np.argmin(abs(SPEEDS - speed_mps))]
    return (float(s), float(v)) if abs(s - setpoint_m) <= HALF[0] and abs(v - speed_mps) <= HALF[1] else None


def domain_campaign(start: str, optimizer: str, samples: int, seed: int):
    return campaign_of({"scenario": {"setpoint_m": [3.0, 15.0], "speed_mps": [20.0, 30.0], "start": start},
                        "attack": {"family": "knots", "delta_s": 6.0, "horizon_s": 48.0},
                        "search": {"optimizer": optimizer, "samples": samples, "seed": seed}})


def figure(grid: dict[str, set], runs: dict, path: Path) -> None:
    from d4sumo.results.figures import _figure, _save

    fig = _figure(figsize=(5.0 * (1 + len(runs) // 2), 7.0))
    starts = ("rest", "steady")
    optimizers = sorted({o for _, o in runs})
    axes = fig.subplots(2, 1 + len(optimizers), squeeze=False)
    for row, start in enumerate(starts):
        ax = axes[row, 0]
        cells = [(s, v) for s in SETPOINTS for v in SPEEDS]
        ax.scatter([c[0] for c in cells], [c[1] for c in cells], s=60, marker="s",
                   c=["tab:red" if c in grid[start] else "lightgrey" for c in cells])
        ax.set(title=f"the grid, start {start}: {len(grid[start])} of {len(cells)} cells found", xlabel="setpoint [m]",
               ylabel="target speed [m/s]")
        for col, optimizer in enumerate(optimizers, start=1):
            ax = axes[row, col]
            points, wins = runs[start, optimizer]["points"], runs[start, optimizer]["wins"]
            ax.scatter(points[~wins, 0], points[~wins, 1], s=4, color="lightgrey")
            ax.scatter(points[wins, 0], points[wins, 1], s=8, color="tab:red")
            ax.set(title=f"{optimizer} over the domain, start {start}: {len(points)} samples", xlabel="setpoint [m]",
                   ylabel="target speed [m/s]")
    fig.suptitle("Successes (red): the paper's grid of campaigns (7,800 samples a start) and one campaign a start over the "
                 "whole domain", fontsize=10)
    _save(fig, path)


def main() -> None:
    parser = Parser(__doc__)
    parser.add_argument("--samples", type=int, default=2000)
    parser.add_argument("--optimizers", nargs="+", default=["auto", "ce"])
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--workers", type=int, default=2)
    parser.add_argument("--grid-db", type=Path)
    parser.add_argument("--figure", type=Path)
    args = parser.parse_args()
    parser.check_counts({"--samples": (args.samples, 1, 100_000), "--seed": (args.seed, 0), "--workers": (args.workers, 1, 1024)})
    parser.check_optimizers(args.optimizers)
    if args.grid_db is not None and not args.grid_db.is_file():
        parser.error(refusal("--grid-db", str(args.grid_db), "a database of examples/sweeps/paper_nonparametric.toml"))
    with tempfile.TemporaryDirectory() as tmp:
        db = args.grid_db
        if db is None:
            db = Path(tmp) / "grid.sqlite"
            t0 = time.perf_counter()
            run_sweep(Sweep.load(GRID), db, workers=args.workers)
            print(f"the grid: {time.perf_counter() - t0:.0f} s", flush=True)
        grid = grid_found(db)
        runs = {}
        for start in ("rest", "steady"):
            for optimizer in args.optimizers:
                t0 = time.perf_counter()
                summary = run_campaign(domain_campaign(start, optimizer, args.samples, args.seed))
                points = np.array([s.params[-2:] for s in summary.samples])
                wins = np.array([s.outcome == "success" for s in summary.samples])
                found, complete_at = set(), None
                for i, (p, w) in enumerate(zip(points, wins)):
                    cell = cell_of(*p) if w else None
                    if cell is not None:
                        found.add(cell)
                        if complete_at is None and grid[start] <= found:
                            complete_at = i + 1
                runs[start, optimizer] = {"points": points, "wins": wins}
                both = len(found & grid[start])
                print(f"start {start}, {optimizer}: the grid found {len(grid[start])} of {SETPOINTS.size * SPEEDS.size} cells "
                      f"in 7,800 samples; the domain campaign found {both} of them"
                      + (f", all after {complete_at} samples" if complete_at else f" in {args.samples} samples")
                      + f", and {len(found - grid[start])} the grid did not; {int(wins.sum())} successes "
                      f"({time.perf_counter() - t0:.0f} s)", flush=True)
        if args.figure:
            figure(grid, runs, args.figure)
            print(f"figure: {args.figure}")


if __name__ == "__main__":
    run_main(main)
