"""Traffic around the platoon (issue 37), for real in SUMO: SUMO's traffic warms up, the platoon's places
are cleared, every follower senses whatever is ahead in its lane (a traffic car included) and the gaps,
collisions and verdicts agree with SUMO's FCD."""

from __future__ import annotations

import dataclasses
from pathlib import Path

import numpy as np
import pytest
from sumolib.xml import parse_fast_nested

from d4sumo.engine.scenarios import build_road, config_road
from d4sumo.search.evaluator import Evaluator
from d4sumo.engine.simulation import simulate, simulate_batch
from d4sumo.engine.sumo import open_world
from d4sumo.errors import ConfigError
from d4sumo.model.config import EpisodeConfig
from d4sumo.model.world.traffic import is_traffic

pytestmark = pytest.mark.sumo

#: the 3-lane motorway, 1500 vehicles per hour in each lane, the platoon joining it at 30 m/s
BUSY = EpisodeConfig(network="highway_3lane_120kmh", start="steady", speed_mps=30.0, duration_s=30.0,
                     traffic={"vehicles_per_hour": 1500, "warmup_s": 40.0})


#: among traffic, with an attacker that changes lanes, the gap to the nearest car ahead in each lane a car covers
#: is exact up to this far: SUMO's search for a car's leader, across a junction, missed one farther (170 m on
#: SUMO's Bremen motorway); a traffic car edging into a lane is sensed there (traffic.edging_sensed)
SENSED_EXACTLY_M = 150.0


def _fcd(path):
    """{time: {vehicle: (lane, front position, length)}} from SUMO's FCD of a road of one edge."""
    steps: dict[float, dict] = {}
    for step, v in parse_fast_nested(str(path), "timestep", ["time"], "vehicle", ["id", "pos", "lane"]):
        steps.setdefault(float(step.time), {})[v.id] = (v.lane, float(v.pos))
    return steps


def test_every_gap_the_followers_sense_is_the_one_sumo_fcd_shows_to_whatever_car_is_ahead(tmp_path):
    u = np.full(BUSY.steps, np.nan)
    u[40:120] = -0.6  # the attacker brakes; the traffic ahead drives on
    episode = simulate(BUSY, u, fcd_path=tmp_path / "fcd.xml")
    steps = _fcd(tmp_path / "fcd.xml")
    times = sorted(steps)
    t0 = next(t for t in times if "v0" in steps[t])  # the platoon joins after the traffic's warm-up
    assert t0 == pytest.approx(BUSY.traffic.warmup_s)
    lengths = {vid: 5.0 for t in times for vid in steps[t]}  # SUMO's passenger car
    lengths.update({vid: v.length_m for vid, v in zip(BUSY.vehicle_ids, BUSY.car_vehicles)})
    compared = 0
    for k, t in enumerate(times[times.index(t0):][:len(episode.trace)]):
        cars = steps[t]
        for vid in ("v0", "v1", "v2", "v3"):
            lane, pos = cars[vid]
            ahead = [p - lengths[o] - pos for o, (ln, p) in cars.items() if ln == lane and p > pos and o != vid]
            fcd_gap = min(ahead) if ahead else 1000.0
            sensed = episode.trace[f"gap_{vid}"][k]
            assert min(fcd_gap, 1000.0) == pytest.approx(sensed, abs=2.5e-6), (t, vid)
            compared += 1
    assert compared == 4 * len(episode.trace)
    traffic_ahead = [k for k in episode.min_gaps if k.startswith("traffic-")]
    assert traffic_ahead == ["traffic-v0"]  # a traffic car led the attacker, none came between the cars


def test_the_platoon_joins_traffic_in_its_own_places_and_every_episode_meets_the_same_traffic():
    u = np.full(BUSY.steps, np.nan)
    first, again = simulate(BUSY, u), simulate(BUSY, u)
    assert first.trace.signals.keys() == again.trace.signals.keys()
    assert all(np.array_equal(first.trace[k], again.trace[k]) for k in first.trace.names)
    assert first.trace["gap_v0"][0] >= BUSY.traffic.clear_m  # cleared ahead of the attacker
    other = dataclasses.replace(BUSY, traffic={"vehicles_per_hour": 1500, "warmup_s": 40.0, "seed": 7})
    assert not np.array_equal(simulate(other, u).trace["gap_v0"], first.trace["gap_v0"])  # another seed, other traffic
    # a batch plays its episodes one at a time with traffic, each as alone
    batch = simulate_batch(BUSY, [u, u])
    assert all(np.array_equal(b.trace[k], first.trace[k]) for b in batch for k in first.trace.names)


def test_a_traffic_car_that_comes_between_two_followers_is_the_one_the_rear_follower_senses():
    config = dataclasses.replace(BUSY, setpoint_m=40.0)
    road = build_road(config.network)
    with open_world(config, road, [config]) as world:
        api, ids = world.api, world.platoons[0]
        x = [world.get_position(v) for v in ids]
        # a car of traffic lands 15 m behind v1's rear bumper (as a lane change would put it)
        api.vehicle.add("traffic.in", "platoon", depart="now", departLane="0", departPos=repr(x[1] - 4.5 - 15.0),
                        departSpeed="30")
        world.step()
        x, v = [world.get_position(vid) for vid in ids], [world.get_speed(vid) for vid in ids]
        pairs, names, xs, vs = world.sense(0, x, v)
        t = names.index("traffic.in")
        front = api.vehicle.getLanePosition("traffic.in")
        assert (t, 2, pytest.approx(front - 5.0 - x[2], abs=1e-9)) in pairs  # v2 senses it, 5 m long
        assert (1, t, pytest.approx(x[1] - 4.5 - front, abs=1e-9)) in pairs  # and it follows v1
        assert (1, 2) not in [(a, b) for a, b, _ in pairs]
        assert xs[t] == pytest.approx(front, abs=1e-9) and vs[t] == api.vehicle.getSpeed("traffic.in")


def test_an_attacker_that_runs_into_traffic_ahead_is_an_attacker_crash_with_the_traffic_car_named():
    episode = simulate(BUSY, np.ones(BUSY.steps))  # full throttle into the traffic ahead
    first = episode.first_collision
    assert is_traffic(first.leader) and first.follower == "v0"
    assert episode.outcome == "attacker_crash"
    assert episode.min_gaps["traffic-v0"] < 0 and episode.trace["attacker_gap"][-1] < 0


def test_a_density_sumo_cannot_insert_and_a_vehicle_type_it_refuses_get_one_line():
    jammed = dataclasses.replace(BUSY, traffic={"vehicles_per_hour": 3600, "warmup_s": 40.0})
    with pytest.raises(ConfigError) as info:
        simulate(jammed, np.full(jammed.steps, np.nan))
    assert info.value.field == "traffic.vehicles_per_hour" and "waited to enter" in info.value.allowed
    refused = dataclasses.replace(BUSY, traffic={"types": {"car": {"carFollowModel": "Nope"}}})
    with pytest.raises(ConfigError) as info:
        simulate(refused, np.full(refused.steps, np.nan))
    assert info.value.field.startswith("traffic")


def test_sumo_own_bremen_motorway_plays_with_its_own_demand_the_ramp_traffic_merging_into_the_platoon_lane(tmp_path):
    from d4sumo.sumohome import sumo_home

    game = Path(sumo_home()) / "tools" / "game" / "highway"
    config = EpisodeConfig(network=str(game / "highway.net.xml"), route=("145354574", "189597495", "E0", "191842213"),
                           start="steady", speed_mps=30.0, duration_s=20.0, traffic={"demand": str(game / "highway.rou.xml")})
    assert config.whole_network
    road = config_road(config)
    assert road.lane_path == (0, 0, 1, 0) and road.through_lanes == (0, 1, 2)
    u = np.full(config.steps, np.nan)
    u[:100] = -0.5
    episode = simulate(config, u, road=road, fcd_path=tmp_path / "fcd.xml")
    assert np.array_equal(episode.trace["gap_v0"], simulate(config, u, road=road).trace["gap_v0"])
    seen = {v.id for _, v in parse_fast_nested(str(tmp_path / "fcd.xml"), "timestep", ["time"], "vehicle", ["id"])}
    assert any(v.startswith("traffic.ramp.") for v in seen) and any(v.startswith("traffic.highway.") for v in seen)
    assert "traffic-v0" in episode.min_gaps


def test_a_demand_over_edges_the_network_lacks_is_refused_naming_the_file(tmp_path):
    demand = tmp_path / "elsewhere.rou.xml"
    demand.write_text('<routes><route id="r" edges="nowhere"/><flow id="f" route="r" begin="0" end="10" vehsPerHour="100"/></routes>')
    config = dataclasses.replace(BUSY, traffic={"demand": str(demand)})
    with pytest.raises(ConfigError) as info:
        simulate(config, np.full(config.steps, np.nan))
    assert info.value.field == "traffic.demand" and "nowhere" in info.value.allowed


def test_each_sample_meets_traffic_of_its_own_where_asked_and_a_replay_meets_it_again(tmp_path):
    from d4sumo.search.campaign import Campaign
    from d4sumo.search.runner import Evaluator

    config = dataclasses.replace(BUSY, traffic={"vehicles_per_hour": 1500, "warmup_s": 40.0, "per_sample": True})
    evaluator = Evaluator(Campaign(config=config, attack="knots", optimizer="random"))
    x = np.zeros(evaluator.family.dimension)
    first, second = evaluator.simulate(0, x), evaluator.simulate(1, x)
    assert not np.array_equal(first.trace["gap_v0"], second.trace["gap_v0"])  # other traffic ahead
    assert np.array_equal(evaluator.simulate(1, x).trace["gap_v0"], second.trace["gap_v0"])
    r = evaluator(1, x)
    assert r.min_gaps == second.min_gaps_m()


def test_no_traffic_car_is_in_the_platoon_places_when_it_joins_not_even_one_entering_with_it():
    """A traffic car entering the road in the platoon's insertion step does not see it: the platoon then joins a
    step later (the trucks of this draw entered on top of the rear follower before it did)."""
    later = []
    for seed in range(12):
        config = dataclasses.replace(BUSY, followers=6, setpoint_m=11.2, traffic={
            "vehicles_per_hour": 1400, "warmup_s": 20.0, "clear_m": 10.0, "seed": seed,
            "types": {"truck": {"vClass": "truck", "length": 12.0, "maxSpeed": 25.0}}})
        road = build_road(config.network)
        with open_world(config, road, [config]) as world:
            ids = world.platoons[0]
            x, v = [world.get_position(vid) for vid in ids], [world.get_speed(vid) for vid in ids]
            pairs, names, _, _ = world.sense(0, x, v)
            assert all(gap >= 10.0 for a, b, gap in pairs if max(a, b) >= len(ids)), seed
            later.append(world.api.simulation.getTime() > 20.0 + config.step_s + 1e-9)  # joined after its first step
    assert any(later)  # some draws joined a step later


def test_a_swerving_attacker_among_traffic_senses_and_is_sensed_in_every_lane_it_covers_as_sumo_fcd_shows(tmp_path):
    """Who follows whom from SUMO's FCD alone (each car's lanes from its lateral coordinate, the nearest
    cars in each lane, traffic included) is what the followers and the attacker sensed, every sample."""
    from d4sumo.model.attacks.pedals import make_attack
    from d4sumo.model.config import ControllerConfig
    from d4sumo.model.attacks.maneuvers import attack_plan, maneuver_of
    from d4sumo.model.world.lanes import lane_pairs, occupied_lanes

    config = EpisodeConfig(network="highway_3lane_120kmh", maneuver="swerve", start="steady", speed_mps=28.0,
                           controller=ControllerConfig("timegap"), duration_s=40.0, traffic={"vehicles_per_hour": 1200})
    family = maneuver_of(config).family(make_attack("knots"))
    x = family.lower + np.random.default_rng(0).random(family.dimension) * (family.upper - family.lower)
    episode = simulate(config, attack_plan(family, x, config), fcd_path=tmp_path / "fcd.xml")
    assert any(k.startswith("traffic-v") and k != "traffic-v0" for k in episode.min_gaps)  # traffic ahead of a follower
    steps: dict[float, dict] = {}
    for step, v in parse_fast_nested(str(tmp_path / "fcd.xml"), "timestep", ["time"], "vehicle", ["id", "y", "pos"]):
        steps.setdefault(float(step.time), {})[v.id] = (float(v.pos), float(v.y))
    n, width = len(config.vehicle_ids), 3.2
    lengths = {vid: v.length_m for vid, v in zip(config.vehicle_ids, config.car_vehicles)}
    for k, t in enumerate(sorted(steps)[:len(episode.trace)]):
        cars = steps[t]
        order = [*config.vehicle_ids, *sorted(c for c in cars if c not in lengths)]
        lanes = [occupied_lanes(cars[c][1] - cars["v1"][1] + 0.5 * width, width) for c in order]
        pairs = lane_pairs([cars[c][0] for c in order], lanes, [lengths.get(c, 5.0) for c in order], apart=n)
        for i, vid in enumerate(config.vehicle_ids):
            ahead = [g for a, b, g in pairs if b == i and (a < n or g < 1000.0)]
            want, got = min(ahead, default=1000.0), episode.trace[f"gap_{vid}"][k]
            if want < SENSED_EXACTLY_M:
                assert want == pytest.approx(got, abs=2.5e-6), (t, vid)
            else:  # farther, a traffic car just edging into the lane from beside it may be sensed only once in it
                assert got >= want - 2.5e-6, (t, vid)


def test_a_collision_of_two_traffic_cars_is_kept_apart_from_the_platoon_verdict():
    config = BUSY
    road = build_road(config.network)
    with open_world(config, road, [config]) as world:
        api, ids = world.api, world.platoons[0]
        x, v = [world.get_position(vid) for vid in ids], [world.get_speed(vid) for vid in ids]
        world.sense(0, x, v)  # t = 0
        ahead = [t for t in api.lane.getLastStepVehicleIDs("highway_2") if api.vehicle.getLanePosition(t) > 300.0][0]
        at = api.vehicle.getLanePosition(ahead)
        api.vehicle.add("traffic.ram", "platoon", depart="now", departLane="2", departPos=repr(at - 3.0), departSpeed="40")
        for _ in range(3):
            world.step()
            x, v = [world.get_position(vid) for vid in ids], [world.get_speed(vid) for vid in ids]
            world.sense(0, x, v)
        kept = world.traffic_collisions(0)
        assert [(a, b) for _, a, b in kept] == [("traffic.ram", ahead)]  # once, though the overlap lasts
        assert kept[0][0] == pytest.approx(config.step_s)  # the step it entered, on top of the other


def test_traffic_entering_with_the_platoon_on_the_road_keeps_sumos_insertion_checks():
    """Regression: SUMO's saved state of the warm-up dropped the flows' insertion checks, and the episode
    inserts with none: from the platoon's joining on, each car entered onto the one before it (25 collisions
    among the traffic in 40 s at 1,500 veh/h/lane, cars stacked at the road's start at 0 m/s). A campaign
    stored before (its [traffic] table without the key) replays as it ran."""
    config = dataclasses.replace(BUSY, duration_s=40.0, traffic=dataclasses.replace(BUSY.traffic, vehicles_per_hour=1500.0))
    assert simulate(config, np.full(config.steps, np.nan)).traffic_collisions == ()
    as_before = dataclasses.replace(config, traffic=dataclasses.replace(config.traffic, insertion_checks=False))
    assert len(simulate(as_before, np.full(config.steps, np.nan)).traffic_collisions) >= 5


def test_the_traffic_after_its_warm_up_is_the_same_whatever_the_process_that_warmed_it_up_ran_before(tmp_path, monkeypatch):
    """Regression: SUMO's saved state of the warm-up holds how many random numbers its demand's stream drew in
    the process, other simulations' included: a warm-up saved after other episodes (here, this test process's)
    met other traffic than one saved by a fresh process (the gap to the traffic ahead 38.9 m, not 55.4 m)."""
    import json
    import os
    import subprocess
    import sys

    from d4sumo.engine import command, warmup

    for module in (command, warmup):  # warmed up anew
        monkeypatch.setattr(module, "default_cache_dir", lambda: tmp_path / "here" / "d4sumo" / "nets")
    u = np.full(BUSY.steps, -0.2)
    here = simulate(BUSY, u).min_gaps
    code = ("import json, numpy as np; from d4sumo.engine.simulation import simulate; from test_traffic import BUSY; "
            "print(json.dumps(simulate(BUSY, np.full(BUSY.steps, -0.2)).min_gaps))")
    fresh = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=300, cwd=Path(__file__).parent,
                           env={**os.environ, "XDG_CACHE_HOME": str(tmp_path / "fresh")})
    assert fresh.returncode == 0, fresh.stderr
    assert json.loads(fresh.stdout) == here


def test_a_traffic_type_an_earlier_check_passed_is_checked_again(tmp_path, monkeypatch):
    """Regression: a demand 0.16's check passed was kept in the cache under its text's name, so a misspelt
    type attribute it had let through was taken without a word where it had run before, refused elsewhere."""
    from d4sumo.engine import command as sumo  # the demand's check is SUMO's command line's

    monkeypatch.setattr(sumo, "default_cache_dir", lambda: tmp_path / "d4sumo" / "nets")
    monkeypatch.setattr(sumo, "_CHECKED", {})
    config = dataclasses.replace(BUSY, traffic={"types": {"truck": {"share": 1.0, "speedfactor": 0.5}}})
    road = build_road(config.network)
    with monkeypatch.context() as earlier:  # as 0.16 checked it: the types not against SUMO's schema
        earlier.setattr(sumo, "DEMAND_CHECK", 1)
        earlier.setattr(sumo, "_check_demand", lambda *args: None)
        assert all(f.is_file() for f in sumo.traffic_files(config, road))
    sumo._CHECKED.clear()
    with pytest.raises(ConfigError) as info:
        sumo.traffic_files(config, road)
    assert info.value.field == "traffic.types.truck.speedfactor"


def test_on_bremen_the_traffic_ahead_of_the_attacker_is_where_sumo_fcd_puts_it_edge_after_edge(tmp_path):
    """A traffic car's gap is SUMO's, along lanes and junctions: on SUMO's Bremen motorway, with its own
    demand, the attacker's gap to the traffic car ahead agrees with the FCD's positions wherever both drive
    one edge of the route (each edge's start along the route read from the attacker's own odometer)."""
    from d4sumo.sumohome import sumo_home

    game = Path(sumo_home()) / "tools" / "game" / "highway"
    config = EpisodeConfig(network=str(game / "highway.net.xml"), route=("145354574", "189597495", "E0", "191842213"),
                           start="steady", speed_mps=30.0, duration_s=40.0, traffic={"demand": str(game / "highway.rou.xml")})
    # no attack: the attacker drives behind the traffic ahead (the paper's followers, 7 m apart at 30 m/s,
    # crash on their own when it brakes for a car from the ramp)
    episode = simulate(config, np.full(config.steps, np.nan), fcd_path=tmp_path / "fcd.xml")
    steps: dict[float, dict] = {}
    for step, v in parse_fast_nested(str(tmp_path / "fcd.xml"), "timestep", ["time"], "vehicle", ["id", "pos", "lane", "odometer"]):
        steps.setdefault(float(step.time), {})[v.id] = (v.lane, float(v.pos), float(v.odometer))
    times = [t for t in sorted(steps) if "v0" in steps[t]]  # from the platoon's joining (here after the warm-up's end)
    start = steps[times[0]]["v0"]
    offsets = {}  # each edge's start along the route, as the attacker drove it
    for t in times:
        lane, pos, odometer = steps[t]["v0"]
        offsets.setdefault(lane.rpartition("_")[0], start[1] + odometer - pos)
    compared, edges = 0, set()
    for k, t in enumerate(times[:len(episode.trace)]):
        cars = steps[t]
        lane0, pos0, _ = cars["v0"]
        edge0 = lane0.rpartition("_")[0]
        ahead = [(offsets[edge0] + p - 5.0 - (offsets[edge0] + pos0), vid) for vid, (lane, p, _) in cars.items()
                 if lane == lane0 and p > pos0 and vid != "v0"]
        gap = episode.trace["gap_v0"][k]
        if ahead and min(ahead)[0] < 1000.0 and gap < 1000.0:
            assert min(ahead)[0] == pytest.approx(gap, abs=2.5e-6), t
            compared += 1
            edges.add(edge0)
    assert compared > 300 and len(edges) >= 3  # before, on and past the ramp's edge


def _edge_starts(road) -> dict[str, float]:
    """Where each edge of the route, and each junction's edge of lanes between two of them, starts along the
    route [m], from the network file (sumolib): the platoon's lanes' lengths, edge by edge."""
    import sumolib

    net = sumolib.net.readNet(str(road.net_file), withInternal=True)
    starts, along = {}, 0.0
    path = road.platoon_path
    for k, edge in enumerate(road.route_edges):
        starts[edge] = along
        lane = net.getLane(f"{edge}_{path[k]}")
        along += lane.getLength()
        for _ in range(8) if k + 1 < len(path) else ():  # through the junction along the platoon's lane
            via = next((c.getViaLaneID() for c in lane.getOutgoing()
                        if c.getToLane().getID() == f"{road.route_edges[k + 1]}_{path[k + 1]}"), "")
            if not via:
                break
            starts.setdefault(via.rpartition("_")[0], along)
            lane = net.getLane(via)
            along += lane.getLength()
    return starts


def _fcd_gaps_ahead(config: EpisodeConfig, episode, fcd: Path,
                    type_lengths: dict[str, float] | None = None) -> tuple[np.ndarray, set[tuple[str, int]]]:
    """Each car's gap to the nearest car ahead in the lanes it covers (1000 m: none), at every sample, from
    SUMO's FCD and the network file alone: the platoon's cars along the route by their odometers, a traffic car
    by its lane position from where its edge starts (`_edge_starts`); across it from its lane, counted from the
    platoon's on that edge (a junction's lane: the one it came from), and its lateral position in it. Also the
    (edge, lane) pairs the attacker covered. ``type_lengths``: the traffic's lengths by vehicle type (else 5 m,
    SUMO's passenger car)."""
    from d4sumo.model.world.lanes import lane_pairs, occupied_lanes

    steps: dict[float, dict] = {}
    kinds: dict[str, str] = {}
    for step, v in parse_fast_nested(str(fcd), "timestep", ["time"], "vehicle", ["id", "type", "pos", "lane", "odometer", "posLat"]):
        steps.setdefault(float(step.time), {})[v.id] = (v.lane, float(v.pos), float(v.odometer), float(v.posLat))
        kinds[v.id] = v.type
    times = [t for t in sorted(steps) if "v0" in steps[t]][:len(episode.trace)]
    ids, n, width = config.vehicle_ids, len(config.vehicle_ids), 3.2
    lengths = {vid: v.length_m for vid, v in zip(ids, config.car_vehicles)}
    first = {vid: steps[times[0]][vid][1] for vid in ids}
    road = config_road(config)
    starts = _edge_starts(road)  # each lane's edge (a junction's too): where it starts along the route
    platoon_lane = dict(zip(road.route_edges, road.platoon_path))  # the platoon's lane on each edge
    for t in times:  # and v1's lane there, as SUMO drove it
        lane, _, index = steps[t]["v1"][0].rpartition("_")
        assert platoon_lane.get(lane, int(index)) == int(index) or lane.startswith(":")
    came: dict[str, int] = {}
    gaps, attacker = np.full((len(times), n), 1000.0), set()
    for k, t in enumerate(times):
        order, along, y = [], [], []
        for c, (lane, pos, odometer, lateral) in sorted(steps[t].items(), key=lambda item: (0, ids.index(item[0])) if item[0] in lengths else (1, 0)):
            edge, _, index = lane.rpartition("_")
            if edge in platoon_lane and not edge.startswith(":"):
                came[c] = int(index) - platoon_lane[edge]
            elif not edge.startswith(":"):
                came.pop(c, None)
            if c in came and edge in starts:
                order.append(c)
                along.append(first[c] + odometer if c in lengths else starts[edge] + pos)
                y.append((came[c] + 0.5) * width + lateral)
        assert order[:n] == list(ids)
        assert y[0] == pytest.approx(episode.trace["y_v0"][k], abs=1e-6), t
        lanes = [occupied_lanes(yi, width) for yi in y]
        attacker.update((steps[t]["v0"][0].rpartition("_")[0], lane) for lane in lanes[0])
        sizes = [lengths[c] if c in lengths else (type_lengths or {}).get(kinds[c], 5.0) for c in order]
        for a, b, g in lane_pairs(along, lanes, sizes, apart=n):
            if b < n:
                gaps[k, b] = min(gaps[k, b], g)
    return gaps, attacker


def assert_sensed_as_the_fcd_shows(gaps: np.ndarray, sensed: np.ndarray) -> None:
    """Every gap sensed is the FCD's within `SENSED_EXACTLY_M`, to its precision; farther, no less (SUMO's
    search for a car's leader across a junction may miss one that far), where the FCD places a car at all (it
    places none on an edge no car of the platoon reached)."""
    near, far = gaps < SENSED_EXACTLY_M, (gaps >= SENSED_EXACTLY_M) & (gaps < 1000.0)
    assert np.max(np.abs(gaps - sensed)[near]) < 2.5e-6
    assert np.all(sensed[far] >= gaps[far] - 2.5e-6)


def test_on_bremen_a_swerving_attacker_among_its_own_demand_senses_and_is_sensed_in_every_lane_as_sumo_fcd_shows(tmp_path):
    """Issue 52: a lane-changing attacker among traffic was refused on any road of several edges. On SUMO's
    Bremen motorway, with its own demand, through the on-ramp that moves the platoon's lane from SUMO's
    index 0 to 1 and back: every car's gap to the nearest car ahead in the lanes it covers, from SUMO's FCD
    alone, is what it sensed, every sample; the attacker's lanes are the plan's."""
    from d4sumo.model.attacks.pedals import make_attack
    from d4sumo.model.config import ControllerConfig
    from d4sumo.model.attacks.maneuvers import attack_plan, maneuver_of
    from d4sumo.sumohome import sumo_home

    game = Path(sumo_home()) / "tools" / "game" / "highway"
    config = EpisodeConfig(network=str(game / "highway.net.xml"), route=("145354574", "189597495", "E0", "191842213"),
                           maneuver="swerve", swerve_lanes=3, start="steady", speed_mps=30.0, duration_s=38.0,
                           controller=ControllerConfig("timegap"), traffic={"demand": str(game / "highway.rou.xml")})
    family = maneuver_of(config).family(make_attack("knots"))
    x = family.lower + np.random.default_rng(4).random(family.dimension) * (family.upper - family.lower)
    plan = attack_plan(family, x, config)
    episode = simulate(config, plan, fcd_path=tmp_path / "fcd.xml")
    gaps, attacker = _fcd_gaps_ahead(config, episode, tmp_path / "fcd.xml")
    assert_sensed_as_the_fcd_shows(gaps, np.column_stack([episode.trace[f"gap_{vid}"] for vid in config.vehicle_ids]))
    assert ("E0", 1) in attacker or ("E0", 2) in attacker  # beside the platoon where the ramp joins
    assert len(plan.lane_changes) >= 2
    assert min(episode.min_gaps_m().get(f"traffic-{vid}", np.inf) for vid in config.vehicle_ids[1:]) < SENSED_EXACTLY_M


@pytest.mark.parametrize("edging_sensed", [True, False])
def test_a_traffic_car_edging_into_the_lane_past_sumos_nearest_is_sensed_there(tmp_path, edging_sensed):
    """Regression: SUMO names only the nearest car of each lane beside a car. A traffic car farther on in
    the lane beside, already edging into the platoon's lane, was sensed only once SUMO had it there: the
    benign lead's gap read 1000 m (the free road) where the FCD showed that car 93.6 m ahead of it. With
    traffic.edging_sensed (the default) every gap is the FCD's; false plays it as 0.21 did (its stored
    campaigns replay so)."""
    from d4sumo.model.attacks.pedals import make_attack
    from d4sumo.model.attacks.maneuvers import attack_plan, maneuver_of
    from d4sumo.model.world.vehicle import VehicleParams
    from d4sumo.sumohome import sumo_home

    game = Path(sumo_home()) / "tools" / "game" / "highway"
    config = EpisodeConfig(network=str(game / "highway.net.xml"), route=("145354574", "189597495", "E0", "191842213"),
                           followers=7, setpoint_m=8.7, start="steady", speed_mps=30.0, duration_s=30.0, maneuver="cutin",
                           cutin_follower=3, cutin_offset_m=-1.718926990753264, vehicle=VehicleParams(actuator_lag_s=0.5),
                           traffic={"vehicles_per_hour": 1100.0, "warmup_s": 40.0, "clear_m": 10.0, "seed": 209,
                                    "types": {"car": {"share": 0.8, "speedDev": 0.1},
                                              "idm": {"carFollowModel": "IDM", "share": 0.5, "tau": 1.2}},
                                    "edging_sensed": edging_sensed})
    params = [-0.11934101804723207, 0.46089884373321666, 0.9841947062201131, 0.15263077137869785, 0.47104790144247644,
              -0.3534936991124522, 0.5677914955952064, -0.6990707229297737, 24.67744572787224]
    plan = attack_plan(maneuver_of(config).family(make_attack("knots-coded")), params, config)
    episode = simulate(config, plan, fcd_path=tmp_path / "fcd.xml")
    gaps, _ = _fcd_gaps_ahead(config, episode, tmp_path / "fcd.xml")
    lead = config.vehicle_ids.index("lead")
    k = int(round(8.05 / config.step_s))
    assert gaps[k, lead] == pytest.approx(93.5638, abs=1e-3)
    assert episode.trace["gap_lead"][k] == (pytest.approx(gaps[k, lead], abs=2.5e-6) if edging_sensed else 1000.0)
    if edging_sensed:
        assert_sensed_as_the_fcd_shows(gaps, np.column_stack([episode.trace[f"gap_{vid}"] for vid in config.vehicle_ids]))


@pytest.mark.parametrize("edging_sensed", [True, False])
def test_the_nearest_car_of_the_lane_beside_past_the_cars_edge_is_sensed(tmp_path, edging_sensed):
    """Regression: SUMO names no car of a lane beside past the car's own edge. The swerving attacker, changing
    lanes toward Bremen's on-ramp, covered the lane to its right where a truck drove 85.2 m ahead on the next
    edge; it sensed the car 382.8 m ahead in its own lane instead. With traffic.edging_sensed, the truck."""
    from d4sumo.inputs import campaign_of
    from d4sumo.sumohome import sumo_home

    game = Path(sumo_home()) / "tools" / "game" / "highway"
    campaign = campaign_of({
        "scenario": {"network": str(game / "highway.net.xml"), "route": ["145354574", "189597495", "E0", "191842213"],
                     "followers": 6, "setpoint_m": 14.7, "speed_mps": 25.0, "start": "steady", "duration_s": 30.0,
                     "maneuver": "swerve", "swerve_knots": 7, "swerve_lanes": 2},
        "vehicle": {"actuator_lag_s": 0.5,
                    "v1": {"length_m": 16.5, "max_accel_mps2": 1.9845750014311185, "max_decel_mps2": 8.407622788714432,
                           "actuator_lag_s": 0.0, "vclass": "bus"},
                    "v3": {"length_m": 3.0, "max_accel_mps2": 2.4537168523571804, "max_decel_mps2": 3.695480887363365,
                           "actuator_lag_s": 0.0, "vclass": "truck"},
                    "v5": {"length_m": 7.5, "max_accel_mps2": 1.1365259780615475, "max_decel_mps2": 6.934135372439975,
                           "actuator_lag_s": 0.0, "vclass": "delivery"}},
        "controller": {"class": "ploeg"},
        "traffic": {"vehicles_per_hour": 1100.0, "warmup_s": 40.0, "clear_m": 10.0, "seed": 45, "edging_sensed": edging_sensed,
                    "types": {"car": {"share": 0.8, "speedDev": 0.1},
                              "truck": {"length": 12.0, "maxSpeed": 25.0, "share": 0.2, "vClass": "truck"}}},
        "attack": {"family": "persistent-coded"}})
    params = [0.9017792661135129, 4.8044056054660125, 9.281312522936645, 0.0594190842796436, 1.3163055893517215,
              0.21842527860747385, 1.5266789427732017, 0.22872079997379124, 0.27124487697443334, 0.818936641507714]
    config = campaign.config
    episode = Evaluator(campaign).simulate(0, np.array(params), fcd_path=tmp_path / "fcd.xml")
    gaps, _ = _fcd_gaps_ahead(config, episode, tmp_path / "fcd.xml", {"traffic_truck": 12.0})
    k = 277  # the attacker half across the line to its right, 3.3 s before the ramp's edge
    assert gaps[k, 0] == pytest.approx(85.2262, abs=1e-3)
    assert episode.trace["gap_v0"][k] == pytest.approx(gaps[k, 0] if edging_sensed else 382.8408, abs=1e-3)
    if edging_sensed:
        assert_sensed_as_the_fcd_shows(gaps, np.column_stack([episode.trace[f"gap_{vid}"] for vid in config.vehicle_ids]))


@pytest.mark.parametrize("merged", [True, False])
def test_several_demand_files_are_merged_by_departure_as_sumo_merges_its_route_files(tmp_path, merged):
    """Issue 48: two demand files of vehicles each sorted by departure were written one after the other into one
    route file, which SUMO reads ahead by departure: the second file's vehicles entered only once the first's
    had (none of them in a 600 s demand's first 80 s); as ``sumo -r a,b`` does, both drive from the start.
    ``merge_by_departure = false`` plays them as d4sumo 0.18 did (its stored campaigns)."""
    from d4sumo.sumohome import sumo_home

    game = Path(sumo_home()) / "tools" / "game" / "corridor"
    for name, edges, every in (("a", "gneE28 gneE10 gneE11 gneE26", 4), ("b", "gneE28 gneE10 gneE11 gneE26", 6)):
        (tmp_path / f"{name}.rou.xml").write_text("<routes>\n" + "".join(
            f'    <vehicle id="{name}{k}" depart="{k * every}"><route edges="{edges}"/></vehicle>\n' for k in range(600 // every))
            + "</routes>\n")
    config = EpisodeConfig(network=str(game / "corridor.net.xml"), route=("gneE27", "gneE25", "gneE18", "gneE29"),
                           start="steady", speed_mps=13.0, duration_s=20.0, signals="ignore",
                           traffic={"demand": [str(tmp_path / "a.rou.xml"), str(tmp_path / "b.rou.xml")], "warmup_s": 60.0,
                                    "merge_by_departure": merged})
    assert ("merge_by_departure" in config.to_dict()["traffic"]) is merged  # as 0.18 stored it: no such key
    simulate(config, np.full(config.steps, np.nan), fcd_path=tmp_path / "fcd.xml")
    seen = {v.id.split(".")[1][0] for _, v in parse_fast_nested(str(tmp_path / "fcd.xml"), "timestep", ["time"], "vehicle", ["id"])
            if v.id.startswith("traffic.")}
    assert seen == ({"a", "b"} if merged else {"a"})


def test_a_demand_whose_flows_have_no_end_plays_as_sumo_plays_it():
    """Issue 48: SUMO's corridor example's own demand, flows without an end beginning after 1 s, was refused
    ("Flow 'traffic.W30' ends before its begin time"): the check loaded it with SUMO's end at 1 s, which a flow
    without one takes for its own. SUMO plays the file; so does d4sumo."""
    from d4sumo.sumohome import sumo_home

    game = Path(sumo_home()) / "tools" / "game" / "corridor"
    config = EpisodeConfig(network=str(game / "corridor.net.xml"), route=("gneE27", "gneE25", "gneE18", "gneE29"),
                           start="steady", speed_mps=13.0, duration_s=20.0, traffic={"demand": str(game / "corridor.rou.xml")})
    episode = simulate(config, np.full(config.steps, np.nan))
    assert "traffic-v0" in episode.min_gaps  # traffic ahead of the attacker: the demand drives


def test_the_warm_up_cache_keeps_its_most_recently_used_and_never_one_in_use(tmp_path):
    """Issue 48: the cache grew by a warm-up for every sample that met traffic of its own; it keeps the most recently
    used (a hit marks it used), and never lets go one used within the hour, which another process may be loading."""
    import os
    import time

    from d4sumo.engine.warmup import IN_USE_S, _prune

    now = time.time()
    for k in range(10):
        f = tmp_path / f"{k}.xml.gz"
        f.write_text("state")
        used = now - IN_USE_S - 100 * (10 - k) if k < 8 else now - 60  # 8 old ones, then 2 in use
        os.utime(f, (used, used))
    _prune(tmp_path, 4)
    assert sorted(f.name for f in tmp_path.iterdir()) == ["6.xml.gz", "7.xml.gz", "8.xml.gz", "9.xml.gz"]
    _prune(tmp_path, 1)  # the two in use stay, whatever the cap
    assert sorted(f.name for f in tmp_path.iterdir()) == ["8.xml.gz", "9.xml.gz"]


def test_the_sensing_among_traffic_in_cpp_is_the_pythons_step_by_step_and_episode_by_episode(monkeypatch):
    """Who is ahead of each car among traffic, with libsumo's own C++ functions (`calls.native_traffic_pairs`): at each
    step the same pairs, ids, positions and speeds as the Python's, traffic between two followers and behind the rear
    car included; and the same episodes."""
    from conftest import NATIVE_CALLS_EXPECTED, assert_same_episode
    from d4sumo.engine import calls

    if not NATIVE_CALLS_EXPECTED:
        pytest.skip("no C++ compiler: libsumo's own calls are not built")
    config = dataclasses.replace(BUSY, setpoint_m=40.0)
    road = build_road(config.network)
    compared = traffic_between = 0
    with open_world(config, road, [config]) as world:
        api, ids, sense = world.api, world.platoons[0], world.traffic[0]
        assert sense._native is not None
        x = [world.get_position(v) for v in ids]
        api.vehicle.add("traffic.in", "platoon", depart="now", departLane="0", departPos=repr(x[1] - 4.5 - 15.0), departSpeed="30")
        rng = np.random.default_rng(0)
        for k in range(300):
            for vid in ids:
                api.vehicle.setSpeed(vid, float(rng.uniform(20.0, 34.0)))
            world.step()
            x, v = [world.get_position(vid) for vid in ids], [world.get_speed(vid) for vid in ids]
            native = sense(x, v)
            with monkeypatch.context() as m:
                m.setattr(sense, "_native", None)
                python = sense(x, v)
            assert native == python and [type(p[2]) for p in native[0]] == [float] * len(native[0])
            compared += 1
            traffic_between += any(0 < b < len(ids) and a >= len(ids) for a, b, _ in native[0])
    assert compared == 300 and traffic_between > 10
    u = np.full(config.steps, np.nan)
    u[40:200] = -0.8
    for c in (config, dataclasses.replace(BUSY, setpoint_m=3.0)):
        native = simulate(c, u, road=road)
        monkeypatch.setattr(calls, "NATIVE", False)
        assert_same_episode(native, simulate(c, u, road=road))
        monkeypatch.setattr(calls, "NATIVE", True)


@pytest.mark.parametrize("edging_sensed", [True, False])
def test_the_sensing_of_every_lane_among_traffic_in_cpp_is_the_pythons(monkeypatch, edging_sensed):
    """Where the attacker changes lanes among traffic, who follows whom in every lane each car covers, with libsumo's own
    C++ functions (`calls.native_lateral_pairs`): whole episodes the Python's, bit for bit, on SUMO's Bremen motorway
    with its own demand (through its on-ramp) and on a busy motorway of one edge (where, without edging_sensed, 0.21's
    way of placing a car off the route is kept)."""
    from conftest import NATIVE_CALLS_EXPECTED, assert_same_episode, random_plans
    from d4sumo.engine import calls
    from d4sumo.model.config import ControllerConfig
    from d4sumo.sumohome import sumo_home

    if not NATIVE_CALLS_EXPECTED:
        pytest.skip("no C++ compiler: libsumo's own calls are not built")
    game = Path(sumo_home()) / "tools" / "game" / "highway"
    traffic = {"demand": str(game / "highway.rou.xml"), "edging_sensed": edging_sensed}
    bremen = EpisodeConfig(network=str(game / "highway.net.xml"), route=("145354574", "189597495", "E0", "191842213"),
                           join_m=450.0, maneuver="swerve", swerve_lanes=3, start="steady", speed_mps=30.0, duration_s=30.0,
                           controller=ControllerConfig("timegap"), traffic=traffic)
    busy = dataclasses.replace(BUSY, maneuver="swerve", setpoint_m=5.0,
                               traffic=dataclasses.replace(BUSY.traffic, edging_sensed=edging_sensed))
    from d4sumo.model.attacks.maneuvers import attack_plan, maneuver_of
    from d4sumo.model.attacks.pedals import make_attack

    # a swerve through Bremen's on-ramp, changing lanes four times (tools/bench_traffic.py's)
    swerve = [-0.20975098924303356, 0.5169840989617727, -0.23673070044692715, 0.4845074166041973, -0.5402281130028335,
              0.13495804807098258, -0.18713697476514404, -0.21222790026910407, -0.3277738304971303, 2.8101446115896187,
              0.8226207432445664, 0.6022549884190292, 1.6178362246396496, 1.9772874541113046, 2.1528750560297025]
    outcomes = set()
    for config in (bremen, busy):
        road = config_road(config)
        plans = random_plans(config, 3, seed=5)
        if config is bremen:
            plans.append(attack_plan(maneuver_of(config).family(make_attack("knots")), swerve, config))
        for plan in plans:
            monkeypatch.setattr(calls, "NATIVE", True)
            native = simulate(config, plan, road=road)
            monkeypatch.setattr(calls, "NATIVE", False)
            assert_same_episode(native, simulate(config, plan, road=road))
            outcomes.add((config.network, native.outcome, len(native.trace)))
    # the episodes end apart, and one drives on for most of its 30 s: many steps of the lanes are compared
    assert len(outcomes) >= 3 and max(samples for network, _, samples in outcomes if network == bremen.network) > 400, outcomes


def test_a_lane_named_past_its_index_is_refused_as_the_python_refuses_it(tmp_path):
    """Found by review: placing a traffic car off the route as 0.21 did reads its lane's index from the lane's id; where
    that is no number the C++ read a leading number or failed with another error, where the Python's int() says
    ValueError. Now both say Python's ValueError, and a lane's index is read alike."""
    import types

    import libsumo
    from conftest import NATIVE_CALLS_EXPECTED
    from d4sumo.engine.calls import native_lateral_pairs, vehicle_call
    from d4sumo.engine.neighbours import _LateralTrafficSense

    if not NATIVE_CALLS_EXPECTED:
        pytest.skip("no C++ compiler: libsumo's own calls are not built")
    (tmp_path / "road.nod.xml").write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="1000" y="0"/></nodes>')
    (tmp_path / "road.edg.xml").write_text('<edges><edge id="e" from="a" to="b" numLanes="3" speed="33.33"/></edges>')
    said = {}
    for name in ("e_2", "e_2x", "e_two"):  # SUMO loads a lane of any id
        net = tmp_path / f"{name}.net.xml"
        net.write_text(Path(build_road(str(tmp_path)).net_file).read_text().replace('id="e_2"', f'id="{name}"')
                       .replace('incLanes="e_0 e_1 e_2"', f'incLanes="e_0 e_1 {name}"'))
        libsumo.start(["sumo", "-n", str(net), "--no-step-log", "--collision.action", "none"])
        try:
            libsumo.route.add("r", ["e"])
            for vid, lane, pos in (("v0", "1", "200"), ("v1", "1", "170"), ("t.a", "2", "190")):
                libsumo.vehicle.add(vid, "r", departLane=lane, departPos=pos, departSpeed="20")
            libsumo.simulationStep()
            s = object.__new__(_LateralTrafficSense)  # placing as 0.21 did, the route's lanes named by their index
            s.ids, s.index, s.names, s.lengths, s.width = ("v0", "v1"), {"v0": 0, "v1": 1}, ["v0", "v1"], [5.0, 5.0], 3.2
            s.lateral = types.SimpleNamespace(sense=lambda: [(1,), (1,)])
            s.route_lanes = types.SimpleNamespace(lanes={"e_0": (0.0, 0, 0), "e_1": (0.0, 1, 0), "e_2": (0.0, 2, 0)},
                                                  by_place={p: [(0.0, 1000.0, f"e_{p}")] for p in range(3)})
            s.edging_sensed, s.as_0_21, s.platoon_lane, s.edging_m, s.longest_m = False, True, 0, 0.7, 5.0
            for method in ("getLeader", "getFollower", "getNeighbors", "getLanePosition", "getSpeed", "getLength", "getLaneID",
                           "getLateralLanePosition"):
                setattr(s, {"getLeader": "get_leader", "getFollower": "get_follower", "getNeighbors": "get_neighbors",
                            "getLanePosition": "get_position", "getSpeed": "get_speed", "getLength": "get_length",
                            "getLaneID": "get_lane", "getLateralLanePosition": "get_lateral"}[method], vehicle_call(libsumo, method))
            s.get_vehicles = libsumo.lane.getLastStepVehicleIDs
            sense, native = native_lateral_pairs(libsumo)
            s._state = sense(s.ids, s.lengths, s.width, s.edging_m, s.longest_m, False, True, 0, s.route_lanes.lanes,
                             s.route_lanes.by_place)
            x, v = [libsumo.vehicle.getLanePosition(c) for c in s.ids], [libsumo.vehicle.getSpeed(c) for c in s.ids]
            answers = []
            for step in (native, None):
                s._native = step
                try:
                    answers.append(s(x, v))
                except ValueError as exc:
                    answers.append(f"ValueError: {exc}")
            said[name] = answers
        finally:
            libsumo.close()
    assert said["e_2"][0] == said["e_2"][1] and "t.a" in said["e_2"][0][1]
    for name, word in (("e_2x", "2x"), ("e_two", "two")):
        assert said[name] == [f"ValueError: invalid literal for int() with base 10: '{word}'"] * 2


def test_a_lane_changing_attackers_traffic_is_warmed_up_as_its_own_not_as_an_in_lane_ones(tmp_path, monkeypatch):
    """Found while comparing machines: the traffic's warm-up was cached by a key without SUMO's lanechange.duration,
    which a lane-changing attacker's SUMO is started with, so a swerve among traffic met the in-lane campaign's warmed-up
    traffic where that came first (or the in-lane one the swerve's), and played another episode than on a machine with
    an empty cache. Each is now warmed up as its SUMO is started."""
    from d4sumo.engine.warmup import traffic_state

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path / "cache"))
    swerve = dataclasses.replace(BUSY, maneuver="swerve")
    in_lane = traffic_state(BUSY, build_road(BUSY.network))
    lateral = traffic_state(swerve, build_road(swerve.network))
    assert lateral != in_lane and lateral.is_file()
    assert traffic_state(swerve, build_road(swerve.network)) == lateral  # and found again
