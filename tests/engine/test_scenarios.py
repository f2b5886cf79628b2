"""Network variants: plain node/edge XML built by netconvert and cached."""

from __future__ import annotations

import re
import shutil
from pathlib import Path

import pytest

from d4sumo.engine.networks import SCENARIOS_DIR, list_scenarios
from d4sumo.engine.scenarios import build_road
from d4sumo.errors import ConfigError, SumoError


def test_at_least_three_variants_ship():
    names = list_scenarios()
    assert {"highway_4lane", "highway_1lane"} <= set(names) and len(names) >= 3
    for name in names:
        assert (SCENARIOS_DIR / name / "README.md").is_file()


@pytest.mark.sumo
@pytest.mark.parametrize("name", list_scenarios())
def test_every_variant_builds_into_a_straight_road(name, tmp_path):
    road = build_road(name, cache_dir=tmp_path)
    assert road.net_file.is_file() and road.route_edges
    assert road.length_m >= 3000 and road.speed_limit_mps > 30


@pytest.mark.sumo
def test_the_net_is_cached_and_rebuilt_when_the_variant_changes(tmp_path):
    variant = tmp_path / "mine"
    shutil.copytree(SCENARIOS_DIR / "highway_1lane", variant)
    cache = tmp_path / "cache"
    first = build_road(str(variant), cache_dir=cache)
    mtime = first.net_file.stat().st_mtime_ns
    assert build_road(str(variant), cache_dir=cache).net_file.stat().st_mtime_ns == mtime
    edges = variant / "highway.edg.xml"
    edges.write_text(edges.read_text().replace('speed="40"', 'speed="30"'))
    changed = build_road(str(variant), cache_dir=cache)
    assert changed.net_file != first.net_file and changed.speed_limit_mps == 30.0


def test_an_unknown_variant_lists_the_known_ones():
    with pytest.raises(ConfigError, match="highway_4lane"):
        build_road("autobahn")


def test_a_missing_netconvert_is_a_clear_error(tmp_path):
    with pytest.raises(SumoError, match="netconvert"):
        build_road("highway_4lane", cache_dir=tmp_path, netconvert=str(tmp_path / "netconvert"))


def _road_folder(folder, edges: str, nodes: str = '<node id="a" x="0" y="0"/><node id="b" x="2000" y="0"/>'
                                                 '<node id="c" x="5000" y="0"/>'):
    folder.mkdir()
    (folder / "road.nod.xml").write_text(f"<nodes>{nodes}</nodes>")
    (folder / "road.edg.xml").write_text(f"<edges>{edges}</edges>")
    return folder


def test_a_road_of_several_edges_counts_only_the_lanes_that_lead_on_through_every_junction(tmp_path):
    """A lane that ends at a junction would stop the cars in it: a lane drop on the left leaves three
    lanes for maneuvers; one on the right moves the platoon to the lane that leads on (issue 37)."""
    left = _road_folder(tmp_path / "left", '<edge id="e" from="a" to="c" numLanes="4" speed="40">'
                                           '<split pos="2000" lanes="0 1 2"/></edge>', '<node id="a" x="0" y="0"/><node id="c" x="5000" y="0"/>')
    road = build_road(str(left), cache_dir=tmp_path / "cache")
    assert (road.route_edges, road.lanes, road.first_edge_m) == (("e", "e.2000"), 3, pytest.approx(2000.0, abs=5))
    right = _road_folder(tmp_path / "right", '<edge id="e1" from="a" to="b" numLanes="2" speed="40"/>'
                                             '<edge id="e2" from="b" to="c" numLanes="1" speed="40"/>')
    road = build_road(str(right), cache_dir=tmp_path / "cache")
    assert (road.lane_path, road.platoon_lane, road.lanes) == ((1, 0), 1, 1)


@pytest.mark.sumo
def test_a_road_on_which_no_lane_leads_on_is_refused_naming_the_longest_piece_that_does(tmp_path):
    """Lane 0 of e1 joins the lane of e2 that ends at the next junction: no car gets through without a
    lane change. The refusal names the furthest lane and the route to take instead."""
    import subprocess

    from d4sumo.sumohome import sumo_binary

    (tmp_path / "r.nod.xml").write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="1000" y="0"/>'
                                        '<node id="c" x="2000" y="0"/><node id="d" x="4000" y="0"/></nodes>')
    (tmp_path / "r.edg.xml").write_text('<edges><edge id="e1" from="a" to="b" numLanes="1" speed="40"/>'
                                        '<edge id="e2" from="b" to="c" numLanes="2" speed="40"/>'
                                        '<edge id="e3" from="c" to="d" numLanes="1" speed="40"/></edges>')
    (tmp_path / "r.con.xml").write_text('<connections><connection from="e1" to="e2" fromLane="0" toLane="0"/>'
                                        '<connection from="e2" to="e3" fromLane="1" toLane="0"/></connections>')
    net = tmp_path / "r.net.xml"
    subprocess.run([sumo_binary("netconvert"), "-n", str(tmp_path / "r.nod.xml"), "-e", str(tmp_path / "r.edg.xml"),
                    "-x", str(tmp_path / "r.con.xml"), "-o", str(net)], check=True, capture_output=True)
    with pytest.raises(ConfigError, match=r"scenario.network: got .*; allowed: a road with a lane that leads on through every "
                                          r"junction \(none of e1's does: the furthest, lane 0, ends on e2 as lane 0\); the "
                                          r"longest piece along which a lane leads on is 2 edges \(29\d\d m, speed limit 40 m/s\): "
                                          r'scenario.route = \["e2", "e3"\]'):
        build_road(str(net), cache_dir=tmp_path / "cache")
    assert build_road(str(net), route=("e2", "e3"), cache_dir=tmp_path / "cache").lane_path == (1, 0)


@pytest.mark.sumo
def test_a_lone_net_xml_is_a_road_and_plays_as_its_node_and_edge_files(tmp_path):
    """A network file (netconvert's, netgenerate's, an OSM import's) is taken back to plain XML by
    netconvert; its connections go with it, into every side-by-side copy of a batch."""
    import numpy as np
    from conftest import assert_same_episode, random_plans

    from d4sumo.engine.simulation import simulate, simulate_batch
    from d4sumo.model.config import EpisodeConfig

    plain = Path(__file__).resolve().parents[2] / "examples" / "roads" / "three_edges"
    folder = tmp_path / "lone"
    folder.mkdir()
    shutil.copy(build_road(str(plain), cache_dir=tmp_path / "cache").net_file, folder / "highway.net.xml")
    roads = [build_road(name, cache_dir=tmp_path / "cache") for name in (str(folder), str(folder / "highway.net.xml"))]
    assert roads[0].name == str(folder) and roads[1].name == str(folder / "highway.net.xml")  # as the user named them
    for road in roads:
        assert (road.route_edges, road.lanes, road.speed_limit_mps) == (("e1", "e2", "e3"), 4, 35.0)
    config = EpisodeConfig(network=str(plain), start="steady", speed_mps=30.0, duration_s=90.0)
    u = np.full(config.steps, np.nan)
    reference = simulate(config, u)
    lone = EpisodeConfig(network=str(folder / "highway.net.xml"), start="steady", speed_mps=30.0, duration_s=90.0)
    assert_same_episode(simulate(lone, u), reference)
    plans = random_plans(lone, 6, seed=2)
    for batched, plan in zip(simulate_batch(lone, plans), plans):
        assert_same_episode(batched, simulate(lone, plan))


@pytest.mark.sumo
def test_a_network_file_sumo_cannot_load_or_with_no_one_chain_is_one_line(tmp_path):
    import subprocess

    from d4sumo.sumohome import sumo_binary

    bad = tmp_path / "bad.net.xml"
    bad.write_text("<net><edge id=")
    # regression: refusals named a network file by its stem ('bad'), where the user gave its path
    with pytest.raises(ConfigError, match=rf"scenario.network: got '{re.escape(str(bad))}'; allowed: a network file SUMO loads \(netconvert: "):
        build_road(str(bad), cache_dir=tmp_path / "cache")
    grid = tmp_path / "grid.net.xml"  # netgenerate's grid: two-way streets, no one chain of edges to drive
    subprocess.run([sumo_binary("netgenerate"), "--grid", "--grid.number", "3", "-o", str(grid)], check=True, capture_output=True)
    with pytest.raises(ConfigError, match=rf"got '{re.escape(str(grid))}'; allowed: a network with exactly one road start"):
        build_road(str(grid), cache_dir=tmp_path / "cache")


@pytest.mark.sumo
def test_a_route_through_a_network_of_many_ways_is_the_road_alone_and_batches_copy_only_it(tmp_path):
    """netgenerate's grid has no one chain of edges: scenario.route names the platoon's; the road (and
    each copy of it in a batch) is those edges alone."""
    import subprocess

    import numpy as np
    from conftest import assert_same_episode, random_plans

    from d4sumo.engine.simulation import simulate, simulate_batch
    from d4sumo.model.config import EpisodeConfig
    from d4sumo.sumohome import sumo_binary

    grid = tmp_path / "grid.net.xml"
    subprocess.run([sumo_binary("netgenerate"), "--grid", "--grid.number", "4", "--grid.length", "600", "-L", "2",
                    "-o", str(grid)], check=True, capture_output=True)
    route = ("A0B0", "B0C0", "C0D0")
    road = build_road(str(grid), route=route, cache_dir=tmp_path / "cache")
    assert road.route_edges == route and road.lanes == 2 and road.length_m > 1700
    config = EpisodeConfig(network=str(grid), route=list(route), speed_mps=12.0, duration_s=80.0, setpoint_m=5.0)
    assert config.to_dict()["scenario"]["route"] == list(route) and "route" not in EpisodeConfig().to_dict()["scenario"]
    episode = simulate(config, np.full(config.steps, np.nan))
    assert episode.outcome == "no_crash" and episode.trace["pos_v0"][-1] > 700.0  # past the first junction
    plans = random_plans(config, 5, seed=1)
    for batched, plan in zip(simulate_batch(config, plans), plans):
        assert_same_episode(batched, simulate(config, plan))
    for bad, message in ((("A0B0", "X"), f"edges of {re.escape(str(grid))} \\(it has no edge 'X'\\)"), (("A0B0", "C0D0"), "edges that lead on one to the next"),
                         (("A0B0", "A0B0"), "each edge once")):
        with pytest.raises(ConfigError, match=f"scenario.route: got .*; allowed: {message}"):
            build_road(str(grid), route=bad, cache_dir=tmp_path / "cache")
    # regression: a route round a block, and one whose turn leaves lane 0, were said not to lead on
    with pytest.raises(ConfigError, match="scenario.route: got .*; allowed: edges that lead on one to the next, never back to a junction"):
        build_road(str(grid), route=("A0B0", "B0B1", "B1A1", "A1A0"), cache_dir=tmp_path / "cache")
    # a left turn: the platoon drives the lane that turns (issue 37: it was refused, lane 0 turning right only)
    turning = build_road(str(grid), route=("A0B0", "B0B1"), cache_dir=tmp_path / "cache")
    assert turning.platoon_lane == 1 and turning.lanes == 1


@pytest.mark.sumo
def test_the_osm_example_imports_into_a_road_of_two_ways(tmp_path):
    import subprocess

    from d4sumo.sumohome import sumo_binary

    osm = Path(__file__).resolve().parents[2] / "examples" / "roads" / "osm" / "motorway.osm"
    net = tmp_path / "motorway.net.xml"
    subprocess.run([sumo_binary("netconvert"), "--osm-files", str(osm), "-o", str(net)], check=True, capture_output=True)
    road = build_road(str(net), cache_dir=tmp_path / "cache")
    assert road.route_edges == ("10", "11") and road.lanes == 3 and road.length_m > 4000
    assert road.speed_limit_mps == pytest.approx(120 / 3.6, abs=0.01)


@pytest.mark.sumo
@pytest.mark.parametrize("edge, lane", [
    ('speed="nan"', "e1_0: nan"),
    ('speed="inf"', "e1_0: inf"),
    ('speed="30"><lane index="1" speed="nan"/></edge', "e1_1: nan"),
])
def test_a_speed_limit_that_is_not_a_positive_number_is_refused_naming_the_lane(tmp_path, edge, lane):
    """Regression: netconvert built a road with speed="nan" (an edge's or one lane's); SUMO then refused
    it in every episode, so falsify and sweep stored error samples and exited 0."""
    edges = f'<edge id="e1" from="a" to="c" numLanes="2" {edge}/>'.replace("</edge/>", "</edge>")
    folder = _road_folder(tmp_path / "bad", edges)
    with pytest.raises(ConfigError, match=f"speed limits that are positive numbers of m/s \\(lane {lane}"):
        build_road(str(folder), cache_dir=tmp_path / "cache")
