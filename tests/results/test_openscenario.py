"""A stored counterexample out as OpenDRIVE and OpenSCENARIO 1.2 (results/openscenario.py), checked by
ASAM's own checkers, and back: netconvert imports the road, d4sumo plays the exported attacker motion on
it, and the same crash comes."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from conftest import made_ahead, side_by_side
from d4sumo.errors import ConfigError
from d4sumo.results.openscenario import heading_rad, read_motion

SUCCESS_KNOTS = "0.46,-0.65,0.73,0.08,-0.4,-0.15,-0.94,-0.75,0.34"


def run(*argv, cwd=None):
    return subprocess.run([sys.executable, "-m", "d4sumo.cli", *argv], capture_output=True, text=True, timeout=300, cwd=cwd)


#: the campaign each test below exports from, as falsify's flags
CAMPAIGNS = {
    # seed 2's first two samples: a success (v2-v3) and an attacker crash (v0-v1), one counterexample of each kind
    "checked": ("--start", "steady", "--setpoint", "5", "--optimizer", "random", "--samples", "2", "--seed", "2"),
    "swerving": ("--maneuver", "swerve", "--controller", "timegap", "--start", "steady", "--speed", "28", "--optimizer",
                 "random", "--samples", "4"),
    "refused": ("--start", "steady", "--optimizer", "random", "--samples", "2"),
}


@made_ahead()
def campaigns(tmp_path_factory):
    """Each campaign of CAMPAIGNS run by `d4sumo falsify` into a database of its own, side by side: {name: (the
    process, the database)}. The tests only read them."""
    folder = tmp_path_factory.mktemp("campaigns")
    names = list(CAMPAIGNS)
    done = side_by_side([lambda name=name: run("falsify", *CAMPAIGNS[name], "--db", str(folder / f"{name}.sqlite"), "--quiet")
                         for name in names])
    return {name: (ran, folder / f"{name}.sqlite") for name, ran in zip(names, done)}


def xosc_issues(path: Path, tmp: Path) -> dict[str, list[str]]:
    """ASAM's OpenSCENARIO checker (asam-qc-openscenarioxml) on a file: the issues of each of its checks."""
    from qc_baselib import Configuration, Result
    from qc_openscenario import constants
    from qc_openscenario.main import run_checks

    config_file = tmp / "xosc-config.xml"
    config_file.write_text(f'<?xml version="1.0" encoding="UTF-8"?><Config><Param name="InputFile" value="{path}"/>'
                           f'<CheckerBundle application="{constants.BUNDLE_NAME}"><Param name="resultFile" '
                           f'value="{tmp / "xosc.xqar"}"/></CheckerBundle></Config>')
    config = Configuration()
    config.load_from_file(str(config_file))
    result = Result()
    result.register_checker_bundle(name=constants.BUNDLE_NAME, description="", version=constants.BUNDLE_VERSION, summary="")
    result.set_result_version(version=constants.BUNDLE_VERSION)
    run_checks(config, result)
    checkers = {c.checker_id: c for b in result.get_checker_bundle_results() for c in b.checkers}
    assert checkers["check_asam_xosc_xml_valid_schema"].status.name == "COMPLETED"  # against OpenSCENARIO 1.2's schema
    return {k: [i.description for i in c.issues] for k, c in checkers.items()}


def test_the_heading_is_openscenarios_and_a_ballistic_trajectory_gives_back_its_speeds(tmp_path):
    assert heading_rad(90.0) == 0.0 and heading_rad(0.0) == pytest.approx(np.pi / 2) and heading_rad(180.0) == pytest.approx(1.5 * np.pi)
    dt, v = 0.05, [20.0, 21.0, 19.5, 0.3, 0.0, 0.0]  # then it stops within a step (at 8 m/s^2: in 0.0375 s), and stands
    x = [0.0]
    for a, b in zip(v, v[1:]):
        x.append(x[-1] + ((a + b) / 2 * dt if b > 0 else a * a / (2 * 8.0)))  # stopping within the step at 8 m/s^2
    vertices = "".join(f'<Vertex time="{k * dt!r}"><Position><WorldPosition x="{xi!r}" y="5.0"/></Position></Vertex>'
                       for k, xi in enumerate(x))
    path = tmp_path / "s.xosc"
    path.write_text(f'<OpenSCENARIO><Storyboard><Init><Actions><Private entityRef="v0"><PrivateAction><LongitudinalAction>'
                    f'<SpeedAction><SpeedActionTarget><AbsoluteTargetSpeed value="20.0"/></SpeedActionTarget></SpeedAction>'
                    f'</LongitudinalAction></PrivateAction></Private></Actions></Init></Storyboard>'
                    f'<Trajectory name="v0_as_played"><Shape><Polyline>{vertices}</Polyline></Shape></Trajectory></OpenSCENARIO>')
    assert read_motion(path, "v0", dt, 7) == pytest.approx([21.0, 19.5, 0.3, 0.0, 0.0, 0.0, 0.0], abs=1e-9)
    with pytest.raises(ConfigError) as info:
        read_motion(path, "v9", dt, 6)
    assert info.value.field == "--openscenario"


@pytest.mark.sumo
def test_an_exported_counterexample_passes_asams_checkers_and_replays_to_the_same_crash_on_its_road_imported_back(
        tmp_path, asam_opendrive_checker, campaigns):
    ran, db = campaigns["checked"]
    assert ran.returncode == 0
    from d4sumo.search.campaign import open_store

    with open_store(db, create=False) as store:
        samples = store.samples()
    crashed = [s for s in samples if s.outcome != "no_crash"]
    assert {s.outcome for s in crashed} >= {"success", "attacker_crash"} or len(crashed) >= 2

    def exported_and_replayed(s):
        """The sample's export, ASAM's OpenDRIVE checker's issues with its road, and its replay on that road."""
        out = tmp_path / f"sample{s.id}"
        exported = run("export", str(db), str(s.id), "--openscenario", str(out))
        if exported.returncode != 0:
            return exported, None, None
        checks = tmp_path / f"checks{s.id}"
        checks.mkdir()
        road_issues = asam_opendrive_checker(out / "road.xodr", checks)
        back = run("replay", str(db), str(s.id), "--openscenario", str(out / "scenario.xosc"), "--network",
                   str(out / "road.xodr"), "--json")
        return exported, road_issues, back

    # each sample's commands side by side: they read the database and write folders of their own
    for s, (exported, road_issues, back) in zip(crashed, side_by_side([lambda s=s: exported_and_replayed(s) for s in crashed])):
        out = tmp_path / f"sample{s.id}"
        assert exported.returncode == 0, exported.stderr
        assert not any(issues for issues in xosc_issues(out / "scenario.xosc", tmp_path).values())
        assert not any(issues for issues in road_issues.values())
        assert back.returncode == 0, back.stderr
        summary = json.loads(back.stdout)
        assert summary["reproduced"] and summary["collision"]["pair"] == s.collision["pair"]
        assert abs(summary["collision"]["time_s"] - s.collision["time_s"]) <= 0.05
        assert max(summary["largest_position_difference_m"].values()) < 1e-3  # measured: 2e-5 m


@pytest.mark.sumo
def test_a_swerving_attackers_export_replays_to_the_same_crash(tmp_path, campaigns):
    """Its lane changes come from the stored sample; its speeds from the trajectory, read along its lane (the
    heading it starts with: a lane change turns its heading, the more the slower it drives): the same crash,
    every car where it was to the FCD's precision. Regression: read along its turning heading, the cars
    were up to 5 m from where they were, and the replay was still called reproduced."""
    ran, db = campaigns["swerving"]
    assert ran.returncode == 0
    from d4sumo.search.campaign import open_store

    with open_store(db, create=False) as store:
        crashed = [s for s in store.samples() if s.outcome != "no_crash"]
    assert crashed
    s = crashed[0]
    assert run("export", str(db), str(s.id), "--openscenario", str(tmp_path / "x")).returncode == 0
    back = run("replay", str(db), str(s.id), "--openscenario", str(tmp_path / "x" / "scenario.xosc"), "--network",
               str(tmp_path / "x" / "road.xodr"), "--json")
    summary = json.loads(back.stdout)
    assert back.returncode == 0 and summary["reproduced"] and summary["collision"]["pair"] == s.collision["pair"]
    assert max(summary["largest_position_difference_m"].values()) < 1e-3  # measured: 5e-5 m at most


@pytest.mark.sumo
def test_what_cannot_be_exported_or_replayed_gets_one_line_and_writes_nothing(tmp_path, campaigns):
    ran, stored = campaigns["refused"]
    assert ran.returncode == 0
    db = tmp_path / "c.sqlite"
    shutil.copy(stored, db)
    afile = tmp_path / "a.txt"
    afile.write_text("x")
    cases = [
        (("export", str(db), "1"), "--openscenario"),
        (("export", str(db), "9", "--openscenario", str(tmp_path / "o")), "sample: got 9"),
        (("export", str(db), "1", "--openscenario", str(afile)), "a folder (this is a file)"),
        (("export", str(db), "1", "--openscenario", str(tmp_path / "no" / "o")), "a new one in an existing folder"),
        (("replay", str(db), "1", "--network", "road.xodr"), "with --openscenario"),
        (("replay", str(db), "1", "--openscenario", str(afile)), "an OpenSCENARIO file d4sumo exported"),
        (("replay", str(db), "1", "--openscenario", str(tmp_path / "s2" / "scenario.xosc")), "the export of sample 1 (this one is sample 2's)"),
        # regression: a position that is no number was played (a NaN), or ended in a traceback (a word)
        (("replay", str(db), "2", "--openscenario", str(tmp_path / "s2" / "nan.xosc")), "positions, headings and initial speed numbers"),
        (("replay", str(db), "2", "--openscenario", str(tmp_path / "s2" / "word.xosc")), "positions, headings and initial speed numbers"),
        # regression: sample 2 of another database's campaign was played as this one's, and said not to reproduce
        (("replay", str(db), "2", "--openscenario", str(tmp_path / "s2" / "foreign.xosc")), "(this one is of another campaign, exported from"),
    ]
    assert run("export", str(db), "2", "--openscenario", str(tmp_path / "s2")).returncode == 0
    exported = (tmp_path / "s2" / "scenario.xosc").read_text()
    at = exported.index("<WorldPosition x=\"", exported.index("v0_as_played")) + len("<WorldPosition x=\"")
    for name, value in (("nan", "nan"), ("word", "ten")):  # v0's first timed position's x
        (tmp_path / "s2" / f"{name}.xosc").write_text(exported[:at] + value + exported[exported.index('"', at):])
    key = re.search(r'name="d4sumo.campaign" value="(\w+)"', exported).group(1)
    (tmp_path / "s2" / "foreign.xosc").write_text(exported.replace(key, "0" * len(key)))
    # side by side: each refused command reads the database only
    for (argv, said), result in zip(cases, side_by_side([lambda argv=argv: run(*argv) for argv, _ in cases])):
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1 and said in lines[0] and "Traceback" not in result.stderr, (argv, result.stderr)
    assert not (tmp_path / "o").exists() and sorted(p.name for p in tmp_path.iterdir()) == ["a.txt", "c.sqlite", "s2"]


@pytest.mark.sumo
def test_a_message_attack_is_refused_and_an_honest_cooperative_platoon_exports_its_channel(tmp_path, capsys):
    """A lie over V2V was exported as an attacker that only drives (the lie nowhere in the file): it is refused
    in one line; an honest cooperative platoon's followers carry their channel, part of the system under test."""
    from d4sumo.cli import main

    lies, honest = tmp_path / "lies.sqlite", tmp_path / "honest.sqlite"
    common = ["--controller", "cacc", "--start", "steady", "--duration", "10", "--samples", "1", "--quiet"]
    assert main(["falsify", *common, "--set", "attack.message=offset", "--set", "attack.message_field=speed",
                 "--db", str(lies)]) == 0
    assert main(["falsify", *common, "--set", "v2v.latency_s=0.2", "--db", str(honest)]) == 0
    capsys.readouterr()
    assert main(["export", str(lies), "1", "--openscenario", str(tmp_path / "lie")]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and "without a message attack" in err and not (tmp_path / "lie").exists()
    # issue 48: the sample is the value refused, not the folder it was to be written into
    assert "sample: got '1 (its campaign has a message attack, offset)'" in err and str(tmp_path / "lie") not in err
    assert main(["export", str(honest), "1", "--openscenario", str(tmp_path / "ok")]) == 0
    text = (tmp_path / "ok" / "scenario.xosc").read_text()
    assert 'name="v2v.latency_s" value="0.2"' in text and 'name="v2v.beacon_interval_s" value="0.1"' in text


@pytest.mark.sumo
def test_a_counterexample_among_traffic_on_a_curved_real_motorway_exports_as_it_ran_and_replays_within_a_centimetre(tmp_path):
    """Issue 48: on SUMO's Bremen motorway (curved, geo-referenced) with its own demand, the export is in the network's
    coordinates with its geo-reference, every platoon car drives its trajectory (the followers, the systems under test,
    while followers_as_played says so), the traffic that came near drives its own; the replay gives the same crash, every
    car within 1 cm (measured: 1e-4 m; 2-11 cm before the positions were read along the lanes as SUMO counts them)."""
    from xml.etree import ElementTree as ET

    from d4sumo.sumohome import sumo_home

    game = Path(sumo_home()) / "tools" / "game" / "highway"
    db = tmp_path / "bremen.sqlite"
    ran = run("falsify", "--network", str(game / "highway.net.xml"), "--set",
              'scenario.route=["145354574","189597495","E0","191842213"]', "--set",
              f'traffic.demand="{game / "highway.rou.xml"}"', "--start", "steady", "--speed", "30", "--duration", "20",
              "--optimizer", "random", "--samples", "3", "--seed", "1", "--db", str(db), "--quiet")
    assert ran.returncode == 0, ran.stderr
    from d4sumo.search.campaign import open_store

    with open_store(db, create=False) as store:
        sample = next(s for s in store.samples() if s.outcome != "no_crash")
    out = tmp_path / "x"
    exported = run("export", str(db), str(sample.id), "--openscenario", str(out))
    assert exported.returncode == 0, exported.stderr
    road = ET.parse(out / "road.xodr").getroot().find("header")
    assert "+proj=utm +zone=32" in road.find("geoReference").text and road.find("offset").get("x") == "498221.06"
    scenario = ET.parse(out / "scenario.xosc").getroot()
    objects = [o.get("name") for o in scenario.iter("ScenarioObject")]
    assert objects[:4] == ["v0", "v1", "v2", "v3"] and any(o.startswith("traffic.") for o in objects)
    played = {t.get("name") for t in scenario.iter("Trajectory")}
    assert {f"{vid}_as_played" for vid in objects} == played  # every car drives as it drove, traffic included
    assert [p.get("name") for p in scenario.iter("ParameterDeclaration")] == ["followers_as_played"]
    assert [c.get("name") for c in scenario.iter("Controller")] == ["v1_switching", "v2_switching", "v3_switching"]
    west, east = float(road.get("west")), float(road.get("east"))
    x0 = float(next(scenario.iter("Vertex")).find("./Position/WorldPosition").get("x"))
    assert west <= x0 <= east  # the network's own coordinates
    assert not any(issues for issues in xosc_issues(out / "scenario.xosc", tmp_path).values())
    back = run("replay", str(db), str(sample.id), "--openscenario", str(out / "scenario.xosc"), "--json")
    assert back.returncode == 0, back.stderr
    summary = json.loads(back.stdout)
    assert summary["reproduced"] and summary["collision"]["pair"] == sample.collision["pair"]
    assert max(summary["largest_position_difference_m"].values()) < 0.01


@pytest.mark.sumo
def test_a_sample_of_a_campaign_that_searched_its_situation_exports_and_replays_in_its_own(tmp_path, capsys):
    """Regression: the export wrote the campaign's setpoint and speed (its ranges' low ends), and the replay of the
    exported motion played there, not in the sample's own situation."""
    from d4sumo.cli import main
    from d4sumo.search.campaign import open_store

    db = tmp_path / "situation.sqlite"
    assert main(["falsify", "--set", "scenario.setpoint_m=[3, 12]", "--set", "scenario.speed_mps=[20, 30]", "--start", "steady",
                 "--duration", "20", "--optimizer", "random", "--samples", "10", "--db", str(db), "--quiet"]) == 0
    with open_store(db, create=False) as store:
        s = next(s for s in store.samples() if s.outcome != "no_crash")
    capsys.readouterr()
    assert main(["export", str(db), str(s.id), "--openscenario", str(tmp_path / "x")]) == 0
    text = (tmp_path / "x" / "scenario.xosc").read_text()
    assert f'name="setpoint_m" value="{s.params[-2]!r}"' in text and f'name="target_speed_mps" value="{s.params[-1]!r}"' in text
    capsys.readouterr()
    assert main(["replay", str(db), str(s.id), "--openscenario", str(tmp_path / "x" / "scenario.xosc"), "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    assert summary["reproduced"] and max(summary["largest_position_difference_m"].values()) < 1e-3
