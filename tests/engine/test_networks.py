"""What --network names: shipped variants, folders, network files; and what is said of a name that is none."""

from __future__ import annotations

import shutil
from pathlib import Path

import pytest

from d4sumo.engine.networks import network_source
from d4sumo.errors import ConfigError


@pytest.mark.parametrize("given, allowed", [
    ("nosuch.net.xml", "a *.net.xml that exists (there is no {cwd}/nosuch.net.xml)"),
    ("{tmp}/two_edges/road.nod.xml", "the folder that holds the node and edge files ({tmp}/two_edges), not one of them"),
    ("{tmp}/two_edges/notes.txt", "one of highway_1lane, highway_3lane_120kmh, highway_4lane, a folder with *.nod.xml and "
                                  "*.edg.xml, or a *.net.xml (notes.txt is not one: a network file's name ends in .net.xml, or .net.xml.gz)"),
    ("{tmp}/two_edges/map.osm", "a network file (*.net.xml): import an OpenStreetMap file with netconvert first: "
                                "netconvert --osm-files {tmp}/two_edges/map.osm -o map.net.xml"),
    ("{tmp}/nosuch.osm", "an OpenStreetMap file that exists, imported with netconvert first (there is no {tmp}/nosuch.osm)"),
    ("{tmp}", "a folder with exactly one *.nod.xml and one *.edg.xml, or one *.net.xml (it holds 0 *.nod.xml, 0 *.edg.xml, "
              "0 *.net.xml)"),
], ids=["missing network file", "a node file", "another file", "an OSM file", "a missing OSM file", "a folder of none"])
def test_a_network_that_is_none_says_what_is_wrong_with_the_path_given(tmp_path, monkeypatch, given, allowed):
    """Regression: a missing *.net.xml and an OSM file were told only the list of what --network takes."""
    monkeypatch.chdir(tmp_path)
    shutil.copytree(Path(__file__).resolve().parents[2] / "examples" / "roads" / "two_edges", tmp_path / "two_edges")
    (tmp_path / "two_edges" / "notes.txt").write_text("notes")
    (tmp_path / "two_edges" / "map.osm").write_text("<osm/>")
    given, allowed = given.format(tmp=tmp_path), allowed.format(tmp=tmp_path, cwd=tmp_path)
    with pytest.raises(ConfigError) as info:
        network_source(given)
    assert str(info.value) == f"scenario.network: got {given!r}; allowed: {allowed}"


@pytest.mark.sumo
def test_a_network_files_signal_plans_that_the_built_road_drops_are_said_once(tmp_path, caplog):
    """Issue 37: a corridor's traffic lights came out with netconvert's default programs in the road d4sumo
    builds (its nodes and edges keep no signal plans) and nothing said so."""
    import subprocess

    from d4sumo.sumohome import sumo_binary

    (tmp_path / "r.nod.xml").write_text('<nodes><node id="a" x="0" y="0"/><node id="b" x="1000" y="0" type="traffic_light"/>'
                                        '<node id="c" x="3000" y="0"/></nodes>')
    (tmp_path / "r.edg.xml").write_text('<edges><edge id="e1" from="a" to="b" numLanes="2" speed="30"/>'
                                        '<edge id="e2" from="b" to="c" numLanes="2" speed="30"/></edges>')
    net = tmp_path / "signals.net.xml"
    subprocess.run([sumo_binary("netconvert"), "-n", str(tmp_path / "r.nod.xml"), "-e", str(tmp_path / "r.edg.xml"),
                    "-o", str(net)], check=True, capture_output=True)
    with caplog.at_level("WARNING"):
        network_source(str(net))
        network_source(str(net))
        network_source(str(net), route=("e2",))  # starts past the light
    notes = [r.getMessage() for r in caplog.records if "traffic light" in r.getMessage()]
    assert len(notes) == 1 and "its 1 traffic light (b) netconvert's default program, not the network's own" in notes[0]
    assert "without the programs netconvert writes" in notes[0] and "keep no signal plans" not in notes[0]  # issue 48: said truly
    caplog.clear()
    network_source(str(tmp_path / "r.nod.xml").replace("r.nod.xml", ""))  # the same nodes as a folder: the user's own plan
    assert not [r for r in caplog.records if "traffic light" in r.getMessage()]


@pytest.mark.sumo
def test_a_compressed_network_file_is_the_network_it_holds(tmp_path):
    """Regression: a *.net.xml.gz (SUMO reads them, and ships its example networks so) was refused ('a network
    file's name ends in .net.xml'); it plays the episode its plain file plays, bit for bit."""
    import gzip

    import numpy as np

    from d4sumo.engine.scenarios import build_road
    from d4sumo.engine.simulation import simulate
    from d4sumo.model.config import EpisodeConfig

    plain = tmp_path / "three.net.xml"
    shutil.copy(build_road(str(Path(__file__).resolve().parents[2] / "examples" / "roads" / "three_edges")).net_file, plain)
    packed = tmp_path / "three.net.xml.gz"
    packed.write_bytes(gzip.compress(plain.read_bytes()))
    u = np.full(EpisodeConfig().steps, -0.3)
    a, b = (simulate(EpisodeConfig(network=str(p), start="steady"), u) for p in (plain, packed))
    assert a.outcome == b.outcome and all(np.array_equal(a.trace[k], b.trace[k]) for k in a.trace.names)
    assert network_source(str(packed)).stem == "three"


@pytest.mark.sumo
def test_a_network_file_runs_as_given_its_signal_programmes_and_coordinates_kept(tmp_path, caplog):
    """Issue 48: a network file was taken back to plain XML and rebuilt by netconvert: its signal programmes
    became netconvert's defaults (SUMO's corridor example's gneJ12: y3 / r3 / G10005 in the file, 42 / 3 / 42 / 3
    in d4sumo) and its coordinates moved. SUMO now runs the file itself; ``rebuild = true`` plays it as 0.18 did."""
    import gzip
    from xml.etree import ElementTree as ET

    import numpy as np
    from sumolib.xml import parse_fast_nested

    from d4sumo.engine.scenarios import build_road
    from d4sumo.engine.simulation import simulate
    from d4sumo.model.config import EpisodeConfig
    from d4sumo.sumohome import sumo_home

    net = Path(sumo_home()) / "tools" / "game" / "corridor" / "corridor.net.xml"
    route = ("gneE27", "gneE25", "gneE18", "gneE29")
    given = EpisodeConfig(network=str(net), route=route, start="steady", speed_mps=13.0, duration_s=20.0)
    assert given.network_given and given.to_dict()["scenario"]["rebuild"] is False
    with caplog.at_level("WARNING"):
        road = build_road(given.network, route=route, whole=given.whole_network, given=True)
    assert road.net_file.read_bytes() == net.read_bytes()  # the file itself
    assert not [r for r in caplog.records if "traffic light" in r.getMessage()]  # nothing to say: its own programmes
    programme = lambda f: [p.get("duration") for p in ET.parse(f).getroot().find("tlLogic[@id='gneJ12']")]  # noqa: E731
    rebuilt = build_road(str(net), route=route)
    assert programme(road.net_file) == ["3", "3", "10005", "3", "3", "10005"][:len(programme(road.net_file))]
    assert programme(rebuilt.net_file) != programme(road.net_file)
    simulate(given, np.full(given.steps, np.nan), road=road, fcd_path=tmp_path / "fcd.xml")
    first = next(v for _, v in parse_fast_nested(str(tmp_path / "fcd.xml"), "timestep", ["time"], "vehicle", ["id", "x", "y"]))
    lane = ET.parse(net).getroot().find("edge[@id='gneE27']/lane")
    start = [float(c) for c in lane.get("shape").split()[0].split(",")]
    assert float(first.y) == pytest.approx(start[1])  # the file's own coordinates (its lane runs along y = 1.6)
    assert 207.0 <= float(first.x) <= start[0]
    # compressed, the same file
    packed = tmp_path / "corridor.net.xml.gz"
    packed.write_bytes(gzip.compress(net.read_bytes()))
    assert build_road(str(packed), route=route, given=True).net_file.read_bytes() == net.read_bytes()
    assert EpisodeConfig(network=str(net), rebuild=True).to_dict()["scenario"].get("rebuild") is None  # as 0.18 stored it


@pytest.mark.sumo
def test_a_folder_holding_one_network_file_runs_it_as_given(tmp_path):
    """A folder holding a network file and nothing else was rebuilt (0.19): it runs as the file does; a folder of node
    and edge files is built, whatever it says; a campaign 0.19 stored on the folder replays rebuilt, and says so."""
    import shutil

    from d4sumo.engine.scenarios import config_road
    from d4sumo.model.config import EpisodeConfig
    from d4sumo.search.campaign import Campaign
    from d4sumo.sumohome import sumo_home

    net = Path(sumo_home()) / "tools" / "game" / "corridor" / "corridor.net.xml"
    folder = tmp_path / "corridor"
    folder.mkdir()
    shutil.copy(net, folder / net.name)
    route = ("gneE27", "gneE25", "gneE18", "gneE29")
    config = EpisodeConfig(network=str(folder), route=route, start="steady", speed_mps=13.0, duration_s=20.0)
    assert config.network_given and config.to_dict()["scenario"]["rebuild"] is False
    road = config_road(config)
    assert road.given and road.net_file.read_bytes() == net.read_bytes()
    assert [key for key, _, _ in Campaign(config=config).changes_of("0.19")] == ["scenario.rebuild"]
    plain = tmp_path / "plain"
    shutil.copytree(Path(__file__).resolve().parents[2] / "examples" / "roads" / "three_edges", plain)
    assert EpisodeConfig(network=str(plain), rebuild=False).rebuild  # node and edge files: built


@pytest.mark.sumo
def test_a_batch_on_a_network_as_given_plays_its_episodes_one_at_a_time_each_as_alone():
    import numpy as np

    from d4sumo.engine.simulation import simulate, simulate_batch
    from d4sumo.model.attacks.pedals import make_attack
    from d4sumo.model.config import EpisodeConfig
    from d4sumo.model.attacks.maneuvers import attack_plan
    from d4sumo.sumohome import sumo_home

    net = Path(sumo_home()) / "tools" / "game" / "corridor" / "corridor.net.xml"
    config = EpisodeConfig(network=str(net), route=("gneE27", "gneE25", "gneE18", "gneE29"), start="steady",
                           speed_mps=13.0, duration_s=30.0)
    plans = [attack_plan(make_attack("knots"), knots, config) for knots in ([0.6] * 9, [-0.8, 0.9] * 4 + [0.0], [0.1] * 9)]
    for batched, plan in zip(simulate_batch(config, plans), plans):
        alone = simulate(config, plan)
        assert batched.outcome == alone.outcome
        assert all(np.array_equal(batched.trace[n], alone.trace[n]) for n in alone.trace.names)
