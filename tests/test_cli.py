"""The command line: real runs, and one clear line with exit code 2 for every bad input."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

from conftest import made_ahead, side_by_side, sigint_at_default
from d4sumo.cli import main
from d4sumo.search.optimizers import EARLIER_OPTIONS


def run(*argv):
    return subprocess.run([sys.executable, "-m", "d4sumo.cli", *argv], capture_output=True, text=True, timeout=120)


@pytest.mark.sumo
def test_simulate_json_summary_with_fcd(tmp_path):
    fcd = tmp_path / "out.xml"
    result = run("simulate", "--setpoint", "7", "--speed", "25", "--start", "rest",
                 "--knots=0.46,-0.65,0.73,0.08,-0.4,-0.15,-0.94,-0.75,0.34", "--fcd", str(fcd), "--json")
    assert result.returncode == 0, result.stderr
    s = json.loads(result.stdout)
    assert s["outcome"] == "success"
    assert s["first_collision"]["pair"] == "v2-v3"
    assert s["robustness"] > 0
    assert set(s["min_gaps_m"]) == {"v0-v1", "v1-v2", "v2-v3"} and s["min_gaps_m"]["v2-v3"] < 0
    assert s["config"]["controller"]["acc_kp"] == 0.9304
    assert fcd.is_file() and "acceleration=" in fcd.read_text()[:5000]


@pytest.mark.sumo
def test_simulate_reads_a_toml_config_and_flags_override_it(tmp_path, capsys):
    cfg = tmp_path / "c.toml"
    cfg.write_text('[scenario]\nsetpoint_m = 9\nstart = "steady"\n[attack]\nfamily = "constant"\nparams = [0.2]\n')
    assert main(["simulate", "--config", str(cfg), "--setpoint", "6", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["config"]["scenario"]["setpoint_m"] == 6 and s["config"]["scenario"]["start"] == "steady"
    assert s["attack"]["family"] == "constant" and s["attack"]["values"] == [0.2]


@pytest.mark.sumo
def test_scenarios_lists_the_variants(capsys):
    assert main(["scenarios"]) == 0
    out = capsys.readouterr().out
    assert "highway_4lane" in out and "highway_1lane" in out


@pytest.mark.sumo
def test_a_campaign_against_a_mixed_platoon_of_sumo_models_is_stored_exported_and_replayed(tmp_path, capsys):
    db = tmp_path / "m.sqlite"
    argv = ["falsify", "--controller", "sumo:ACC,switching,sumo:IDM", "--set", "controller.v1.tau=0.5",
            "--optimizer", "random", "--samples", "5", "--seed", "3", "--db", str(db), "--quiet", "--json"]
    assert main(argv) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["samples"] == 5
    csv_path = tmp_path / "m.csv"
    assert main(["export", str(db), "--out", str(csv_path)]) == 0
    header, first = csv_path.read_text().splitlines()[:2]
    column = header.split(",").index("system")
    assert first.split(",")[column] == "sumo:ACC(tau=0.5) / switching / sumo:IDM"
    assert main(["replay", str(db), str(s["best"]["sample_id"]), "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["reproduced"] is True


@pytest.mark.sumo
def test_one_controller_flag_replaces_a_config_files_mixed_platoon(tmp_path, capsys):
    cfg = tmp_path / "mixed.toml"
    cfg.write_text('[[controller]]\nclass = "sumo:ACC"\n[[controller]]\nclass = "switching"\n'
                   '[[controller]]\nclass = "sumo:IDM"\ntau = 1.5\n')
    assert main(["simulate", "--config", str(cfg), "--duration", "5", "--json"]) == 0
    assert [c["class"] for c in json.loads(capsys.readouterr().out)["config"]["controller"]] == ["sumo:ACC", "switching", "sumo:IDM"]
    assert main(["simulate", "--config", str(cfg), "--controller", "timegap", "--duration", "5", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["config"]["controller"]["class"] == "timegap"


def test_the_network_flags_help_names_every_kind_of_road_it_takes(capsys):
    """Regression: its help said "scenario variant ... or a folder", never a *.net.xml nor what to do with an OSM file."""
    assert main(["falsify", "--help"]) == 0
    said = " ".join(capsys.readouterr().out.split())
    assert ("--network NETWORK the road: a shipped variant (see `d4sumo scenarios`), a folder of one *.nod.xml and one "
            "*.edg.xml (or of one *.net.xml), or a *.net.xml file" in said and "netconvert --osm-files" in said)


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["--network", "autobahn"], "--network (scenario.network): got 'autobahn'"),
        (["--setpoint", "-1"], "--setpoint (scenario.setpoint_m): got -1.0; allowed: a number in (0, 200]"),
        (["--followers", "0"], "--followers (scenario.followers): got 0"),
        (["--knots=-1,1.5"], "--knots (attack.params: m1): got 1.5; allowed: a number in [-1, 1]"),
        (["--knots=-1,x"], "--knots: got '-1,x'"),
        (["--attack", "sine"], "--params"),
        (["--set", "vehicle.wheels=4"], "vehicle.wheels"),
        (["--knots=1", "--constant", "1"], "one attack"),
    ],
)
def test_bad_input_is_one_clear_line_and_exit_2(argv, expected, capsys):
    assert main(["simulate", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and err.startswith("d4sumo: error: ")
    assert expected in err


def test_malformed_toml_is_one_clear_line(tmp_path, capsys):
    cfg = tmp_path / "bad.toml"
    cfg.write_text("[scenario\n")
    assert main(["simulate", "--config", str(cfg)]) == 2
    assert "valid TOML" in capsys.readouterr().err


def test_a_missing_sumo_binary_is_one_clear_line(tmp_path, monkeypatch, capsys):
    import d4sumo.engine.netconvert as netconvert

    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))  # nothing cached: netconvert must run
    monkeypatch.setattr(netconvert, "sumo_binary", lambda name, explicit=None: str(tmp_path / "no" / name))
    assert main(["simulate"]) == 2
    err = capsys.readouterr().err
    assert "netconvert" in err and "Traceback" not in err


def test_an_unknown_flag_is_exit_2():
    result = run("simulate", "--setpoitn", "3")
    assert result.returncode == 2 and "unrecognized arguments" in result.stderr


@pytest.mark.sumo
def test_falsify_labels_every_number_of_the_best_samples_collision(tmp_path, capsys):
    """Regression: the summary gave 'v2-v3 at 24.00 s, 181.4 m, 63.1 km/h', three numbers without a word."""
    db = tmp_path / "r.sqlite"
    assert main(["falsify", "--optimizer", "random", "--samples", "6", "--seed", "2", "--db", str(db), "--quiet"]) == 0
    lines = capsys.readouterr().out.splitlines()
    assert re.fullmatch(r"  distinct successes: \d+ attacks? \(parameters more than 5% of their range apart\), \d+ kinds? of "
                        r"crash \(by the pair, the time in 2 s bins and the speed difference in 10 km/h bins\)", lines[2]), lines[2]
    assert lines[3].startswith("  best: sample ") and ", robustness " in lines[3]
    assert re.fullmatch(r"  first collision: v\d-v\d collided at t = \d+\.\d\d s, -?\d+\.\d m along the road, "
                        r"speed difference \d+\.\d km/h", lines[4]), lines[4]


@pytest.mark.sumo
def test_falsify_then_export_and_replay_a_stored_sample(tmp_path, capsys):
    db = tmp_path / "r.sqlite"
    assert main(["falsify", "--optimizer", "random", "--samples", "6", "--seed", "2", "--db", str(db), "--quiet", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["samples"] == 6 and sum(s["outcomes"].values()) == 6
    best = s["best"]["sample_id"]

    csv_path = tmp_path / "r.csv"
    assert main(["export", str(db), "--out", str(csv_path)]) == 0
    lines = csv_path.read_text().splitlines()
    assert len(lines) == 7 and lines[0].startswith("sample_id,campaign_id,index,network") and lines[0].endswith(",m8")
    import csv

    rows = list(csv.DictReader(lines))
    assert "min_gap_v0-v1_m,min_gap_v1-v2_m,min_gap_v2-v3_m,m0" in lines[0]
    for row in rows:  # the minimum gaps agree with the outcome
        gaps = [float(row[f"min_gap_v{i}-v{i + 1}_m"]) for i in range(3)]
        expected = "attacker_crash" if gaps[0] < 0 else "success" if min(gaps[1:]) < 0 else "no_crash"
        assert row["outcome"] == expected

    fcd = tmp_path / "best.xml"
    assert main(["replay", str(db), str(best), "--fcd", str(fcd), "--json"]) == 0
    replay = json.loads(capsys.readouterr().out)
    assert replay["reproduced"] is True and replay["robustness"] == s["best"]["robustness"]
    assert fcd.is_file()


@pytest.mark.sumo
@pytest.mark.parametrize("tamper, named", [
    ("pair = 'v0-v1', time_s = 1.0", "collision"),
    ("min_gaps = json_set(min_gaps, '$.\"v1-v2\"', 99.0)", "min_gaps"),
    ("robustness = robustness + 1e-12", "robustness"),
])
def test_replay_compares_the_whole_stored_verdict_and_exits_1_when_it_differs(tmp_path, capsys, tamper, named):
    """Regression: replay compared only the robustness and the outcome, and exited 0 even when it said
    the sample differs: a stored collision record or minimum gap it did not reproduce passed unnoticed."""
    import sqlite3

    db = tmp_path / "r.sqlite"
    assert main(["falsify", "--optimizer", "random", "--samples", "3", "--seed", "4", "--db", str(db), "--quiet"]) == 0
    with sqlite3.connect(db) as con:
        sample = con.execute("SELECT id FROM sample WHERE pair IS NOT NULL ORDER BY id LIMIT 1").fetchone()[0]
    capsys.readouterr()
    assert main(["replay", str(db), str(sample)]) == 0
    assert "reproduces the stored sample exactly" in capsys.readouterr().out
    with sqlite3.connect(db) as con:
        con.execute(f"UPDATE sample SET {tamper} WHERE id = ?", (sample,))
    assert main(["replay", str(db), str(sample), "--json"]) == 1
    replay = json.loads(capsys.readouterr().out)
    assert replay["reproduced"] is False and replay["differs"] == [named]
    assert main(["replay", str(db), str(sample)]) == 1
    assert f"differs from the stored sample: {named}: stored" in capsys.readouterr().out


@pytest.mark.sumo
def test_knots_that_act_past_the_episodes_end_are_named(tmp_path, capsys):
    """Issue 37: a 17 s episode searched 9 knots over 48 s without a word. Knots from 30 s on (PCHIP: a
    knot shapes the two intervals before it) change nothing in it, and the note says which."""
    assert main(["falsify", "--duration", "17", "--samples", "2", "--db", str(tmp_path / "a.sqlite"), "--quiet"]) == 0
    err = capsys.readouterr().err
    assert "4 of the knots attack's 9 parameters (m5, m6, m7, m8) change nothing in a 17 s episode" in err
    assert main(["falsify", "--samples", "2", "--db", str(tmp_path / "b.sqlite"), "--quiet"]) == 0
    assert "change nothing" not in capsys.readouterr().err


@pytest.mark.sumo
def test_a_warm_up_campaign_stored_by_0_11_replays_with_the_minimum_gaps_it_stored(tmp_path, capsys):
    """d4sumo 0.11 and before stored the minimum gaps of a warm-up's whole episode, the warm-up included;
    0.12 stores them from the attack's start. A campaign 0.11 began holds samples of either meaning (0.12
    resumed it): each reproduces exactly; one stored now is compared with the attack's window."""
    import sqlite3

    db = tmp_path / "r.sqlite"
    assert main(["falsify", "--start", "warmup", "--controller", "timegap", "--optimizer", "random", "--samples", "2",
                 "--db", str(db), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["replay", str(db), "1", "--json"]) == 0
    now = json.loads(capsys.readouterr().out)
    whole = {k: min(v, now["warmup_min_gaps_m"][k]) for k, v in now["min_gaps_m"].items()}
    assert whole != now["min_gaps_m"]  # the warm-up from rest came closer than the attack
    with sqlite3.connect(db) as con:  # as 0.11 stored it
        con.execute("UPDATE campaign SET version = '0.11.0'")
        con.execute("UPDATE sample SET min_gaps = ? WHERE id = 1", (json.dumps(whole),))
    assert main(["replay", str(db), "1"]) == 0
    assert "reproduces the stored sample exactly" in capsys.readouterr().out
    assert main(["replay", str(db), "2"]) == 0  # a sample 0.12 added when it resumed the campaign
    assert "reproduces the stored sample exactly" in capsys.readouterr().out
    with sqlite3.connect(db) as con:  # the same minima, stored by this version: the attack's window was meant
        con.execute("UPDATE campaign SET version = '0.12.0'")
    assert main(["replay", str(db), "1"]) == 1
    assert "differs from the stored sample: min_gaps" in capsys.readouterr().out


@pytest.mark.sumo
def test_a_cut_in_campaign_is_stored_exported_replayed_and_plotted_by_lane(tmp_path, capsys):
    db = tmp_path / "r.sqlite"
    argv = ["falsify", "--maneuver", "cutin", "--set", "scenario.cutin_follower=2", "--start", "steady",
            "--optimizer", "random", "--samples", "8", "--db", str(db), "--quiet", "--json"]
    assert main(argv) == 0
    s = json.loads(capsys.readouterr().out)
    assert sum(s["outcomes"].values()) == 8 and s["outcomes"].get("error", 0) == 0
    csv_path = tmp_path / "r.csv"
    assert main(["export", str(db), "--out", str(csv_path)]) == 0
    header, first = csv_path.read_text().splitlines()[:2]
    assert header.split(",")[8] == "maneuver" and header.endswith(",m8,t_lc_s") and first.split(",")[8] == "cutin"
    for sample in range(1, 9):
        assert main(["replay", str(db), str(sample), "--json"]) == 0
        replay = json.loads(capsys.readouterr().out)
        assert replay["reproduced"] is True
        assert replay["config"]["scenario"]["maneuver"] == "cutin" and "lead-v1" in replay["min_gaps_m"]
    png = tmp_path / "ts.png"
    assert main(["plot", "time-space", str(db), "--sample", "1", "--out", str(png)]) == 0
    assert png.stat().st_size > 10_000


@pytest.mark.parametrize(
    "argv, expected",
    [
        (["--samples", "0"], "--samples (search.samples): got 0"),
        (["--maneuver", "cutin", "--network", "highway_1lane"],
         "--maneuver (scenario.maneuver): got 'cutin'; allowed: a road with at least 2 lanes that lead on, the platoon's and those to its left (highway_1lane has 1)"),
        (["--maneuver", "cutin", "--set", "scenario.cutin_follower=5"], "scenario.cutin_follower: got 5"),
        (["--maneuver", "cutin", "--formula", "eventually(gap_1 <= 0)"], "unknown: gap_1"),
        (["--formula", "eventually(foo < 1)"], "unknown: foo"),
        (["--formula", "always(gap_1 >"], "rtamt can parse"),
        (["--attack", "knots", "--delta", "5"], "attack.horizon_s: got 48.0; allowed: a whole multiple of delta_s=5 s"),
        (["--seed", "-2"], "--seed (search.seed)"),
    ],
)
def test_bad_falsify_input_is_one_line_and_writes_nothing(argv, expected, tmp_path, capsys):
    db = tmp_path / "r.sqlite"
    assert main(["falsify", "--db", str(db), "--quiet", *argv]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count("\n") == 0 and expected in err
    assert not db.exists()


def test_a_database_that_is_not_ours_is_refused(tmp_path, capsys):
    db = tmp_path / "notes.sqlite"
    db.write_text("not a database")
    assert main(["falsify", "--db", str(db), "--quiet"]) == 2
    assert "not a d4sumo results database" in capsys.readouterr().err
    assert db.read_text() == "not a database"
    assert main(["export", str(tmp_path / "missing.sqlite")]) == 2


def test_output_piped_into_head_ends_quietly(tmp_path):
    """Regression: `d4sumo export db | head` ended with a BrokenPipeError traceback."""
    from d4sumo.search.campaign import Campaign
    from d4sumo.search.store import Store

    db = tmp_path / "r.sqlite"
    with Store(db) as store:
        cid = store.open_campaign(Campaign().definition(), 5000)
        store.add_samples(cid, [(i, [0.1] * 9, -0.5, "no_crash", None, {"v0-v1": 1.0}, 0.01, None) for i in range(5000)])
    result = subprocess.run(f"{sys.executable} -m d4sumo.cli export {db} | head -1", shell=True, capture_output=True,
                            text=True, timeout=120)
    assert result.stdout.startswith("sample_id,") and result.stdout.count("\n") == 1
    assert result.stderr == ""


ROOT = Path(__file__).resolve().parent.parent
GUIDE = [ROOT / "README.md", *sorted((ROOT / "docs").glob("*.md"))]


def documented_commands() -> list[tuple[str, str]]:
    """(page, command) for every d4sumo and tools/ command the README and the guide show: each line of a
    code block, and each inline `d4sumo ...` with arguments (a synopsis with alternatives, a|b, is not one)."""
    import re

    found = []
    for page in GUIDE:
        text = page.read_text()
        for block in re.findall(r"```[a-z]*\n(.*?)```", text, flags=re.S):
            for line in re.sub(r"\\\n\s*", " ", block).splitlines():  # a command continued with a backslash is one line
                for part in re.sub(r"\s+#.*$", "", line.strip()).split("&&"):
                    part = part.strip().removeprefix("$ ").removeprefix(".venv/bin/")
                    if part.startswith(("d4sumo ", "python tools/")):
                        found.append((page.name, part))
        for span in re.findall(r"`([^`\n]+)`", re.sub(r"```.*?```", "", text, flags=re.S)):
            if span.startswith(("d4sumo ", "python tools/")) and "|" not in span and len(span.split()) > 2:
                found.append((page.name, span))
    return found


@made_ahead()
def tools_helps(tmp_path_factory):
    """Each tools/ script the README and the guide show, run with --help (the scripts side by side): {its path
    as shown: the process}."""
    import shlex

    scripts = sorted({argv[1] for argv in (shlex.split(c) for _, c in documented_commands())
                      if argv[0] != "d4sumo" and (ROOT / argv[1]).is_file()})
    return dict(zip(scripts, side_by_side([lambda script=script: subprocess.run(
        [sys.executable, str(ROOT / script), "--help"], capture_output=True, text=True, timeout=120) for script in scripts])))


def test_every_command_in_the_readme_and_the_guide_is_valid(tools_helps):
    """Each d4sumo command parses as shown; each tools/ script exists and has the flags shown."""
    import shlex

    from d4sumo.cli import _join_negative_lists
    from d4sumo.cli.parser import build_parser

    commands = documented_commands()
    assert len(commands) > 30 and {page for page, _ in commands} >= {"README.md", "campaigns.md", "sweeps.md", "roads.md"}
    helps: dict[str, str] = {}
    for page, command in commands:
        argv = shlex.split(command)
        if argv[0] == "d4sumo":
            try:
                build_parser().parse_args(_join_negative_lists(argv[1:]))
            except SystemExit as exc:
                raise AssertionError(f"{page}: `{command}` does not parse (exit {exc.code})") from None
            continue
        script = ROOT / argv[1]
        assert script.is_file(), f"{page}: {argv[1]} does not exist"
        if argv[1] not in helps:
            done = tools_helps[argv[1]]
            assert done.returncode == 0, done.stderr
            helps[argv[1]] = done.stdout
        for flag in (a.split("=")[0] for a in argv[2:] if a.startswith("--")):
            assert flag in helps[argv[1]], f"{page}: {argv[1]} has no {flag}"


def test_every_flag_in_the_readme_and_the_guide_exists_and_the_main_ones_are_documented(capsys):
    import re

    from d4sumo.cli.parser import build_parser

    parser = build_parser()
    known = {o for action in parser._actions for o in action.option_strings}  # the command's own: --version
    for action in parser._actions:
        for name, sub in getattr(action, "choices", None).items() if isinstance(getattr(action, "choices", None), dict) else []:
            for a in sub._actions:
                known.update(a.option_strings)
    text = "\n".join(page.read_text() for page in GUIDE)
    mentioned = set(re.findall(r"(?<![\w-])--[a-z][a-z-]+", text))
    tools = {"--nthreads", "--port", "--runs", "--baseline", "--repeats", "--batch", "--db", "--benchmark",
             "--grid", "--osm-files", "--specs", "--held", "--recheck-dt", "--first-seed", "--jobs", "--no-deps",
             "--there-python", "--there-env", "--here-env", "--traffic", "--fmu", "--systems", "--examples", "--only",
             "--opendrive-output", "--opendrive-files", "--python", "--cooperative", "--collision", "--figure",
             "--proposals", "--clients", "--situation", "--seeds", "--verifai-python", "--ramps", "--problems"}  # dask's, netgenerate's, netconvert's, SUMO's, tools/', pip's
    assert mentioned - known - tools == set()
    main_flags = {"--config", "--network", "--followers", "--setpoint", "--speed", "--start", "--warmup", "--set", "--knots",
                  "--attack", "--params", "--optimizer", "--samples", "--seed", "--formula", "--d-safe", "--db", "--fcd",
                  "--json", "--gui", "--workers", "--dask", "--out", "--sample"}
    assert main_flags - mentioned == set()


@pytest.mark.sumo
@pytest.mark.parametrize("optimizer, earlier", [(o, e) for o, earliers in EARLIER_OPTIONS.items() for e in earliers])
def test_falsify_says_how_to_go_on_with_a_campaign_an_earlier_version_ran(tmp_path, capsys, optimizer, earlier):
    """d4sumo 0.2 ran bo one point per score with scikit-optimize's GP, 0.3 five at a time with it, 0.6 and
    before with the exact GP however many scores; 0.4 ran ce without noise; 0.9 ran auto without suffix
    moves and exploring from its design on, 0.8 also through stalls, 0.7 with uniform exploration."""
    db = str(tmp_path / "r.sqlite")
    flags = [a for k, v in earlier.items() for a in ("--set", f"search.{optimizer}.{k}={v}")]
    run = ["falsify", "--optimizer", optimizer, "--db", db, "--quiet", "--json"]
    assert main([*run, "--samples", "2", *flags]) == 0
    capsys.readouterr()
    assert main([*run, "--samples", "3"]) == 0
    err = capsys.readouterr().err
    assert " ".join(f"--set search.{optimizer}.{k}={v}" for k, v in earlier.items()) in err and err.count("\n") == 1
    assert main([*run, "--samples", "3", *flags]) == 0
    assert capsys.readouterr().err == ""  # it went on with it


@pytest.mark.sumo
def test_a_resumed_campaigns_progress_bar_starts_at_what_is_stored_and_a_complete_one_shows_none(tmp_path, capsys):
    db = str(tmp_path / "r.sqlite")
    falsify = ["falsify", "--optimizer", "random", "--seed", "2", "--db", db]
    assert main([*falsify, "--samples", "3"]) == 0
    capsys.readouterr()
    assert main([*falsify, "--samples", "3"]) == 0
    err = capsys.readouterr().err
    assert "all 3 samples stored already, nothing to run" in err and "sample/s" not in err and "0/3" not in err
    assert main([*falsify, "--samples", "5"]) == 0
    err = capsys.readouterr().err
    assert "3 of 5 samples stored already: resuming" in err and "3/5" in err and "5/5" in err
    assert "0/5" not in err and "1/5" not in err


def test_ctrl_c_while_the_libraries_load_is_one_line_and_exit_130():
    """Regression: Ctrl-C in the first half second of any command (numpy, scipy, rtamt and SUMO's bindings
    loading) ended in a traceback of the import."""
    code = """
import sys
import d4sumo.cli
assert "numpy" not in sys.modules, "d4sumo.cli loads the library at import"
class Interrupt:  # a Ctrl-C that lands while the parser's imports load
    def find_spec(self, name, path=None, target=None):
        if name == "d4sumo.cli.parser":
            raise KeyboardInterrupt
sys.meta_path.insert(0, Interrupt())
sys.exit(d4sumo.cli.main(["falsify"]))
"""
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60)
    assert (done.returncode, done.stderr) == (130, "d4sumo: interrupted\n")


@pytest.mark.sumo
@pytest.mark.parametrize("sig, code", [(2, 130), (15, 143)])
def test_an_episode_stopped_midway_leaves_no_fcd_and_keeps_the_file_it_would_replace(tmp_path, sig, code):
    """Regression: Ctrl-C or SIGTERM in `simulate --fcd` left the episode's first seconds in the file,
    closed with </fcd-export> so that it looked whole, in place of the file that was there."""
    import os
    import time

    fcd = tmp_path / "sim.xml"
    fcd.write_text("an earlier episode")
    proc = subprocess.Popen([sys.executable, "-m", "d4sumo.cli", "simulate", "--step", "0.001", "--duration", "120",
                             "--fcd", str(fcd)], stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                            preexec_fn=sigint_at_default)
    deadline = time.time() + 60
    while not any(p.name.endswith(".part") and p.stat().st_size > 0 for p in tmp_path.iterdir()) and time.time() < deadline:
        time.sleep(0.1)
    os.kill(proc.pid, sig)
    _, err = proc.communicate(timeout=30)
    assert proc.returncode == code and "Traceback" not in err
    assert [p.name for p in tmp_path.iterdir()] == ["sim.xml"] and fcd.read_text() == "an earlier episode"


@pytest.mark.sumo
def test_ctrl_c_in_falsify_says_where_the_samples_are_and_how_to_resume(tmp_path):
    import os
    import signal
    import sqlite3
    import time

    db = tmp_path / "r.sqlite"
    cmd = [sys.executable, "-m", "d4sumo.cli", "falsify", "--optimizer", "random", "--samples", "5000", "--db", str(db)]
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                            preexec_fn=sigint_at_default)
    deadline = time.time() + 60
    while time.time() < deadline:
        try:
            if sqlite3.connect(f"file:{db}?mode=ro", uri=True).execute("SELECT COUNT(*) FROM sample").fetchone()[0] >= 70:
                break
        except sqlite3.Error:
            pass
        time.sleep(0.2)
    os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does
    proc.wait(timeout=20)
    err = proc.stderr.read().decode()
    assert proc.returncode == 130 and "Traceback" not in err
    assert f"campaign interrupted; every sample it finished is in {db}: run the same command to resume" in err
    assert err.count("interrupted") == 1


MYCTL = '''
import pathlib
pathlib.Path("imported.marker").write_text("myctl ran")

from dataclasses import dataclass

from d4sumo.model.controllers.control import SwitchingController, SwitchingParams


class Gentle(SwitchingController):
    """A user's controller: the paper's, with its own parameter table."""

    @dataclass(frozen=True)
    class Params(SwitchingParams):
        gentle: float = 1.0
'''


@pytest.mark.sumo
def test_a_controller_in_the_current_folder_is_found_and_reading_its_database_imports_nothing(tmp_path):
    """A module beside the user (python -m's rule) is a controller; reading a database that names one
    (export, the tables) never imports it; replaying says it imports it, and without it says how to
    make it importable, not "damaged"."""
    (tmp_path / "myctl.py").write_text(MYCTL)
    marker = tmp_path / "imported.marker"

    script = Path(sys.executable).parent / "d4sumo"  # the installed command: its sys.path lacks the current folder
    assert script.is_file()

    def d4sumo(*argv, cwd=tmp_path):
        return subprocess.run([str(script), *argv], cwd=cwd, capture_output=True, text=True, timeout=120)

    done = d4sumo("falsify", "--controller", "myctl:Gentle", "--optimizer", "random", "--samples", "3", "--db", "r.sqlite",
                  "--quiet")
    assert done.returncode == 0, done.stderr
    assert marker.is_file()
    marker.unlink()
    exported = d4sumo("export", "r.sqlite")
    assert exported.returncode == 0 and "myctl:Gentle(" in exported.stdout.splitlines()[1]
    from d4sumo.results.records import load_records

    records = load_records([tmp_path / "r.sqlite"])
    assert len(records) == 3 and records[0].system.startswith("myctl:Gentle(")
    assert not marker.exists(), "reading a database imported the controller it names"
    replayed = d4sumo("replay", "r.sqlite", "1")
    assert replayed.returncode == 0, replayed.stderr
    assert "importing myctl (a follower controller of r.sqlite: campaign 1) to simulate it" in replayed.stderr
    assert marker.is_file()
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    refused = d4sumo("replay", str(tmp_path / "r.sqlite"), "1", cwd=elsewhere)
    assert refused.returncode == 2 and "Traceback" not in refused.stderr and "damaged" not in refused.stderr
    assert refused.stderr.count("\n") == 2  # the import note, and one line of why
    assert ("its follower controller myctl:Gentle cannot be simulated here: myctl did not import here "
            "(No module named 'myctl'): run from the folder that holds myctl.py, or put its folder on PYTHONPATH"
            in refused.stderr)


#: bo as d4sumo 0.7 ran it by default: with today's options, and with those of 0.7.0
EARLIER_DEFAULT = [[], ["--set", "search.bo.inducing=0"]]


@made_ahead()
def falsify_chains(tmp_path_factory):
    """The commands of the two tests below: each test's one after another on a database of its own ({db}),
    the tests' side by side. {("earlier", flags) or "unused": the processes in order}."""
    chains = {("earlier", tuple(earlier)): [
        ("falsify", "--optimizer", "bo", *earlier, "--samples", "3", "--db", "{db}", "--quiet"),
        ("falsify", "--samples", "3", "--db", "{db}", "--quiet"),
        ("falsify", "--optimizer", "bo", *earlier, "--samples", "3", "--db", "{db}", "--quiet"),
    ] for earlier in EARLIER_DEFAULT}
    chains["unused"] = [
        ("falsify", "--samples", "2", "--db", "{db}", "--quiet", "--set", "search.bo.inducing=0"),
        ("falsify", "--optimizer", "bo", "--samples", "2", "--db", "{db}", "--quiet", "--set", "search.bo.inducing=0"),
    ]

    def play(chain):
        db = str(tmp_path_factory.mktemp("falsify") / "r.sqlite")
        return [run(*(db if a == "{db}" else a for a in argv)) for argv in chain]

    return dict(zip(chains, side_by_side([lambda chain=chain: play(chain) for chain in chains.values()])))


@pytest.mark.sumo
@pytest.mark.parametrize("earlier", EARLIER_DEFAULT)  # bo now, and as 0.7.0 stored it
def test_falsify_names_a_campaign_run_by_the_earlier_default_optimizer(earlier, falsify_chains):
    """The default optimiser became auto: a database whose campaign ran by default with bo (d4sumo 0.7
    and before, whose bo had no inducing points) is named, with the flags that go on with it."""
    first, now, again = falsify_chains["earlier", tuple(earlier)]  # bo, then the default, then bo again
    assert first.returncode == 0
    assert now.returncode == 0, now.stderr
    assert "holds this campaign run with bo, the default optimiser of d4sumo 0.7 and before" in now.stderr
    assert now.stderr.rstrip().endswith("To go on with that one: --optimizer bo" + (" --set search.bo.inducing=0" if earlier else ""))
    assert again.returncode == 0 and "holds this campaign run with" not in again.stderr


@pytest.mark.sumo
def test_falsify_names_a_campaign_among_traffic_an_earlier_version_ran(tmp_path):
    """d4sumo 0.16 let traffic enter after the warm-up unchecked: its campaign is another one now, and falsify
    with the same flags says so, with the flag that goes on with it."""
    db = str(tmp_path / "r.sqlite")
    flags = ["--start", "steady", "--duration", "20", "--set", "traffic.vehicles_per_hour=600", "--optimizer", "random",
             "--samples", "2", "--db", db, "--quiet"]
    assert main(["falsify", *flags, "--set", "traffic.insertion_checks=false"]) == 0  # as 0.16 stored it
    now = run("falsify", *flags)
    assert now.returncode == 0, now.stderr
    assert "holds this campaign as d4sumo 0.16 or before ran it" in now.stderr
    # its one traffic played once without the attack: whose doing its crashes are
    assert "  without the attack (the attacker only cruising, in the same traffic): no crash in 1 episode\n" in now.stdout
    assert now.stderr.rstrip().endswith("To go on with that one: --set traffic.insertion_checks=false")
    # one an earlier auto ran too (d4sumo 0.10: held inputs cut across signals): both keys said at once
    older = [*flags[:6], "--samples", "2", "--db", str(tmp_path / "older.sqlite"), "--quiet"]  # the default: auto
    assert main(["falsify", *older, "--set", "search.auto.per_signal=0", "--set", "traffic.insertion_checks=false"]) == 0
    said = run("falsify", *older)
    assert said.returncode == 0 and said.stderr.rstrip().endswith(
        "To go on with that one: --set search.auto.per_signal=0 --set traffic.insertion_checks=false"), said.stderr


@pytest.mark.sumo
def test_falsify_names_a_cooperative_campaign_0_19_ran_with_beacons_read_whatever_the_radar_saw(tmp_path):
    """d4sumo 0.19's cooperative followers read the platoon's beacons with another car cut in between: its campaign
    is another one now, and falsify with the same flags says so, with the flag that goes on with it."""
    flags = ["--start", "steady", "--controller", "cacc", "--set", "traffic.vehicles_per_hour=600", "--duration", "10",
             "--optimizer", "random", "--samples", "2", "--db", str(tmp_path / "r.sqlite"), "--quiet"]
    assert main(["falsify", *flags, "--set", "v2v.match_radar=false"]) == 0  # as 0.19 stored it
    now = run("falsify", *flags)
    assert now.returncode == 0, now.stderr
    assert ("holds this campaign as d4sumo 0.19 or before ran it (cooperative followers reading the beacons whatever "
            "their radar saw)") in now.stderr
    assert now.stderr.rstrip().endswith("To go on with that one: --set v2v.match_radar=false")


@pytest.mark.sumo
def test_falsify_names_a_cooperative_cut_in_0_20_ran_with_the_radar_matched_to_the_beacons_and_goes_on_with_it(tmp_path):
    """Found by the release fixtures: d4sumo 0.20.0 matched the followers' radar to the beacons' sender in the
    lane-changing maneuvers too (the review that followed kept it to traffic). Its campaigns replay as they ran
    (tests/search/test_releases.py); one run with today's d4sumo is another campaign, and falsify says so, with the
    flag that goes on with 0.20.0's."""
    import sqlite3

    db = tmp_path / "r.sqlite"
    flags = ["--start", "steady", "--controller", "cacc", "--maneuver", "cutin", "--duration", "10", "--optimizer", "random",
             "--samples", "2", "--db", str(db), "--quiet"]
    assert main(["falsify", *flags, "--set", "v2v.match_in_maneuvers=true"]) == 0  # as 0.20.0 stored it
    (stored,) = [json.loads(d) for (d,) in sqlite3.connect(db).execute("SELECT definition FROM campaign")]
    assert stored["config"]["v2v"]["match_radar"] is True and "match_in_maneuvers" not in stored["config"]["v2v"]
    _names_the_earlier_campaign_and_goes_on_with_it(flags, "v2v.match_in_maneuvers=true", "holds this campaign as d4sumo 0.20 or "
                                                    "before ran it (cooperative followers in a lane-changing maneuver")


@pytest.mark.sumo
def test_falsify_names_a_campaign_on_a_road_of_ones_own_an_earlier_version_ran_through_red_lights(tmp_path):
    """d4sumo 0.18 drove the platoon through red lights: its campaign on a road of one's own is another one now, and
    falsify with the same flags says so, with the flag that goes on with it (which then resumes it)."""
    road = str(Path(__file__).resolve().parent.parent / "examples" / "roads" / "three_edges")
    flags = ["--network", road, "--start", "steady", "--duration", "10", "--optimizer", "random", "--samples", "2",
             "--db", str(tmp_path / "r.sqlite"), "--quiet"]
    assert main(["falsify", *flags, "--set", "scenario.signals=ignore"]) == 0  # as 0.18 stored it
    _names_the_earlier_campaign_and_goes_on_with_it(flags, "scenario.signals=ignore", "holds this campaign as d4sumo 0.18 "
                                                    "or before ran it (the platoon driving through red lights)")


def _names_the_earlier_campaign_and_goes_on_with_it(flags: list[str], then: str, said: str) -> None:
    """falsify with ``flags`` (2 samples, --quiet last) on a database holding the campaign as an earlier version ran it
    (``--set then``): it says so (``said``) with the flag that goes on with it, and with that flag resumes it."""
    now = run("falsify", *flags)
    assert now.returncode == 0, now.stderr
    assert said in now.stderr
    assert now.stderr.rstrip().endswith(f"To go on with that one: --set {then}")
    again = run("falsify", *[a if a != "2" else "3" for a in flags[:-1]], "--set", then)
    assert again.returncode == 0 and "2 of 3 samples stored already: resuming" in again.stderr, again.stderr


@pytest.mark.sumo
@pytest.mark.parametrize("given", ["folder", "network file"])
def test_a_sample_on_a_road_of_ones_own_replays_from_another_folder_and_after_the_road_moved(tmp_path, given):
    """Regression: the summary's "replay it:" line failed from any folder but the one the campaign ran in
    (its road a relative path), and once the road's files moved; the campaign keeps them by their content."""
    import shutil

    work, elsewhere = tmp_path / "work", tmp_path / "elsewhere"
    elsewhere.mkdir()
    shutil.copytree(ROOT / "examples" / "roads" / "three_edges", work / "road")
    if given == "network file":  # netconvert's network of it, named by its path
        built = subprocess.run([sys.executable, "-c", "import sys; from d4sumo.engine.scenarios import build_road; "
                                "print(build_road(sys.argv[1]).net_file)", "road"], cwd=work, capture_output=True, text=True)
        shutil.copy(built.stdout.strip(), work / "road.net.xml")
    network = "road/" if given == "folder" else "road.net.xml"
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "cache")}
    ran = lambda *argv, cwd: subprocess.run([sys.executable, "-m", "d4sumo.cli", *argv], capture_output=True, text=True,  # noqa: E731
                                            timeout=120, cwd=cwd, env=env)
    assert ran("falsify", "--network", network, "--start", "steady", "--optimizer", "random", "--samples", "2", "--db",
               "r.sqlite", "--quiet", cwd=work).returncode == 0
    there = ran("replay", str(work / "r.sqlite"), "2", "--json", cwd=elsewhere)
    assert there.returncode == 0, there.stderr
    assert json.loads(there.stdout)["reproduced"]
    assert f"no road {network} here: playing the copy of the road the campaign ran" in there.stderr
    (work / network.rstrip("/")).rename(tmp_path / "moved")
    moved = ran("replay", "r.sqlite", "1", "--json", cwd=work)
    assert moved.returncode == 0 and json.loads(moved.stdout)["reproduced"], moved.stderr


@pytest.mark.sumo
def test_falsify_says_when_an_optimizers_options_go_unused(falsify_chains):
    """Earlier notes said `--set search.bo.inducing=0`; with auto the default, bo's table alone would go
    unused without a word."""
    said, quiet = falsify_chains["unused"]  # the default with bo's options, then bo with them
    assert said.returncode == 0
    assert "note: the options of [search.bo] are unused: this campaign runs auto (--optimizer bo runs bo)" in said.stderr
    assert quiet.returncode == 0 and "unused" not in quiet.stderr


@pytest.mark.sumo
@pytest.mark.parametrize("argv, note", [
    (["falsify", "--attack", "persistent", "--delta", "3"], "--delta is unused: the persistent attack has no delta_s"),
    (["falsify", "--start", "rest", "--warmup", "10"], "--warmup is unused: start rest has no warm-up drive"),
    (["simulate", "--horizon", "30"], "--horizon is unused: there is no attack (the attacker cruises)"),
    (["simulate", "--set", "scenario.cutin_follower=2"], "--set scenario.cutin_follower is unused: the inlane maneuver"),
    (["falsify", "--maneuver", "cutin", "--set", "scenario.obstacle_distance_m=100"],
     "--set scenario.obstacle_distance_m is unused: the cutin maneuver does not read it"),
    (["simulate", "--formula", "always(gap_0 > 0)", "--d-safe", "1"], "--d-safe is unused: it is the paper's psi's"),
    (["falsify", "--formula", "eventually(gap_2 <= 0)", "--d-safe", "1"], "--d-safe is unused: it is the paper's psi's"),
])
def test_a_flag_the_episode_does_not_read_is_said(tmp_path, capsys, argv, note):
    """Regression: these flags were dropped without a word."""
    extra = ["--samples", "2", "--quiet", "--db", str(tmp_path / "r.sqlite")] if argv[0] == "falsify" else ["--duration", "5"]
    assert main([*argv, *extra]) == 0
    assert f"d4sumo: note: {note}" in capsys.readouterr().err


@pytest.mark.sumo
def test_a_gap_a_hair_under_the_collision_distance_is_printed_under_it(capsys):
    """Regression: --json rounded the minimum gaps to 4 decimals and the text to 2, so a cut-in that
    collided with v0-v1 at -0.0000089 m printed that gap as -0.0 (and "-0.00 m") beside attacker_crash."""
    argv = ["simulate", "--followers", "1", "--network", str(Path(__file__).resolve().parent.parent / "examples" / "roads" / "three_edges"),
            "--maneuver", "cutin", "--set", "scenario.cutin_follower=1", "--set", "scenario.lane_change_s=0",
            "--start", "steady", "--setpoint", "5", "--speed", "15", "--duration", "30", "--controller", "timegap",
            "--attack", "knots", "--params=-1,-1,1,1,-1,-1,-1,-0.04,-1,0.274"]
    assert main([*argv, "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["outcome"] == "attacker_crash" and s["first_collision"]["pair"] == "v0-v1"
    assert -1e-4 < s["min_gaps_m"]["v0-v1"] < 0
    assert main(argv) == 0
    assert "v0-v1 -0.000009 m" in capsys.readouterr().out


@pytest.mark.sumo
@pytest.mark.parametrize("maneuver", ["cutin", "cutout"])
def test_knots_with_a_lane_change_take_the_lane_change_time_last(capsys, maneuver):
    """Regression: --knots counted the lane change time as a knot, so 10 values asked for 11, and 11 for 12:
    a cut-in or cut-out could never be played with --knots."""
    assert main(["simulate", "--maneuver", maneuver, "--knots=0,0,0,0,0,0,0,0,0,5", "--json"]) == 0
    s = json.loads(capsys.readouterr().out)
    assert s["attack"]["values"][-1] == 5.0 and len(s["attack"]["values"]) == 10
    assert s["config"]["scenario"]["maneuver"] == maneuver


def test_knots_beside_a_maneuver_that_is_no_name_is_one_line(capsys):
    assert main(["simulate", "--knots=0,0,0", "--set", "scenario.maneuver=[1]"]) == 2
    assert "scenario.maneuver: got [1]" in capsys.readouterr().err


@pytest.mark.sumo
def test_falsify_with_a_formula_of_ones_own_says_how_many_samples_falsified_it(tmp_path, capsys):
    """The outcomes count crashes; with a formula of one's own the summary said nothing of how often it broke."""
    from d4sumo.search.campaign import open_store

    db = tmp_path / "f.sqlite"
    assert main(["falsify", "--formula", "always(gap_1 > 6)", "--duration", "10", "--samples", "4", "--db", str(db), "--quiet"]) == 0
    out = capsys.readouterr().out
    with open_store(db, create=False) as store:
        rhos = [s.robustness for s in store.iter_samples()]
    assert f"formula falsified (robustness < 0) by {sum(r < 0 for r in rhos)} of 4 samples" in out
    assert main(["falsify", "--duration", "10", "--samples", "2", "--db", str(db), "--quiet"]) == 0
    assert "formula falsified" not in capsys.readouterr().out  # the paper's specification: its outcomes say it


def test_a_campaigns_best_parameters_name_what_the_pedals_do_not_set():
    """Issue 48: a lie's parameters (its value and start) were printed among the knots without names."""
    from d4sumo.cli.campaigns import params_text
    from d4sumo.inputs import campaign_of

    lie = campaign_of({"controller": {"class": "cacc"}, "attack": {"message": "offset", "message_field": "speed"}})
    family = lie.family()
    text = params_text(family, [0.5] * 9 + [-14.15, 1.25])
    assert text == "0.500, " * 8 + "0.500; msg_value -14.150, msg_start_s 1.250"
    plain = campaign_of({}).family()
    assert params_text(plain, [0.25] * 9) == ", ".join(["0.250"] * 9)


def test_the_controller_flag_names_every_registered_controller(capsys):
    """Found by review: the IDM, registered from its own file, was missing from --controller's help."""
    from d4sumo.model.controllers.control import registered_controllers, resolve_controller

    assert main(["simulate", "--help"]) == 0
    said = " ".join(capsys.readouterr().out.split())
    own = [name for name in registered_controllers() if resolve_controller(name).__module__.startswith("d4sumo.")]
    assert len(own) >= 6 and all(re.search(rf"\b{name}\b", said) for name in own), said  # (tests register others)


def test_version_says_which_speed_ups_this_install_has(capsys, monkeypatch):
    """A machine without a C or C++ compiler installs without the extensions and plays the same episodes, slower:
    --version says so, and how to have them."""
    from conftest import NATIVE_CALLS_EXPECTED

    from d4sumo import __version__
    from d4sumo.engine import calls
    from d4sumo.model.controllers import compiled

    assert main(["--version"]) == 0
    out = capsys.readouterr().out
    assert out.startswith(f"d4sumo {__version__}\n")
    assert "stepped in C: yes" in out and ("C++ calls: yes" in out) == NATIVE_CALLS_EXPECTED, out
    monkeypatch.setattr(compiled, "play_column", None)
    monkeypatch.setattr(calls, "_NATIVE", {"calls": None})
    assert main(["--version"]) == 0
    out = capsys.readouterr().out
    assert "stepped in C: no (install with a C compiler" in out and "C++ calls: no (on Linux, install with a C++ compiler" in out
