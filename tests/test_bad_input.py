"""Malformed input of every kind, fed to the command line as a new user would: each ends in one clear
line (`d4sumo: error: ...`), exit code 2, no traceback, and every stored file byte-identical."""

from __future__ import annotations

import re
import shutil
import subprocess
import sqlite3
import sys
from pathlib import Path

import pytest

from d4sumo.cli import main

SIMULATE = [
    ["--setpoint", "inf"], ["--setpoint", "nan"], ["--setpoint", "-1"], ["--setpoint", "abc"],
    ["--followers", "3.5"], ["--followers", "0"], ["--followers", "11"], ["--start", "fast"],
    ["--network", "nowhere"], ["--network", "/"], ["--knots=1,x"], ["--knots="], ["--knots=2"], ["--knots", "1,,2"],
    ["--params", "-0.5,0.2,1"], ["--attack", "sine", "--params", "-0.5,0.2,1"], ["--attack", "sine"],
    ["--attack", "sine", "--params", "0.5,0.2"], ["--attack", "zigzag"], ["--constant", "2"],
    ["--knots=1,1", "--constant", "1"], ["--controller", "foo"], ["--controller", "nope.module:X"],
    ["--controller", "os:path"], ["--controller", ""], ["--set", "scenario.setpoint_m=inf"], ["--set", "nosection"],
    ["--set", "vehicle.length_m=[1,2]"], ["--set", "scenario.setpont_m=3"], ["--set", "scenario.route=[]"], ["--set", "controller.acc_kp=nan"],
    ["--set", "controller.acc_kp=-1"], ["--set", "=3"], ["--set", "a.b.c=1"],
    ["--formula", "eventually[5:2](gap_1 <= 0)"], ["--formula", "eventually[0:1e12](gap_1 <= 0)"],
    ["--formula", "eventually[0:0.01](gap_1 <= 0)"], ["--formula", "always(foo > 0)"], ["--formula", "always(gap_1 >"],
    ["--formula", "always(gap_9 > 0)"], ["--formula", ""], ["--d-safe", "nan"], ["--duration", "0"], ["--step", "2"],
    ["--start", "warmup", "--warmup", "15.01"], ["--warmup", "-1"], ["--speed", "45"], ["--duration", "500"],
    ["--fcd", "/nonexistent/folder/out.xml"], ["--delta", "0"], ["--horizon", "-3"], ["--delta", "5", "--knots=1,1,1", "--horizon", "7"],
    ["--length", "0"], ["--config", "/nonexistent.toml"], ["--bogus"], ["--json", "extra"],
    # SUMO's car-following models: unknown models and attributes, values SUMO itself refuses, mixed platoons
    ["--controller", "sumo:FOO"], ["--controller", "sumo:"], ["--controller", "sumo:IDM", "--set", "controller.speedControlGain=1"],
    ["--controller", "sumo:ACC", "--set", "controller.tau=0"], ["--controller", "sumo:ACC", "--set", "controller.accel=9"],
    ["--controller", "sumo:ACC", "--set", "controller.actionStepLength=0.07"], ["--controller", "sumo:CC", "--set", "controller.active_controller=1"],
    ["--controller", "sumo:ACC,switching"], ["--controller", "sumo:ACC,switching,sumo:IDM", "--set", "controller.tau=1"],
    ["--controller", "sumo:ACC,switching,sumo:IDM", "--set", "controller.v4.tau=1"], ["--controller", "sumo:ACC,,switching"],
    ["--controller", "timegap", "--set", "controller.time_gap_s=-1"],
    ["--controller", "sumo:Krauss", "--set", "scenario.attacker_declared_decel_mps2=0"],
    # a platoon of different vehicles: a car that does not exist, a key or value [vehicle] does not take
    ["--set", "vehicle.v7.length_m=12"], ["--set", "vehicle.lead.length_m=12"], ["--set", "vehicle.v2.length=12"],
    ["--set", "vehicle.v2.length_m=50"], ["--set", "vehicle.v2.vclass=tram"], ["--set", "vehicle.v2.shape=ship"],
    ["--set", "vehicle.v2=3"], ["--set", "vehicle.vclass=rail"], ["--set", "vehicle.shape={a=1}"],
    # the paper's psi and the collisions draw their line at one distance
    ["--set", "scenario.collision_gap_m=0.5", "--d-safe", "0.2"], ["--d-safe", "-1"], ["--d-safe", "7"],
    # issue 48: a lie with no attack played was taken without a word, whatever it said
    ["--set", "attack.message=teleport"], ["--controller", "cacc", "--set", "attack.message_field=colour"],
    ["--controller", "cacc", "--set", "attack.message_sender=9"], ["--set", "attack.message=offset"],
    ["--controller", "cacc", "--set", "attack.message=offset"],
    # a .sumocfg that is none, and the keys it fills
    ["--network", "/nonexistent/scenario.sumocfg"], ["--set", "scenario.signals=stop"], ["--set", "scenario.rebuild=1"],
    ["--set", "scenario.sumo_options={lateral-resolution=0.8}"], ["--set", 'scenario.additional=["/nonexistent.add.xml"]'],
    ["--set", "traffic.merge_by_departure=2"], ["--set", "scenario.join_m=4990"], ["--set", "scenario.join_m=-1"],
    ["--set", 'scenario.sumo_options={scale="x"}'], ["--set", 'scenario.sumo_options={"device.rerouting.bogus"="1"}'],
]


@pytest.mark.parametrize("argv", SIMULATE, ids=lambda a: " ".join(a) or "empty")
def test_simulate_refuses_bad_input_in_one_line(argv, capsys):
    assert main(["simulate", *argv]) == 2
    check_one_line(capsys)


def check_one_line(capsys):
    captured = capsys.readouterr()
    err = captured.err.strip()
    assert err.startswith("d4sumo: error: ") and err.count("\n") == 0, err
    assert "Traceback" not in captured.err + captured.out
    return err


def test_a_list_that_starts_with_a_negative_number_is_read_with_or_without_equals(capsys):
    for argv in (["--attack", "sine", "--params", "-0.5,0.2,1"], ["--attack", "sine", "--params=-0.5,0.2,1"]):
        assert main(["simulate", *argv]) == 2
        assert "amplitude): got -0.5" in check_one_line(capsys)  # read as values, refused by range


def test_gui_without_a_display_is_one_line_at_once(monkeypatch, capsys):
    monkeypatch.delenv("DISPLAY", raising=False)
    monkeypatch.delenv("WAYLAND_DISPLAY", raising=False)
    assert main(["simulate", "--gui"]) == 2
    assert "DISPLAY is not set" in check_one_line(capsys)


def test_a_results_database_path_that_cannot_be_opened_names_the_field_the_value_and_what_is_allowed(tmp_path, capsys):
    missing = tmp_path / "no" / "r.sqlite"
    assert main(["falsify", "--samples", "2", "--db", str(missing)]) == 2
    assert f"results database: got '{missing}'; allowed: a file in an existing folder ({missing.parent} does not exist)" \
        in check_one_line(capsys)
    assert main(["report", str(tmp_path / "none.sqlite"), "--out", str(tmp_path / "r")]) == 2
    assert "allowed: a results database d4sumo wrote (no such file)" in check_one_line(capsys)
    assert main(["export", str(tmp_path), "--out", str(tmp_path / "x.csv")]) == 2
    assert "allowed: a database file (this is a folder)" in check_one_line(capsys)
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing made


def test_output_paths_that_cannot_be_written(tmp_path, capsys):
    assert main(["simulate", "--fcd", str(tmp_path)]) == 2
    assert "this is a folder" in check_one_line(capsys)
    assert main(["simulate", "--fcd", str(tmp_path / "no" / "f.xml")]) == 2
    assert "does not exist" in check_one_line(capsys)
    assert not (tmp_path / "no").exists()


BAD_FILES = {
    "not utf-8": b"[scenario]\nnetwork = '\xff'\n",
    "unknown table": b"[scenaro]\nx = 1\n",
    "unknown key": b"[scenario]\nsetpont_m = 3\n",
    "unknown spec key": b"[spec]\nformulas = 'x'\n",
    "inf gain": b"[controller]\nacc_kp = inf\n",
    "nan vehicle": b"[vehicle]\nmax_decel_mps2 = nan\n",
    "wrong type": b"[scenario]\nfollowers = 'three'\n",
    "table as value": b"scenario = 3\n",
    "bad optimizer option": b"[search.ce]\nelite_fraction = 2.0\n",
    "params in a campaign": b"[attack]\nfamily = 'sine'\nparams = [0.1, 0.1, 0.1]\n",
    "malformed": b"[scenario\n",
}


@pytest.mark.parametrize("name", BAD_FILES)
def test_a_bad_config_file_is_refused_and_writes_nothing(tmp_path, name, capsys):
    config = tmp_path / "c.toml"
    config.write_bytes(BAD_FILES[name])
    db = tmp_path / "r.sqlite"
    assert main(["falsify", "--config", str(config), "--db", str(db), "--quiet"]) == 2
    check_one_line(capsys)
    assert not db.exists()


FALSIFY = [
    ["--samples", "0"], ["--samples", "x"], ["--seed", "-1"], ["--optimizer", "anneal"], ["--attack", "constant"],
    ["--set", "search.ce.batch_size=0"], ["--set", "search.bo.xi=nan"], ["--set", "search.random.x=1"],
    ["--set", "search.samples=-3"], ["--formula", "eventually[0:99](gap_1 <= 0)"], ["--followers", "1"],
    ["--db", "/nonexistent/folder/r.sqlite"],
    # traffic SUMO cannot insert: refused by its warm-up, before a sample is stored
    ["--network", "highway_4lane", "--start", "steady", "--set", "traffic.vehicles_per_hour=3600", "--set", "traffic.warmup_s=40"],
    # regression: a traffic type of a class SUMO does not know (it drove as its default) or with an attribute its
    # <vType> has not (ignored) was stored as a campaign
    ["--start", "steady", "--set", "traffic.types.truck.share=1", "--set", 'traffic.types.truck.vClass="truk"'],
    ["--start", "steady", "--set", "traffic.types.truck.share=1", "--set", "traffic.types.truck.speedfactor=0.5"],
]


@pytest.mark.parametrize("argv", FALSIFY, ids=lambda a: " ".join(a))
def test_falsify_refuses_bad_input_and_creates_no_database(tmp_path, argv, capsys):
    db = tmp_path / "r.sqlite"
    assert main(["falsify", "--db", str(db), "--quiet", *argv]) == 2
    check_one_line(capsys)
    assert not db.exists()


def test_falsify_into_a_folder_or_a_foreign_file_changes_nothing(tmp_path, capsys):
    assert main(["falsify", "--db", str(tmp_path), "--quiet"]) == 2
    check_one_line(capsys)
    foreign = tmp_path / "notes.sqlite"
    foreign.write_bytes(b"not a database" * 100)
    assert main(["falsify", "--db", str(foreign), "--quiet", "--samples", "1"]) == 2
    check_one_line(capsys)
    assert foreign.read_bytes() == b"not a database" * 100


SWEEPS = {
    "not utf-8": b"[grid]\nsetpoint_m = [5.0]\nname = '\xff'\n",
    "unknown grid key": b"[grid]\nsetpoint = [5.0]\n",
    "unknown top key": b"[grid]\nsetpoint_m = [5.0]\n[sweep]\nx = 1\n",
    "grid not lists": b"[grid]\nsetpoint_m = 5.0\n",
    "grid wrong type": b"[grid]\nsetpoint_m = ['five']\n",
    "grid nan": b"[grid]\nsetpoint_m = [nan]\n",
    "unknown search option": b"[grid]\nsetpoint_m = [5.0]\n[search.ce]\nbatch = 3\n",
    "name not a string": b"name = 5\n[grid]\nsetpoint_m = [5.0]\n",
    "reversed formula bounds": b"[grid]\nsetpoint_m = [5.0]\n[spec]\nformula = 'eventually[3:1](gap_1 <= 0)'\n",
    "bad spec key": b"[grid]\nsetpoint_m = [5.0]\n[spec]\nd_safe = 1\n",
    "traffic sumo cannot insert": b"[grid]\ntraffic = [{vehicles_per_hour = 3600, warmup_s = 40}]\n"
                                  b"[scenario]\nnetwork = 'highway_4lane'\nstart = 'steady'\n",
}


@pytest.mark.parametrize("name", SWEEPS)
def test_a_bad_sweep_file_is_refused_and_writes_nothing(tmp_path, name, capsys):
    path = tmp_path / "s.toml"
    path.write_bytes(SWEEPS[name])
    db = tmp_path / "r.sqlite"
    assert main(["sweep", str(path), "--db", str(db), "--quiet"]) == 2
    check_one_line(capsys)
    assert not db.exists()


@pytest.mark.parametrize("argv", [
    ["--dask", "not an address"], ["--dask", "tcp://host:99999"], ["--dask", "http//x:1"], ["--dask-timeout", "-1"],
    ["--dask-timeout", "nan"], ["--workers", "0"], ["--workers", "two"],
], ids=lambda a: " ".join(a))
def test_sweep_flags_are_checked_up_front(tmp_path, argv, capsys):
    path = tmp_path / "s.toml"
    path.write_text("[grid]\nsetpoint_m = [5.0]\n[search]\nsamples = 2\n")
    db = tmp_path / "r.sqlite"
    assert main(["sweep", str(path), "--db", str(db), "--quiet", *argv]) == 2
    check_one_line(capsys)
    assert not db.exists()


# --- commands that read a database: bad flags, damaged databases; never a changed byte ----------


@pytest.fixture(scope="module")
def good_db(tmp_path_factory):
    db = tmp_path_factory.mktemp("good") / "r.sqlite"
    assert main(["falsify", "--optimizer", "random", "--samples", "3", "--db", str(db), "--quiet"]) == 0
    return db


def readers(db, tmp):
    return [
        ["export", str(db)],
        ["replay", str(db), "1"],
        ["report", str(db), "--out", str(tmp / "report"), "--quiet"],
        ["plot", "heatmap", str(db), "--out", str(tmp / "h.png")],
        ["falsify", "--optimizer", "random", "--samples", "4", "--db", str(db), "--quiet"],  # a resume reads it all
    ]


@pytest.mark.sumo
@pytest.mark.parametrize("argv", [
    ["replay", "{db}", "999999"], ["replay", "{db}", "abc"], ["export", "{db}", "--campaign", "99"],
    ["replay", "{db}", "99999999999999999999999"],  # past SQLite's integers: once an OverflowError traceback
    ["plot", "time-space", "{db}", "--out", "{tmp}/f.png", "--sample", "99999999999999999999999"],
    ["export", "{db}", "--out", "{tmp}/absent/x.csv"], ["export", "{db}", "--out", "{tmp}"],
    ["plot", "time-space", "{db}", "--out", "{tmp}/f.png"], ["plot", "heatmap", "{db}", "--out", "{tmp}/absent/f.png"],
    ["plot", "heatmap", "{db}", "--out", "{tmp}/f.png", "--setpoint", "99"], ["plot", "heatmap", "{db}", "--out", "{tmp}/f.xyz"],
    ["replay", "{db}", "1", "--fcd", "{tmp}/absent/f.xml"], ["report", "{db}", "--out", "{tmp}/absent/deep/report"],
    ["report", "{tmp}/missing.sqlite"], ["export", "{tmp}"],
    ["report", "{db}", "--out", "/proc/d4sumo_report"],  # its parent exists, yet nothing can be made there: once a traceback
    ["report", "{db}", "{db}", "--out", "{tmp}/report"],  # every sample counted twice, once
    ["plot", "heatmap", "{db}", "{db}", "--out", "{tmp}/f.png"],
], ids=lambda a: " ".join(a))
def test_reading_commands_refuse_bad_flags_and_change_nothing(good_db, tmp_path, argv, capsys):
    before = good_db.read_bytes()
    argv = [a.format(db=good_db, tmp=tmp_path) for a in argv]
    assert main(argv) == 2
    check_one_line(capsys)
    assert good_db.read_bytes() == before
    assert sorted(p.name for p in good_db.parent.iterdir()) == ["r.sqlite"]
    assert not (tmp_path / "absent").exists()


DAMAGE = {
    "schema version not a number": "UPDATE meta SET value = 'x' WHERE key = 'schema_version'",
    "old schema": "UPDATE meta SET value = '1' WHERE key = 'schema_version'",
    "foreign app": "UPDATE meta SET value = 'other' WHERE key = 'app'",
    "missing table": "DROP TABLE sample",
    "bad params json": "UPDATE sample SET params = '[0.1,'",
    "unknown outcome": "UPDATE sample SET outcome = 'maybe'",
    "orphan sample": "UPDATE sample SET campaign_id = 42",
    "bad definition": "UPDATE campaign SET definition = '[]'",
    "definition of bad values": "UPDATE campaign SET definition = replace(definition, '\"followers\": 3', '\"followers\": -3')",
    "bad min gaps": "UPDATE sample SET min_gaps = 'x'",
}


@pytest.mark.sumo
@pytest.mark.parametrize("damage", DAMAGE)
def test_a_damaged_database_is_one_clear_line_in_every_command(good_db, tmp_path, damage, capsys):
    db = tmp_path / "r.sqlite"
    shutil.copy(good_db, db)
    con = sqlite3.connect(db)
    con.execute(DAMAGE[damage])
    con.commit()
    con.close()
    before = db.read_bytes()
    for argv in readers(db, tmp_path):
        assert main(argv) == 2, argv
        check_one_line(capsys)
        assert db.read_bytes() == before, argv
    assert sorted(p.name for p in tmp_path.iterdir()) == ["r.sqlite"]


@pytest.mark.sumo
def test_a_malformed_page_is_one_clear_line(good_db, tmp_path, capsys):
    db = tmp_path / "r.sqlite"
    data = bytearray(good_db.read_bytes())
    data[4096: 4096 + 8] = b"\x07" * 8  # the second page's header: an invalid page type
    db.write_bytes(bytes(data))
    before = db.read_bytes()
    for argv in readers(db, tmp_path):
        assert main(argv) == 2, argv
        check_one_line(capsys)
        assert db.read_bytes() == before


@pytest.mark.sumo
def test_a_full_device_is_reported_and_leaves_no_file(good_db, tmp_path, monkeypatch, capsys):
    import errno

    import d4sumo.cli as cli

    def full(*args):
        raise OSError(errno.ENOSPC, "No space left on device")

    monkeypatch.setattr(cli.os, "replace", full)
    out = tmp_path / "s.csv"
    assert main(["export", str(good_db), "--out", str(out)]) == 2
    assert "No space left on device" in check_one_line(capsys)
    assert list(tmp_path.iterdir()) == []  # no partial file, never "written"


def test_an_fcd_file_cut_short_is_an_error_and_leaves_nothing(tmp_path):
    from d4sumo.engine.simulation import fcd_file
    from d4sumo.errors import SumoError

    fcd = tmp_path / "f.xml"
    fcd.write_text("kept")
    with pytest.raises(SumoError, match="could not be written completely"):
        with fcd_file(fcd) as part:  # what SUMO leaves on a full disk
            part.write_text('<fcd-export>\n  <timestep time="0.00">\n')
    assert [p.name for p in tmp_path.iterdir()] == ["f.xml"] and fcd.read_text() == "kept"
    with fcd_file(fcd) as part:
        part.write_text('<fcd-export>\n</fcd-export>\n')
    assert [p.name for p in tmp_path.iterdir()] == ["f.xml"] and fcd.read_text().endswith("</fcd-export>\n")


@pytest.mark.sumo
@pytest.mark.parametrize("nodes, edges, expected", [
    ("garbage <<<", "", "netconvert: invalid document structure in the node file, line"),
    ("", "", "netconvert: "),
    ('<nodes><node id="a" x="0" y="0"/></nodes>', "<edges></edges>", "netconvert: No edges loaded"),
    # regression: netconvert crashes on a negative lane count, and the line said "netconvert: no message"
    ('<nodes><node id="a" x="0" y="0"/><node id="b" x="5000" y="0"/></nodes>',
     '<edges><edge id="e1" from="a" to="b" numLanes="-2" speed="30"/></edges>',
     "netconvert: it crashed (signal "),
])
def test_a_road_netconvert_cannot_build_is_one_line_naming_the_network(tmp_path, capsys, nodes, edges, expected):
    """netconvert's own five lines ("Quitting (on error).") once reached the user."""
    (tmp_path / "road.nod.xml").write_text(nodes)
    (tmp_path / "road.edg.xml").write_text(edges)
    assert main(["simulate", "--network", str(tmp_path)]) == 2
    err = capsys.readouterr().err
    assert err.startswith("d4sumo: error: --network (scenario.network): got '") and err.count("\n") == 1, err
    assert expected in err and "Quitting" not in err and "/tmp" not in err.split("allowed:")[1]


@pytest.mark.skipif(not Path("/dev/full").exists(), reason="needs /dev/full")
@pytest.mark.parametrize("argv", [["scenarios"], ["export", "{db}"]])
def test_standard_output_that_cannot_be_written_is_one_line(good_db, argv):
    """Regression: `d4sumo ... > /dev/full` (a full disk) ended in an OSError traceback."""
    with open("/dev/full", "w") as full:
        done = subprocess.run([sys.executable, "-m", "d4sumo.cli", *[a.format(db=good_db) for a in argv]],
                              stdout=full, stderr=subprocess.PIPE, text=True, timeout=120)
    assert (done.returncode, done.stderr) == (2, "d4sumo: error: standard output could not be written (No space left on device)\n")


CONTROLLERS = '''
from dataclasses import dataclass


@dataclass
class P:
    k: float = 1.0


class FailsToBuild:
    Params = P

    def __init__(self, *args, **kwargs):
        raise ValueError("init fails")

    def command(self, *args):
        return 0.0


class FailsToCommand:
    Params = P

    def __init__(self, *args, **kwargs):
        pass

    def command(self, *args):
        raise RuntimeError("cmd fails")


class ParamsNotADataclass:
    Params = dict

    def command(self, *args):
        return 0.0
'''


@pytest.mark.sumo
@pytest.mark.parametrize("module, cls, said", [
    ("raise RuntimeError('boom at import')", "X", "a module that imports without error ({m} raised RuntimeError: boom at import)"),
    ("def broken(:\n", "X", "a module that imports without error ({m} raised SyntaxError: invalid syntax"),
    (CONTROLLERS, "ParamsNotADataclass", "a class with a Params dataclass and an observe() method (or command() on three floats)"),
    (CONTROLLERS, "Missing", "allowed: a class of {m}; {m} imported ("),
    (CONTROLLERS, "FailsToBuild", "the controller of v1 ({m}:FailsToBuild) could not be made: ValueError: init fails"
                                  " (d4sumo -v shows its traceback)"),
    (CONTROLLERS, "FailsToCommand", "the controller of v1 ({m}:FailsToCommand) raised RuntimeError: cmd fails"
                                    " (d4sumo -v shows its traceback)"),
], ids=["raises at import", "syntax error", "Params not a dataclass", "no such class", "__init__ raises", "command raises"])
def test_a_users_controller_that_fails_is_one_line_naming_it(tmp_path, monkeypatch, capsys, module, cls, said):
    """Regression: each of these ended in a traceback of 20-40 lines and exit 1."""
    import uuid

    name = f"ctl_{uuid.uuid4().hex[:8]}"  # a module of its own: Python caches what it imported
    (tmp_path / f"{name}.py").write_text(module)
    monkeypatch.syspath_prepend(str(tmp_path))
    assert main(["simulate", "--duration", "5", "--controller", f"{name}:{cls}"]) == 2
    assert said.format(m=name) in check_one_line(capsys)


@pytest.mark.sumo
def test_d4sumo_v_shows_where_a_users_controller_failed(tmp_path, monkeypatch, capsys):
    (tmp_path / "ctl_shows_where.py").write_text(CONTROLLERS)
    monkeypatch.syspath_prepend(str(tmp_path))
    assert main(["-v", "simulate", "--duration", "5", "--controller", "ctl_shows_where:FailsToCommand"]) == 2
    err = capsys.readouterr().err
    assert "Traceback" in err and re.search(rf'{tmp_path / "ctl_shows_where.py"}", line \d+, in command', err)
    assert err.rstrip().endswith("d4sumo: error: the controller of v1 (ctl_shows_where:FailsToCommand) raised RuntimeError: cmd fails")
