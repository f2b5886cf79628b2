"""Verdict invariants over many random episodes, checked against SUMO's own FCD output.

Plays N random episodes (on the shipped 4-lane highway, in lane 0, 1 or 2, and on roads of several edges: a
speed change, a lane drop, a curve, an acceleration lane, a route through netgenerate's grid, SUMO's own
Bremen motorway through its on-ramp (the platoon's lane index changing along both); one episode in seven
among SUMO's traffic on the 4-lane highway (densities, warm-ups, clearances, seeds, per-sample traffic
and mixes of car-following models and trucks drawn: who follows whom from the FCD is then the nearest
car in each lane a car covers, a traffic car included); one in five with the paper-as-run preset, its controllers (a third of them with other systems), families and scenario,
some with a coasting car; every attack family, every start mode, setpoints with and without fractional
metres, 1-10 followers, three target speeds; followers run the paper's controller, the time-gap one,
SUMO's models, the paper's controller as the FMU d4sumo ships, or the cooperative ones (PATH's CACC, Ploeg's and the
consensus, in Python, and Plexe's CACC and CONSENSUS in SUMO) over a V2V channel, half of those late or
lossy and half of those attacked over the air (every message attack, every field), a quarter of the platoons mixed, some Python followers behind a radar with a range, noise
and latency; one episode in four a cut-in, a cut-out or a swerving
attacker with a random target follower, offset, obstacle, lane knots, lanes and lane change duration), each scored and stored exactly as a
campaign stores a sample, and counts the samples where any of these disagree:

- outcome and collision record: no collision <=> no_crash; a collision involving v0 <=> attacker_crash;
  a collision is a bumper gap below scenario.collision_gap_m (0: an overlap; the paper-as-run draws:
  0.05 m, as the authors' code counts a crash), written c below;
- outcome and the stored minimum gaps: no_crash <=> every minimum gap >= c; attacker_crash <=> a pair
  with v0 < c; success <=> no pair with v0 < c and some other pair < c;
- outcome and the sign of the stored robustness (psi with d_safe = c): success <=> rho > 0; for the
  paper's maneuver, rtamt's robustness and a direct numpy evaluation of psi agree;
- the collision time is the last simulated step, and the collision pair's gap is below c there;
- the FCD file SUMO wrote: every car's position along its route at every step (on a road of several
  edges: its first lane position plus SUMO's odometer) agrees with the trace to the FCD's
  precision (6 decimals), and no gap recomputed from the FCD alone (who follows whom from its lateral
  coordinate) is below c (beyond that precision) before the stored collision time, nor is the
  collision pair's FCD gap above c at it; every car that keeps its lane drove the road's lane path
  (the platoon's lane on each edge, as d4sumo reads it from the network's connections); with a
  lane-changing attacker, every car's gap signal is the FCD's gap to the nearest car ahead in the lanes
  it covers (within 150 m to the FCD's precision, farther no less);
- among a network's own demand across signalised crossings (SUMO's corridor example, --junctions), in 2D:
  no car of the platoon overlaps any other vehicle in SUMO's FCD (`bodies.body_gap_m` of its x, y, angle,
  length and width) before the stored collision time, and a collision with a traffic car is a 2D
  clearance below c in the FCD at it (there the lane gaps are not recomputed from the FCD: the traffic's
  lane positions start again on every edge);
- the episode played in a batch (beside --batch - 1 other random attacks, half of them of its
  configuration, half of other campaigns' that may share its SUMO: other setpoints, target speeds and
  starts; in one SUMO, on a random copy of the road) is bit for bit the episode played alone: every
  signal, the collision record, the minimum gaps.

With --situation P, a share of the campaigns search their setpoint (and some their speed, start, vehicle's actuator
lag, V2V loss and latency, radar noise and controller gain) with the attack: each sample plays its own, and is
checked as any other.

With --ramps P, a share of the lane-changing episodes play through an on-ramp that moves the platoon's lane to
another of SUMO's indices and back (SUMO's Bremen motorway, the example acceleration lane) or through the example
lane drop, half of them among traffic (Bremen's own demand, or a flow): who follows whom from the FCD then places each car across the road by its
lane, counted from the platoon's on that edge, and its lateral position in it; along the route by where its lane's
edge starts (sumolib's lengths).

Usage: python tools/check_invariants.py [N] [--seed S] [--batch K] [--traffic P] [--cooperative P] [--junctions P]
       [--ramps P] [--situation P]. Prints the counts; exits 1 if any is
non-zero.
"""

from __future__ import annotations

import dataclasses
import json
import sys
import tempfile
import time
from collections import Counter
from pathlib import Path

import numpy as np
from sumolib.xml import parse_fast_nested

from d4sumo.engine.scenarios import MAX_COPIES, config_road
from d4sumo.engine.simulation import check_road, simulate, simulate_batch
from d4sumo.engine.warmup import traffic_state
from d4sumo.errors import ConfigError
from d4sumo.inputs import campaign_of
from d4sumo.model.attacks.pedals import FAMILIES
from d4sumo.model.stepping.batch import batch_key
from d4sumo.model.world.bodies import Body, body_gap_m
from d4sumo.model.config import START_MODES, ControllerConfig, EpisodeConfig
from d4sumo.model.attacks.maneuvers import attack_plan, maneuver_of
from d4sumo.model.world.lanes import CAR_WIDTH_M, lane_pairs, occupied_lanes
from d4sumo.model.attacks.messages import MESSAGE_ATTACKS, MESSAGE_FIELDS
from d4sumo.model.world.sensing import RadarParams
from d4sumo.search.campaign import Campaign, open_store
from d4sumo.search.runner import Evaluator
from d4sumo.search.spec import psi_robustness
from d4sumo.search.store import Store
from toolargs import Parser, run_main

FCD_TOLERANCE_M = 2.5e-6  # two positions, each one or two numbers rounded to 6 decimals
#: with a lane-changing attacker, each car's gap to the nearest car ahead in the lanes it covers is exact up to
#: this far: SUMO's search for a car's leader across a junction missed one farther (tests/engine/test_traffic.py)
SENSED_EXACTLY_M = 150.0
#: the roads drawn from: the shipped 4-lane highway (one edge), and roads of several edges: a speed
#: change, a lane drop, a curve (in-lane maneuvers only there: lanes are told from the FCD's y); then
#: netgenerate's grid and three sharp turns (`sharp_turns`), made at the first run
ROADS = ["highway_4lane", *(str(Path(__file__).resolve().parent.parent / "examples" / "roads" / name)
                            for name in ("three_edges", "lane_drop", "curved", "acceleration_lane"))]
STRAIGHT = ROADS[:3]
#: networks with many ways, driven along a named route: netgenerate's grid (made at the first run), and
#: SUMO's own Bremen motorway (in the eclipse-sumo wheel), whose on-ramp moves the platoon's lane 0 -> 1 -> 0
ROUTES: dict[str, tuple[str, ...]] = {}
#: roads too short for the default 60 s episode: the duration drawn there
DURATIONS: dict[str, float] = {}
#: the lanes the platoon is put in (scenario.lane) besides the road's own choice, by road
LANES = {"highway_4lane": (1, 2)}


def bremen_motorway() -> str:
    """SUMO's own example motorway (tools/game/highway), its main route through an on-ramp: 1.9 km."""
    from d4sumo.sumohome import sumo_home

    path = str(Path(sumo_home()) / "tools" / "game" / "highway" / "highway.net.xml")
    ROUTES[path] = ("145354574", "189597495", "E0", "191842213")
    DURATIONS[path] = 20.0
    return path


def sharp_turns() -> str:
    """A road of three sharp turns (junction radii 15-25 m, about 4 m/s through them): SUMO's models slow
    down for them, and netconvert builds their lanes otherwise in a batch's copies (played alone then)."""
    folder = Path(tempfile.gettempdir()) / "d4sumo-check-sharp-turns"
    folder.mkdir(exist_ok=True)
    (folder / "road.nod.xml").write_text(
        '<nodes><node id="n0" x="0" y="0"/><node id="n1" x="160" y="0" radius="25"/><node id="n2" x="160" y="30" radius="15"/>'
        '<node id="n3" x="190" y="60" radius="20"/><node id="n4" x="3500" y="60"/></nodes>')
    (folder / "road.edg.xml").write_text("<edges>" + "".join(
        f'<edge id="{e}" from="n{i}" to="n{i + 1}" numLanes="2" speed="33"/>' for i, e in enumerate("abcd")) + "</edges>")
    return str(folder)


def netgenerate_grid() -> str:
    """netgenerate's grid of two-lane streets at 40 m/s, 1.5 km between crossings, made once per machine."""
    import subprocess

    from d4sumo.sumohome import sumo_binary

    path = Path(tempfile.gettempdir()) / "d4sumo-check-grid.net.xml"
    if not path.is_file():
        subprocess.run([sumo_binary("netgenerate"), "--grid", "--grid.number", "4", "--grid.length", "1500", "-L", "2",
                        "--default.speed", "40", "-o", str(path)], check=True, capture_output=True)
    ROUTES[str(path)] = ("A0B0", "B0C0", "C0D0")
    return str(path)
#: the systems under test drawn from: Python controllers and SUMO-driven followers
SYSTEMS = [ControllerConfig("switching"), ControllerConfig("timegap"), ControllerConfig("sumo:ACC"),
           ControllerConfig("sumo:ACC", (("tau", 0.5),)), ControllerConfig("sumo:IDM"), ControllerConfig("sumo:Krauss"),
           ControllerConfig("sumo:CACC"), ControllerConfig("cacc"), ControllerConfig("ploeg"), ControllerConfig("consensus"),
           ControllerConfig("sumo:CC", (("active_controller", "CACC"),)),
           ControllerConfig("sumo:CC", (("active_controller", "CONSENSUS"),))]


#: the share of in-lane episodes played among traffic (--traffic)
TRAFFIC_SHARE = [0.15]
#: the share of in-lane episodes played on SUMO's corridor among its own demand, through its signalised crossings (--junctions)
JUNCTION_SHARE = [0.0]
#: the share of lane-changing episodes played through an on-ramp, where the platoon's lane index changes
#: (SUMO's Bremen motorway and the example acceleration lane), half of those among traffic (--ramps)
RAMP_SHARE = [0.0]
#: SUMO's corridor example (tools/game/corridor): its main route through three signalised crossings
CORRIDOR_ROUTE = ("gneE27", "gneE25", "gneE18", "gneE29")
CORRIDOR: dict[str, str] = {}


def corridor() -> tuple[str, str]:
    """SUMO's corridor network, and its demand with an end given to each flow (a flow without one plays for ever)."""
    from d4sumo.sumohome import sumo_home

    if not CORRIDOR:
        game = Path(sumo_home()) / "tools" / "game" / "corridor"
        demand = Path(tempfile.gettempdir()) / "d4sumo-check-corridor.rou.xml"
        demand.write_text((game / "corridor.rou.xml").read_text().replace("<flow ", '<flow end="3600" '))
        CORRIDOR.update(network=str(game / "corridor.net.xml"), demand=str(demand))
    return CORRIDOR["network"], CORRIDOR["demand"]


#: the share of episodes whose every follower runs one of d4sumo's cooperative controllers, in lane (--cooperative)
COOPERATIVE_SHARE = [0.0]
SITUATION_SHARE = [0.0]  # of campaigns that search their setpoint and speed (`search.situation`)


def random_episode(rng: np.random.Generator) -> tuple[Campaign, np.ndarray]:
    while True:  # a draw the config refuses (an obstacle the warm-up would reach) is drawn again
        try:
            return _random_episode(rng)
        except ConfigError:
            continue


def _random_episode(rng: np.random.Generator) -> tuple[Campaign, np.ndarray]:
    setpoint = float(rng.choice([rng.integers(2, 16), round(rng.uniform(2, 15), 1), rng.uniform(2, 15)]))
    followers = int(rng.integers(1, 11))
    if rng.random() < 0.2:  # the paper as its authors ran it, sometimes with a coasting car
        return _as_run_episode(rng, setpoint, followers)
    systems = [SYSTEMS[i] for i in rng.integers(0, len(SYSTEMS), followers)]
    maneuver = lane_change(rng, followers) if rng.random() < 0.25 else {}
    if COOPERATIVE_SHARE[0] and rng.random() < COOPERATIVE_SHARE[0]:  # (drawn only when asked: earlier seeds draw alike)
        mitigation = float(rng.choice([0.0, 1.0, 3.0]))  # 0: none
        systems = [ControllerConfig(str(rng.choice(["cacc", "ploeg", "consensus"])), (("fallback_mps", mitigation),))] * followers
        maneuver = {}
    network = str(rng.choice(STRAIGHT if maneuver else ROADS))
    lanes = LANES.get(network, ())
    config = EpisodeConfig(
        network=network,
        route=ROUTES.get(network, ()),
        lane=int(rng.choice(lanes)) if lanes and rng.random() < 0.3 else None,
        duration_s=DURATIONS.get(network, 60.0),
        followers=followers,
        setpoint_m=setpoint,
        speed_mps=float(rng.choice([20.0, 25.0, 30.0])),
        start=str(rng.choice(START_MODES)),
        # one system for the whole platoon, or (one time in four) a mixed platoon
        controller=systems if rng.random() < 0.25 else systems[0],
        **maneuver,
    )
    if rng.random() < 0.15 and not all(c.sumo_model for c in config.controllers):  # a radar with range, noise, latency
        config = dataclasses.replace(config, radar=RadarParams(
            range_m=float(rng.choice([np.inf, 60.0, 150.0])), gap_noise_m=float(rng.choice([0.0, 0.2, 1.0])),
            speed_noise_mps=float(rng.choice([0.0, 0.1, 0.5])), latency_s=float(rng.choice([0.0, 0.1, 0.3])),
            seed=int(rng.integers(0, 1000))))
    if rng.random() < TRAFFIC_SHARE[0]:  # SUMO's traffic around it on the 4-lane highway, joined at speed
        config = dataclasses.replace(config, network="highway_4lane", network_sha256=None, route=(), duration_s=60.0, start="steady",
                                     traffic=traffic_table(rng))
    if JUNCTION_SHARE[0] and not maneuver and rng.random() < JUNCTION_SHARE[0]:  # (drawn only when asked)
        network, demand = corridor()  # through signalised crossings among the network's own demand
        config = dataclasses.replace(config, network=network, network_sha256=None, route=CORRIDOR_ROUTE, lane=None, duration_s=50.0,
                                     start="steady", speed_mps=float(rng.choice([8.0, 11.0, 13.0])), rebuild=True,
                                     traffic={"demand": demand, "seed": int(rng.integers(0, 1000))})
    if RAMP_SHARE[0] and config.maneuver_class.lateral and rng.random() < RAMP_SHARE[0]:  # (drawn only when asked)
        config = through_a_ramp(config, rng)
    if config.v2v is not None and rng.random() < 0.5:  # cooperative followers over a late or lossy channel
        config = dataclasses.replace(config, v2v={"beacon_interval_s": float(rng.choice([0.05, 0.1, 0.2])),
                                                  "latency_s": float(rng.choice([0.0, 0.1, 0.3])),
                                                  "loss": float(rng.choice([0.0, 0.1, 0.5])), "seed": int(rng.integers(0, 1000))})
    if rng.random() < 0.25:  # a platoon of different vehicles: a truck, a bus or a small car among the cars
        cars = rng.choice(config.vehicle_ids, size=int(rng.integers(1, min(3, len(config.vehicle_ids)) + 1)), replace=False)
        config = dataclasses.replace(config, vehicles={str(car): vehicle_table(rng) for car in cars})
    family = str(rng.choice(FAMILIES))
    # with one follower the paper's psi is undefined: score the attacker's gap instead
    formula = None if config.followers >= 2 or config.maneuver != "inlane" else "always(gap_0 > 0)"
    message = {}
    if config.v2v is not None and config.maneuver == "inlane" and rng.random() < 0.5:  # the attacker lies over the air
        message = {"message": str(rng.choice(MESSAGE_ATTACKS)), "message_field": str(rng.choice(MESSAGE_FIELDS))}
        insiders = [k for k in range(1, config.followers) if config.listening(k + 1)]
        if insiders and rng.random() < 0.4:  # an insider follower lies to the car behind it
            message["message_sender"] = int(rng.choice(insiders))
    situation = ()
    if SITUATION_SHARE[0] and rng.random() < SITUATION_SHARE[0]:  # the setpoint (and the speed) searched: the sample's own
        situation = (("setpoint_m", config.setpoint_m, config.setpoint_m + float(rng.choice([0.5, 3.0, 8.0]))),)
        if config.traffic is None and rng.random() < 0.5:  # (its traffic is checked at one speed)
            situation += (("speed_mps", config.speed_mps, config.speed_mps + float(rng.choice([1.0, 5.0]))),)
        if config.start != "warmup" and config.traffic is None and rng.random() < 0.3:  # from rest or steady state
            situation += (("start", ("rest", "steady")),)
        # keys a batch holds for all its episodes: each sample plays in a batch of its own configuration
        lag = config.vehicle.actuator_lag_s
        if rng.random() < 0.3:
            situation += (("vehicle.actuator_lag_s", lag, lag + float(rng.choice([0.1, 0.4]))),)
        if config.v2v is not None and rng.random() < 0.5:
            situation += (("v2v.loss", 0.0, float(rng.choice([0.2, 0.6]))), ("v2v.latency_s", (0.0, 0.1, 0.3)))
        if config.radar is not None and rng.random() < 0.5:
            situation += (("radar.gap_noise_m", config.radar.gap_noise_m, config.radar.gap_noise_m + 0.5),)
        if isinstance(config.controller, ControllerConfig) and config.controller.cls == "switching" and rng.random() < 0.4:
            situation += (("controller.acc_kp", 0.5, 1.5),)
    campaign = Campaign(config=config, attack=family, optimizer="random", formula=formula, situation=situation, **message)
    f = campaign.family()
    return campaign, f.lower + rng.random(f.dimension) * (f.upper - f.lower)


#: the traffic's vehicle types drawn from, and their lengths [m] (SUMO's passenger car is 5 m)
TRAFFIC_TYPES = {"car": {"share": 0.8, "speedDev": 0.1}, "truck": {"share": 0.2, "vClass": "truck", "length": 12.0, "maxSpeed": 25.0},
                 "idm": {"share": 0.5, "carFollowModel": "IDM", "tau": 1.2}}
TRAFFIC_LENGTHS = {"traffic_car": 5.0, "traffic_truck": 12.0, "traffic_idm": 5.0, "DEFAULT_VEHTYPE": 5.0,
                   "highway": 5.0, "ramp": 5.0}  # and the types of SUMO's Bremen demand


def through_a_ramp(config: EpisodeConfig, rng: np.random.Generator) -> EpisodeConfig:
    """The lane-changing episode on a road of many edges: SUMO's Bremen motorway, whose on-ramp moves the
    platoon's lane to another of SUMO's indices and back (among its own demand, a flow, or alone), the
    example acceleration lane (the same shape, among a flow, or alone), or the example lane drop (a lane
    ending on the left), from steady state."""
    from d4sumo.sumohome import sumo_home

    bremen = bremen_motorway()
    network = str(rng.choice([bremen, ROADS[4], ROADS[2]]))  # and the example lane drop (a lane ends on the left)
    traffic = None
    if rng.random() < 0.5:
        traffic = (traffic_table(rng) if network != bremen or rng.random() < 0.5 else
                   {"demand": str(Path(sumo_home()) / "tools" / "game" / "highway" / "highway.rou.xml"),
                    "seed": int(rng.integers(0, 1000)), "per_sample": bool(rng.random() < 0.3)})
    return dataclasses.replace(config, network=network, network_sha256=None, route=ROUTES.get(network, ()), lane=None,
                               rebuild=network != bremen, start="steady", speed_mps=float(rng.choice([25.0, 30.0])), traffic=traffic,
                               duration_s=30.0 if network == bremen else 80.0 if network == ROADS[4] else 60.0)


def traffic_table(rng: np.random.Generator) -> dict:
    """A [traffic] table: a density, a warm-up, how much is cleared, a seed and a mix of types."""
    names = [str(n) for n in rng.choice(list(TRAFFIC_TYPES), size=int(rng.integers(1, 3)), replace=False)]
    return {"vehicles_per_hour": float(rng.choice([500.0, 800.0, 1100.0])), "warmup_s": float(rng.choice([20.0, 40.0])),
            "clear_m": float(rng.choice([10.0, 50.0])), "seed": int(rng.integers(0, 1000)),
            "types": {n: TRAFFIC_TYPES[n] for n in names}, "per_sample": bool(rng.random() < 0.3)}


def vehicle_table(rng: np.random.Generator) -> dict:
    """A car's own [vehicle] table: its length, limits, lag and class."""
    kind = str(rng.choice(["truck", "bus", "delivery", "passenger"]))
    return {"length_m": float(rng.choice([3.0, 7.5, 12.0, 16.5])) if kind != "passenger" else float(rng.uniform(3.0, 5.5)),
            "max_accel_mps2": float(rng.uniform(1.0, 4.0)), "max_decel_mps2": float(rng.uniform(3.0, 9.0)),
            "actuator_lag_s": float(rng.choice([0.0, 0.3, 0.5, 1.0])), "vclass": kind}


def _as_run_episode(rng: np.random.Generator, setpoint: float, followers: int) -> tuple[Campaign, np.ndarray]:
    """An episode of the paper-as-run preset: the authors' controllers, attack families and scenario."""
    followers = max(2, followers)
    doc = {"preset": "paper-as-run", "attack": {"family": str(rng.choice(["persistent", "intermittent", "knots"]))},
           "scenario": {"setpoint_m": setpoint, "followers": followers, "network": str(rng.choice(STRAIGHT))},
           "vehicle": {"coast_decel_mps2": float(rng.choice([0.0, 0.0, 1.0, 2.0]))}, "search": {"optimizer": "random"}}
    if rng.random() < 1 / 3:  # other systems under the preset (they keep their own options): one for all, or mixed
        systems = [SYSTEMS[i] for i in rng.integers(0, len(SYSTEMS), followers)]
        tables = [{"class": c.cls} if c.cls == "switching" else {"class": c.cls, **dict(c.params)} for c in systems]
        doc["controller"] = tables if rng.random() < 0.5 else tables[0]
    campaign = campaign_of(doc)
    f = campaign.family()
    return campaign, f.lower + rng.random(f.dimension) * (f.upper - f.lower)


def lane_change(rng: np.random.Generator, followers: int) -> dict:
    """The settings of a random cut-in, cut-out or swerving attacker."""
    if rng.random() < 1 / 3:
        return dict(maneuver="swerve", swerve_knots=int(rng.integers(1, 9)), swerve_lanes=int(rng.integers(2, 4)),
                    lane_change_s=float(rng.choice([0.0, 1.0, 2.0])))
    if rng.random() < 0.5:
        return dict(maneuver="cutin", cutin_follower=int(rng.integers(1, followers + 1)),
                    cutin_offset_m=float(rng.uniform(-10, 15)), lane_change_s=float(rng.choice([0.0, 1.0, 2.0, 3.5])))
    return dict(maneuver="cutout", obstacle_distance_m=float(rng.uniform(20, 400)),
                obstacle_speed_mps=float(rng.choice([0.0, 5.0, 12.5])), lane_change_s=float(rng.choice([0.0, 2.0])))


def read_fcd(path: Path, ids: tuple[str, ...], road, traffic: list | None = None) -> tuple[np.ndarray, np.ndarray, dict[str, list[str]]]:
    """Positions along the route and across it, samples x cars, and each car's lanes in the order it drove
    them (junction lanes left out). On a route of many edges a position is the car's first lane position
    (every car starts on the first edge) plus SUMO's odometer, not the lane position, which starts again
    at 0 on each edge. Across the road: a coordinate from the right edge of the platoon's lane (`Across`).
    ``traffic``: a list to which each sample's traffic cars on the route are appended, {id: (lane, position
    along the route, length, across)}."""
    rows: dict[float, dict[str, tuple]] = {}
    lanes: dict[str, list[str]] = {}
    others: dict[float, dict] = {}
    for step, v in parse_fast_nested(str(path), "timestep", ["time"], "vehicle",
                                     ["id", "y", "type", "pos", "lane", "odometer", "posLat"]):
        if v.id not in ids:
            others.setdefault(float(step.time), {})[v.id] = (v.lane, float(v.pos), TRAFFIC_LENGTHS[v.type], float(v.y),
                                                             float(v.posLat))
            continue
        rows.setdefault(float(step.time), {})[v.id] = (float(v.pos), float(v.y), float(v.odometer), v.lane, float(v.posLat))
        driven = lanes.setdefault(v.id, [])
        if not v.lane.startswith(":") and (not driven or driven[-1] != v.lane):
            driven.append(v.lane)
    times = sorted(rows)
    table = np.array([[rows[t][vid][:3] for vid in ids] for t in times])
    positions = table[:, :, 0] if road.one_edge else table[0, :, 0] + table[:, :, 2]
    place = Across(road, ids)
    cross = np.array([[np.nan if (a := place(vid, *rows[t][vid][3:], rows[t][vid][1], rows[t]["v1"][1])) is None else a
                       for vid in ids] for t in times])
    if traffic is not None:
        seen = {}
        for t in sorted(others):  # every traffic car in the order it drove (a junction's lane: the one it came from)
            cars = {}
            for vid, (lane, pos, length, y, lateral) in others[t].items():
                a = place(vid, lane, lateral, y, rows[t]["v1"][1] if t in rows else np.nan)
                along = place.along(lane, pos)
                if along is not None and a is not None:
                    cars[vid] = (lane, along, length, a)
            seen[t] = cars
        traffic += [seen.get(t, {}) for t in times]
    return positions, cross, lanes


class Across:
    """Where a car is across the road and along the route, from the FCD and the network file alone.

    On a road of one edge (straight): across, its y less v1's (v1 keeps the platoon's lane) plus half a
    lane; along, its lane position. On a route of many edges: across, its place from the platoon's lane on
    the edge it drives (SUMO's index less the road's lane path's there; on a junction's lane, the place of
    the lane it came from) times the lane width, plus its lateral position in its lane (posLat); along,
    where the lane's edge starts (sumolib's lengths of the route's edges and of the junction lanes of the
    platoon's lane path) plus its lane position. A car on a lane off the route is nowhere (None)."""

    def __init__(self, road, ids: tuple[str, ...]):
        self.one_edge, self.width = road.one_edge, road.lane_width_m
        self.path = dict(zip(road.route_edges, road.platoon_path))
        self.came: dict[str, int] = {}
        self.starts: dict[str, float] = {}
        if not road.one_edge:
            import sumolib

            net = sumolib.net.readNet(str(road.net_file), withInternal=True)
            along = 0.0
            for edge, to, (p, q) in zip(road.route_edges, [*road.route_edges[1:], None], zip(road.platoon_path, [*road.platoon_path[1:], 0])):
                self.starts[edge] = along
                lane = net.getLane(f"{edge}_{p}")
                along += lane.getLength()
                for _ in range(8) if to is not None else ():  # through the junction along the platoon's lane
                    via = next((c.getViaLaneID() for c in lane.getOutgoing() if c.getToLane().getID() == f"{to}_{q}"), "")
                    if not via:
                        break
                    self.starts.setdefault(via.rpartition("_")[0], along)
                    lane = net.getLane(via)
                    along += lane.getLength()

    def __call__(self, vid: str, lane: str, lateral: float, y: float, y_v1: float) -> float | None:
        if self.one_edge:
            return y - y_v1 + 0.5 * self.width
        edge, _, index = lane.rpartition("_")
        if edge in self.path:
            self.came[vid] = int(index) - self.path[edge]
        elif not lane.startswith(":"):
            self.came.pop(vid, None)
        place = self.came.get(vid)
        return None if place is None else (place + 0.5) * self.width + lateral

    def along(self, lane: str, pos: float) -> float | None:
        if self.one_edge:
            return pos
        start = self.starts.get(lane.rpartition("_")[0])
        return None if start is None else start + pos


def fcd_traffic_pairs(config: EpisodeConfig, positions: np.ndarray, lanes: list[str],
                      traffic: list[dict]) -> list[list[tuple]]:
    """Who follows whom at each FCD sample with traffic, from the FCD alone: each platoon car's nearest car
    ahead in its lane, and the nearest car behind each platoon car where it is traffic (a traffic car is
    index N + 1, as the stored pairs count it)."""
    n, lengths = len(config.vehicle_ids), [v.length_m for v in config.car_vehicles]
    out = []
    for xs, cars in zip(positions, traffic):
        sample = []
        for b in range(n):
            ahead = [(xs[a] - lengths[a] - xs[b], a) for a in range(n) if a != b and xs[a] > xs[b]]
            ahead += [(p - length - xs[b], n) for lane, p, length, _ in cars.values() if lane == lanes[b] and p > xs[b]]
            if ahead:
                gap, a = min(ahead)
                if gap < 1000.0 or a < n:
                    sample.append((a, b, gap))
            behind = [(xs[b] - lengths[b] - xs[c], c) for c in range(n) if c != b and xs[c] < xs[b]]
            behind += [(xs[b] - lengths[b] - p, n) for lane, p, _, _ in cars.values() if lane == lanes[b] and p < xs[b]]
            if behind and min(behind)[1] == n and min(behind)[0] < 1000.0:
                sample.append((b, n, min(behind)[0]))
        out.append(sample)
    return out


def fcd_lateral_traffic_pairs(config: EpisodeConfig, positions: np.ndarray, cross: np.ndarray, traffic: list[dict],
                              lane_width_m: float) -> list[list[tuple]]:
    """Who follows whom at each FCD sample with traffic and a lane-changing attacker, from the FCD alone:
    every car's lanes from its coordinate across the road (`Across`), the nearest cars in each lane, a pair
    of two traffic cars or of a traffic car over 1000 m away left out (a traffic car is index N + 1, as the
    stored pairs count it)."""
    n, lengths = len(config.vehicle_ids), [v.length_m for v in config.car_vehicles]
    out = []
    for xs, across, cars in zip(positions, cross, traffic):
        ids = sorted(cars)
        lanes = [occupied_lanes(a, lane_width_m) for a in [*across, *(cars[t][3] for t in ids)]]
        pairs = lane_pairs([*xs, *(cars[t][1] for t in ids)], lanes, [*lengths, *(cars[t][2] for t in ids)], apart=n)
        out.append([(min(a, n), min(b, n), g) for a, b, g in pairs if g < 1000.0 or max(a, b) < n])
    return out


def fcd_gaps_differ(config: EpisodeConfig, episode, pairs: list[list[tuple]]) -> bool:
    """Whether some car's gap signal (to the nearest car ahead in the lanes it covers, whoever it is) is not
    the FCD's at some sample: nearer than `SENSED_EXACTLY_M`, within the FCD's precision; farther, no less."""
    for k, sample in enumerate(pairs[:len(episode.trace)]):
        for i, vid in enumerate(config.vehicle_ids):
            want = min((g for a, b, g in sample if b == i and g < 1000.0), default=1000.0)  # the trace's free road
            got = episode.trace[f"gap_{vid}"][k]
            if (abs(want - got) > FCD_TOLERANCE_M) if want < SENSED_EXACTLY_M else (got < want - FCD_TOLERANCE_M):
                return True
    return False


def fcd_lanes_differ(config: EpisodeConfig, road, lanes: dict[str, list[str]]) -> bool:
    """Whether a car that keeps its lane (every car in-lane; the followers in a lane change) drove other
    lanes than the road's lane path (`Road.lane_path`) edge by edge."""
    path = road.platoon_path
    expected = [f"{edge}_{lane}" for edge, lane in zip(road.route_edges, path)]
    keeping = config.vehicle_ids[1:config.followers + 1] if config.maneuver_class.lateral else config.vehicle_ids
    return any(lanes[vid] != expected[:len(lanes[vid])] for vid in keeping)


def fcd_pairs(config: EpisodeConfig, positions: np.ndarray, cross: np.ndarray, lane_width_m: float) -> list[list[tuple]]:
    """Who follows whom at each FCD sample, from the FCD alone: lanes from the coordinate across the road (`Across`)."""
    maneuver = maneuver_of(config)
    out = []
    for xs, across in zip(positions, cross):
        lanes = [occupied_lanes(a, lane_width_m) for a in across] if maneuver.lateral else None
        out.append(maneuver.pairs(list(xs), lanes))
    return out


def check(campaign: Campaign, evaluator: Evaluator, params: np.ndarray, store: Store, campaign_id: int, index: int,
          fcd: Path) -> list[str]:
    """The names of the invariants this sample breaks."""
    config = campaign.config
    r = evaluator(index, params, fcd_path=fcd)
    if r.outcome == "error" and not r.error.startswith("WarmupCollision"):
        return [f"error: {r.error}"]
    store.add_sample(campaign_id, index, r.params, r.robustness, r.outcome, r.collision, r.min_gaps, r.wall_s, r.error)
    if r.outcome == "error":  # a collision in the warm-up: no attack was played, no verdict to check
        return []
    row = store.samples(campaign_id)[-1]  # what a reader of the database sees
    broken = []
    c = row.collision
    if (c is None) != (row.outcome == "no_crash"):
        broken.append("outcome/collision")
    if c is not None and ("v0" in c["pair"].split("-")) != (row.outcome == "attacker_crash"):
        broken.append("outcome/collision pair")
    with_attacker = [g for pair, g in row.min_gaps.items() if "v0" in pair.split("-")]
    others = [g for pair, g in row.min_gaps.items() if "v0" not in pair.split("-")]
    crash = config.collision_gap_m  # a pair has collided below this gap (0: an overlap)
    expected = ("attacker_crash" if min(with_attacker, default=crash) < crash else
                "success" if min(others, default=crash) < crash else "no_crash")
    if expected != row.outcome:
        broken.append("outcome/min gaps")
    # the paper's psi scores what the outcome counts when it draws the line where a collision is
    if (config.followers >= 2 or config.maneuver != "inlane") and campaign.d_safe_m == crash:
        if (row.robustness > 0) != (row.outcome == "success"):
            broken.append("outcome/robustness sign")
    # an independent look: SUMO's FCD file
    episode = evaluator.simulate(row.index, row.params)  # in the traffic that sample met
    if (config.followers >= 2 and config.maneuver == "inlane" and config.traffic is None  # the paper's psi is the default
            and abs(psi_robustness(episode.trace.window(evaluator.spec.start_step), campaign.d_safe_m) - row.robustness) > 1e-9):
        broken.append("rtamt/numpy psi")
    road = evaluator.road
    traffic: list[dict] = []
    positions, cross, lanes = read_fcd(fcd, config.vehicle_ids, road, traffic)
    if fcd_lanes_differ(config, road, lanes):
        broken.append("FCD/platoon lane")
    trace_positions = np.column_stack([episode.trace[f"pos_{vid}"] for vid in config.vehicle_ids])
    rounding = 0.6e-6 if road.one_edge else 1.1e-6  # one number rounded to 6 decimals, or two
    if positions.shape != trace_positions.shape or np.max(np.abs(positions - trace_positions)) > rounding:
        broken.append("FCD/trace positions")
        return broken
    if config.traffic is not None and not road.one_edge and not config.maneuver_class.lateral:  # across junctions: in 2D
        return broken + fcd_bodies_differ(config, fcd, episode, c, crash)
    if config.traffic is not None and config.maneuver_class.lateral:
        pairs = fcd_lateral_traffic_pairs(config, positions, cross, traffic, road.lane_width_m)
    elif config.traffic is not None:
        pairs = fcd_traffic_pairs(config, positions, [lanes[vid][0] for vid in config.vehicle_ids], traffic)
    else:
        pairs = fcd_pairs(config, positions, cross, road.lane_width_m)
    if any(g < crash - FCD_TOLERANCE_M for sample in pairs[:-1] for _, _, g in sample):
        broken.append("FCD collision before the end")
    if config.maneuver_class.lateral and fcd_gaps_differ(config, episode, pairs):
        broken.append("FCD/gaps ahead")
    if config.maneuver == "inlane":  # the minimum gaps from the attack's start, as the FCD shows them
        ids, seen = (*config.vehicle_ids, "traffic"), {}
        for sample in pairs[config.attack_start_step:]:
            for a, b, g in sample:
                seen[f"{ids[a]}-{ids[b]}"] = min(seen.get(f"{ids[a]}-{ids[b]}", g), g)
        if seen.keys() != row.min_gaps.keys() or any(abs(seen[k] - row.min_gaps[k]) > FCD_TOLERANCE_M for k in seen):
            broken.append("FCD/min gaps")
    if c is not None:
        if abs(c["time_s"] - episode.trace.times_s[-1]) > 1e-9:
            broken.append("collision time/end of episode")
        ids = (*config.vehicle_ids, "traffic")
        last: dict[str, float] = {}
        for a, b, g in pairs[-1]:  # a car covering two lanes may be in two pairs of one name: the nearer
            last[f"{ids[a]}-{ids[b]}"] = min(g, last.get(f"{ids[a]}-{ids[b]}", g))
        pair = "-".join(car if car in ids else "traffic" for car in c["pair"].split("-"))  # any traffic car as one
        # with a car off the platoon's lanes, inside a junction (`junctions`): a 2D collision
        in_2d = "traffic" in pair and not road.one_edge and fcd_collision_2d(config, fcd, episode, c, crash)
        if (last.get(pair, np.inf) > crash + FCD_TOLERANCE_M and not in_2d) or row.min_gaps[pair] >= crash:
            broken.append("collision pair/gap")
    elif len(episode.trace) != config.steps + 1:
        x = episode.trace["pos_v0"]  # only the end distance may end it early: the attacker there, not before
        if not (config.end_distance_m and x[-1] - x[0] >= config.end_distance_m > x[-2] - x[0]):
            broken.append("no collision but the episode ended early")
    return broken


def fcd_bodies(config: EpisodeConfig, fcd: Path, episode) -> tuple[dict[float, dict[str, Body]], list[float]]:
    """Every vehicle's body at each FCD sample, and the episode's samples' times."""
    ids = config.vehicle_ids
    sizes = {vid: (v.length_m, CAR_WIDTH_M) for vid, v in zip(ids, config.car_vehicles)}
    steps: dict[float, dict[str, Body]] = {}
    for step, v in parse_fast_nested(str(fcd), "timestep", ["time"], "vehicle", ["id", "x", "y", "angle", "type"]):
        length, width = sizes.get(v.id, (TRAFFIC_LENGTHS.get(v.type, 5.0), CAR_WIDTH_M))  # the demand's: SUMO's passenger car
        steps.setdefault(float(step.time), {})[v.id] = Body(float(v.x), float(v.y), float(v.angle), length, width)
    return steps, [t for t in sorted(steps) if "v0" in steps[t]][:len(episode.trace)]


def fcd_collision_2d(config: EpisodeConfig, fcd: Path, episode, collision: dict, crash: float) -> bool:
    """Whether the stored collision's pair is within c of each other in 2D in the FCD at its time."""
    steps, times = fcd_bodies(config, fcd, episode)
    a, b = collision["pair"].split("-", 1)
    return bool(times) and body_gap_m(steps[times[-1]][a], steps[times[-1]][b]) <= crash + FCD_TOLERANCE_M


def fcd_bodies_differ(config: EpisodeConfig, fcd: Path, episode, collision: dict | None, crash: float) -> list[str]:
    """In 2D, from SUMO's FCD alone: no car of the platoon within c of any other vehicle before the stored
    collision (or the episode's end), and the stored collision's pair within c at it."""
    ids = config.vehicle_ids
    steps, times = fcd_bodies(config, fcd, episode)
    broken = []
    for k, t in enumerate(times):
        cars = steps[t]
        near = min((body_gap_m(cars[vid], body), vid, other) for vid in ids for other, body in cars.items()
                   if other != vid and not (other in ids and ids.index(other) < ids.index(vid)))
        if k < len(times) - 1 and near[0] < crash - FCD_TOLERANCE_M:
            broken.append("FCD 2D collision before the end")
            break
    if collision is not None and times and any("traffic" in car for car in collision["pair"].split("-", 1)) and not (
            fcd_collision_2d(config, fcd, episode, collision, crash)):
        broken.append("collision pair/2D gap")
    return broken


def partner_config(config: EpisodeConfig, rng: np.random.Generator, road) -> EpisodeConfig:
    """Another campaign's configuration that may share the episode's SUMO (`batch.batch_key`): another
    setpoint and, where allowed, target speed and start; the episode's own where the draw is refused."""
    changes: dict = {"setpoint_m": float(rng.choice([3.0, 5.5, 7.0, 9.25, 12.0]))}
    if not config.sumo_driven:
        changes["speed_mps"] = float(rng.choice([20.0, 25.0, 30.0]))
    if config.start != "warmup":
        changes["start"] = str(rng.choice(["rest", "steady"]))
    try:
        other = dataclasses.replace(config, **changes)
        check_road(other, road)
    except ConfigError:
        return config
    return other if batch_key(other) == batch_key(config) else config


def batch_differs(campaign: Campaign, evaluator: Evaluator, params: np.ndarray, partners: int,
                  rng: np.random.Generator, road) -> str | None:
    """Play the episode beside ``partners`` random others in one SUMO, half of them of other campaigns'
    configurations (`partner_config`); what differs from it alone, if anything."""
    f = evaluator.family
    slot = int(rng.integers(0, partners + 1))  # on any copy of the road
    own = evaluator.config_for(params)  # in the situation it plays, where its campaign searches one
    configs = [partner_config(own, rng, road) if i % 2 else None for i in range(partners)]
    xs = [f.lower + rng.random(f.dimension) * (f.upper - f.lower) for _ in range(partners)]
    key = batch_key(own)
    # its campaign's, in their own situations, where a batch may carry them beside it (else in the episode's own)
    configs = [c or (lambda cx: cx if batch_key(cx) == key else own)(evaluator.config_for(x)) for c, x in zip(configs, xs)]
    plans = [attack_plan(f, x, c) for x, c in zip(xs, configs)]
    plans.insert(slot, evaluator.plan(params))
    configs.insert(slot, own)
    batched = simulate_batch(configs, plans)[slot]
    try:
        alone = simulate(own, plans[slot], road=road)
    except Exception as exc:
        return None if type(batched) is type(exc) and str(batched) == str(exc) else "batch: the error differs from alone"
    if isinstance(batched, Exception):
        return "batch: an error where alone there was none"
    if (batched.outcome, batched.collisions, batched.min_gaps_m()) != (alone.outcome, alone.collisions, alone.min_gaps_m()):
        return "batch: the verdict differs from alone"
    if batched.trace.names != alone.trace.names or not all(
            np.array_equal(batched.trace[n], alone.trace[n]) for n in alone.trace.names):
        return "batch: a signal differs from alone"
    return None


def main(argv=None) -> int:
    parser = Parser(__doc__.splitlines()[0])
    parser.add_argument("n", type=int, nargs="?", default=2000, help="episodes [2000]")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--batch", type=int, default=8,
                        help="play each episode also in a batch of K (more than engine.loop.DETACH_AT, so that the "
                             "arrays command it) [8]; 0: not")
    parser.add_argument("--traffic", type=float, default=TRAFFIC_SHARE[0],
                        help=f"the share of in-lane episodes played among SUMO's traffic [{TRAFFIC_SHARE[0]}]")
    parser.add_argument("--cooperative", type=float, default=COOPERATIVE_SHARE[0],
                        help="the share of episodes whose platoon runs cacc, ploeg or consensus throughout, in lane "
                             f"(their followers stepped in C) [{COOPERATIVE_SHARE[0]}]")
    parser.add_argument("--junctions", type=float, default=JUNCTION_SHARE[0],
                        help="the share of in-lane episodes played on SUMO's corridor among its own demand, through its "
                             f"signalised crossings (checked in 2D) [{JUNCTION_SHARE[0]}]")
    parser.add_argument("--ramps", type=float, default=RAMP_SHARE[0],
                        help="the share of lane-changing episodes played through an on-ramp that moves the platoon's "
                             f"lane index (SUMO's Bremen motorway, the example acceleration lane) or the example lane "
                             f"drop, half of them among traffic [{RAMP_SHARE[0]}]")
    parser.add_argument("--situation", type=float, default=SITUATION_SHARE[0],
                        help="the share of episodes whose campaign searches its setpoint (and, half of those without "
                             f"traffic, its speed): each sample plays its own [{SITUATION_SHARE[0]}]")
    parser.add_argument("--only", default="", help="check only these episodes of the seed's draw (comma-separated "
                                                   "indices, as --examples records them)")
    parser.add_argument("--examples", type=Path, help="write every disagreeing episode here, whole (JSON lines)")
    args = parser.parse_args(argv)
    only = {int(i) for i in args.only.split(",") if i.strip().isdigit()}
    parser.check_counts({"n": (args.n, 1), "--seed": (args.seed, 0), "--batch": (args.batch, 0, MAX_COPIES)})
    if not 0.0 <= args.traffic <= 1.0:
        parser.error(f"--traffic: got {args.traffic}; allowed: a share in [0, 1]")
    TRAFFIC_SHARE[0] = args.traffic
    if not 0.0 <= args.cooperative <= 1.0:
        parser.error(f"--cooperative: got {args.cooperative}; allowed: a share in [0, 1]")
    COOPERATIVE_SHARE[0] = args.cooperative
    if not 0.0 <= args.junctions <= 1.0:
        parser.error(f"--junctions: got {args.junctions}; allowed: a share in [0, 1]")
    JUNCTION_SHARE[0] = args.junctions
    if not 0.0 <= args.ramps <= 1.0:
        parser.error(f"--ramps: got {args.ramps}; allowed: a share in [0, 1]")
    RAMP_SHARE[0] = args.ramps
    if not 0.0 <= args.situation <= 1.0:
        parser.error(f"--situation: got {args.situation}; allowed: a share in [0, 1]")
    SITUATION_SHARE[0] = args.situation
    rng = np.random.default_rng(args.seed)
    ROADS.extend([netgenerate_grid(), sharp_turns(), bremen_motorway()])
    roads = {(name, lane): config_road(EpisodeConfig(network=name, route=ROUTES.get(name, ()), lane=lane))
             for name in ROADS for lane in (None, *LANES.get(name, ()))}
    if JUNCTION_SHARE[0]:  # the corridor rebuilt (netconvert's programmes: red lights on its main road), whole
        roads[corridor()[0], None] = config_road(EpisodeConfig(network=corridor()[0], route=CORRIDOR_ROUTE, rebuild=True, start="steady",
                                                               traffic={"demand": corridor()[1]}))
    outcomes: Counter[str] = Counter()
    broken: Counter[str] = Counter()
    ramps: Counter[str] = Counter()  # lane-changing episodes through an on-ramp (or the example lane drop)
    examples: dict[str, str] = {}
    t0 = time.perf_counter()
    with tempfile.TemporaryDirectory() as tmp:
        store = open_store(Path(tmp) / "invariants.sqlite")
        fcd = Path(tmp) / "fcd.xml"
        from d4sumo.fmus import build_switching_fmu

        SYSTEMS.append(ControllerConfig(f"fmu:{build_switching_fmu(Path(tmp) / 'switching.fmu', 2)}"))  # the shipped FMU
        for index in range(args.n):
            while True:  # a draw its road refuses (a platoon longer than the sharp turns' first edge) is drawn again
                campaign, params = random_episode(rng)
                road = roads[campaign.config.network, campaign.config.lane]
                try:
                    evaluator = Evaluator(campaign, road=road)
                    if campaign.config.traffic is not None:  # a density SUMO cannot insert is refused by its warm-up
                        traffic_state(campaign.config, road)
                    break
                except ConfigError:
                    continue
            if only and index not in only:  # (its batch partners are drawn from a generator of its own index)
                continue
            if campaign.config.maneuver_class.lateral and (road.lane_shifts or road.name == ROADS[2]):
                ramps["among traffic" if campaign.config.traffic is not None else "alone"] += 1
            cid = store.open_campaign(campaign.definition(), 1)
            problems = check(campaign, evaluator, params, store, cid, len(store.samples(cid)), fcd)
            outcome = store.samples(cid)[-1].outcome if not problems or not problems[0].startswith("error") else "error"
            outcomes["warm-up collision" if outcome == "error" and not problems else outcome] += 1
            if args.batch > 1:  # its partners drawn apart, so that the episodes are those of a run without
                differs = batch_differs(campaign, evaluator, params, args.batch - 1,
                                        np.random.default_rng([args.seed, index]), road)
                problems = [*problems, differs] if differs else problems
            for p in problems:
                broken[p] += 1
                examples.setdefault(p, f"{campaign.definition()} params {list(params)}")
                if args.examples:
                    with open(args.examples, "a") as f:
                        f.write(json.dumps({"index": index, "problem": p, "definition": campaign.definition(),
                                            "params": [float(x) for x in params]}) + "\n")
            if (index + 1) % 100 == 0:
                print(f"{index + 1} episodes, {sum(broken.values())} disagreements, {time.perf_counter() - t0:.0f} s",
                      file=sys.stderr)
        store.close()
    print(f"episodes: {args.n} (seed {args.seed}); outcomes: " + ", ".join(f"{k} {v}" for k, v in sorted(outcomes.items())))
    if ramps:
        print("lane changes through an on-ramp or a lane drop: " + ", ".join(f"{k} {v}" for k, v in sorted(ramps.items())))
    print(f"disagreements: {sum(broken.values())}")
    for name, count in sorted(broken.items()):
        print(f"  {name}: {count}  e.g. {examples[name][:400]}")
    return 1 if broken else 0


if __name__ == "__main__":
    run_main(main)
