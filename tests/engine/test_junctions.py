"""Collisions inside junctions, in 2D (`engine.junctions`), for real in SUMO on SUMO's own corridor example
(three signalised crossings, its own demand): a car crossing the platoon's way is no leader of any of its
cars, and before, a platoon car driving into it was stored as no crash (or the attacker's later crash)."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from sumolib.xml import parse_fast_nested

from d4sumo.engine.scenarios import config_road
from d4sumo.engine.simulation import simulate
from d4sumo.model.attacks.pedals import attack_signal, make_attack
from d4sumo.model.world.bodies import Body, body_gap_m
from d4sumo.model.config import EpisodeConfig
from d4sumo.search.spec import Specification, default_formula

pytestmark = pytest.mark.sumo

ROUTE = ("gneE27", "gneE25", "gneE18", "gneE29")
#: knots of a random campaign on it (seed 1): the attacker runs into a car crossing gneJ12 at 35.1 s
ATTACKER_INTO_CROSSING = [-0.7447586270078608, -0.5549862681074551, 0.1241031801994188, -0.2244617686880921,
                          0.5833124111806811, 0.21027317855502892, 0.7225333695739882, 0.46472167465120906, 0.20364689551713]
#: and v1 into a car crossing it at 32.9 s, the attacker untouched
FOLLOWER_INTO_CROSSING = [-0.9631791376346108, -0.8005999926707543, 0.04798407405002658, 0.18453739923955204,
                          0.6678056367488387, 0.909295963797373, -0.19739115025017195, 0.6473903489160595,
                          -0.18966050630131748]

#: and nobody into anybody
NO_CRASH = [-0.7805306719866065, -0.5935169118252068, -0.43238702211173785, -0.3717322087953956, -0.37390428236012463,
            0.15339943250590404, 0.9433799512395094, 0.549328269847464, 0.5822678963456105]


@pytest.fixture(scope="module")
def corridor(tmp_path_factory):
    """SUMO's corridor example, its demand's flows given an end (SUMO plays a flow without one for ever)."""
    from d4sumo.sumohome import sumo_home

    game = Path(sumo_home()) / "tools" / "game" / "corridor"
    folder = tmp_path_factory.mktemp("corridor")
    demand = folder / "corridor_end.rou.xml"
    demand.write_text((game / "corridor.rou.xml").read_text().replace("<flow ", '<flow end="3600" '))
    # the network rebuilt and the platoon driving through red, as d4sumo 0.18 played them (its samples below):
    # into the crossing traffic
    config = EpisodeConfig(network=str(game / "corridor.net.xml"), route=ROUTE, start="steady", speed_mps=13.0,
                           duration_s=50.0, traffic={"demand": str(demand)}, signals="ignore", rebuild=True)
    return config, config_road(config)


def _play(config, road, knots, fcd_path=None):
    u = attack_signal(make_attack("knots"), knots, steps=config.steps, step_s=config.step_s, start_step=config.attack_start_step)
    return simulate(config, u, road=road, fcd_path=fcd_path)


def _fcd_bodies(path, lengths):
    """{time: {vehicle: Body}} from SUMO's FCD."""
    steps: dict[float, dict] = {}
    for step, v in parse_fast_nested(str(path), "timestep", ["time"], "vehicle", ["id", "x", "y", "angle"]):
        length, width = lengths.get(v.id, (5.0, 1.8))  # SUMO's passenger car: the demand's type
        steps.setdefault(float(step.time), {})[v.id] = Body(float(v.x), float(v.y), float(v.angle), length, width)
    return steps


def test_the_attacker_running_into_a_car_crossing_a_junction_is_an_attacker_crash(corridor, tmp_path):
    config, road = corridor
    episode = _play(config, road, ATTACKER_INTO_CROSSING, tmp_path / "fcd.xml")
    assert episode.outcome == "attacker_crash"  # stored as no_crash before
    collision = episode.first_collision
    assert (collision.pair, collision.time_s) == ("v0-traffic.S30.4", pytest.approx(35.1))
    assert episode.min_gaps["v0-traffic"] < 0
    assert Specification(followers=config.followers, step_s=config.step_s,
                         formula=default_formula(config.maneuver, config.followers, traffic=True)).robustness(episode.trace) < 0
    _check_against_fcd(config, episode, tmp_path / "fcd.xml")


def test_a_follower_running_into_a_car_crossing_a_junction_is_a_success(corridor, tmp_path):
    config, road = corridor
    episode = _play(config, road, FOLLOWER_INTO_CROSSING, tmp_path / "fcd.xml")
    assert episode.outcome == "success"
    collision = episode.first_collision
    assert (collision.pair, collision.time_s) == ("v1-traffic.S30.3", pytest.approx(32.9))
    gap = episode.min_gaps["v1-traffic"]
    assert gap < 0
    assert episode.trace["victim_gap"][-1] == gap  # the specification reads it: the robustness says success
    spec = Specification(followers=config.followers, step_s=config.step_s,
                         formula=default_formula(config.maneuver, config.followers, traffic=True))
    assert spec.robustness(episode.trace) == min(-gap, episode.trace["attacker_gap"].min()) > 0
    _check_against_fcd(config, episode, tmp_path / "fcd.xml")


def _check_against_fcd(config, episode, fcd_path):
    """No car of the platoon overlaps any other vehicle in SUMO's FCD before the stored collision, in 2D, and
    the collision's pair overlaps at it by the stored depth."""
    lengths = {vid: (v.length_m, 1.8) for vid, v in zip(config.vehicle_ids, config.car_vehicles)}
    steps = _fcd_bodies(fcd_path, lengths)
    times = sorted(steps)
    t0 = next(t for t in times if "v0" in steps[t])
    collision = episode.first_collision
    checked = 0
    for t in times[times.index(t0):]:
        cars = steps[t]
        elapsed = round(t - t0, 6)
        for vid in config.vehicle_ids:
            for other, body in cars.items():
                if other in config.vehicle_ids:
                    continue
                gap = body_gap_m(cars[vid], body)
                if elapsed < collision.time_s - 1e-9:
                    assert gap > -1e-5, (t, vid, other, gap)
                    checked += 1
        if elapsed == pytest.approx(collision.time_s):
            leader, follower = collision.pair.split("-", 1)
            assert body_gap_m(cars[leader], cars[follower]) == pytest.approx(min(episode.min_gaps.values()), abs=2e-5)
            break
    else:
        pytest.fail("the FCD ends before the collision")
    assert checked > 1000


def test_an_episode_without_a_collision_in_a_junction_is_bit_for_bit_what_it_was_without_the_check(corridor, monkeypatch):
    from d4sumo.engine.junctions import JunctionCrossings

    config, road = corridor
    knots = NO_CRASH  # nobody runs into anybody, every car of the platoon through gneJ12 (193-207 m along the route)
    episode = _play(config, road, knots)
    assert episode.outcome == "no_crash" and episode.trace["pos_v3"][-1] - 4.5 > 207.2
    looked = []
    measured = JunctionCrossings.__call__
    monkeypatch.setattr(JunctionCrossings, "__call__", lambda self, *a: looked.append(measured(self, *a)) or [])
    without = _play(config, road, knots)
    assert len(looked) == len(episode.trace) and not any(looked)  # every step looked, and saw nothing
    assert episode.trace.names == without.trace.names
    for name in episode.trace.names:
        assert np.array_equal(episode.trace[name], without.trace[name], equal_nan=True), name
    assert episode.min_gaps == without.min_gaps
