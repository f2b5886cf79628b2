"""The platoon's lane along the route: where an on-ramp adds a lane on its right, or an exit or a lane
drop takes one away, its index changes as SUMO's connections say (`layout.lane_path`), and SUMO's cars
drive exactly that way (their FCD lanes), on roads of our own and on SUMO's own Bremen motorway."""

from __future__ import annotations

import dataclasses
import json
from pathlib import Path

import numpy as np
import pytest
from conftest import assert_same_episode, random_plans
from sumolib.xml import parse_fast_nested

from d4sumo.engine.scenarios import batch_road, build_road
from d4sumo.engine.simulation import simulate, simulate_batch
from d4sumo.errors import ConfigError
from d4sumo.model.attacks.maneuvers import attack_plan, lane_changes, maneuver_of
from d4sumo.model.attacks.pedals import make_attack
from d4sumo.model.config import EpisodeConfig
from d4sumo.sumohome import sumo_home

pytestmark = pytest.mark.sumo

EXAMPLES = Path(__file__).resolve().parents[2] / "examples" / "roads"
#: SUMO's own Bremen motorway (shipped in the eclipse-sumo wheel), its main route: an on-ramp joins on
#: the right at E0, whose lane 0 (the acceleration lane) then ends
BREMEN = Path(sumo_home()) / "tools" / "game" / "highway" / "highway.net.xml"
BREMEN_ROUTE = ("145354574", "189597495", "E0", "191842213")
#: SUMO's OSM import of the Berlin A10 motorway interchange (tools/game/A10KW), a 2.7 km motorway route
#: past two on-ramps, each with its acceleration lane
A10 = Path(sumo_home()) / "tools" / "game" / "A10KW" / "osm.net.xml"
A10_ROUTE = ("264306385", "264308375", "264308383", "4054057", "264308376")
NODES = ('<node id="a" x="0" y="0"/><node id="b" x="1000" y="0"/><node id="c" x="2000" y="0"/>'
         '<node id="d" x="4000" y="0"/>')


def _road_folder(folder: Path, lanes: tuple[int, ...]) -> Path:
    """A straight road of three edges with these numbers of lanes, joined as netconvert guesses."""
    folder.mkdir()
    (folder / "road.nod.xml").write_text(f"<nodes>{NODES}</nodes>")
    edges = "".join(f'<edge id="e{i}" from="{a}" to="{b}" numLanes="{n}" speed="40"/>'
                    for i, (a, b, n) in enumerate(zip("abc", "bcd", lanes), start=1))
    (folder / "road.edg.xml").write_text(f"<edges>{edges}</edges>")
    return folder


def fcd_lanes(path: Path) -> dict[str, list[str]]:
    """Each car's lanes in the order it drove them, junction lanes left out."""
    seen: dict[str, list[str]] = {}
    for _, v in parse_fast_nested(str(path), "timestep", ["time"], "vehicle", ["id", "lane"]):
        lanes = seen.setdefault(v.id, [])
        if not v.lane.startswith(":") and (not lanes or lanes[-1] != v.lane):
            lanes.append(v.lane)
    return seen


def assert_drives_the_lane_path(fcd: Path, road, offsets: dict[str, int] | None = None) -> None:
    """Every car drives the road's lane path (plus its maneuver lane, ``offsets``) edge by edge, as far as it got."""
    path = road.platoon_path
    expected = [f"{edge}_{lane}" for edge, lane in zip(road.route_edges, path)]
    lanes = fcd_lanes(fcd)
    assert lanes
    for vid, driven in lanes.items():
        offset = (offsets or {}).get(vid, 0)
        assert driven == [f"{e}_{int(i) + offset}" for e, _, i in (x.rpartition("_") for x in expected[:len(driven)])], vid
    assert max(len(d) for d in lanes.values()) > 1  # the front car got past a junction


@pytest.mark.parametrize("lanes, lane, path", [
    ((1, 2, 1), None, (0, 1, 0)),         # a lane added on the right, then dropped on the right
    ((2, 4, 2), None, (0, 2, 0)),         # one lane joins three: the one that leads on is taken
    ((2, 4, 2), 1, (1, 3, 1)),
    ((2, 4, 4), 1, (1, 1, 1)),            # alike lanes lead on: the rightmost, as SUMO takes it
    ((2, 1, 1), None, (1, 0, 0)),         # the rightmost lane ends at the first junction
])
def test_sumos_cars_drive_the_lane_path_where_lanes_are_added_and_dropped(tmp_path, lanes, lane, path):
    road_dir = _road_folder(tmp_path / "road", lanes)
    road = build_road(str(road_dir), cache_dir=tmp_path / "cache", lane=lane)
    assert road.platoon_path == path
    config = EpisodeConfig(network=str(road_dir), lane=lane, speed_mps=35.0, start="steady", duration_s=85.0, followers=2)
    fcd = tmp_path / "fcd.xml"
    episode = simulate(config, np.full(config.steps, np.nan), road=road, fcd_path=fcd)
    assert episode.outcome == "no_crash" and episode.trace["pos_v0"][-1] > 2100.0  # past both junctions
    assert_drives_the_lane_path(fcd, road)


def test_sumos_bremen_motorway_plays_its_main_route_through_the_on_ramp(tmp_path):
    """Issue 37: every motorway tried was refused at its first ramp. The Bremen motorway's main route
    (1.9 km) now plays: the platoon is in lane 0, then 1 where the ramp's lane joins, then 0; batches
    equal episodes alone; and a lane-changing attacker keeps its lane beside the platoon's through the ramp."""
    road = build_road(str(BREMEN), route=BREMEN_ROUTE, cache_dir=tmp_path / "cache", given=True)  # as SUMO runs the file
    assert road.lane_path == (0, 0, 1, 0) and road.lanes == 3 and 1850 < road.length_m < 1870
    config = EpisodeConfig(network=str(BREMEN), route=BREMEN_ROUTE, speed_mps=30.0, start="steady", duration_s=40.0,
                           followers=3)
    fcd = tmp_path / "fcd.xml"
    episode = simulate(config, np.full(config.steps, np.nan), road=road, fcd_path=fcd)
    assert episode.outcome == "no_crash" and episode.trace["pos_v3"][-1] > 1100.0  # the last car is past the ramp
    assert_drives_the_lane_path(fcd, road)
    assert min(episode.min_gaps_m().values()) == pytest.approx(config.setpoint_m, abs=1e-6)  # nothing slowed them
    plans = random_plans(config, 4, seed=3)
    for batched, plan in zip(simulate_batch(config, plans), plans):
        assert_same_episode(batched, simulate(config, plan, road=road))
    # a cut-in there (refused before: SUMO's index of the platoon's lane changes at the ramp): the attacker
    # starts in the lane to the platoon's left, and keeps it through the ramp, SUMO's index 1, then 2, then 1
    cutin = dataclasses.replace(config, maneuver="cutin", cutin_follower=2)
    plan = attack_plan(maneuver_of(cutin).family(make_attack("knots")), [0.0] * 9 + [cutin.duration_s], cutin)
    assert all(step >= cutin.steps for step, _ in lane_changes(plan, maneuver_of(cutin)))  # none within the episode
    simulate(cutin, plan, road=road, fcd_path=fcd)
    assert fcd_lanes(fcd)["v0"] == ["145354574_1", "189597495_1", "E0_2", "191842213_1"]
    assert_drives_the_lane_path(fcd, road, {"v0": 1})
    for maneuver in (cutin, dataclasses.replace(config, maneuver="swerve", swerve_lanes=3)):  # each copy's own lanes
        plans = random_plans(maneuver, 4, seed=5)
        assert sum(len(lane_changes(p, maneuver_of(maneuver))) for p in plans) >= 4
        for batched, plan in zip(simulate_batch(maneuver, plans), plans):
            assert_same_episode(batched, simulate(maneuver, plan, road=road))


def test_sumos_osm_motorway_interchange_plays_a_route_past_two_on_ramps(tmp_path):
    road = build_road(str(A10), route=A10_ROUTE, cache_dir=tmp_path / "cache", given=True)
    assert road.lane_path == (0, 1, 0, 1, 0) and road.lanes == 3 and road.length_m > 2700
    config = EpisodeConfig(network=str(A10), route=A10_ROUTE, speed_mps=25.0, start="steady", duration_s=80.0, followers=3)
    fcd = tmp_path / "fcd.xml"
    episode = simulate(config, np.full(config.steps, np.nan), road=road, fcd_path=fcd)
    assert episode.outcome == "no_crash" and episode.trace["pos_v3"][-1] > 2000.0  # the last car is past both ramps
    assert_drives_the_lane_path(fcd, road)


def test_a_lane_the_user_names_plays_as_lane_0_does_on_a_road_of_even_lanes(tmp_path, road):
    """scenario.lane puts the platoon (and a maneuver's lanes, counted from it) in another lane: on lanes
    alike, every signal is the one lane 0 gives, bit for bit."""
    for base in (EpisodeConfig(duration_s=20.0), EpisodeConfig(maneuver="cutin", duration_s=20.0, cutin_follower=2)):
        plan = random_plans(base, 1, seed=5)[0]
        moved = dataclasses.replace(base, lane=1)
        fcd = tmp_path / "fcd.xml"
        there = simulate(moved, plan, fcd_path=fcd)
        assert_same_episode(there, simulate(base, plan, road=road))
        lanes = fcd_lanes(fcd)
        assert lanes["v1"] == ["highway_1"] and lanes["v0"][0] == ("highway_2" if base.maneuver == "cutin" else "highway_1")
    assert moved.to_dict()["scenario"]["lane"] == 1 and "lane" not in base.to_dict()["scenario"]


def test_a_lane_that_does_not_lead_on_is_refused_naming_those_that_do(tmp_path):
    road_dir = _road_folder(tmp_path / "road", (2, 1, 1))
    with pytest.raises(ConfigError, match=r"scenario.lane: got 0; allowed: a lane of .*'s first edge e1 that leads on through "
                                          r"every junction of the route without a lane change: 1 \(0 the rightmost\)"):
        build_road(str(road_dir), cache_dir=tmp_path / "cache", lane=0)
    for bad in (-1, 16, 1.5, "1"):
        with pytest.raises(ConfigError, match="scenario.lane: got"):
            EpisodeConfig(lane=bad)


def test_earlier_versions_sharing_the_cache_find_only_roads_they_drive_as_this_one_does(tmp_path):
    """Their description's keys are written only where the platoon drives lane 0 all along: of any other
    road an earlier d4sumo finds no description and describes (and refuses) it itself."""
    cache = tmp_path / "cache"
    straight = build_road("highway_4lane", cache_dir=cache)
    shifted = build_road(str(_road_folder(tmp_path / "road", (1, 2, 1))), cache_dir=cache)
    straight_info = json.loads(straight.net_file.with_suffix(".json").read_text())
    shifted_info = json.loads(shifted.net_file.with_suffix(".json").read_text())
    assert straight_info["lanes"] == 4 and straight_info["lane_widths_m"] == [3.2] and "lane_width_m" in straight_info
    assert "lane_widths_m" not in shifted_info and "corridors" in shifted_info


def test_the_example_acceleration_lane_shifts_the_platoons_lane_and_the_time_space_diagram_keeps_one_panel(tmp_path):
    from d4sumo.results import timespace

    road = build_road(str(EXAMPLES / "acceleration_lane"), cache_dir=tmp_path / "cache")
    assert road.lane_path == (0, 1, 0) and road.lanes == 3
    config = EpisodeConfig(network=str(EXAMPLES / "acceleration_lane"), speed_mps=30.0, start="steady", duration_s=90.0)
    fcd = tmp_path / "fcd.xml"
    simulate(config, np.full(config.steps, np.nan), road=road, fcd_path=fcd)
    assert_drives_the_lane_path(fcd, road)
    read = timespace.read_fcd(fcd, road.platoon_lanes)
    assert timespace.lanes(read) == ["0"]  # counted from the platoon's lane: one lane, one panel
    assert len(timespace.lanes(timespace.read_fcd(fcd))) == 2  # SUMO's indices: 0 and 1
    # a swerve through it, batched on the road's copies (each copy's own lanes, their indices shifting) as alone
    swerve = dataclasses.replace(config, maneuver="swerve", swerve_lanes=3)
    plans = random_plans(swerve, 4, seed=2)
    assert not batch_road(str(EXAMPLES / "acceleration_lane"), 4).copies_unlike
    assert sum(len(lane_changes(p, maneuver_of(swerve))) for p in plans) >= 4
    for batched, plan in zip(simulate_batch(swerve, plans), plans):
        assert_same_episode(batched, simulate(swerve, plan, road=road))


def test_a_roads_speed_limit_stays_what_stored_campaigns_were_played_with(tmp_path):
    """Each edge's limit is its fastest lane's (SUMO's edge speed), the lowest along the route: what the
    attacker was clamped to in every earlier version, whatever the lanes' own limits."""
    folder = tmp_path / "road"
    folder.mkdir()
    (folder / "road.nod.xml").write_text(f"<nodes>{NODES}</nodes>")
    (folder / "road.edg.xml").write_text(
        '<edges><edge id="e1" from="a" to="b" numLanes="2" speed="40"><lane index="0" speed="30"/></edge>'
        '<edge id="e2" from="b" to="c" numLanes="2" speed="38"/><edge id="e3" from="c" to="d" numLanes="2" speed="40"/></edges>')
    road = build_road(str(folder), cache_dir=tmp_path / "cache")
    assert road.speed_limit_mps == 38.0 and road.lane_path == ()


def test_where_sumo_looks_ahead_less_far_than_the_route_the_episode_stops_with_one_line_never_a_verdict(tmp_path):
    """Regression: one lane joins two, of which the right one ends 3 km on. d4sumo's lane path takes the
    left one, which leads on; SUMO, looking ahead less far, put the cars in the right one, and they hit
    its end: 'attacker_crash' with no attack at all. Now the first car off the path ends the episode
    with a SumoError naming it and both lanes."""
    from d4sumo.errors import SumoError

    folder = tmp_path / "far"
    folder.mkdir()
    nodes = "".join(f'<node id="n{i}" x="{300 * i}" y="0"/>' for i in range(13))
    edges = "".join(f'<edge id="e{i}" from="n{i}" to="n{i + 1}" numLanes="{1 if i in (0, 11) else 2}" speed="40"/>'
                    for i in range(12))
    (folder / "road.nod.xml").write_text(f"<nodes>{nodes}</nodes>")
    (folder / "road.edg.xml").write_text(f"<edges>{edges}</edges>")
    road = build_road(str(folder), cache_dir=tmp_path / "cache")
    assert road.lane_path == (0,) + (1,) * 10 + (0,) and road.forks
    config = EpisodeConfig(network=str(folder), speed_mps=38.0, start="steady", duration_s=80.0, followers=2)
    with pytest.raises(SumoError, match=r"SUMO drove v\d into lane e1_0 of .*far, not lane 1 that leads on through the "
                                        r"route: .*name a shorter scenario.route"):
        simulate(config, np.full(config.steps, np.nan), road=road)
    plans = random_plans(config, 2, seed=0)
    with pytest.raises(SumoError, match="into lane c\\d_e1_0"):  # in a batch too, on its copy of the road
        simulate_batch(config, plans)
    # the roads SUMO drives as d4sumo reads them are checked too, and play (the forks above: a lane added)
    assert build_road(str(_road_folder(tmp_path / "widen", (2, 4, 2))), cache_dir=tmp_path / "cache").forks
