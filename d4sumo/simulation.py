"""The SUMO co-simulation: the only module that talks to SUMO (libsumo, or traci for sumo-gui).

Each step Python commands every car's speed (SUMO's car-following, lane changing and speed checks are
off: speed mode 32, lane-change mode 0) and SUMO moves the cars (ballistic update). A collision is any
bumper overlap at the end of a step, measured on SUMO's positions (`platoon.collisions_at`): SUMO's own
reports miss overlaps of 1 mm or less. The episode ends at the first one: SUMO lets the cars drive
through each other afterwards, so later data are not physical.
"""

from __future__ import annotations

import logging
from pathlib import Path

import numpy as np

from .config import EpisodeConfig
from .errors import ConfigError, SumoError
from .platoon import Platoon, collisions_at, initial_state, road_needed_m
from .scenarios import Road, build_road, sumo_binary
from .trace import Episode

log = logging.getLogger(__name__)

ROUTE_ID = "platoon"
VTYPE_ID = "d4car"
SPEED_MODE_PYTHON = 32  # all checks off: Python's speed is applied as given
FCD_PRECISION = 6  # decimals in FCD: gaps recomputed from it agree with the trace to far below 1 cm


def check_road(config: EpisodeConfig, road: Road) -> None:
    """Refuse episodes the road cannot hold: a target speed above the limit, or a road too short."""
    if config.speed_mps > road.speed_limit_mps + 1e-9:
        raise ConfigError("scenario.speed_mps", config.speed_mps, f"at most the speed limit of {road.name}: {road.speed_limit_mps:g} m/s")
    needed = road_needed_m(config, road.speed_limit_mps)
    if needed > road.length_m:
        raise ConfigError(
            "scenario.duration_s",
            config.duration_s,
            f"an episode that fits on {road.name} ({road.length_m:g} m; this one may need {needed:.0f} m)",
        )


def sumo_command(config: EpisodeConfig, road: Road, fcd_path: str | Path | None = None, binary: str = "sumo") -> list[str]:
    """The SUMO command line, as one explicit list."""
    cmd = [
        binary,
        "--net-file", str(road.net_file),
        "--begin", "0",
        "--step-length", repr(config.step_s),
        "--step-method.ballistic", "true",
        "--collision.action", "warn",
        "--collision.mingap-factor", "0",
        "--collision.check-junctions", "false",
        "--insertion-checks", "none",
        "--seed", "0",
        "--no-step-log", "true",
        "--no-warnings", "true",
        "--duration-log.disable", "true",
    ]
    if fcd_path is not None:
        cmd += ["--fcd-output", str(fcd_path), "--fcd-output.acceleration", "true", "--precision", str(FCD_PRECISION)]
    if binary != "sumo":  # sumo-gui: start at once and leave the window open at the end
        cmd += ["--start", "true", "--quit-on-end", "false", "--delay", "50"]
    return cmd


def load_platoon(api, config: EpisodeConfig, road: Road) -> None:
    api.route.add(ROUTE_ID, list(road.route_edges))
    api.vehicletype.copy("DEFAULT_VEHTYPE", VTYPE_ID)
    v = config.vehicle
    api.vehicletype.setLength(VTYPE_ID, v.length_m)
    api.vehicletype.setMinGap(VTYPE_ID, 0.0)
    api.vehicletype.setMaxSpeed(VTYPE_ID, 100.0)  # Python clamps speeds itself
    api.vehicletype.setAccel(VTYPE_ID, v.max_accel_mps2)
    api.vehicletype.setDecel(VTYPE_ID, v.max_decel_mps2)
    api.vehicletype.setEmergencyDecel(VTYPE_ID, v.max_decel_mps2)
    api.vehicletype.setImperfection(VTYPE_ID, 0.0)
    api.vehicletype.setSpeedDeviation(VTYPE_ID, 0.0)
    positions, speeds = initial_state(config)
    for vid, x, s in zip(config.vehicle_ids, positions, speeds):
        api.vehicle.add(vid, ROUTE_ID, typeID=VTYPE_ID, depart="0", departLane="0", departPos=repr(x), departSpeed=repr(s))
    api.simulationStep()  # inserts the cars: this state is t = 0
    present = set(api.vehicle.getIDList())
    missing = [vid for vid in config.vehicle_ids if vid not in present]
    if missing:
        raise SumoError(f"SUMO did not insert {', '.join(missing)} on {road.name}")
    for vid in config.vehicle_ids:
        api.vehicle.setSpeedMode(vid, SPEED_MODE_PYTHON)
        api.vehicle.setLaneChangeMode(vid, 0)


def simulate(
    config: EpisodeConfig,
    attack_u: np.ndarray,
    *,
    road: Road | None = None,
    fcd_path: str | Path | None = None,
    gui: bool = False,
) -> Episode:
    """Play one episode in SUMO. ``attack_u`` holds the attacker's command at each step's start
    (``config.steps`` values in [-1, 1], NaN where the attacker cruises)."""
    road = road or build_road(config.network)
    check_road(config, road)
    platoon = Platoon(config, attack_u, attacker_max_speed_mps=road.speed_limit_mps)
    if gui:
        import traci as api  # libsumo has no window; traci drives sumo-gui with the same API

        cmd = sumo_command(config, road, fcd_path, binary=sumo_binary("sumo-gui"))
    else:
        import libsumo as api

        cmd = sumo_command(config, road, fcd_path)
    try:
        api.start(cmd)
    except Exception as exc:  # libsumo/traci raise their own types, or FatalTraCIError
        raise SumoError(f"SUMO did not start: {exc}") from None
    try:
        load_platoon(api, config, road)
        return _run(api, config, platoon)
    except api.TraCIException as exc:
        raise SumoError(f"SUMO failed during the episode: {exc}") from None
    finally:
        api.close()


def _run(api, config: EpisodeConfig, platoon: Platoon) -> Episode:
    ids = config.vehicle_ids
    get_position = api.vehicle.getLanePosition
    get_speed = api.vehicle.getSpeed
    set_speed = api.vehicle.setSpeed
    step = api.simulationStep
    advance = platoon.advance
    length, dt = config.vehicle.length_m, config.step_s
    positions = [get_position(v) for v in ids]
    speeds = [get_speed(v) for v in ids]
    rows_x, rows_v = [positions], [speeds]
    collisions: tuple = ()
    for k in range(config.steps):
        commanded = advance(k, positions, speeds)
        for vid, v in zip(ids, commanded):
            set_speed(vid, v)
        step()
        positions = [get_position(v) for v in ids]
        speeds = [get_speed(v) for v in ids]
        rows_x.append(positions)
        rows_v.append(speeds)
        collisions = collisions_at((k + 1) * dt, positions, speeds, length)
        if collisions:
            break
    times = np.arange(len(rows_x)) * config.step_s
    return Episode(platoon.trace(times, np.array(rows_x), np.array(rows_v)), collisions)

