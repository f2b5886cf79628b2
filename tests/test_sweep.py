"""Sweeps: validation before running, parallel and Dask execution, kill -9 and resume."""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import sqlite3
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import made_ahead, sigint_at_default
from d4sumo.cli import main
from d4sumo.errors import ConfigError
from d4sumo.search.store import Store, StoreError
from d4sumo.sweep import Sweep, claim, run_sweep

TINY = """
name = "tiny"
[grid]
setpoint_m = [5.0, 7.0]
start = ["rest", "steady"]
optimizer = ["random"]
seed = [0]
[search]
samples = 6
"""


def write(tmp_path, text, name="sweep.toml"):
    path = tmp_path / name
    path.write_text(text)
    return path


def outcomes(db):
    with Store(db, create=False) as store:
        by_key = {c.id: c.key for c in store.campaigns()}
        return sorted((by_key[s.campaign_id], s.index, s.params, s.robustness, s.outcome) for s in store.samples())


def swept_alone(tmp_path_factory, text, *flags):
    """The database of the sweep ``text`` run by `d4sumo sweep` on one worker: what a test's sweep must store."""
    folder = tmp_path_factory.mktemp("alone")
    db = folder / "alone.sqlite"
    done = subprocess.run([sys.executable, "-m", "d4sumo.cli", "sweep", str(write(folder, text)), "--db", str(db),
                           "--workers", "1", "--quiet", *flags], capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return db


def test_a_sweep_is_the_product_of_its_grid(tmp_path):
    sweep = Sweep.load(write(tmp_path, TINY))
    assert sweep.name == "tiny" and len(sweep.campaigns) == 4 and sweep.samples == 24
    assert {(c.config.setpoint_m, c.config.start) for c in sweep.campaigns} == {(5, "rest"), (5, "steady"), (7, "rest"), (7, "steady")}


def test_a_sweep_grid_ranges_over_systems_under_test(tmp_path):
    grid = '[grid]\ncontroller = ["switching", {class = "sumo:ACC", tau = 0.5}, ["sumo:ACC", "timegap", "sumo:IDM"]]\n'
    sweep = Sweep.load(write(tmp_path, TINY.replace("[grid]\n", grid, 1)))
    assert len(sweep.campaigns) == 12
    assert {c.config.system_label for c in sweep.campaigns} == {"switching", "sumo:ACC(tau=0.5)", "sumo:ACC / timegap / sumo:IDM"}
    sweep.check()  # SUMO loads the models' types


def test_a_sweep_grid_ranges_over_the_cut_in_target_follower_and_offset(tmp_path):
    grid = '[grid]\nmaneuver = ["cutin"]\ncutin_follower = [1, 2, 3]\ncutin_offset_m = [-2.0, 0.0]\n'
    sweep = Sweep.load(write(tmp_path, TINY.replace("[grid]\n", grid, 1)))
    assert len(sweep.campaigns) == 24
    assert {(c.config.cutin_follower, c.config.cutin_offset_m) for c in sweep.campaigns} == {
        (k, d) for k in (1, 2, 3) for d in (-2.0, 0.0)}
    assert all(c.family().names[-1] == "t_lc_s" for c in sweep.campaigns)
    sweep.check()
    # without a cut-in the follower changes nothing: the same campaign twice, refused
    with pytest.raises(ConfigError, match="grid points that are different campaigns"):
        Sweep.load(write(tmp_path, TINY.replace("[grid]\n", "[grid]\ncutin_follower = [1, 2]\n", 1)))


def test_a_sweep_grid_ranges_over_radars_each_a_whole_table_the_empty_one_perfect(tmp_path):
    grid = '[grid]\nradar = [{}, {gap_noise_m = 0.5, latency_s = 0.2}]\n'
    sweep = Sweep.load(write(tmp_path, TINY.replace("[grid]\n", grid, 1)))
    radars = [c.config.radar for c in sweep.campaigns]
    assert len(radars) == 8 and radars.count(None) == 4
    assert {r.label for r in radars if r is not None} == {"gap_noise_m=0.5, latency_s=0.2"}
    assert all("radar" not in c.definition()["config"] for c in sweep.campaigns if c.config.radar is None)


@pytest.mark.parametrize(
    "text, message",
    [
        (TINY.replace("setpoint_m", "setpoint"), "grid.setpoint"),
        (TINY.replace("[grid]\n", '[grid]\nmaneuver = ["cutout"]\n') + '[scenario]\nnetwork = "highway_1lane"\n',
         "at least 2 lanes"),
        (TINY.replace("[grid]\n", '[grid]\ncutin_follower = [4]\nmaneuver = ["cutin"]\n'), "scenario.cutin_follower"),
        (TINY.replace("[5.0, 7.0]", "[]"), "non-empty list"),
        (TINY.replace("[5.0, 7.0]", "[5.0, -7.0]"), "scenario.setpoint_m"),
        (TINY.replace('["random"]', '["anneal"]'), "optimizer"),
        (TINY.replace("samples = 6", "samples = 0"), "samples"),
        (TINY + "\n[scenario]\nspeed_mps = 45.0\n", "speed limit"),
        ("name = 'x'\n", "[grid]"),
        ("[grid\n", "valid TOML"),
        (TINY.replace("[grid]\n", '[grid]\ncontroller = ["sumo:ACC", {class = "sumo:ACC", tau = 0}]\n'), "Must be greater than 0"),
        (TINY.replace("[grid]\n", '[grid]\ncontroller = [["sumo:ACC", "switching"]]\n'), "one per follower (3: --controller A,B,C or [[controller]] tables)"),
        # a table every campaign shares that one grid point cannot take: the point is named
        (TINY.replace("[grid]\n", '[grid]\ncontroller = ["switching", "sumo:ACC"]\n') + "\n[radar]\ngap_noise_m = 0.5\n",
         "grid point {'controller': 'sumo:ACC'"),
        (TINY.replace("[grid]\n", '[grid]\nradar = [{gap_noise_m = 0.5}]\n') + "\n[radar]\nlatency_s = 0.1\n",
         "no [radar] table beside grid.radar"),
        (TINY.replace("[grid]\n", '[grid]\nradar = [5]\n'), "radar: got 5; allowed: a [radar] table"),
        (TINY.replace("[grid]\n", '[grid]\nradar = [{noise = 1}]\n'), "radar.noise: got 1"),
    ],
)
def test_a_bad_sweep_file_is_refused_before_anything_runs(tmp_path, text, message, capsys):
    db = tmp_path / "r.sqlite"
    assert main(["sweep", str(write(tmp_path, text)), "--db", str(db), "--quiet"]) == 2
    err = capsys.readouterr().err.strip()
    assert message in err and err.count("\n") == 0
    assert not db.exists()


@pytest.mark.sumo
def test_local_workers_run_every_campaign_once_and_match_a_single_worker(tmp_path):
    sweep = Sweep.load(write(tmp_path, TINY))
    one = run_sweep(sweep, tmp_path / "one.sqlite", workers=1)
    two = run_sweep(sweep, tmp_path / "two.sqlite", workers=2)
    assert one.samples == two.samples == 24
    assert outcomes(tmp_path / "one.sqlite") == outcomes(tmp_path / "two.sqlite")
    again = run_sweep(sweep, tmp_path / "two.sqlite", workers=2)  # complete: nothing to do, nothing added
    assert again.samples == 24 and len(outcomes(tmp_path / "two.sqlite")) == 24


@pytest.mark.sumo
def test_by_default_a_sweep_runs_a_worker_on_each_core_it_may_use_not_each_of_the_machines(tmp_path, monkeypatch, tiny_alone):
    """Regression: the default --workers was the machine's count of cores, so a sweep given one core of many
    (a container's share, taskset) started a worker for each, all waiting for that one."""
    from d4sumo.sweep import run as sweep_run
    from d4sumo.sweep import workers as sweep_workers

    pools = []
    monkeypatch.setattr(os, "cpu_count", lambda: 64)  # a machine of 64 cores ...
    monkeypatch.setattr(os, "sched_getaffinity", lambda pid: {3, 5})  # ... of which this process may use 2
    monkeypatch.setattr(sweep_run, "new_pool", lambda workers: pools.append(workers) or sweep_workers.new_pool(workers))
    assert run_sweep(Sweep.load(write(tmp_path, TINY)), tmp_path / "r.sqlite").samples == 24
    assert pools == [2] and outcomes(tmp_path / "r.sqlite") == tiny_alone


@pytest.mark.sumo
def test_a_database_of_another_sweep_is_refused_untouched(tmp_path):
    db = tmp_path / "r.sqlite"
    run_sweep(Sweep.load(write(tmp_path, TINY)), db, workers=1)
    other = Sweep.load(write(tmp_path, TINY.replace("[5.0, 7.0]", "[6.0]"), "other.toml"))
    before = outcomes(db)
    with pytest.raises(StoreError, match="holds sweep 'tiny'"):
        run_sweep(other, db, workers=1)
    assert outcomes(db) == before


KILLED_WHOLE = TINY.replace("samples = 6", "samples = 150")  # 600 samples: about a second on 2 cores, killed midway


@made_ahead()
def killed_whole_alone(tmp_path_factory):
    return outcomes(swept_alone(tmp_path_factory, KILLED_WHOLE))


@pytest.mark.sumo
def test_kill_9_loses_nothing_and_the_same_command_resumes(tmp_path, killed_whole_alone):
    path = write(tmp_path, KILLED_WHOLE)
    db = tmp_path / "r.sqlite"
    cmd = [sys.executable, "-m", "d4sumo.cli", "sweep", str(path), "--db", str(db), "--workers", "2", "--quiet"]
    proc = subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 60
    stored = 0
    while time.time() < deadline and stored < 30:
        time.sleep(0.02)
        if db.exists():
            try:
                stored = sqlite3.connect(db, timeout=5).execute("SELECT COUNT(*) FROM sample").fetchone()[0]
            except sqlite3.OperationalError:
                stored = 0
    os.killpg(proc.pid, signal.SIGKILL)  # the whole sweep: parent and workers
    proc.wait()
    assert 30 <= stored < 600, "the sweep should have been killed midway"
    assert subprocess.run(cmd, timeout=300).returncode == 0
    rows = outcomes(db)
    assert len(rows) == 600 and len({(r[0], r[1]) for r in rows}) == 600  # every sample exactly once
    assert rows == killed_whole_alone


@made_ahead()
def tiny_alone(tmp_path_factory):
    return outcomes(swept_alone(tmp_path_factory, TINY))


@pytest.mark.sumo
def test_a_sweep_runs_on_a_real_local_dask_cluster(tmp_path, tiny_alone):
    from distributed import LocalCluster

    sweep = Sweep.load(write(tmp_path, TINY))
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                      dashboard_address=None) as cluster:
        result = run_sweep(sweep, tmp_path / "dask.sqlite", dask_address=cluster.scheduler_address)
    assert result.samples == 24
    assert outcomes(tmp_path / "dask.sqlite") == tiny_alone


TURBO = TINY.replace('optimizer = ["random"]', 'optimizer = ["turbo"]').replace("samples = 6", "samples = 16")


@made_ahead()
def turbo_alone(tmp_path_factory):
    return outcomes(swept_alone(tmp_path_factory, TURBO))


@pytest.mark.parametrize("proposals", ["client", "workers"])
def test_a_dask_sweep_on_workers_of_other_numerics_stores_what_the_client_proposes(tmp_path, proposals, turbo_alone):
    """Issue 36: on a cluster of mixed machines a sweep's samples differed from the same sweep run locally:
    each worker asked its campaigns' GPs with its own BLAS. With the optimisers on the client (the
    default) the workers only play episodes, which are the same on every machine: here workers whose
    GP numerics are one ulp off store, bit for bit, what the client's machine proposes alone. With
    them on the workers, every sample is still stored once and replays (its proposals are the workers')."""
    from pathlib import Path

    from distributed import LocalCluster

    sweep = Sweep.load(write(tmp_path, TURBO))
    preload = [str(Path(__file__).parent / "search" / "nudged_worker.py")]
    if proposals == "client":  # and none is asked for a point on a worker
        preload.append(str(Path(__file__).parent / "search" / "no_optimizer_worker.py"))
    with LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1", dashboard_address=None,
                      preload=preload) as cluster:
        result = run_sweep(sweep, tmp_path / "dask.sqlite", dask_address=cluster.scheduler_address, dask_proposals=proposals)
    assert result.samples == 64
    rows = outcomes(tmp_path / "dask.sqlite")
    assert len({(r[0], r[1]) for r in rows}) == 64
    if proposals == "client":  # what this machine's process alone stores
        assert rows == turbo_alone


def test_dask_proposals_without_dask_is_said_to_be_unused(tmp_path, capsys):
    path = write(tmp_path, TINY)
    assert main(["sweep", str(path), "--db", str(tmp_path / "r.sqlite"), "--workers", "1", "--dask-proposals", "workers",
                 "--quiet"]) == 0
    assert "--dask-proposals is unused" in capsys.readouterr().err


TINY30 = TINY.replace("samples = 6", "samples = 30")


@made_ahead()
def tiny30_alone(tmp_path_factory):
    return outcomes(swept_alone(tmp_path_factory, TINY30))


@pytest.mark.sumo
def test_a_sweep_on_a_real_scheduler_with_workers_in_other_folders_writes_only_on_the_client(tmp_path, tiny30_alone):
    """Regression: Dask workers wrote into a database on their own side and the client reported
    '0 samples'. Now the workers (started elsewhere, with their own cache) only compute; the client
    stores everything, and a worker killed mid-sweep loses nothing finished."""
    from conftest import dask_elsewhere

    with dask_elsewhere(tmp_path, workers=2) as (address, workers):
        path = write(tmp_path, TINY30)
        db = tmp_path / "client" / "r.sqlite"
        db.parent.mkdir()
        cmd = [sys.executable, "-m", "d4sumo.cli", "sweep", str(path), "--db", str(db), "--dask", address, "--quiet"]
        sweep = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        wait_for_samples(db, 10)
        os.killpg(workers[0].pid, signal.SIGKILL)  # one worker dies mid-sweep
        out, err = sweep.communicate(timeout=300)
        assert sweep.returncode == 0, err
        assert "4 campaigns, 120 samples" in out
        for i in (1, 2):  # the workers wrote nothing of the results on their side
            assert not list((tmp_path / f"worker{i}").rglob("*.sqlite"))
    rows = outcomes(db)
    assert len(rows) == 120 and len({(r[0], r[1]) for r in rows}) == 120
    assert rows == tiny30_alone


@pytest.mark.sumo
def test_dask_local_runs_a_local_cluster(tmp_path):
    path = write(tmp_path, TINY)
    result = run_sweep(Sweep.load(path), tmp_path / "d.sqlite", workers=2, dask_address="local")
    assert result.samples == 24


def test_an_unreachable_dask_scheduler_is_a_clear_error(tmp_path, capsys):
    path = write(tmp_path, TINY)
    assert main(["sweep", str(path), "--db", str(tmp_path / "r.sqlite"), "--dask", "tcp://127.0.0.1:9", "--dask-timeout", "0.5", "--quiet"]) == 2
    assert "no Dask scheduler answered" in capsys.readouterr().err
    assert not (tmp_path / "r.sqlite").exists()  # regression: an empty database was left behind


def test_campaign_chunks_run_with_one_blas_thread(tmp_path, monkeypatch):
    """Regression: each worker's BLAS pool used every core, so two workers ran no faster than one."""
    import numpy  # noqa: F401  (loads the BLAS library threadpoolctl inspects)
    from threadpoolctl import threadpool_info

    import d4sumo.sweep as sweep_module
    from d4sumo.engine.scenarios import network_source
    from d4sumo.search.runner import CampaignRunner

    seen = []

    def fake_pending(self):
        seen.extend(pool["num_threads"] for pool in threadpool_info() if pool["user_api"] == "blas")
        raise StopIteration

    monkeypatch.setattr(CampaignRunner, "pending", fake_pending)
    campaign = Sweep.load(write(tmp_path, TINY)).campaigns[0]
    with pytest.raises(StopIteration):
        sweep_module.run_chunks((sweep_module.Chunk(campaign, network_source("highway_4lane"), (), None),))
    assert seen and all(n == 1 for n in seen)


# --- processes: nothing outlives the command, nothing is lost or doubled -----------------------


def children(pid):
    """Processes whose parent is ``pid`` (from /proc)."""
    out = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            try:
                with open(f"/proc/{entry}/stat") as fh:
                    fields = fh.read().rsplit(")", 1)[1].split()
            except OSError:
                continue
            if int(fields[1]) == pid:
                out.append(int(entry))
    return out


def alive(pid):
    try:
        with open(f"/proc/{pid}/stat") as fh:
            return fh.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def count_samples(db):
    try:
        return sqlite3.connect(f"file:{db}?mode=ro", uri=True, timeout=5).execute("SELECT COUNT(*) FROM sample").fetchone()[0]
    except sqlite3.Error:
        return 0


def start_sweep(path, db, *extra):
    cmd = [sys.executable, "-m", "d4sumo.cli", "sweep", str(path), "--db", str(db), "--workers", "2", "--quiet", *extra]
    return cmd, subprocess.Popen(cmd, start_new_session=True, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE,
                                 preexec_fn=sigint_at_default)


def wait_for_samples(db, n, timeout=90):
    deadline = time.time() + timeout
    while time.time() < deadline:
        if count_samples(db) >= n:
            return
        time.sleep(0.02)
    raise AssertionError(f"fewer than {n} samples in {timeout} s")


LONG = TINY.replace("samples = 6", "samples = 400")  # 1,600 samples, about 3 s on 2 cores: long enough to kill midway


@made_ahead()
def long_reference(tmp_path_factory):
    return outcomes(swept_alone(tmp_path_factory, LONG))


@pytest.mark.sumo
@pytest.mark.parametrize("how", ["SIGTERM", "SIGINT to the group", "kill -9 of the parent alone"])
def test_killing_a_sweep_leaves_no_worker_behind_and_resume_completes_it(tmp_path, how, long_reference):
    """Regression: in 7 of 7 kills both workers and the resource tracker lived on and wrote hundreds
    more samples."""
    path = write(tmp_path, LONG)
    db = tmp_path / "r.sqlite"
    cmd, proc = start_sweep(path, db)
    wait_for_samples(db, 20)
    workers = [p for p in children(proc.pid)]
    assert len(workers) >= 2  # the pool's processes (and the resource tracker)
    t0 = time.time()
    if how == "SIGTERM":
        proc.send_signal(signal.SIGTERM)
    elif how == "SIGINT to the group":
        os.killpg(proc.pid, signal.SIGINT)  # what Ctrl-C in a terminal does
    else:
        proc.kill()
    proc.wait(timeout=10)
    while any(alive(p) for p in workers) and time.time() - t0 < 10:
        time.sleep(0.1)
    assert not any(alive(p) for p in workers), "a worker outlived its sweep"
    assert time.time() - t0 < 6
    err = proc.stderr.read().decode()  # read once every process that holds it (the resource tracker too) is gone
    assert "Traceback" not in err
    if how != "kill -9 of the parent alone":
        assert proc.returncode in (130, 143) and "resume" in err
        assert err.count("interrupted") == 1  # said once (a SIGINT had it said twice)
    else:  # regression: multiprocessing's resource tracker warned of "5 leaked semaphore objects", often amid the next run
        assert err == "", err
    stored = count_samples(db)
    assert stored < 1600, "the sweep ended before it was killed"
    time.sleep(1.5)
    assert count_samples(db) == stored, "samples were written after the sweep was killed"
    assert subprocess.run(cmd, timeout=300, capture_output=True).returncode == 0
    rows = outcomes(db)
    assert len(rows) == 1600 and len({(r[0], r[1]) for r in rows}) == 1600
    assert rows == long_reference


@pytest.mark.sumo
def test_a_second_run_on_the_same_database_is_refused_while_the_first_writes(tmp_path):
    """Regression: two runs of one sweep on one database both crashed part-way ("already has sample 0")."""
    path = write(tmp_path, LONG)
    db = tmp_path / "r.sqlite"
    cmd, first = start_sweep(path, db)
    try:
        wait_for_samples(db, 5)
        # the first sweep (its workers too) held where it is, midway, with its database open for writing, for as
        # long as the second takes to start, whatever this machine's speed; then it goes on
        os.killpg(first.pid, signal.SIGSTOP)
        try:
            second = subprocess.run(cmd, capture_output=True, text=True, timeout=60)
        finally:
            os.killpg(first.pid, signal.SIGCONT)
    except BaseException:  # the first sweep (a session of its own) does not outlive a failed test
        os.killpg(first.pid, signal.SIGKILL)
        raise
    assert second.returncode == 2 and second.stderr.count("\n") == 1
    assert "another d4sumo command is writing to it" in second.stderr
    assert first.wait(timeout=300) == 0
    rows = outcomes(db)
    assert len(rows) == 1600 and len({(r[0], r[1]) for r in rows}) == 1600


@pytest.mark.sumo
def test_a_kill_while_the_database_is_created_never_leaves_one_the_next_run_refuses(tmp_path):
    """Regression: kills in the first milliseconds left tables without the meta row."""
    db = tmp_path / "r.sqlite"
    cmd = [sys.executable, "-m", "d4sumo.cli", "falsify", "--optimizer", "random", "--samples", "2", "--db", str(db), "--quiet"]
    for delay in (0.3, 0.45, 0.6, 0.75, 0.9, 1.1):
        proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(delay)
        proc.kill()
        proc.wait()
        from d4sumo.search.store import Store as S

        if db.exists() and db.stat().st_size:
            with S(db):  # opens (and if needed, creates) cleanly
                pass
    done = subprocess.run(cmd, capture_output=True, text=True, timeout=120)
    assert done.returncode == 0, done.stderr


def test_grid_points_that_are_one_campaign_are_refused_before_anything_runs(tmp_path):
    # SUMO's ACC written out with d4sumo's default, and one table per follower alike: the same campaign twice
    for axis in ('controller = ["sumo:Krauss", {class = "sumo:Krauss", sigma = 0.0}]',
                 'controller = ["sumo:ACC", ["sumo:ACC", "sumo:ACC", "sumo:ACC"]]'):
        with pytest.raises(ConfigError, match="grid points that are different campaigns"):
            Sweep.load(write(tmp_path, TINY.replace("[grid]\n", f"[grid]\n{axis}\n")))
    # a fixed [controller] beside a controller axis would be dropped: refused
    with pytest.raises(ConfigError, match="no \\[controller\\] beside grid.controller"):
        Sweep.load(write(tmp_path, TINY.replace("[grid]\n", '[grid]\ncontroller = ["sumo:ACC"]\n') + "[controller]\ntau = 0.5\n"))


#: every optimiser, from rest and steady: tasks of two campaigns whose episodes share a batch, each with its own
#: start, cut by batches of 7 and chunks returned between them
BATCHED = (TINY.replace('optimizer = ["random"]', 'optimizer = ["random", "ce", "cmaes", "bo"]')
           .replace("samples = 6", "samples = 23").replace("setpoint_m = [5.0, 7.0]", "setpoint_m = [5.0]"))


@made_ahead()
def batched_played_alone(tmp_path_factory):
    """BATCHED on one worker, every episode alone in its SUMO (--batch 1)."""
    return outcomes(swept_alone(tmp_path_factory, BATCHED, "--batch", "1"))


@pytest.mark.sumo
def test_a_sweep_stores_the_same_samples_whether_its_episodes_play_in_batches_or_alone(tmp_path, batched_played_alone):
    """Issue 13: batches, and the chunks a worker returns between them, change the speed only."""
    run_sweep(Sweep.load(write(tmp_path, BATCHED)), tmp_path / "batched.sqlite", workers=2, batch=7)
    assert outcomes(tmp_path / "batched.sqlite") == batched_played_alone
    assert len(batched_played_alone) == 8 * 23


@pytest.mark.sumo
def test_a_grid_of_the_platoon_alone_and_among_a_networks_own_demand_plays_each_on_its_road(tmp_path):
    """Regression: a sweep's campaigns shared one road per network and route, the first one's: the platoon
    alone's, the route's edges, on which the Bremen demand's routes over the network's other ways are not
    ("The edge '153180751' within the route 'ramp' is not known"), and the sweep stopped before it began."""
    from d4sumo.sumohome import sumo_home

    game = Path(sumo_home()) / "tools" / "game" / "highway"
    text = f"""name = "bremen"
[grid]
traffic = [{{}}, {{demand = "{game / 'highway.rou.xml'}"}}]
[scenario]
network = "{game / 'highway.net.xml'}"
route = ["145354574", "189597495", "E0", "191842213"]
start = "steady"
speed_mps = 30.0
duration_s = 20.0
[search]
optimizer = "random"
samples = 2
"""
    result = run_sweep(Sweep.load(write(tmp_path, text)), tmp_path / "r.sqlite", workers=1)
    assert result.samples == 4
    with Store(tmp_path / "r.sqlite", create=False) as store:
        assert sorted("traffic" in c.definition["config"] for c in store.campaigns()) == [False, True]


@pytest.mark.sumo
def test_a_sweep_an_earlier_version_ran_on_a_road_of_ones_own_among_traffic_is_told_how_to_go_on(tmp_path, capsys):
    """d4sumo 0.16 stored no road digest and let traffic enter after the warm-up unchecked: its sweep's grid is
    another one now, refused untouched with the keys that go on with it as it ran."""
    road = tmp_path / "road"
    shutil.copytree(Path(__file__).resolve().parent.parent / "examples" / "roads" / "three_edges", road)
    text = (f'name = "mine"\n[grid]\nsetpoint_m = [5.0, 7.0]\n[scenario]\nnetwork = "{road}/"\nstart = "steady"\n'
            '[traffic]\nvehicles_per_hour = 600\n[search]\noptimizer = "random"\nsamples = 2\n')
    as_before = text.replace('start = "steady"', 'start = "steady"\nnetwork_sha256 = ""\nsignals = "ignore"').replace(
        "vehicles_per_hour = 600", "vehicles_per_hour = 600\ninsertion_checks = false\njunction_collisions = false")
    db = tmp_path / "r.sqlite"
    assert main(["sweep", str(write(tmp_path, as_before, "before.toml")), "--db", str(db), "--quiet"]) == 0
    stored = outcomes(db)
    capsys.readouterr()
    assert main(["sweep", str(write(tmp_path, text)), "--db", str(db), "--quiet"]) == 2
    said = capsys.readouterr().err
    assert said.count("\n") == 1 and "It was run by d4sumo 0.16 or before" in said
    assert ('`network_sha256 = ""` in [scenario] and `insertion_checks = false` in [traffic] (or in each table of '
            'grid.traffic) and `signals = "ignore"` in [scenario] and `junction_collisions = false` in [traffic]') in said
    assert outcomes(db) == stored
    # one whose optimiser an earlier d4sumo ran otherwise too (ce without its noise): both said at once
    ce = text.replace('optimizer = "random"', 'optimizer = "ce"')
    ce_before = as_before.replace('optimizer = "random"', 'optimizer = "ce"') + "[search.ce]\nnoise_fraction = 0.0\n"
    older = tmp_path / "older.sqlite"
    assert main(["sweep", str(write(tmp_path, ce_before, "ce_before.toml")), "--db", str(older), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["sweep", str(write(tmp_path, ce, "ce.toml")), "--db", str(older), "--quiet"]) == 2
    said = capsys.readouterr().err
    assert ('set `noise_fraction = 0.0` in [search.ce]; `network_sha256 = ""` in [scenario] and `insertion_checks = false` '
            'in [traffic]' in said), said


def test_a_grid_of_maneuvers_and_cut_in_settings_counts_the_in_lane_attack_once(tmp_path):
    """Regression: maneuver = [inlane, cutin] with a cut-in offset axis was refused, the in-lane campaigns
    (which read no offset) being the same campaign twice; now they are one campaign."""
    grid = '[grid]\nmaneuver = ["inlane", "cutin"]\ncutin_offset_m = [-2.0, 0.0, 5.0]\n'
    sweep = Sweep.load(write(tmp_path, TINY.replace("[grid]\n", grid, 1)))
    by_maneuver = {m: [c for c in sweep.campaigns if c.config.maneuver == m] for m in ("inlane", "cutin")}
    assert len(by_maneuver["inlane"]) == 4 and len(by_maneuver["cutin"]) == 12
    assert {c.config.cutin_offset_m for c in by_maneuver["cutin"]} == {-2.0, 0.0, 5.0}


GAPPED = (TINY.replace('optimizer = ["random"]', 'optimizer = ["ce", "bo"]').replace("samples = 6", "samples = 30")
          + "\n[search.bo]\nbatch_size = 1\n")  # one point per score: 30 chunks


@made_ahead()
def gapped_whole(tmp_path_factory):
    """GAPPED run whole on one worker: its database."""
    return swept_alone(tmp_path_factory, GAPPED)


@pytest.mark.sumo
def test_a_sweep_resumes_a_campaign_with_a_sample_missing_in_between(tmp_path, gapped_whole):
    """Regression: a stored campaign with a gap (sample 3 gone) made the resumed sweep stop with 'a
    worker returned samples out of order'; the campaign runner plays just the missing samples."""
    sweep = Sweep.load(write(tmp_path, GAPPED))
    db = tmp_path / "r.sqlite"
    shutil.copy(gapped_whole, db)  # the sweep stored whole
    with Store(db) as store:  # a short gap, and one longer than a chunk
        store.db.execute("DELETE FROM sample WHERE idx = 3 OR idx BETWEEN 8 AND 24")
        store.db.commit()
    for batch in (1, 64):
        shutil.copy(db, tmp_path / f"b{batch}.sqlite")
        run_sweep(sweep, tmp_path / f"b{batch}.sqlite", workers=2, batch=batch)
        assert outcomes(tmp_path / f"b{batch}.sqlite") == outcomes(gapped_whole)


def test_a_sweep_begun_where_the_numerics_differ_resumes_and_says_so_once(tmp_path, caplog):
    """Issue 36: a sweep resumed on another machine, where each campaign's GP proposed otherwise, goes on
    from its stored samples (a model's points stand; here each campaign's sample 12 as another machine's
    BLAS could have proposed it) and says so once, not once a campaign."""
    text = TINY.replace('optimizer = ["random"]', 'optimizer = ["bo"]').replace("samples = 6", "samples = 18")
    sweep = Sweep.load(write(tmp_path, text))
    db = tmp_path / "r.sqlite"
    run_sweep(sweep, db, workers=1)
    with Store(db) as store:
        for campaign_id, params in store.db.execute("SELECT campaign_id, params FROM sample WHERE idx = 12").fetchall():
            moved = [v + 1e-9 if i == 0 else v for i, v in enumerate(json.loads(params))]
            store.db.execute("UPDATE sample SET params = ? WHERE idx = 12 AND campaign_id = ?", (json.dumps(moved), campaign_id))
        store.db.execute("DELETE FROM sample WHERE idx >= 15")
        store.db.commit()
        kept = sorted((s.campaign_id, s.index, s.params, s.robustness) for s in store.samples())
    with caplog.at_level("WARNING"):
        result = run_sweep(sweep, db, workers=2)
    assert result.samples == 4 * 18
    with Store(db, create=False) as store:
        assert sorted((s.campaign_id, s.index, s.params, s.robustness) for s in store.samples() if s.index < 15) == kept
    notes = [r.getMessage() for r in caplog.records if "numerics differ" in r.getMessage()]
    assert len(notes) == 1 and "stored sample 12" in notes[0] and "samples this run plays" in notes[0], notes


@pytest.mark.parametrize("earlier", [
    {"bo": "inducing = 0"},  # 0.5-0.6
    {"bo": "inducing = 0", "ce": "noise_fraction = 0.0"},  # 0.4
    {"bo": "gp_version = 1\ninducing = 0", "ce": "noise_fraction = 0.0"},  # 0.3
    {"bo": "batch_size = 1\ngp_version = 1\ninducing = 0", "ce": "noise_fraction = 0.0"},  # 0.2
    {"auto": "per_signal = 0"},  # 0.10.1
    {"auto": "patience = 0\nper_signal = 0"},  # 0.10.0
    {"auto": "suffix = 0.0\npatience = 0\nper_signal = 0"},  # 0.9
    {"auto": "stall = 0\nsuffix = 0.0\npatience = 0\nper_signal = 0"},  # 0.8
    {"auto": "version = 1\nlearn_points = 256\ninducing = 256"},  # 0.7.0
])
def test_a_database_of_a_sweep_an_earlier_version_ran_says_how_to_go_on_with_it(tmp_path, earlier):
    """A sweep database an earlier d4sumo wrote has another grid (bo's, ce's and auto's options then), and
    the refusal says which options give it back."""
    text = TINY.replace('optimizer = ["random"]', f'optimizer = {json.dumps(["bo", "ce"] if "auto" not in earlier else ["auto"])}')
    tables = "".join(f"\n[search.{o}]\n{lines}\n" for o, lines in earlier.items())
    before = Sweep.load(write(tmp_path, text + tables, "before.toml"))
    now = Sweep.load(write(tmp_path, text, "now.toml"))
    assert before.fingerprint() != now.fingerprint()
    said = "; ".join(", ".join(f"`{line}`" for line in lines.split("\n")) + f" in [search.{o}]" for o, lines in earlier.items())
    with Store(tmp_path / "r.sqlite") as store:
        store.set_meta("sweep", json.dumps({"name": now.name, "fingerprint": before.fingerprint()}))
        with pytest.raises(StoreError, match=f"set {re.escape(said)} of the sweep file"):
            claim(store, now)
        claim(store, before)  # the sweep file with it goes on


class KillsItsWorkerAt9m:
    """The paper's controller, except that at a setpoint of 9 m it kills the worker process it runs in."""

    from d4sumo.model.controllers.control import SwitchingParams as Params

    def __init__(self, params, *, setpoint_m, **kwargs):
        import multiprocessing

        from d4sumo.model.controllers.control import SwitchingController

        self.inner = SwitchingController(params, setpoint_m=setpoint_m, **kwargs)
        self.kill = setpoint_m == 9.0 and multiprocessing.parent_process() is not None

    def command(self, gap_m, speed_mps, lead_speed_mps):
        if self.kill:
            os._exit(1)
        return self.inner.command(gap_m, speed_mps, lead_speed_mps)


@pytest.mark.sumo
def test_a_campaign_that_kills_its_worker_is_found_alone_and_named(tmp_path):
    """Regression: a worker's death counted a failure against every campaign of its task (up to 32),
    and against whichever task in flight the client heard of first, and the sweep stopped naming the
    one that reached three first. The tasks in flight now run again one at a time and a gang in
    halves, so only the campaign that kills its worker fails three times and is named."""
    from d4sumo.errors import D4sumoError

    grid = "[grid]\nsetpoint_m = [" + ", ".join(f"{s:.1f}" for s in range(3, 19)) + "]\n"  # 16 campaigns: tasks of 4
    text = TINY.replace("[grid]\nsetpoint_m = [5.0, 7.0]\n", grid).replace('start = ["rest", "steady"]', 'start = ["rest"]')
    path = write(tmp_path, text + f'\n[controller]\nclass = "{__name__}:KillsItsWorkerAt9m"\n')
    db = tmp_path / "r.sqlite"
    with pytest.raises(D4sumoError, match=r"campaign (\d+) failed 3 times \(its worker process died\)") as raised:
        run_sweep(Sweep.load(path), db, workers=2)
    named = int(re.search(r"campaign (\d+)", str(raised.value)).group(1))
    with Store(db, create=False) as store:
        setpoints = {c.id: c.definition["config"]["scenario"]["setpoint_m"] for c in store.campaigns()}
        counts = {cid: store.count_samples(cid) for cid in setpoints}
    assert setpoints[named] == 9.0 and counts[named] == 0
    assert all(n in (0, 6) for n in counts.values())  # whatever else ran was stored whole


EIGHT = TINY.replace("[grid]\nsetpoint_m = [5.0, 7.0]\n", "[grid]\nsetpoint_m = [" + ", ".join(f"{s:.1f}" for s in range(3, 11)) + "]\n").replace(
    'start = ["rest", "steady"]', 'start = ["rest"]')  # 8 campaigns


@made_ahead()
def eight_alone(tmp_path_factory):
    return outcomes(swept_alone(tmp_path_factory, EIGHT))


@pytest.mark.sumo
def test_a_worker_that_dies_between_two_submissions_loses_nothing(tmp_path, monkeypatch, eight_alone):
    """Regression: when a worker died after the sweep last looked at its pool, the next submission raised
    BrokenProcessPool out of the sweep, a traceback. The tasks in flight now run again, as on any death."""
    from d4sumo.sweep import run as sweep_run
    from d4sumo.sweep import workers as sweep_workers

    path = write(tmp_path, EIGHT)
    pools = []

    def new_pool(workers):  # the first pool's workers die just before its third submission
        pool = sweep_workers.new_pool(workers)
        pools.append(pool)
        if len(pools) == 1:
            submit, calls = pool.submit, []

            def submit_after_a_death(*args, **kwargs):
                calls.append(args)
                if len(calls) == 3:
                    for process in list(pool._processes.values()):
                        process.kill()
                    deadline = time.time() + 10
                    while not pool._broken and time.time() < deadline:
                        time.sleep(0.01)
                return submit(*args, **kwargs)

            pool.submit = submit_after_a_death
        return pool

    monkeypatch.setattr(sweep_run, "new_pool", new_pool)
    run_sweep(Sweep.load(path), tmp_path / "r.sqlite", workers=2)
    assert len(pools) >= 2  # the death was seen, and the sweep went on on a new pool
    assert outcomes(tmp_path / "r.sqlite") == eight_alone


@pytest.mark.parametrize("earlier", ["", "[search.bo]\ninducing = 0\n"])  # bo now, and as 0.7.0 ran it
def test_a_database_of_a_sweep_run_with_the_earlier_default_optimizer_says_how_to_go_on_with_it(tmp_path, earlier):
    """A sweep file that names no optimiser ran bo in d4sumo 0.7 and before, auto now: the refusal says
    to name bo (with the options bo ran with then)."""
    text = TINY.replace('optimizer = ["random"]\n', "")
    now = Sweep.load(write(tmp_path, text, "now.toml"))
    before = Sweep.load(write(tmp_path, text.replace("[search]\n", '[search]\noptimizer = "bo"\n') + earlier, "before.toml"))
    assert {c.optimizer for c in now.campaigns} == {"auto"} and {c.optimizer for c in before.campaigns} == {"bo"}
    said = 'set `optimizer = "bo"`' + (", `inducing = 0` in [search.bo]" if earlier else "") + " in the sweep file to go on with it"
    with Store(tmp_path / "r.sqlite") as store:
        store.set_meta("sweep", json.dumps({"name": now.name, "fingerprint": before.fingerprint()}))
        with pytest.raises(StoreError, match=re.escape(said)):
            claim(store, now)
        claim(store, before)


@pytest.mark.parametrize("fixed, field", [
    ("[scenario]\nsetpoint_m = 9.0\n", "[scenario] setpoint_m"),
    ('optimizer = "bo"\n', "[search] optimizer"),  # into [search]
    ('[attack]\nfamily = "sine"\n', "[attack] family"),
])
def test_a_value_fixed_beside_its_grid_axis_is_refused(tmp_path, fixed, field):
    """Regression: the grid won silently (setpoint_m = [5.0, 7.0] beside setpoint_m = 9.0 ran 5 and 7)."""
    text = TINY.replace('[grid]\n', '[grid]\nattack = ["knots"]\n') + fixed
    with pytest.raises(ConfigError, match=re.escape(f"sweep.toml: {field}: got ") + ".*no fixed value beside grid"):
        Sweep.load(write(tmp_path, text))


@pytest.mark.sumo
def test_ctrl_c_to_a_local_dask_sweep_is_one_line_not_the_workers_tracebacks(tmp_path):
    """Regression: the terminal's Ctrl-C, sent to the whole group, reached the local cluster's workers,
    and each printed its KeyboardInterrupt traceback (pages of them) after the sweep's one line."""
    db = tmp_path / "r.sqlite"
    _, proc = start_sweep(write(tmp_path, LONG), db, "--dask", "local")
    wait_for_samples(db, 20)
    t0 = time.time()
    os.killpg(proc.pid, signal.SIGINT)
    proc.wait(timeout=20)
    err = proc.stderr.read().decode()
    assert proc.returncode == 130 and err.count("interrupted") == 1, err
    assert "KeyboardInterrupt" not in err and "NameError" not in err, err
    assert time.time() - t0 < 8


@pytest.mark.sumo
def test_kill_9_of_a_local_dask_sweep_leaves_no_process_and_says_nothing(tmp_path):
    """Regression: after `kill -9` of `sweep --dask local`, multiprocessing's resource tracker warned of
    "12 leaked semaphore objects to clean up at shutdown" (the cluster's, which it removes as it should)."""
    db = tmp_path / "r.sqlite"
    _, proc = start_sweep(write(tmp_path, LONG), db, "--dask", "local")
    wait_for_samples(db, 20)
    workers = children(proc.pid)
    t0 = time.time()
    proc.kill()
    proc.wait(timeout=10)
    while any(alive(p) for p in workers) and time.time() - t0 < 10:
        time.sleep(0.1)
    assert not any(alive(p) for p in workers), "a process outlived its sweep"
    err = proc.stderr.read().decode()
    assert "leaked" not in err and "Traceback" not in err, err


def test_a_local_dask_worker_ignores_ctrl_c_and_the_interrupted_sync_error_is_dropped():
    import logging

    from d4sumo.sweep import dask_cluster

    held = signal.getsignal(signal.SIGINT)
    try:
        dask_cluster.dask_setup(worker=None)  # as a worker runs its preload
        assert signal.getsignal(signal.SIGINT) is signal.SIG_IGN
    finally:
        signal.signal(signal.SIGINT, held)

    def record(exc):
        try:
            raise exc
        except Exception:
            return logging.LogRecord("tornado.application", logging.ERROR, __file__, 1, "Exception in callback",
                                     None, sys.exc_info())

    # distributed/utils.py's cancel, whose future is not made yet when Ctrl-C lands
    sync = {}
    exec(compile("def cancel():\n    return future\n", os.path.join("site-packages", "distributed", "utils.py"), "exec"), sync)
    try:
        sync["cancel"]()
    except NameError as exc:
        assert dask_cluster._interrupted_sync(record(exc)) is False
    assert dask_cluster._interrupted_sync(record(NameError("another"))) is True
    assert dask_cluster._interrupted_sync(logging.LogRecord("x", logging.ERROR, __file__, 1, "m", None, None)) is True
    # regression: after kill -9 of the sweep, a worker of a loaded machine logged the heartbeat it could not
    # send to the scheduler (the sweep's process), with its traceback
    lost = logging.LogRecord("distributed.worker", logging.ERROR, __file__, 1,
                             "Failed to communicate with scheduler during heartbeat.", None, None)
    assert dask_cluster._scheduler_lost(lost) is False
    assert dask_cluster._scheduler_lost(logging.LogRecord("distributed.worker", logging.ERROR, __file__, 1, "m", None, None))
    worker_log = logging.getLogger("distributed.worker")
    assert dask_cluster._scheduler_lost in worker_log.filters
    worker_log.removeFilter(dask_cluster._scheduler_lost)


_INTERRUPTED = """
import os, signal, sys
from distributed import LocalCluster
from d4sumo.sweep.dask_cluster import _dask_client

method = sys.argv[1]  # the LocalCluster method during which Ctrl-C lands: __init__ (it starts) or close; none: no Ctrl-C
if method != "none":
    original = getattr(LocalCluster, method)
    def interrupted(self, *args, **kwargs):
        os.kill(os.getpid(), signal.SIGINT)
        return original(self, *args, **kwargs)
    setattr(LocalCluster, method, interrupted)
with _dask_client("local", 30.0, 1) as client:
    print(client.submit(sum, [1, 2]).result(), flush=True)
print("closed", flush=True)
"""


def _run_interrupted(method: str) -> tuple[subprocess.CompletedProcess, float]:
    import time

    t0 = time.monotonic()
    done = subprocess.run([sys.executable, "-c", _INTERRUPTED, method], capture_output=True, text=True, timeout=120,
                          preexec_fn=sigint_at_default)
    return done, time.monotonic() - t0


@pytest.fixture(scope="module")
def uninterrupted_s() -> float:
    """How long the same cluster takes to start, work and close with no Ctrl-C, on this machine now."""
    done, took = _run_interrupted("none")
    assert (done.returncode, done.stdout) == (0, "3\nclosed\n"), done.stderr
    return took


@pytest.mark.parametrize("method", ["__init__", "close"], ids=["while it starts", "while it closes"])
def test_ctrl_c_as_a_local_dask_cluster_starts_or_closes_is_taken_in_order(method, uninterrupted_s):
    """Regression: a Ctrl-C that landed while `sweep --dask local` closed its cluster cut the close short,
    and Python's exit then waited 10 s for Dask to close it again; one that landed while the cluster
    started printed pages of Dask's tracebacks."""
    done, took = _run_interrupted(method)
    if method == "__init__":  # taken once the cluster has started, before any task; the cluster closed in order
        assert done.returncode == -2 and done.stdout == "" and done.stderr.rstrip().endswith("KeyboardInterrupt")
        assert done.stderr.count("Traceback") == 1 and "in _signals_deferred" in done.stderr, done.stderr
    else:  # the work was done: the close ends it, the late Ctrl-C held off
        assert (done.returncode, done.stdout) == (0, "3\nclosed\n"), done.stderr
    # the 10 s more at exit it took before, against the run without Ctrl-C (a busy machine slows both alike)
    assert took < uninterrupted_s + 6.0, (took, uninterrupted_s)


@pytest.mark.sumo
def test_a_sweep_d4sumo_0_18_ran_on_a_road_of_ones_own_is_told_the_keys_that_go_on_with_it(tmp_path, capsys):
    """Regression: the hint for a sweep 0.18 stored (its platoon through red lights) raised AttributeError."""
    road = tmp_path / "road"
    shutil.copytree(Path(__file__).resolve().parent.parent / "examples" / "roads" / "three_edges", road)
    text = (f'name = "mine"\n[grid]\nsetpoint_m = [5.0, 7.0]\n[scenario]\nnetwork = "{road}/"\nstart = "steady"\n'
            'duration_s = 10.0\n[search]\noptimizer = "random"\nsamples = 2\n')
    db = tmp_path / "r.sqlite"
    assert main(["sweep", str(write(tmp_path, text.replace('start = "steady"', 'start = "steady"\nsignals = "ignore"'),
                                    "before.toml")), "--db", str(db), "--quiet"]) == 0
    capsys.readouterr()
    assert main(["sweep", str(write(tmp_path, text)), "--db", str(db), "--quiet"]) == 2
    said = capsys.readouterr().err
    assert said.count("\n") == 1 and "It was run by d4sumo 0.18 or before (the platoon driving through red lights)" in said
    assert '`signals = "ignore"` in [scenario]' in said


def test_a_sweeps_client_writes_the_samples_of_a_moment_together_and_what_is_left_when_it_stops(tmp_path):
    """The client's writes (`run._Writes`): the results of every campaign that came in within FLUSH_S in one
    transaction; what is left written when the sweep ends or fails; and a transaction is all or none."""
    from d4sumo.search.campaign import Campaign
    from d4sumo.sweep.run import _Writes

    with Store(tmp_path / "w.sqlite") as store:
        a, b = (store.open_campaign(Campaign(seed=seed).definition(), 10, None) for seed in (1, 2))
        row = (0, (0.5,), -1.0, "no_crash", None, None, 0.01, None)
        with pytest.raises(RuntimeError):
            with _Writes(store) as writes:
                writes.last += 3600  # no moment passes in this block, however slow the machine
                writes.add(a, [row])
                writes.add(b, [row, (1, *row[1:])])
                assert store.samples() == []  # within FLUSH_S of the start: not written yet
                raise RuntimeError("the sweep failed")
        assert sorted((s.campaign_id, s.index) for s in store.samples()) == [(a, 0), (b, 0), (b, 1)]
        writes = _Writes(store)
        writes.last -= _Writes.FLUSH_S  # a moment has passed: the next result writes everything
        writes.add(a, [(1, *row[1:])])
        assert len(store.samples(a)) == 2
        with pytest.raises(StoreError, match="already has sample 0"):
            store.add_samples_of([(a, [(2, *row[1:])]), (b, [row])])  # b's sample 0 is stored: neither goes in
        assert len(store.samples(a)) == 2


@pytest.mark.sumo
def test_a_sweep_in_parts_on_several_clients_stores_what_it_stores_whole_and_a_part_keeps_its_own_database(tmp_path, capsys):
    """`sweep --part K/N`: N clients share a sweep, each its own database; together they hold the samples the
    whole sweep holds, and `report` reads them together. A part's database is refused to another part, and to
    the whole sweep, unchanged; a part that is no part of this grid is one line."""
    from d4sumo.search.store import Store

    path = write(tmp_path, TINY)
    run = ["sweep", str(path), "--workers", "1", "--quiet"]
    assert main([*run, "--db", str(tmp_path / "whole.sqlite")]) == 0
    for k in (1, 2):
        assert main([*run, "--db", str(tmp_path / f"part{k}.sqlite"), "--part", f"{k}/2"]) == 0
    assert "sweep tiny (part 2 of 2): 2 campaigns, 12 samples" in capsys.readouterr().out

    def samples(*dbs):
        rows = []
        for db in dbs:
            with Store(tmp_path / db, create=False) as store:
                rows += [(c.key, s.index, s.params, s.robustness, s.outcome) for c in store.campaigns() for s in store.samples(c.id)]
        return sorted(rows)

    assert samples("part1.sqlite", "part2.sqlite") == samples("whole.sqlite") and len(samples("whole.sqlite")) == 24
    assert not set(samples("part1.sqlite")) & set(samples("part2.sqlite"))
    before = (tmp_path / "part1.sqlite").read_bytes()
    assert main([*run, "--db", str(tmp_path / "part1.sqlite"), "--part", "2/2"]) == 2
    err = capsys.readouterr().err
    assert "holds sweep 'tiny' (part 1 of 2)" in err and "not 'tiny' (part 2 of 2)" in err and err.count("\n") == 1
    assert main([*run, "--db", str(tmp_path / "part1.sqlite")]) == 2
    assert "holds sweep 'tiny' (part 1 of 2)" in capsys.readouterr().err
    assert (tmp_path / "part1.sqlite").read_bytes() == before
    assert main(["report", str(tmp_path / "part1.sqlite"), str(tmp_path / "part2.sqlite"), "--out", str(tmp_path / "r"),
                 "--quiet"]) == 0
    assert (tmp_path / "r" / "index.html").is_file()
    for bad in ("0/2", "3/2", "1/5", "a/b", "1-2", "2"):
        assert main([*run, "--db", str(tmp_path / "bad.sqlite"), "--part", bad]) == 2
        err = capsys.readouterr().err
        assert err.count("\n") == 1 and "--part" in err and "K/N with 1 <= K <= N <= 4" in err
    assert not (tmp_path / "bad.sqlite").exists()


def test_a_dask_sweep_asks_the_scheduler_for_its_threads_at_most_once_a_second(monkeypatch):
    """Each ask is a round trip to the scheduler (0.35 ms on a local cluster); the client asked twice a task,
    which at a thousand workers took a third of its time (tools/bench_client.py)."""
    from d4sumo.sweep import dask_cluster

    class Cluster:
        asks = 0

        def nthreads(self):
            Cluster.asks += 1
            return {"a": 1, "b": 2}

    clock = [100.0]
    monkeypatch.setattr(dask_cluster.time, "monotonic", lambda: clock[0])
    threads = dask_cluster._threads(Cluster())
    assert [threads() for _ in range(50)] == [3] * 50 and Cluster.asks == 1
    clock[0] += 1.0
    assert threads() == 3 and Cluster.asks == 2


def test_every_example_sweep_loads():
    """The sweep files the docs point to are sweeps this version reads (a campaign that searches its situation
    among them)."""
    folder = Path(__file__).resolve().parent.parent / "examples" / "sweeps"
    sweeps = {path.stem: Sweep.load(path) for path in sorted(folder.glob("*.toml"))}
    assert len(sweeps) >= 10 and all(s.campaigns for s in sweeps.values())
    domain = sweeps["domain"].campaigns
    assert [c.optimizer for c in domain] == ["random", "auto"]
    assert domain[0].situation == (("setpoint_m", 3.0, 15.0), ("speed_mps", 20.0, 30.0), ("start", ("rest", "steady")))
