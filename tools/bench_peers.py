"""d4sumo's optimisers beside the falsifiers of the field (issue 51), on d4sumo's problems: the same box, the same
robustness, the same budget and seeds.

The peers, each driven as its user would drive it:

- PSY-TaLiRo 3.2 (``pip install -e '.[peers]'``): its UniformRandom and DualAnnealing optimisers, over the attack's
  parameters as static inputs, minimising the negated robustness (a cost function of PSY-TaLiRo's that plays
  d4sumo's episode);
- VerifAI 2.2, the D4+ paper's own tool, in an environment of its own (``--verifai-python``; its
  metric-temporal-logic pins attrs < 23, which PSY-TaLiRo's 24.1 and later refuse): its BO (GPyOpt), cross-entropy,
  Halton and random samplers over the unit cube of the box (`peers_verifai.py`), fed the negated robustness of
  each episode d4sumo plays, over a pipe.

Every peer's sample i is the episode d4sumo's campaign of that problem and seed plays as its sample i (the same
configuration, the same traffic): only the points differ. For each problem, over the seeds, one row per optimiser:
the runs that found a success; the first success (its 1-based sample, a run without one counted as the budget plus
one), mean and median; successes per 100 samples; distinct successes (attacks more than 5 % of their range apart,
and kinds of crash); and the ratio of each to the default's (first success: the default's over the peer's, so
that above 1 the peer is ahead in every column).

Usage: python tools/bench_peers.py [--samples 100] [--seeds 8] [--problems default steady-30-10 cacc-lie cutin
                                    swerve-bremen insider-lie sumo-acc-steady]
                                   [--d4sumo auto random auto:novelty=0.05] [--psy-taliro uniform annealing]
                                   [--verifai bo ce halton random] [--verifai-python PATH]
"""

from __future__ import annotations

import importlib.util
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Callable

import numpy as np

from d4sumo.inputs import campaign_of
from d4sumo.results.analysis import crash_kinds, distinct_count
from d4sumo.search.campaign import SampleResult
from d4sumo.search.evaluator import Evaluator
from d4sumo.search.optimizers import DEFAULT_OPTIMIZER
from d4sumo.search.runner import run_campaign
from toolargs import Parser, optimizer_of, run_main

HERE = Path(__file__).resolve().parent
def _bremen() -> str:
    from d4sumo.sumohome import sumo_home

    return str(Path(sumo_home()) / "tools" / "game" / "highway")


#: the problems of the issue's table: the default scenario; steady state at 30 m/s, 10 m; the cooperative
#: platoon at 5 m told a lie on the attacker's speed. Then the issue's others: a cut-in ahead of v2; a swerve
#: through SUMO's Bremen motorway among its own demand (docs/lane-changes.md's); an insider (v2) lying about its
#: acceleration to Ploeg's followers; SUMO's ACC from steady state
PROBLEMS = {
    "default": {},
    "steady-30-10": {"scenario": {"start": "steady", "speed_mps": 30.0, "setpoint_m": 10.0}},
    "cacc-lie": {"scenario": {"start": "steady", "setpoint_m": 5.0}, "controller": {"class": "cacc"},
                 "attack": {"message": "offset", "message_field": "speed"}},
    "cutin": {"scenario": {"maneuver": "cutin", "cutin_follower": 2}},
    "swerve-bremen": {"scenario": {"network": f"{_bremen()}/highway.net.xml", "route": ["145354574", "189597495", "E0", "191842213"],
                                   "join_m": 450.0, "maneuver": "swerve", "swerve_lanes": 3, "start": "steady",
                                   "speed_mps": 30.0, "duration_s": 30.0},
                      "controller": {"class": "timegap"}, "traffic": {"demand": f"{_bremen()}/highway.rou.xml"}},
    "insider-lie": {"scenario": {"start": "steady", "setpoint_m": 5.0}, "controller": {"class": "ploeg"},
                    "attack": {"family": "cruise", "message": "knots", "message_sender": 2}},
    "sumo-acc-steady": {"scenario": {"start": "steady"}, "controller": {"class": "sumo:ACC"}},
}
PSY_TALIRO = ("uniform", "annealing")
VERIFAI = ("bo", "ce", "halton", "random")


class Episodes:
    """The episodes of one problem and seed, played in order as its d4sumo campaign plays its samples: sample i of
    any optimiser is that campaign's sample i at the point it gives."""

    def __init__(self, problem: dict, samples: int, seed: int):
        self.campaign = campaign_of({**problem, "search": {"samples": samples, "seed": seed}})
        self.family = self.campaign.family()
        self.evaluator = Evaluator(self.campaign)
        self.samples = samples
        self.results: list[SampleResult] = []

    def robustness(self, x) -> float:
        """Play the next sample at ``x`` (in the box); its robustness (an errored sample: the worst so far)."""
        if len(self.results) >= self.samples:  # an optimiser past its budget (SciPy's annealing may be): not counted
            return min((r.robustness for r in self.results if r.robustness is not None), default=-1.0)
        x = np.clip(np.asarray(x, dtype=float), self.family.lower, self.family.upper)
        r = self.evaluator(len(self.results), x)
        self.results.append(r)
        return r.robustness if r.robustness is not None else min(
            (s.robustness for s in self.results if s.robustness is not None), default=-1.0)


def d4sumo_run(problem: dict, optimizer: str, samples: int, seed: int) -> list[SampleResult]:
    """A d4sumo campaign of the problem: ``optimizer`` a name, or ``name:key=value,...`` with its options."""
    name, options = optimizer_of(optimizer)
    campaign = campaign_of({**problem, "search": {"optimizer": name, "samples": samples, "seed": seed, name: options}})
    return sorted(run_campaign(campaign).samples, key=lambda r: r.index)


def psy_taliro_run(problem: dict, optimizer: str, samples: int, seed: int) -> list[SampleResult]:
    import staliro
    from staliro.optimizers import DualAnnealing, UniformRandom

    episodes = Episodes(problem, samples, seed)
    names = [f"p{i}" for i in range(episodes.family.dimension)]

    @staliro.costfunc
    def cost(inputs) -> float:  # PSY-TaLiRo minimises: the negated robustness, below 0 where an attack succeeded
        return -episodes.robustness([inputs.static[n] for n in names])

    options = staliro.TestOptions(static_inputs={n: (float(lo), float(hi)) for n, lo, hi in
                                                 zip(names, episodes.family.lower, episodes.family.upper)},
                                  iterations=samples, runs=1, seed=seed + 1)
    staliro.staliro(cost, UniformRandom() if optimizer == "uniform" else DualAnnealing(), options)
    return episodes.results


def verifai_run(problem: dict, sampler: str, samples: int, seed: int, python: str) -> list[SampleResult]:
    episodes = Episodes(problem, samples, seed)
    f = episodes.family
    child = subprocess.Popen([python, str(HERE / "peers_verifai.py"), sampler, str(f.dimension), str(samples), str(seed)],
                             stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True)
    try:
        for line in child.stdout:
            z = np.asarray(json.loads(line), dtype=float)
            child.stdin.write(f"{episodes.robustness(f.lower + z * (f.upper - f.lower))!r}\n")
            child.stdin.flush()
    finally:
        child.stdin.close()
        child.wait(timeout=30)
    if child.returncode:
        raise SystemExit(f"--verifai-python: VerifAI's {sampler} sampler exited with {child.returncode}")
    return episodes.results


def _ratio(a: float, b: float) -> str:
    """a / b, two decimals; where the default found none (b = 0): "inf" if the other did, "-" if neither."""
    return f"{a / b:.2f}" if b else ("inf" if a else "-")


def scores(results: list[SampleResult], family, samples: int) -> tuple[float, int, int, int]:
    """(first success, 1-based, or samples + 1; successes; distinct attacks; kinds of crash)."""
    wins = [r for r in results if r.outcome == "success"]
    first = next((i + 1 for i, r in enumerate(results) if r.outcome == "success"), samples + 1)
    return (first, len(wins), distinct_count([r.params for r in wins], family.lower, family.upper),
            crash_kinds([r.collision for r in wins if r.collision]))


def main() -> None:
    parser = Parser(__doc__)
    parser.add_argument("--samples", type=int, default=100)
    parser.add_argument("--seeds", type=int, default=8)
    parser.add_argument("--problems", nargs="+", default=list(PROBLEMS), choices=list(PROBLEMS))
    parser.add_argument("--d4sumo", nargs="+", default=[DEFAULT_OPTIMIZER, "random"], metavar="OPTIMIZER")
    parser.add_argument("--psy-taliro", nargs="*", default=list(PSY_TALIRO), choices=PSY_TALIRO)
    parser.add_argument("--verifai", nargs="*", default=list(VERIFAI), choices=VERIFAI)
    parser.add_argument("--verifai-python", help="the Python of an environment with VerifAI 2.2 and GPyOpt (none: VerifAI "
                                                 "is left out)")
    args = parser.parse_args()
    parser.check_counts({"--samples": (args.samples, 1), "--seeds": (args.seeds, 1)})
    parser.check_optimizers(args.d4sumo)
    if args.psy_taliro and importlib.util.find_spec("staliro") is None:
        parser.error("--psy-taliro: PSY-TaLiRo is not installed here: pip install -e '.[peers]' (or --psy-taliro with "
                     "no names)")
    runs: dict[str, Callable] = {f"d4sumo {o}": (lambda p, n, s, o=o: d4sumo_run(p, o, n, s)) for o in args.d4sumo}
    runs.update({f"PSY-TaLiRo {o}": (lambda p, n, s, o=o: psy_taliro_run(p, o, n, s)) for o in args.psy_taliro})
    if args.verifai_python:
        runs.update({f"VerifAI {o}": (lambda p, n, s, o=o: verifai_run(p, o, n, s, args.verifai_python)) for o in args.verifai})
    t0 = time.perf_counter()
    default = f"d4sumo {args.d4sumo[0]}"
    print(f"{args.samples} samples a run, {args.seeds} seeds; first success: its sample (a run without one: "
          f"{args.samples + 1}); ratios to {default} (above 1: ahead of it)")
    for name in args.problems:
        problem = PROBLEMS[name]
        family = campaign_of(problem).family()
        table = {}
        for label, run in runs.items():
            table[label] = [scores(run(problem, args.samples, seed), family, args.samples) for seed in range(args.seeds)]
        print(f"\n{name} ({family.dimension} parameters)")
        print(f"  {'optimiser':<22}{'falsified':>10}{'first mean':>11}{'median':>8}{'successes':>11}{'distinct':>10}"
              f"{'kinds':>7}   ratio first / successes / kinds")
        base = table[default]
        for label, rows in table.items():
            first = [r[0] for r in rows]
            mean = [statistics.mean(r[i] for r in rows) for i in range(4)]
            ratio = (_ratio(statistics.mean(r[0] for r in base), mean[0]), _ratio(mean[1], statistics.mean(r[1] for r in base)),
                     _ratio(mean[3], statistics.mean(r[3] for r in base)))
            print(f"  {label:<22}{sum(f <= args.samples for f in first):>5}/{len(rows):<4}{mean[0]:>11.1f}{statistics.median(first):>8.1f}"
                  f"{100 * mean[1] / args.samples:>11.1f}{mean[2]:>10.1f}{mean[3]:>7.1f}   {' / '.join(ratio)}")
        sys.stdout.flush()
    print(f"\ntotal {time.perf_counter() - t0:.0f} s")


if __name__ == "__main__":
    run_main(main)
