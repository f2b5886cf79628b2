"""Where the time goes: one episode and one campaign profiled, their time split into SUMO's stepping, the other
libsumo calls, the control laws, sensing and beacons, the step loop and its trace, specification scoring,
optimiser proposals, storage and start-up (SUMO's, the road's), and a figure of the shares.

Each part is the self time (cProfile's tottime) of the functions of its modules; the time of a built-in call
(a list's append, a numpy ufunc) goes to the part of the function that called it. The step loop calls SUMO's C
functions without a Python frame (bound, mapped over the cars), which a profiler does not see: here each goes
through a one-line Python function (`sumo_step`, `libsumo_call`), so that it is seen, at the cost of that frame;
the step loop in C likewise calls them, not libsumo's C++ functions it calls unprofiled (`engine.calls.native_calls`,
which cost about a tenth of libsumo's Python calls: bench_episode measures them).
The profiler adds a cost to every Python call, so the Python parts weigh more here than they do unprofiled:
the totals to hold against targets are bench_episode's. Both ways are profiled in one run: the followers as they play by default (the
paper's controller stepped in C, `model.compiled`) and stepped by the Python (--python's, as d4sumo 0.20
played the paper's controller), so the figure shows what the compiled followers took away.

Usage: python tools/profile_episode.py [--episodes 20] [--samples 60] [--figure docs/profile.png]
"""

from __future__ import annotations

import cProfile
import gc
import pstats
import tempfile
from pathlib import Path

import numpy as np

from d4sumo.engine.simulation import simulate
from d4sumo.model.controllers import compiled
from d4sumo.model.config import EpisodeConfig
from d4sumo.search.campaign import Campaign
from d4sumo.search.runner import Evaluator, run_campaign
from d4sumo.search.store import Store
from toolargs import Parser, run_main

#: each part, and how a function is known to be in it: by its file's path (a fragment) or its name
PARTS = (
    ("SUMO stepping", ("sumo_step", "simulation_step", "simulationStep")),
    ("start-up (SUMO, the road)", ("simulation_start", "simulation_load", "simulation_close", "vehicle_add",
                                   "vehicletype_", "route_add",
                                   "engine/scenarios.py", "engine/networks.py", "engine/netconvert.py",
                                   "engine/command.py", "engine/warmup.py", "subprocess.py", "sumolib")),
    ("libsumo calls", ("libsumo",)),  # (libsumo_call, and any other call into libsumo)
    ("control laws", ("model/controllers/control.py", "model/controllers/cacc.py", "model/controllers/laws/",
                      "model/controllers/carfollowing.py", "model/controllers/commands.py", "model/world/vehicle.py",
                      "model/controllers/arrays.py", "Followers", "model/controllers/compiled.py", "model/controllers/fmu.py")),
    ("sensing and beacons", ("model/world/sensing.py", "model/world/v2v.py", "model/attacks/messages.py",
                             "model/attacks/maneuvers.py", "model/world/lanes.py", "model/world/signals.py",
                             "engine/neighbours.py")),
    ("step loop and control laws in C", ("play_column",)),  # csrc/column.h: the laws and the loop, one C function
    ("step loop and trace", ("engine/loop.py", "model/stepping/", "engine/sumo.py", "engine/simulation.py",
                             "engine/calls.py")),
    ("specification scoring", ("search/spec.py", "rtamt", "antlr4")),
    ("optimiser proposals", ("search/optimizers", "skopt", "sklearn", "scipy", "cma")),
    ("storage", ("search/store.py", "sqlite3")),
)
OTHER = "other (configuration, attacks, interpreter)"


def part_of(func: tuple) -> str | None:
    """A function's part, from (file, line, name); None for a built-in (its caller's part)."""
    filename, _, name = func
    if filename == "~":  # a built-in: libsumo's C++ functions come through as such, named after their module
        if "libsumo" in name or "_libsumo" in name:
            return next(p for p, keys in PARTS if any(k in name for k in keys))
        if "Followers" in name:
            return "control laws"
        if "play_column" in name:
            return "step loop and control laws in C"
        return None
    where = f"{filename}:{name}"
    return next((p for p, keys in PARTS if any(k in where for k in keys)), OTHER)


def split(profile: cProfile.Profile) -> dict[str, float]:
    """Seconds of self time per part, built-ins charged to their callers' parts (in proportion to the calls)."""
    stats = pstats.Stats(profile).stats
    parts: dict[str, float] = {}
    for func, (_, _, tottime, _, callers) in stats.items():
        part = part_of(func)
        if part is not None:
            parts[part] = parts.get(part, 0.0) + tottime
            continue
        edges = {caller: edge[2] for caller, edge in callers.items()}  # the self time spent from each caller
        spent = sum(edges.values())
        if not spent:  # too short to be timed from any caller (or called from none): charged by the calls
            edges = {caller: edge[0] for caller, edge in callers.items()} or {("~", 0, OTHER): 1}
            spent = sum(edges.values())
        for caller, t in edges.items():
            owner = part_of(caller) or OTHER
            parts[owner] = parts.get(owner, 0.0) + tottime * t / spent
    return parts


def sumo_step(step):
    """SUMO's step as the step loop calls it, through a Python frame the profiler sees."""
    return step(0.0)


def libsumo_call(call, *args):
    """A call into libsumo as the step loop makes it, through a Python frame the profiler sees."""
    return call(*args)


def seen_by_the_profiler() -> None:
    """The step loop's bound SUMO calls (`engine.calls`), each through a Python function."""
    import functools

    from d4sumo.engine import calls, sumo

    def api_call(api, domain, name, _raw=calls.api_call):
        return functools.partial(libsumo_call, _raw(api, domain, name))

    def simulation_step(api):
        raw = getattr(getattr(api, "_libsumo", None), "simulation_step", None)
        return functools.partial(sumo_step, raw) if raw else api.simulationStep

    calls.api_call = api_call
    sumo.simulation_step = simulation_step
    calls.NATIVE = False  # the loop in C and the sensing among traffic call libsumo's Python (through these frames), not its C++ functions


def profiled(job) -> tuple[dict[str, float], float]:
    gc.collect()  # the garbage of what ran before is not this job's: a full collection inside it lands on one function
    profile = cProfile.Profile()
    profile.enable()
    job()
    profile.disable()
    parts = split(profile)
    return parts, sum(parts.values())


def episodes_job(n: int):
    config = EpisodeConfig(start="steady")
    attack = np.full(config.steps, np.nan)  # the attacker cruises: every step runs
    return lambda: [simulate(config, attack) for _ in range(n)]


def campaign_job(samples: int, folder: Path):
    campaign = Campaign(config=EpisodeConfig(), samples=samples, optimizer="auto", seed=1)
    evaluator = Evaluator(campaign)
    counter = iter(range(1000))

    def job():
        with Store(folder / f"profile_{next(counter)}.sqlite") as store:
            run_campaign(campaign, store, evaluator=evaluator)
    return job


def table(results: dict[str, tuple[dict[str, float], float]]) -> None:
    names = [p for p, _ in PARTS] + [OTHER]
    print(f"{'part':<32}" + "".join(f"{label:>24}" for label in results))
    for name in names:
        row = "".join(f"{1e3 * parts.get(name, 0.0):>14.1f} ms {100 * parts.get(name, 0.0) / total:>5.1f}%"
                      for parts, total in results.values())
        print(f"{name:<32}{row}")
    print(f"{'total (profiled)':<32}" + "".join(f"{1e3 * total:>14.1f} ms {'':>6}" for _, total in results.values()))


def figure(results: dict[str, tuple[dict[str, float], float]], path: Path) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    names = [p for p, _ in PARTS] + [OTHER]
    labels = list(results)
    # tab10, then Dark2's: a colour of its own for each part (tab10 alone repeats after ten)
    colours = np.concatenate([plt.get_cmap("tab10")(np.arange(10)), plt.get_cmap("Dark2")(np.arange(8))])[:len(names)]
    fig, ax = plt.subplots(figsize=(9.0, 0.75 * len(labels) + 2.2), layout="constrained")
    for row, label in enumerate(labels):
        parts, total = results[label]
        left = 0.0
        for name, colour in zip(names, colours):
            share = 100.0 * parts.get(name, 0.0) / total
            ax.barh(row, share, left=left, color=colour, label=name if row == 0 else None)
            if share >= 6.0:
                ax.text(left + share / 2, row, f"{share:.0f}%", ha="center", va="center", fontsize=8, color="white")
            left += share
    ax.set_yticks(range(len(labels)), labels)
    ax.invert_yaxis()
    ax.set_xlim(0, 100)
    ax.set_xlabel("share of the profiled time [%]")
    ax.legend(loc="upper center", bbox_to_anchor=(0.5, -0.3), ncol=3, fontsize=8, frameon=False)
    ax.set_title("Where the time goes: an episode (1,200 steps, 4 cars) and a campaign (`auto`)", fontsize=10)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    print(f"figure: {path}")


def main() -> None:
    parser = Parser(__doc__)
    parser.add_argument("--episodes", type=int, default=20, help="episodes profiled one after the other [20]")
    parser.add_argument("--samples", type=int, default=60, help="samples of the profiled campaign [60]")
    parser.add_argument("--figure", type=Path, help="write the figure of the shares here (.png, .svg)")
    args = parser.parse_args()
    parser.check_counts({"--episodes": (args.episodes, 1), "--samples": (args.samples, 1, 10_000)})
    results = {}
    seen_by_the_profiler()
    with tempfile.TemporaryDirectory() as folder:
        for in_c in (True, False):  # caches warm (the road, SUMO's types), each way: what a run's first episode pays once
            compiled.ENABLED = in_c
            episodes(2)
        for label, in_c in (("episodes, in C", True), ("episodes, Python", False)):
            compiled.ENABLED = in_c
            results[label] = profiled(episodes_job(args.episodes))
        compiled.ENABLED = True
        results["campaign (auto)"] = profiled(campaign_job(args.samples, Path(folder)))
    print(f"{args.episodes} episodes of the paper's controller from steady state, then a campaign of {args.samples} "
          "samples (auto, the default scenario), profiled:")
    table(results)
    if args.figure:
        figure(results, args.figure)


def episodes(n: int) -> None:
    episodes_job(n)()


if __name__ == "__main__":
    run_main(main)
