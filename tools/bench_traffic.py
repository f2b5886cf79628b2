"""Episode cost with SUMO's traffic around the platoon against bare libsumo stepping of the same vehicles
(the target, SPEC section 7 and issue 50: ratio <= 1.3, as for every episode), and the memory of a busy 10 km motorway (the target: a worker under 1 GiB).

Both sides are timed the same way, start to close, interleaved in one run so machine noise hits both:
  bare     libsumo start in the same warmed-up traffic (`sumo.traffic_state`, made once and cached: both
           load it), the platoon's places cleared and the same platoon inserted (the same cars, vehicle
           types and speed modes: `sumo.clear_platoon_places`, `sumo.load_platoon`), then `steps` calls
           of simulationStep, close
  episode  d4sumo.engine.simulation.simulate: the same, plus every step the followers' sensing of
           whoever is ahead (SUMO's leader, traffic included), their controllers, actuators and speed
           commands, the collision checks and the Trace, for an attack that never crashes

A swerving attacker through an on-ramp among a network's own demand (on by default; --no-swerve): SUMO's Bremen
motorway, the attacker changing lanes four times (sensing who follows whom in every lane each car covers, traffic
edging in included). The target there: ratio <= 1.3.

A real network with signals and its own demand (--corridor, on by default): SUMO's corridor example
(tools/game/corridor, three signalised crossings, its flows given an end), its main route through them,
an attack that crashes nothing; the episode there also measures its cars against the traffic crossing
each junction in 2D (`engine.junctions`). The target there: ratio <= 1.3.

The memory: a falsify campaign on a straight 10 km, 3-lane motorway at 1800 vehicles per hour per lane
(a few hundred vehicles on the road at once), its peak resident set size as the kernel counts it.

Usage: python tools/bench_traffic.py [--repeats 10] [--densities 600 1800] [--no-corridor] [--no-swerve] [--no-memory]
"""

from __future__ import annotations

import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import libsumo
import numpy as np

from d4sumo.engine.scenarios import build_road, config_road
from d4sumo.engine.simulation import check_episode
from d4sumo.engine.command import sumo_command
from d4sumo.engine.sumo import clear_platoon_places, load_platoon
from d4sumo.engine.warmup import traffic_state
from d4sumo.model.config import EpisodeConfig
from bench_episode import episode  # the same episode timing: simulate, start to close
from toolargs import Parser, run_main

TARGET = 1.3  # an episode with traffic at most this many times bare libsumo stepping of the same vehicles (SPEC 7)
MEMORY_TARGET_MIB = 1024.0


def bare(config: EpisodeConfig, road) -> float:
    t0 = time.perf_counter()
    libsumo.start(sumo_command(config, road, types_file=check_episode(config, road), state_file=traffic_state(config, road)))
    clear_platoon_places(libsumo, config, road)
    load_platoon(libsumo, config, road)
    for _ in range(config.steps):
        libsumo.simulationStep()
    libsumo.close()
    return time.perf_counter() - t0


def busy_motorway_peak_mib(samples: int) -> tuple[float, int]:
    """A falsify campaign's peak RSS [MiB] on a 10 km, 3-lane motorway at 1800 veh/h/lane, and the most
    vehicles on the road at once in its first episode."""
    with tempfile.TemporaryDirectory() as tmp:
        road = Path(tmp) / "motorway"
        road.mkdir()
        (road / "road.nod.xml").write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="10000" y="0"/></nodes>')
        (road / "road.edg.xml").write_text('<edges><edge id="m" from="a" to="b" numLanes="3" speed="33.33"/></edges>')
        traffic = {"vehicles_per_hour": 1800, "warmup_s": 300.0}
        config = EpisodeConfig(network=str(road), start="steady", speed_mps=30.0, traffic=traffic)
        built = build_road(config.network)
        libsumo.start(sumo_command(config, built, state_file=traffic_state(config, built)))
        on_road = libsumo.vehicle.getIDCount()
        libsumo.close()
        cmd = [sys.executable, "-m", "d4sumo.cli", "falsify", "--network", str(road), "--start", "steady", "--speed", "30",
               "--set", "traffic.vehicles_per_hour=1800", "--set", "traffic.warmup_s=300", "--samples", str(samples),
               "--db", str(Path(tmp) / "busy.db")]
        before = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        subprocess.run(cmd, check=True, capture_output=True)
        peak = resource.getrusage(resource.RUSAGE_CHILDREN).ru_maxrss
        return max(peak, before) / 1024.0, on_road


#: knots that crash nothing on the corridor among its demand (tests/engine/test_junctions.py)
CORRIDOR_KNOTS = [-0.7805306719866065, -0.5935169118252068, -0.43238702211173785, -0.3717322087953956, -0.37390428236012463,
                  0.15339943250590404, 0.9433799512395094, 0.549328269847464, 0.5822678963456105]


def corridor_case():
    """SUMO's corridor example along its main route among its own demand: (label, config, road, attack)."""
    from d4sumo.model.attacks.pedals import attack_signal, make_attack
    from d4sumo.sumohome import sumo_home

    game = Path(sumo_home()) / "tools" / "game" / "corridor"
    demand = Path(tempfile.gettempdir()) / "d4sumo-bench-corridor.rou.xml"
    demand.write_text((game / "corridor.rou.xml").read_text().replace("<flow ", '<flow end="3600" '))
    config = EpisodeConfig(network=str(game / "corridor.net.xml"), route=("gneE27", "gneE25", "gneE18", "gneE29"),
                           start="steady", speed_mps=13.0, duration_s=50.0, traffic={"demand": str(demand)})
    road = config_road(config)
    u = attack_signal(make_attack("knots"), CORRIDOR_KNOTS, steps=config.steps, step_s=config.step_s,
                      start_step=config.attack_start_step)
    return "corridor, signals, own demand", config, road, u


#: a swerve through SUMO's Bremen motorway among its own demand that crashes nothing: the attacker changes lanes four
#: times, through the on-ramp (sample 7 of docs/lane-changes.md's campaign, its pedals milder: that one met the traffic at
#: 23 s once the traffic's warm-up was a lane-changing attacker's own, d4sumo 0.22)
SWERVE_PARAMS = [-0.20975098924303356, 0.5169840989617727, -0.23673070044692715, 0.4845074166041973, -0.5402281130028335,
                 0.13495804807098258, -0.18713697476514404, -0.21222790026910407, -0.3277738304971303, 2.8101446115896187,
                 0.8226207432445664, 0.6022549884190292, 1.6178362246396496, 1.9772874541113046, 2.1528750560297025]


def swerve_case():
    """A swerving attacker through SUMO's Bremen motorway among its own demand: (label, config, road, attack)."""
    from d4sumo.model.attacks.maneuvers import attack_plan, maneuver_of
    from d4sumo.model.attacks.pedals import make_attack
    from d4sumo.model.config import ControllerConfig
    from d4sumo.sumohome import sumo_home

    game = Path(sumo_home()) / "tools" / "game" / "highway"
    config = EpisodeConfig(network=str(game / "highway.net.xml"), route=("145354574", "189597495", "E0", "191842213"),
                           join_m=450.0, maneuver="swerve", swerve_lanes=3, start="steady", speed_mps=30.0, duration_s=30.0,
                           controller=ControllerConfig("timegap"), traffic={"demand": str(game / "highway.rou.xml")})
    plan = attack_plan(maneuver_of(config).family(make_attack("knots")), SWERVE_PARAMS, config)
    return "Bremen, a swerve, own demand", config, config_road(config), plan


def main() -> None:
    parser = Parser(__doc__)
    parser.add_argument("--repeats", type=int, default=10)
    parser.add_argument("--densities", type=float, nargs="+", default=[600.0, 1800.0])
    parser.add_argument("--memory-samples", type=int, default=20)
    parser.add_argument("--no-memory", action="store_true")
    parser.add_argument("--no-corridor", action="store_true", help="leave out SUMO's corridor example")
    parser.add_argument("--no-swerve", action="store_true", help="leave out the swerve through SUMO's Bremen motorway")
    args = parser.parse_args()
    parser.check_counts({"--repeats": (args.repeats, 1), "--memory-samples": (args.memory_samples, 1)})
    configs = [EpisodeConfig(network="highway_3lane_120kmh", start="steady", speed_mps=30.0, duration_s=40.0,
                             traffic={"vehicles_per_hour": d, "warmup_s": 60.0}) for d in args.densities]
    road = build_road(configs[0].network)
    attack_u = np.full(configs[0].steps, np.nan)  # the attacker cruises: no crash, full length
    times: dict[float, tuple[list[float], list[float]]] = {d: ([], []) for d in args.densities}
    for config in configs:
        bare(config, road), episode(config, road, attack_u)  # warm caches (and check SUMO's demand)
    cases = [(d, config, road, attack_u) for d, config in zip(args.densities, configs)]
    for wanted, case in ((not args.no_corridor, corridor_case), (not args.no_swerve, swerve_case)):
        if wanted:
            cases.append(case())
            times[cases[-1][0]] = ([], [])
            bare(*cases[-1][1:3]), episode(*cases[-1][1:])
    for _ in range(args.repeats):
        for d, config, at, u in cases:
            times[d][0].append(bare(config, at))
            times[d][1].append(episode(config, at, u))
    c = configs[0]
    print(f"{c.steps} steps after a {c.traffic.warmup_s:g} s warm-up, {c.followers + 1} platoon cars, "
          f"{args.repeats} repeats (median, start to close)")
    for d in times:
        mb, me = statistics.median(times[d][0]), statistics.median(times[d][1])
        ratio = me / mb
        if isinstance(d, str):
            print(f"{d}  bare {mb * 1e3:7.1f} ms  episode {me * 1e3:7.1f} ms  ratio {ratio:5.2f}  (target <= {TARGET}: "
                  + ("met)" if ratio <= TARGET else f"{ratio / TARGET:.2f} times it)"))
            continue
        print(f"{d:6g} veh/h/lane  bare {mb * 1e3:7.1f} ms  episode {me * 1e3:7.1f} ms  ratio {ratio:5.2f}  (target <= {TARGET}: "
              + ("met)" if ratio <= TARGET else f"{ratio / TARGET:.2f} times it)"))
    if not args.no_memory:
        peak, on_road = busy_motorway_peak_mib(args.memory_samples)
        print(f"busy 10 km motorway ({on_road} vehicles on the road when the platoon joins): falsify of "
              f"{args.memory_samples} samples peaks at {peak:.0f} MiB resident (target < {MEMORY_TARGET_MIB:g}: "
              + ("met)" if peak < MEMORY_TARGET_MIB else "not met)"))


if __name__ == "__main__":
    run_main(main)
