"""A SUMO configuration file as the scenario (`d4sumo.sumocfg`): its network, demand, additional files and
options laid over the input document; what d4sumo sets itself overridden and said; what it cannot honour refused."""

from __future__ import annotations

from pathlib import Path

import pytest

from d4sumo import sumocfg
from d4sumo.errors import ConfigError


def write(folder: Path, body: str, name: str = "scenario.sumocfg") -> str:
    (folder / "net").mkdir(exist_ok=True)
    for f in ("net/road.net.xml", "a.rou.xml", "b.rou.xml", "detectors.add.xml"):
        (folder / f).write_text("<x/>")
    (folder / name).write_text(f'<?xml version="1.0"?>\n<sumoConfiguration>\n{body}\n</sumoConfiguration>\n')
    return str(folder / name)


def test_its_files_and_options_are_the_keys_d4sumo_has_for_each_paths_from_its_folder(tmp_path, caplog):
    cfg = write(tmp_path, '<input><net-file value="net/road.net.xml"/><route-files value="a.rou.xml,b.rou.xml"/>'
                          '<additional-files value="detectors.add.xml"/></input>'
                          '<time><begin value="0"/><end value="600"/><step-length value="0.2"/></time>'
                          '<processing><time-to-teleport value="-1"/><ignore-route-errors value="true"/></processing>'
                          '<routing><device.rerouting.adaptation-steps value="180"/></routing>'
                          '<output><fcd-output value="fcd.xml"/></output><report><verbose value="true"/></report>')
    with caplog.at_level("WARNING"):
        doc = sumocfg.expand({"scenario": {"network": cfg, "speed_mps": 13.0}})
    assert doc["scenario"]["network"] == str(tmp_path / "net" / "road.net.xml")
    assert doc["traffic"]["demand"] == [str(tmp_path / "a.rou.xml"), str(tmp_path / "b.rou.xml")]  # merged by departure
    assert doc["scenario"]["additional"] == [str(tmp_path / "detectors.add.xml")]
    assert doc["scenario"]["sumo_options"] == {"time-to-teleport": "-1", "ignore-route-errors": "true",
                                               "device.rerouting.adaptation-steps": "180"}
    assert doc["scenario"]["speed_mps"] == 13.0
    said = " ".join(r.getMessage() for r in caplog.records)
    assert "step-length = 0.2 (scenario.step_s)" in said and "end = 600" in said  # overridden, each named
    assert "left out: fcd-output, verbose" in said


def test_a_document_without_a_sumocfg_is_what_it_was():
    doc = {"scenario": {"network": "highway_4lane"}}
    assert sumocfg.expand(doc) == doc


@pytest.mark.parametrize("body, field, allowed", [
    ('<input><net-file value="net/road.net.xml"/></input><processing><lateral-resolution value="0.8"/></processing>',
     "lateral-resolution", "an option d4sumo can honour"),
    ('<input><net-file value="net/missing.net.xml"/></input>', "net-file", "a file that exists"),
    ('<input><net-file value="net/road.net.xml"/><route-files value="gone.rou.xml"/></input>', "route-files",
     "a file that exists"),
    ('<input><route-files value="a.rou.xml"/></input>', "net-file", "one network file"),
])
def test_what_it_cannot_be_is_refused_in_one_line_naming_the_option(tmp_path, body, field, allowed):
    cfg = write(tmp_path, body)
    with pytest.raises(ConfigError) as refused:
        sumocfg.expand({"scenario": {"network": cfg}})
    assert refused.value.field == f"{cfg}: {field}" and refused.value.allowed.startswith(allowed)
    assert "\n" not in str(refused.value)


def test_a_demand_given_beside_its_route_files_and_a_file_that_does_not_parse_are_refused(tmp_path):
    cfg = write(tmp_path, '<input><net-file value="net/road.net.xml"/><route-files value="a.rou.xml"/></input>')
    with pytest.raises(ConfigError, match="traffic.demand: got 'mine.rou.xml'; allowed: none beside"):
        sumocfg.expand({"scenario": {"network": cfg}, "traffic": {"demand": "mine.rou.xml"}})
    (tmp_path / "broken.sumocfg").write_text("<sumoConfiguration><input>")
    with pytest.raises(ConfigError, match="a SUMO configuration file that parses"):
        sumocfg.expand({"scenario": {"network": str(tmp_path / "broken.sumocfg")}})


@pytest.mark.sumo
def test_sumo_own_corridor_sumocfg_plays_its_network_demand_and_additional_file_writing_none_of_its_outputs(tmp_path):
    """SUMO's corridor example as SUMO ships it: a .sumocfg of its network (signals), its demand (flows without an
    end) and an additional file that dumps edge data and signal switches beside it; every episode loads it with
    those outputs going nowhere (many episodes run side by side)."""
    import shutil

    from d4sumo.cli import main
    from d4sumo.sumohome import sumo_home

    game = Path(sumo_home()) / "tools" / "game"
    shutil.copytree(game / "corridor", tmp_path / "corridor")
    shutil.copy(game / "corridor.sumocfg", tmp_path)
    shutil.copy(game / "input_additional.add.xml", tmp_path)
    db = tmp_path / "r.sqlite"
    assert main(["falsify", "--network", str(tmp_path / "corridor.sumocfg"), "--set", 'scenario.route=["gneE27","gneE25","gneE18","gneE29"]',
                 "--start", "steady", "--speed", "13", "--duration", "30", "--optimizer", "random", "--samples", "3",
                 "--db", str(db), "--quiet"]) == 0
    assert not list(tmp_path.glob("*state.xml")) and not list(Path.cwd().glob("netstate.xml"))
    from d4sumo.search.store import Store

    with Store(db, create=False) as store:
        (campaign,) = store.campaigns()
        scenario = campaign.definition["config"]["scenario"]
        assert scenario["network"].endswith("corridor/corridor.net.xml") and scenario["additional"][0].endswith("input_additional.add.xml")
        assert len(scenario["additional_sha256"]) == 64 and campaign.definition["config"]["traffic"]["demand"][0].endswith("corridor.rou.xml")
    assert main(["replay", str(db), "1"]) == 0


@pytest.mark.sumo
def test_an_additional_file_that_writes_outputs_is_loaded_with_the_files_it_reads_and_writes_nothing(tmp_path, monkeypatch):
    """Found by review: the copy that sends an additional file's outputs nowhere lost the files it reads by a relative
    path (a variable speed sign's steps): SUMO refused it."""
    import numpy as np

    from d4sumo.engine.simulation import simulate
    from d4sumo.model.config import EpisodeConfig
    from d4sumo.sumohome import sumo_home

    (tmp_path / "sub").mkdir()
    (tmp_path / "sub" / "vss.def.xml").write_text('<additional>\n  <step time="0" speed="10"/>\n</additional>\n')
    (tmp_path / "sign.add.xml").write_text('<additional>\n  <variableSpeedSign id="vss" lanes="gneE25_0" file="sub/vss.def.xml"/>\n'
                                           '  <edgeData id="dump" file="dump.xml"/>\n</additional>\n')
    monkeypatch.chdir(tmp_path)
    net = Path(sumo_home()) / "tools" / "game" / "corridor" / "corridor.net.xml"
    config = EpisodeConfig(network=str(net), route=("gneE27", "gneE25", "gneE18", "gneE29"), start="steady", speed_mps=13.0,
                           duration_s=10.0, additional=(str(tmp_path / "sign.add.xml"),))
    assert simulate(config, np.full(config.steps, np.nan)).outcome == "no_crash"
    assert not list(tmp_path.rglob("dump.xml"))
