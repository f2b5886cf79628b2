"""An FMU as a follower's controller (model/fmu.py), for real: the shipped switching controller built for
this machine, stepped through fmpy in SUMO episodes, against the Python controller it is."""

from __future__ import annotations

import dataclasses
import json
import os
import shutil
import subprocess
import sys
import zipfile

import numpy as np
import pytest

from conftest import random_plans, side_by_side
from d4sumo.engine.simulation import simulate, simulate_batch
from d4sumo.errors import ConfigError
from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.files import file_sha256
from d4sumo.model.controllers.fmu import SHA_KEY
from d4sumo.search.campaign import open_store

pytestmark = pytest.mark.sumo


def run(*argv, cwd=None, env=None):
    return subprocess.run([sys.executable, "-m", "d4sumo.cli", *argv], capture_output=True, text=True, timeout=300, cwd=cwd,
                          env=env)


def variant(tmp_path, monkeypatch, name: str, version: int = 2, patch: tuple[str, str] | None = None, rename=None):
    """The switching FMU with its C patched (``patch``: old, new) or its variables renamed ({old: new})."""
    import d4sumo.fmus as fmus

    sources = tmp_path / f"{name}-src"
    shutil.copytree(fmus.SOURCES, sources, ignore=shutil.ignore_patterns("*.py", "__pycache__"))
    if patch:
        c = sources / f"fmi{version}.c"
        text = c.read_text()
        assert patch[0] in text
        c.write_text(text.replace(patch[0], patch[1]))
    monkeypatch.setattr(fmus, "SOURCES", sources)
    if rename:
        monkeypatch.setattr(fmus, "VARIABLES", tuple((rename.get(v[0], v[0]), *v[1:]) for v in fmus.VARIABLES))
    return fmus.build_switching_fmu(tmp_path / f"{name}.fmu", version)


def _configs(seed: int, count: int) -> list[EpisodeConfig]:
    rng = np.random.default_rng(seed)
    return [EpisodeConfig(start=str(rng.choice(["rest", "steady", "warmup"])), setpoint_m=float(rng.uniform(3.0, 10.0)),
                          speed_mps=float(rng.uniform(18.0, 32.0)), followers=int(rng.integers(1, 6)), duration_s=40.0)
            for _ in range(count)]


@pytest.mark.parametrize("version, configs, plans", [(2, 10, 10), (3, 4, 5)])
def test_on_random_episodes_the_fmu_is_the_python_controller_verdicts_and_commands(switching_fmus, version, configs, plans):
    """100 random episodes with FMI 2.0 (20 with 3.0): the same outcomes, collision records and minimum
    gaps, and commands that agree to 1e-9 (they are equal: the C does the Python's arithmetic)."""
    worst = 0.0
    for i, python in enumerate(_configs(version, configs)):
        fmu = dataclasses.replace(python, controller=ControllerConfig(f"fmu:{switching_fmus[version]}"))
        drawn = random_plans(python, plans, seed=i)
        for a, b in zip(simulate_batch(python, drawn), simulate_batch(fmu, drawn)):
            assert (a.outcome, a.collisions, a.min_gaps) == (b.outcome, b.collisions, b.min_gaps)
            for j in range(1, python.followers + 1):
                worst = max(worst, float(np.max(np.abs(a.trace[f"cmd_v{j}"] - b.trace[f"cmd_v{j}"]))))
                assert np.array_equal(a.trace[f"mode_v{j}"], b.trace[f"mode_v{j}"])
    assert worst <= 1e-9
    print(f"FMI {version}: the largest difference of a command: {worst:g}")


def test_an_fmu_of_other_names_is_told_them_in_its_table_and_its_parameters_are_set_by_name(tmp_path, monkeypatch):
    renamed = variant(tmp_path, monkeypatch, "renamed", rename={"gap_m": "distance", "command": "pedal"})
    with pytest.raises(ConfigError) as info:
        ControllerConfig(f"fmu:{renamed}")
    assert info.value.field == "controller.gap_m" and "distance" in info.value.allowed
    table = (("gap_m", "distance"), ("command", "pedal"), ("acc_kp", 1.5))
    config = EpisodeConfig(start="steady", setpoint_m=5.0, duration_s=30.0, controller=ControllerConfig(f"fmu:{renamed}", table))
    python = dataclasses.replace(config, controller=ControllerConfig("switching", (("acc_kp", 1.5),)))
    plan = random_plans(config, 1, seed=4)[0]
    a, b = simulate(python, plan), simulate(config, plan)
    assert a.outcome == b.outcome and np.array_equal(a.trace["cmd_v3"], b.trace["cmd_v3"])
    with pytest.raises(ConfigError) as info:
        ControllerConfig(f"fmu:{renamed}", table + (("kp_unknown", 1.0),))
    assert info.value.field == "controller.kp_unknown"


def test_an_acceleration_output_mapped_in_the_table_is_read_though_the_fmu_has_an_output_named_command(tmp_path, monkeypatch):
    """Regression: the default `command` (an output of that name) was read, and the mapped acceleration ignored."""
    fmu = variant(tmp_path, monkeypatch, "two-outputs", rename={"mode": "accel_out"})  # outputs: command, accel_out
    mapped = ControllerConfig(f"fmu:{fmu}", (("acceleration_mps2", "accel_out"),))
    assert dict(mapped.params)["command"] == "" and dict(mapped.params)["acceleration_mps2"] == "accel_out"
    config = EpisodeConfig(start="steady", setpoint_m=5.0, duration_s=10.0, followers=1, controller=mapped)
    episode = simulate(config, random_plans(config, 1, seed=2)[0])
    # the switching controller's mode (0 cruise, 1 ACC) read as an acceleration [m/s^2]: the pedal map's 0 or 1 / 3.5
    assert set(np.unique(episode.trace["cmd_v1"][:-1])) <= {0.0, 1.0 / 3.5}
    assert dict(ControllerConfig(f"fmu:{fmu}").params)["command"] == "command"  # nothing mapped: its command
    both = ControllerConfig(f"fmu:{fmu}", (("command", "command"), ("acceleration_mps2", "accel_out")))
    assert dict(both.params)["command"] == "command"  # a stored campaign's both: the command, as it ran


def test_the_campaign_holds_the_fmu_content_a_changed_fmu_is_refused_where_no_copy_is_kept_and_reading_loads_none(switching_fmus, tmp_path, monkeypatch):
    fmu = tmp_path / "acc.fmu"
    shutil.copy(switching_fmus[2], fmu)
    db = tmp_path / "c.sqlite"
    ran = run("falsify", "--controller", "fmu:acc.fmu", "--start", "steady", "--setpoint", "5", "--optimizer", "random",
              "--samples", "3", "--db", str(db), "--quiet", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    with open_store(db, create=False) as store:
        assert store.campaigns()[0].definition["config"]["controller"][SHA_KEY] == file_sha256(fmu)
    # the replay side by side with the build of the changed FMU (elsewhere in tmp_path, until it is copied in)
    replayed, changed = side_by_side([
        lambda: run("replay", str(db), "1", cwd=tmp_path),
        lambda: variant(tmp_path, monkeypatch, "changed", patch=("switching_step(&((Instance *)c)->law, communicationStepSize);",
                                                                 "switching_step(&((Instance *)c)->law, 2 * communicationStepSize);")),
    ])
    assert replayed.returncode == 0
    stored = db.read_bytes()
    shutil.copy(changed, fmu)
    never_ran = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "empty-cache")}
    # the replays (they read the database) side by side with a campaign of the changed FMU (it writes one): where
    # the campaign ran, its own copy of the FMU replays it (regression: the changed file here refused it); on a
    # machine that never ran it (an empty cache) the changed file is another system, refused
    replay, refused, resumed = side_by_side([
        lambda: run("replay", str(db), "1", cwd=tmp_path),
        lambda: run("replay", str(db), "1", cwd=tmp_path, env=never_ran),
        lambda: run("falsify", "--controller", "fmu:acc.fmu", "--start", "steady", "--setpoint", "5", "--optimizer", "random",
                    "--samples", "6", "--db", str(db), "--quiet", cwd=tmp_path),
    ])
    assert replay.returncode == 0, replay.stderr
    assert "acc.fmu here has changed since the campaign ran: loading the copy of the FMU the campaign ran" in replay.stderr
    said = refused.stderr.strip().splitlines()  # the note that it loads the FMU, then why it will not
    assert refused.returncode == 2 and said[0].startswith("d4sumo: loading fmu:acc.fmu") and len(said) == 2
    assert "acc.fmu has changed since" in said[1] and "Traceback" not in refused.stderr
    assert resumed.returncode == 0  # another system: a campaign of its own, the first one untouched
    fmu.unlink()
    (tmp_path / "elsewhere").mkdir()
    # side by side, each only reads: reading loads no FMU, it need not be there (the export); on a machine that
    # never ran it (an empty cache) the report replays none; where it ran, a sample replays from any folder
    exported, reported, elsewhere = side_by_side([
        lambda: run("export", str(db), cwd=tmp_path),
        lambda: run("report", str(db), "--out", "rep", cwd=tmp_path, env=never_ran),
        lambda: run("replay", str(db), "1", "--json", cwd=tmp_path / "elsewhere"),
    ])
    assert exported.returncode == 0 and exported.stdout.count("\n") == 3 + 6 + 1
    assert db.read_bytes() != stored  # (the second campaign's samples) ...
    with open_store(db, create=False) as store:
        assert len(store.samples(1)) == 3 and len(store.campaigns()) == 2  # ... the first's kept
    # Regression: a report of campaigns whose FMU is gone (or has changed) failed whole; it now shows what
    # it can read and says why it replays none of them
    assert reported.returncode == 0, reported.stderr
    page = (tmp_path / "rep" / "index.html").read_text()
    assert "not replayed here" in page and "no file acc.fmu here" in page
    # Regression: a relative path named no file from another folder, nor once the file was gone; the campaign's
    # content, kept where it ran, replays its sample to the same verdict
    assert elsewhere.returncode == 0, elsewhere.stderr
    assert "no file acc.fmu here: loading the copy of the FMU the campaign ran" in elsewhere.stderr
    assert json.loads(elsewhere.stdout)["reproduced"]


@pytest.mark.parametrize("kind", ["fails", "nan"])
def test_an_fmu_that_fails_or_answers_nan_mid_episode_makes_an_error_sample(tmp_path, monkeypatch, kind):
    step = "    switching_step(&((Instance *)c)->law, communicationStepSize);\n    return fmi2OK;"
    broken = {"fails": step.replace("return fmi2OK;", "return currentCommunicationPoint >= 2.0 ? fmi2Error : fmi2OK;"),
              "nan": step.replace("return fmi2OK;", "if (currentCommunicationPoint >= 2.0) ((Instance *)c)->law.v[VR_COMMAND] = "
                                                    "0.0 / 0.0;\n    return fmi2OK;")}[kind]
    fmu = variant(tmp_path, monkeypatch, kind, patch=(step, broken))
    db = tmp_path / "e.sqlite"
    ran = run("falsify", "--controller", f"fmu:{fmu}", "--start", "steady", "--optimizer", "random", "--samples", "2",
              "--db", str(db), "--json", "--quiet")
    assert ran.returncode == 0, ran.stderr
    import json

    summary = json.loads(ran.stdout)
    assert summary["outcomes"]["error"] == 2
    with open_store(db, create=False) as store:
        message = store.samples()[0].error
    assert "v1" in message and ("status 3" in message if kind == "fails" else "nan" in message)
    # regression: its replay ended in an error line, exit 2, though it failed exactly as stored
    replayed = run("replay", str(db), "1")
    assert replayed.returncode == 0, replayed.stderr
    assert replayed.stdout.strip() == f"reproduces the stored sample exactly: it fails again, {message}"


def _rezip(source, target, drop=(), edit=None):
    with zipfile.ZipFile(source) as z, zipfile.ZipFile(target, "w") as out:
        for name in z.namelist():
            if any(name.startswith(d) for d in drop):
                continue
            data = z.read(name)
            out.writestr(name, edit(name, data) if edit else data)
    return target


def test_bad_fmus_get_one_line_and_exit_2_and_nothing_is_stored(switching_fmus, tmp_path):
    import fmpy

    text = tmp_path / "text.fmu"
    text.write_text("not an FMU")
    exchange = _rezip(switching_fmus[2], tmp_path / "exchange.fmu", edit=lambda n, d: d.replace(
        b"<CoSimulation modelIdentifier", b"<ModelExchange modelIdentifier").replace(b"</CoSimulation>", b"</ModelExchange>")
        if n == "modelDescription.xml" else d)
    other = _rezip(switching_fmus[2], tmp_path / "other.fmu", drop=("sources/", f"binaries/{fmpy.platform}/"))
    with zipfile.ZipFile(other, "a") as z:
        z.writestr("binaries/win64/d4sumo_switching.dll", b"MZ")
    cases = {"missing.fmu": "no file missing.fmu", "": "no path given", str(text): "not a zip archive", str(exchange): "model exchange only",
             str(other): "binaries for win64 and no sources"}
    # side by side, each with a database of its own
    dbs = [tmp_path / f"x{i}.sqlite" for i in range(len(cases))]
    results = side_by_side([lambda fmu=fmu, db=db: run("falsify", "--controller", f"fmu:{fmu}", "--samples", "2", "--db", str(db),
                                                       cwd=tmp_path) for fmu, db in zip(cases, dbs)])
    for (fmu, said), db, result in zip(cases.items(), dbs, results):
        lines = result.stderr.strip().splitlines()
        assert result.returncode == 2 and len(lines) == 1 and said in lines[0] and "Traceback" not in result.stderr, (fmu, result.stderr)
        assert not db.exists()


def test_a_dask_sweep_ships_the_fmu_to_workers_that_cannot_see_the_clients_disk(switching_fmus, tmp_path):
    """A scheduler and a worker started in folders of their own, with caches of their own: the sweep names
    the FMU by a path relative to the client's folder, which the worker does not have. The samples equal
    a local sweep's."""
    from conftest import dask_elsewhere
    from d4sumo.search.store import Store

    client = tmp_path / "client"
    client.mkdir()
    shutil.copy(switching_fmus[2], client / "acc.fmu")
    (client / "sweep.toml").write_text('name = "fmu"\n[grid]\nsetpoint_m = [5.0, 7.0]\noptimizer = ["random"]\n'
                                       '[controller]\nclass = "fmu:acc.fmu"\n[scenario]\nstart = "steady"\n[search]\nsamples = 6\n')

    def rows(db):
        with Store(db, create=False) as store:
            return sorted((s.campaign_id, s.index, s.params, s.robustness, s.outcome) for s in store.samples())

    def on_dask():
        with dask_elsewhere(tmp_path) as (address, _):
            return run("sweep", "sweep.toml", "--db", "dask.sqlite", "--dask", address, "--quiet", cwd=client)

    # the same sweep on the client alone, side by side with the Dask one (another database)
    swept, local = side_by_side([on_dask, lambda: run("sweep", "sweep.toml", "--db", "local.sqlite", "--workers", "1", "--quiet",
                                                      cwd=client)])
    assert swept.returncode == 0, swept.stderr
    assert list((tmp_path / "worker1" / "cache" / "d4sumo" / "fmus" / "by-content").glob("*.fmu"))  # it came by value
    assert local.returncode == 0
    assert rows(client / "dask.sqlite") == rows(client / "local.sqlite") and len(rows(client / "local.sqlite")) == 12


@pytest.mark.sumo
def test_an_fmu_followers_exported_scenario_names_each_controller_property_once(switching_fmus, tmp_path):
    """Regression: an FMU's signal mapping (setpoint_m -> the FMU's variable "setpoint_m") was written beside the
    setpoint's value under the same name: two properties of one name, which ASAM's checker refuses."""
    import xml.etree.ElementTree as ET

    shutil.copy(switching_fmus[2], tmp_path / "acc.fmu")
    db = tmp_path / "c.sqlite"
    ran = run("falsify", "--controller", "fmu:acc.fmu", "--start", "steady", "--setpoint", "5", "--optimizer", "random",
              "--samples", "1", "--db", str(db), "--quiet", cwd=tmp_path)
    assert ran.returncode == 0, ran.stderr
    exported = run("export", str(db), "1", "--openscenario", str(tmp_path / "x"), cwd=tmp_path)
    assert exported.returncode == 0, exported.stderr
    controllers = list(ET.parse(tmp_path / "x" / "scenario.xosc").getroot().iter("Controller"))
    assert len(controllers) == 3
    for controller in controllers:
        names = [p.get("name") for p in controller.iter("Property")]
        assert len(names) == len(set(names)) and "fmu.setpoint_m" in names, names


@pytest.mark.parametrize("kind", ["sound", "fails", "nan", "fails3"])
def test_an_fmu_stepped_in_c_is_the_fmu_stepped_by_the_python_bit_for_bit_its_errors_too(tmp_path, monkeypatch, kind):
    """Its FMI calls made from the loop in C (`compiled`, law 7) where the Python made them through ctypes: the same
    episodes, and a failed call the same error, named as a user's controller's."""
    from conftest import assert_same_episode

    from d4sumo.model.controllers import compiled

    step2 = "    switching_step(&((Instance *)c)->law, communicationStepSize);\n    return fmi2OK;"
    if kind == "sound":
        fmu = variant(tmp_path, monkeypatch, kind)
    elif kind == "fails3":  # FMI 3.0: its DoStep fails at 2 s
        fmu = variant(tmp_path, monkeypatch, kind, version=3, patch=(
            "    switching_step(&s->law, communicationStepSize);\n",
            "    switching_step(&s->law, communicationStepSize);\n    if (currentCommunicationPoint >= 2.0) return fmi3Error;\n"))
    else:
        broken = {"fails": step2.replace("return fmi2OK;", "return currentCommunicationPoint >= 2.0 ? fmi2Error : fmi2OK;"),
                  "nan": step2.replace("return fmi2OK;", "if (currentCommunicationPoint >= 2.0) ((Instance *)c)->law.v[VR_COMMAND] = "
                                                         "0.0 / 0.0;\n    return fmi2OK;")}[kind]
        fmu = variant(tmp_path, monkeypatch, kind, patch=(step2, broken))
    config = EpisodeConfig(controller=ControllerConfig(f"fmu:{fmu}"), start="steady", setpoint_m=5.0, followers=3)
    plans = random_plans(config, 4, seed=2)
    calls = []
    c_loop = compiled.play_column
    monkeypatch.setattr(compiled, "play_column", lambda *a: (calls.append(1), c_loop(*a))[1])
    in_c = simulate_batch(config, plans)
    assert calls, "the FMU's followers did not go on in C"
    monkeypatch.setattr(compiled, "ENABLED", False)
    python = simulate_batch(config, plans)
    for a, b in zip(in_c, python):
        if isinstance(b, Exception):
            assert type(a) is type(b) and str(a) == str(b) and "v1" in str(a), (a, b)
        else:
            assert_same_episode(a, b)
    assert all(isinstance(r, Exception) for r in in_c) == (kind != "sound")
