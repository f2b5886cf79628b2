"""The optimisers on a falsification benchmark outside SUMO, of the kind ARCH-COMP's falsification
category uses: a black-box model with 40 piecewise-constant inputs and long plateaus of nearly
constant robustness.

The model (numpy, 0.1 s steps, 100 s): five cars in a row. The first car's throttle and brake, each in
[0, 1] and constant over 20 segments of 5 s, are the 40 inputs. Cars 2-5 follow their leader with a
constant time-gap ACC (a = 0.2 (gap - 5 m - 1 s * v) + 0.6 (v_leader - v), limited to [-6, 3] m/s^2) behind a first-order
actuator lag of 0.6 s, which makes the platoon string-unstable. The first car's acceleration is
2.5 (throttle - brake) m/s^2, speeds stay in [0, 40] m/s. All start at 20 m/s, 25 m apart (their
equilibrium). Specifications (y_i the position of car i, front to back):
- ``gap``: the last gap never opens past 49 m: G[0,100] (y4 - y5 <= 49);
- ``close``: no gap ever closes below 1.4 m: G[0,100] min_i (y_i - y_{i+1}) >= 1.4;
- ``held``: the last gap never stays above 48.6 m for 10 s: G[0,90] F[0,10] (y4 - y5 <= 48.6).
About 0.3% of uniformly random inputs falsify each; most leave the gaps near their equilibrium, where
the robustness is nearly constant (a plateau).

For each optimiser and specification, ``--runs`` runs (seeds ``--first-seed``, the next, ...) of at most ``--samples``
simulations each, stopped at the first falsification, as ARCH-COMP counts: falsified runs and the
median simulations to falsify. Then each optimiser's own time (ask + tell) per proposal over one run of
the full budget on the ``gap`` specification, against a SUMO episode of d4sumo's default scenario
measured in the same run (target: at most half an episode).

``--benchmark arch-comp-cc`` runs ARCH-COMP's chasing cars instead (`arch_cc.py`: the competition's
model and CC1-CC5, CCx, input instance 1 or 2), 10 runs of up to 1,500 simulations by default as the
competition counts, with each mean's 95% interval (`mean_interval`), and prints FalCAuN's published
figures beside ours.

Usage: python tools/bench_arch.py [--runs 10] [--first-seed 0] [--jobs 1] [--samples 300] [--optimizers ...] [--specs gap close held]
       python tools/bench_arch.py --benchmark arch-comp-cc [--instance 2] [--runs 10] [--first-seed 0] [--jobs 1] [--samples 1500] [--specs CC1 ...]
       python tools/bench_arch.py --benchmark arch-comp-cc --held 40000   (how rare falsifying inputs are)
       python tools/bench_arch.py --benchmark arch-comp-cc --held 20000 --recheck-dt 0.001   (and do they at 1 ms)
"""

from __future__ import annotations

import statistics
import time

import numpy as np
import arch_cc  # tools/ is on the path of a script run from it

from d4sumo.errors import refusal
from d4sumo.search.optimizers import make_optimizer
from d4sumo.sweep.workers import kill_pool, new_pool
from toolargs import Parser, optimizer_of, run_main

DT, DURATION, SEGMENTS = 0.1, 100.0, 20
STEPS = int(round(DURATION / DT))
CARS = 5
LEAD_THROTTLE, LEAD_BRAKE, MAX_SPEED = 2.5, 2.5, 40.0  # m/s^2, m/s^2, m/s
# thresholds where about 0.3% of uniformly random inputs falsify: random search falsifies about half the
# runs of 300 simulations, a search that narrows too early on the plateau fewer
GAP_OPEN_M, GAP_CLOSED_M, GAP_HELD_M = 49.0, 1.4, 48.6


def simulate(params: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Positions and speeds, runs x (steps + 1) x cars, of the five cars under rows of 40 inputs (20
    throttle, 20 brake): one run per row, all at once."""
    params = np.atleast_2d(params)
    runs = len(params)
    hold = STEPS // SEGMENTS
    lead_accel = np.repeat(LEAD_THROTTLE * params[:, :SEGMENTS] - LEAD_BRAKE * params[:, SEGMENTS:], hold, axis=1)
    y = np.tile(-25.0 * np.arange(CARS, dtype=float), (runs, 1))
    v = np.full((runs, CARS), 20.0)
    a = np.zeros((runs, CARS))
    ys, vs = np.empty((runs, STEPS + 1, CARS)), np.empty((runs, STEPS + 1, CARS))
    ys[:, 0], vs[:, 0] = y, v
    lag = DT / 0.6
    for k in range(STEPS):
        gap = y[:, :-1] - y[:, 1:]
        wanted = np.clip(0.2 * (gap - 5.0 - 1.0 * v[:, 1:]) + 0.6 * (v[:, :-1] - v[:, 1:]), -6.0, 3.0)
        a[:, 0] = lead_accel[:, k]
        a[:, 1:] += lag * (wanted - a[:, 1:])
        v_new = np.clip(v + a * DT, 0.0, MAX_SPEED)
        y = y + 0.5 * (v + v_new) * DT
        v = v_new
        ys[:, k + 1], vs[:, k + 1] = y, v
    return ys, vs


def _sliding_min(x: np.ndarray, width: int) -> np.ndarray:
    return np.lib.stride_tricks.sliding_window_view(x, width, axis=-1).min(axis=-1)


def robustness(spec: str, params: np.ndarray) -> np.ndarray:
    """Robustness of the specification for each row of inputs: negative means falsified."""
    ys, vs = simulate(params)
    gaps = ys[:, :, :-1] - ys[:, :, 1:]
    if spec == "gap":
        return np.min(GAP_OPEN_M - gaps[:, :, -1], axis=1)
    if spec == "close":
        return np.min(gaps - GAP_CLOSED_M, axis=(1, 2))
    if spec == "held":  # G[0,90] F[0,10] (y4 - y5 <= GAP_HELD): every 10 s window has a moment at or below it
        window = int(round(10.0 / DT)) + 1
        return np.min(GAP_HELD_M - _sliding_min(gaps[:, :, -1], window), axis=1)
    raise ValueError(spec)


SPECS = ("gap", "close", "held")


#: FalCAuN's figures in ARCH-COMP's summaries (10 runs, its own input model of values held 5 s, 1,500
#: simulations): runs falsified and mean simulations to falsify, 2024 and its latest. Its CC4 script checks
#: FalStar 2019's CC4 (inner window 5 s, `CC4-2019` here), not the competition's (20 s): its CC4 figures
#: are printed beside both, marked.
FALCAUN = {"CC1": ("10/10, 396", "198"), "CC2": ("10/10, 76", "38"), "CC3": ("10/10, 122", "61"),
           "CC4-2019": ("4/10, 1256", "10/10, 474"), "CC5": ("-", "-"), "CCx": ("-", "-")}
FALCAUN["CC4"] = tuple(f"{figure}*" for figure in FALCAUN["CC4-2019"])
ROBUSTNESS = None  # the benchmark's robustness(spec, inputs), set by use_benchmark


def use_benchmark(benchmark: str, instance: int) -> None:
    """The benchmark `run` scores on, in this process (a worker of ``--jobs`` sets it again)."""
    global ROBUSTNESS
    if benchmark == "arch-comp-cc":
        ROBUSTNESS = lambda spec, x: arch_cc.robustness(spec, arch_cc.simulate(x, instance))  # noqa: E731
    else:
        ROBUSTNESS = robustness


def _run_on(benchmark: str, instance: int, *task) -> tuple[int | None, float, int]:
    use_benchmark(benchmark, instance)
    return run(*task)


def runs_by_pair(args, specs: list[str], samples: int):
    """(spec, optimizer, the results of `run` on each seed) for every pair in order. With ``--jobs`` above
    one, every run is submitted at once to one pool of worker processes (they die with this one; Ctrl-C
    and SIGTERM stop them on the way out), and each pair is yielded as soon as its runs are in."""
    seeds = range(args.first_seed, args.first_seed + args.runs)
    pairs = [(spec, o) for spec in specs for o in args.optimizers]
    if args.jobs == 1:
        for spec, o in pairs:
            yield spec, o, [run(o, spec, seed, samples, True) for seed in seeds]
        return
    pool = new_pool(args.jobs)
    try:
        futures = {(spec, o): [pool.submit(_run_on, args.benchmark, args.instance, o, spec, seed, samples, True)
                               for seed in seeds] for spec, o in pairs}
        for spec, o in pairs:
            yield spec, o, [future.result() for future in futures[spec, o]]
    finally:
        kill_pool(pool)


def run(optimizer: str, spec: str, seed: int, samples: int, stop: bool) -> tuple[int | None, float, int]:
    """(simulations to the first falsification or None, own seconds, proposals)."""
    lower, upper = np.zeros(2 * SEGMENTS), np.ones(2 * SEGMENTS)
    name, options = optimizer_of(optimizer)
    opt = make_optimizer(name, lower, upper, budget=samples, rng=np.random.default_rng(seed), options=options,
                         signals=(SEGMENTS, SEGMENTS))  # throttle's values in time order, then brake's
    own, found = 0.0, None
    while opt.asked < samples:
        t0 = time.perf_counter()
        xs = [opt.ask() for _ in range(max(1, min(opt.ready(), samples - opt.asked)))]
        own += time.perf_counter() - t0
        scores = [float(-r) for r in ROBUSTNESS(spec, np.array(xs))]  # the optimisers maximise
        t0 = time.perf_counter()
        for x, s in zip(xs, scores):
            opt.tell(x, s)
        own += time.perf_counter() - t0
        for i, s in enumerate(scores):
            if s > 0 and found is None:
                found = len(opt.y) - len(scores) + i + 1
        if found is not None and stop:
            break
    return found, own, opt.asked


MIN_FALSIFIED = 3  # fewer falsified runs give no interval: one run's mean would be a point


def mean_interval(found: list[int | None], resamples: int = 10_000) -> tuple[float, float] | None:
    """The 95% interval of the mean simulations to falsify, as ARCH-COMP counts it (over the falsified
    runs), by the percentile bootstrap over runs (a fixed stream: the same runs, the same interval); None
    under ``MIN_FALSIFIED`` falsified runs. Ten runs of a rare-event search are a small sample: CC4's mean
    moves by a hundred and more between sets of ten seeds. Approximate: over ten skewed runs the
    percentile bootstrap covers less than it says (about 0.9 drawing tens from the 80 CC4 runs of
    `auto`, 0.87 for geometric runs like CC4's, 0.67 where a third of the runs falsify)."""
    runs = np.array([np.nan if f is None else f for f in found], dtype=float)
    if np.count_nonzero(~np.isnan(runs)) < MIN_FALSIFIED:
        return None
    draws = runs[np.random.default_rng(0).integers(len(runs), size=(resamples, len(runs)))]
    kept = ~np.all(np.isnan(draws), axis=1)  # a resample of failed runs only has no mean
    means = np.nanmean(draws[kept], axis=1)
    return float(np.percentile(means, 2.5)), float(np.percentile(means, 97.5))


def held_rates(args) -> None:
    """How rare each specification's falsifying inputs are: the share of held inputs (as `auto`'s held
    sampling draws them) and of uniform ones that falsify it; with ``--recheck-dt``, how many of the held
    ones that falsify it at the model's step still do at a finer one."""
    specs = args.specs or [*arch_cc.SPECS, *arch_cc.EARLIER_SPECS]
    held = make_optimizer("auto", np.zeros(2 * SEGMENTS), np.ones(2 * SEGMENTS), budget=1,
                          rng=np.random.default_rng(args.first_seed), signals=(SEGMENTS, SEGMENTS))
    draws = {"held": lambda: held._held(), "uniform": lambda: held._arm_rng.random(2 * SEGMENTS)}
    print(f"chasing cars, instance {args.instance}: {args.held} inputs of each kind (seed {args.first_seed})", flush=True)
    falsifying = {spec: [] for spec in specs}  # the held inputs that falsify each specification
    for kind, draw in draws.items():
        hits = dict.fromkeys(specs, 0)
        for start in range(0, args.held, 500):
            x = np.array([draw() for _ in range(min(500, args.held - start))])
            y = arch_cc.simulate(x, args.instance)
            for spec in specs:
                falsified = arch_cc.robustness(spec, y) < 0
                hits[spec] += int(falsified.sum())
                if kind == "held":
                    falsifying[spec] += list(x[falsified])
        print(f"{kind:8s}" + "".join(f"  {spec} {100 * h / args.held:.2f}% ({h})" for spec, h in hits.items()), flush=True)
    if args.recheck_dt:
        print(f"held inputs falsifying at {arch_cc.DT * 1e3:g} ms that still do at {args.recheck_dt * 1e3:g} ms:"
              + "".join(f"  {spec} {int((arch_cc.robustness(spec, arch_cc.simulate(np.array(x), args.instance, args.recheck_dt)) < 0).sum())}"
                        f"/{len(x)}" for spec, x in falsifying.items() if x)
              + ("" if any(falsifying.values()) else "  none falsified at 10 ms"), flush=True)


def sumo_episode_seconds(repeats: int = 20) -> float:
    """One episode of d4sumo's default scenario (random knot attacks, played alone), simulation and scoring."""
    from d4sumo.search.campaign import Campaign
    from d4sumo.search.runner import Evaluator

    ev = Evaluator(Campaign())
    rng = np.random.default_rng(0)
    t0 = time.perf_counter()
    for _ in range(repeats):
        ev.batch(0, [rng.uniform(ev.family.lower, ev.family.upper)], None)
    return (time.perf_counter() - t0) / repeats


def main() -> None:
    parser = Parser(__doc__)
    parser.add_argument("--runs", type=int, default=10)
    parser.add_argument("--first-seed", type=int, default=0, help="the runs' seeds are this and the next ones [0]")
    parser.add_argument("--jobs", type=int, default=1, help="runs at once, on this many worker processes [1]; "
                        "own times are then measured under their shared load")
    parser.add_argument("--samples", type=int, help="simulations per run [300; arch-comp-cc: 1500, the competition's]")
    parser.add_argument("--optimizers", nargs="+", default=["random", "halton", "ce", "ce-bucket", "cmaes", "bo", "auto", "turbo"])
    parser.add_argument("--specs", nargs="+", choices=(*SPECS, *arch_cc.SPECS, *arch_cc.EARLIER_SPECS))
    parser.add_argument("--benchmark", choices=("plateaus", "arch-comp-cc"), default="plateaus")
    parser.add_argument("--instance", type=int, choices=(1, 2), default=2, help="arch-comp-cc's input instance [2]")
    parser.add_argument("--held", type=int, metavar="N", help="arch-comp-cc: the share of N held inputs (auto's "
                        "held sampling) and N uniform ones that falsify each specification, instead of the runs")
    parser.add_argument("--recheck-dt", type=float, metavar="S", help="with --held: how many of the falsifying held "
                        "inputs still falsify at this integration step [s] (the model's: 0.01)")
    args = parser.parse_args()
    dt = args.recheck_dt
    if dt is not None and not (0 < dt <= arch_cc.DT and abs(arch_cc.SAMPLE_S / dt - round(arch_cc.SAMPLE_S / dt)) < 1e-9):
        parser.error(refusal("--recheck-dt", dt, f"a step in (0, {arch_cc.DT}] s that divides {arch_cc.SAMPLE_S} s"))
    parser.check_counts({"--runs": (args.runs, 1), "--first-seed": (args.first_seed, 0), "--jobs": (args.jobs, 1),
                           "--samples": (args.samples, 1), "--held": (args.held, 1)})
    parser.check_optimizers(args.optimizers)
    allowed = SPECS if args.benchmark == "plateaus" else (*arch_cc.SPECS, *arch_cc.EARLIER_SPECS)
    for spec in args.specs or ():
        if spec not in allowed:
            parser.error(refusal("--specs", spec, f"with --benchmark {args.benchmark}, one of {', '.join(allowed)}"))
    if args.held and args.jobs > 1:
        parser.error(refusal("--jobs", args.jobs, "1 with --held (its inputs are drawn and played in this process)"))
    use_benchmark(args.benchmark, args.instance)
    if args.benchmark == "arch-comp-cc":
        return held_rates(args) if args.held else arch_comp(args)
    args.specs = args.specs or list(SPECS)
    args.samples = args.samples or 300
    t0 = time.perf_counter()
    simulate(np.zeros(2 * SEGMENTS))
    print(f"model: 5 cars, 40 piecewise-constant inputs, {STEPS} steps: {(time.perf_counter() - t0) * 1e3:.1f} ms a simulation")
    falsified: dict[str, dict[str, str]] = {o: {} for o in args.optimizers}
    for spec, o, results in runs_by_pair(args, args.specs, args.samples):
        found = [f for f, _, _ in results]
        hits = [f for f in found if f is not None]
        median = f"{statistics.median(hits):.0f}" if hits else "-"
        falsified[o][spec] = f"{len(hits)}/{args.runs} ({median})"
        print(f"[{spec}] {o:12s}: falsified {len(hits)}/{args.runs} runs; simulations to falsify {found}", flush=True)
    episode = sumo_episode_seconds()
    print(f"\nfalsified runs of {args.runs} (median simulations to falsify), {args.samples} simulations per run; "
          f"own time (ask + tell) per proposal over {args.samples} proposals on `gap`, against one SUMO episode "
          f"of the default scenario ({episode * 1e3:.1f} ms)")
    print(f"{'optimizer':12s}" + "".join(f"{s:>16s}" for s in args.specs) + f"{'own ms':>10s}{'own/episode':>13s}")
    for o in args.optimizers:
        _, own, asked = run(o, "gap", 0, args.samples, stop=False)
        print(f"{o:12s}" + "".join(f"{falsified[o][s]:>16s}" for s in args.specs)
              + f"{own / asked * 1e3:10.1f}{own / asked / episode:13.2f}", flush=True)


def arch_comp(args) -> None:
    """ARCH-COMP's chasing cars: each optimiser's falsified runs, mean and median simulations, own time."""
    runs, samples = args.runs, args.samples or 1500
    specs = args.specs or list(arch_cc.SPECS)
    t0 = time.perf_counter()
    arch_cc.simulate(np.zeros(2 * SEGMENTS), args.instance)
    print(f"chasing cars, instance {args.instance}: {(time.perf_counter() - t0) * 1e3:.0f} ms a simulation; "
          f"{runs} runs of up to {samples} simulations", flush=True)
    rows = {o: {} for o in args.optimizers}
    intervals = {o: {} for o in args.optimizers}
    own_time = {}
    for spec, o, results in runs_by_pair(args, specs, samples):
        hits = [f for f, _, _ in results if f is not None]
        own = sum(t for _, t, _ in results) / max(sum(n for _, _, n in results), 1)
        own_time.setdefault(o, []).append(own)
        mean = f"{statistics.mean(hits):.0f}" if hits else "-"
        median = f"{statistics.median(hits):.0f}" if hits else "-"
        rows[o][spec] = f"{len(hits)}/{runs}, {mean} ({median})"
        interval = mean_interval([f for f, _, _ in results])
        intervals[o][spec] = f"{interval[0]:.0f}-{interval[1]:.0f}" if interval else "-"
        print(f"[{spec}] {o:10s}: falsified {len(hits)}/{runs}; simulations {[f for f, _, _ in results]}", flush=True)
    episode = sumo_episode_seconds()
    load = f", measured under {args.jobs} jobs' shared load" if args.jobs > 1 else ""
    print(f"\nfalsified runs, mean (median) simulations to falsify; own time per proposal (ask + tell, over every "
          f"run{load}), and against one SUMO episode of d4sumo's default scenario ({episode * 1e3:.1f} ms, this run)")
    print(f"{'optimizer':12s}" + "".join(f"{s:>22s}" for s in specs) + f"{'own ms':>9s}{'own/episode':>13s}")
    for o in args.optimizers:
        own = statistics.mean(own_time[o])
        print(f"{o:12s}" + "".join(f"{rows[o][s]:>22s}" for s in specs) + f"{own * 1e3:9.2f}{own / episode:13.2f}")
    print(f"\n95% interval of the mean simulations to falsify (percentile bootstrap over the {runs} runs, seeds "
          f"{args.first_seed}-{args.first_seed + runs - 1}; approximate: it covers less than 95% over few runs; "
          f"- under {MIN_FALSIFIED} falsified)")
    for o in args.optimizers:
        print(f"{o:12s}" + "".join(f"{intervals[o][s]:>22s}" for s in specs))
    print("\nFalCAuN's published figures (10 runs each)")
    print(f"{'FalCAuN 2024':12s}" + "".join(f"{FALCAUN[s][0]:>22s}" for s in specs))
    print(f"{'FalCAuN now':12s}" + "".join(f"{FALCAUN[s][1]:>22s}" for s in specs))
    if "CC4" in specs:
        print("* FalCAuN's CC4 script checks FalStar 2019's CC4 (always[0,5] inside, not always[0,20]; on 5 s samples): "
              "--specs CC4-2019")


if __name__ == "__main__":
    run_main(main)
