"""Episode cost against bare libsumo stepping of the same steps and cars (the target: ratio <= 1.3 for every
system, a cooperative platoon with beacons each step included), for followers commanded by the paper's
controller and for followers driven by SUMO's ACC model (or any systems given, e.g. --systems timegap idm cacc
ploeg consensus paper-as-run; paper-as-run: the preset, its authors' controllers and attacker, in the same scenario).

Both sides are timed the same way, start to close, interleaved in one run so machine noise hits both:
  bare     libsumo start, the same cars (and vehicle types) inserted, `steps` calls of simulationStep, close
  episode  d4sumo.engine.simulation.simulate: controllers, actuators, speed commands, sensing, collision
           checks and the Trace, for an attack that never crashes (so every step runs)

With --fmu, the paper's controller also as the FMUs d4sumo ships (FMI 2.0 and 3.0, built here), and the
ratio of their episodes to those of d4sumo's own controller, as it plays (in C where it is built; with
--python, the Python) (the target: at most 2).

Where a platoon's followers are stepped in C (d4sumo.model.controllers.compiled: the paper's controller and the
cooperative ones), --python times the Python that stands for them instead.

Usage: python tools/bench_episode.py [--repeats 30] [--followers 3] [--systems switching sumo:ACC] [--fmu] [--python]
"""

from __future__ import annotations

import dataclasses
import statistics
import tempfile
import time

import libsumo
import numpy as np

from d4sumo.engine.scenarios import build_road
from d4sumo.engine.simulation import check_episode, simulate
from d4sumo.engine.command import sumo_command
from d4sumo.engine.sumo import load_platoon
from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.presets import apply_preset
from toolargs import Parser, run_main


TARGET = 1.3  # an episode at most this many times bare libsumo stepping of the same steps and cars
COOPERATIVE_TARGET = 1.3  # the same for a platoon that exchanges V2V beacons
AS_RUN = "paper-as-run"  # a system: the paper as its authors' code ran it (`presets`)
FMU_TARGET = 2.0  # an episode with the shipped FMU at most this many times the same with the Python controller

def bare(config: EpisodeConfig, road) -> float:
    t0 = time.perf_counter()
    libsumo.start(sumo_command(config, road, types_file=check_episode(config, road)))
    load_platoon(libsumo, config, road)
    for _ in range(config.steps):
        libsumo.simulationStep()
    libsumo.close()
    return time.perf_counter() - t0


def episode(config: EpisodeConfig, road, attack_u: np.ndarray) -> float:
    t0 = time.perf_counter()
    result = simulate(config, attack_u, road=road)
    elapsed = time.perf_counter() - t0
    assert len(result.trace) == config.steps + 1, "the benchmark attack must not crash"
    return elapsed


def system_config(name: str, followers: int) -> EpisodeConfig:
    """The episode a system plays: its followers' controller, from steady state; ``paper-as-run``: the preset (the
    authors' controllers and attacker), in the same scenario as the others (steady state, no end distance), so that
    every step runs."""
    if name == AS_RUN:
        doc = apply_preset({"preset": AS_RUN, "attack": {"family": "knots"}})
        doc["scenario"].update(start="steady", duration_s=EpisodeConfig.duration_s, end_distance_m=0.0)
        return dataclasses.replace(EpisodeConfig.from_dict(doc), followers=followers)
    return EpisodeConfig(followers=followers, start="steady", controller=ControllerConfig(name))


def main() -> None:
    parser = Parser(__doc__)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--followers", type=int, default=3)
    parser.add_argument("--systems", nargs="+", default=["switching", "sumo:ACC"])
    parser.add_argument("--fmu", action="store_true", help="also the shipped FMUs of the paper's controller")
    parser.add_argument("--python", action="store_true", help="followers stepped by the Python, not in C")
    args = parser.parse_args()
    if args.python:
        from d4sumo.model.controllers import compiled

        compiled.ENABLED = False
    parser.check_counts({"--repeats": (args.repeats, 1), "--followers": (args.followers, 1)})
    with tempfile.TemporaryDirectory(prefix="bench-fmu-") as folder:
        fmus = {}
        if args.fmu:
            from d4sumo.fmus import build_switching_fmu

            fmus = {f"fmu:{build_switching_fmu(f'{folder}/switching{v}.fmu', v)}": f"FMI {v}.0" for v in (2, 3)}
            args.systems = list(dict.fromkeys(["switching", *args.systems, *fmus]))
        measure(args, fmus)


def measure(args, fmus: dict) -> None:
    """Time each system's episodes against bare stepping, interleaved, and print the ratios."""
    configs = [system_config(name, args.followers) for name in args.systems]
    road = build_road(configs[0].network)
    attack_u = np.full(configs[0].steps, np.nan)  # the attacker cruises: no crash, full length
    times: dict[str, tuple[list[float], list[float]]] = {name: ([], []) for name in args.systems}
    for config in configs:
        bare(config, road), episode(config, road, attack_u)  # warm caches (and check SUMO's vehicle types)
    for _ in range(args.repeats):
        for name, config in zip(args.systems, configs):
            times[name][0].append(bare(config, road))
            times[name][1].append(episode(config, road, attack_u))
    steps, cars = configs[0].steps, args.followers + 1
    print(f"{steps} steps, {cars} cars, {args.repeats} repeats (median, start to close)")
    ratios = {}
    shown = {name: fmus.get(name, name) for name in args.systems}  # the shipped FMUs by their FMI version
    for name in args.systems:
        mb, me = statistics.median(times[name][0]), statistics.median(times[name][1])
        ratios[name] = me / mb
        print(f"followers {shown[name]:<10} bare libsumo stepping : {mb * 1e3:7.2f} ms  ({mb / steps * 1e6:.1f} us/step)")
        print(f"followers {shown[name]:<10} d4sumo episode        : {me * 1e3:7.2f} ms  ({me / steps * 1e6:.1f} us/step)")
    for name, config in zip(args.systems, configs):
        target = COOPERATIVE_TARGET if config.v2v is not None else TARGET
        print(f"ratio episode / bare, followers {shown[name]:<10}: {ratios[name]:5.2f}   (target <= {target}: "
              + ("met)" if ratios[name] <= target else f"{ratios[name] / target:.2f} times it)"))
    python = statistics.median(times["switching"][1]) if fmus else None
    for name, label in fmus.items():
        ratio = statistics.median(times[name][1]) / python
        print(f"ratio episode with the shipped FMU ({label}) / with d4sumo's controller ({'Python' if args.python else 'as it plays'}): "
              f"{ratio:5.2f}   (target <= "
              f"{FMU_TARGET}: " + ("met)" if ratio <= FMU_TARGET else f"{ratio / FMU_TARGET:.2f} times it)"))


if __name__ == "__main__":
    run_main(main)
