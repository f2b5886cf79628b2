"""Episode cost against bare libsumo stepping of the same steps and cars (SPEC section 7: ratio <= 2.5).

Both sides are timed the same way, start to close, interleaved in one run so machine noise hits both:
  bare     libsumo start, the same cars inserted, `steps` calls of simulationStep, close
  episode  d4sumo.simulation.simulate: controllers, actuators, speed commands, sensing, collision
           checks and the Trace, for an attack that never crashes (so every step runs)

Usage: python tools/bench_episode.py [--repeats 30] [--followers 3]
"""

from __future__ import annotations

import argparse
import statistics
import time

import libsumo
import numpy as np

from d4sumo.config import EpisodeConfig
from d4sumo.scenarios import build_road
from d4sumo.simulation import load_platoon, simulate, sumo_command


def bare(config: EpisodeConfig, road) -> float:
    t0 = time.perf_counter()
    libsumo.start(sumo_command(config, road))
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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--repeats", type=int, default=30)
    parser.add_argument("--followers", type=int, default=3)
    args = parser.parse_args()
    config = EpisodeConfig(followers=args.followers, start="steady")
    road = build_road(config.network)
    attack_u = np.full(config.steps, np.nan)  # the attacker cruises: no crash, full length
    bare(config, road), episode(config, road, attack_u)  # warm caches
    t_bare, t_episode = [], []
    for _ in range(args.repeats):
        t_bare.append(bare(config, road))
        t_episode.append(episode(config, road, attack_u))
    mb, me = statistics.median(t_bare), statistics.median(t_episode)
    cars = config.followers + 1
    print(f"{config.steps} steps, {cars} cars, {args.repeats} repeats (median, start to close)")
    print(f"bare libsumo stepping : {mb * 1e3:7.2f} ms  ({mb / config.steps * 1e6:.1f} us/step)")
    print(f"d4sumo episode        : {me * 1e3:7.2f} ms  ({me / config.steps * 1e6:.1f} us/step)")
    print(f"ratio episode / bare  : {me / mb:7.2f}   (target <= 2.5)")


if __name__ == "__main__":
    main()
