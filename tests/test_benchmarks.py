"""The benchmarks' own models (tools/): ARCH-COMP's chasing cars, with values worked out by hand."""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tools"))
import arch_cc  # noqa: E402
from conftest import made_ahead, side_by_side, sigint_at_default  # noqa: E402


def test_with_no_pedal_nobody_moves_and_each_specification_scores_the_standing_gaps():
    y = arch_cc.simulate(np.zeros(40))
    assert y.shape == (1, 1001, 5) and np.allclose(y[0], [0.0, 10.0, 20.0, 30.0, 40.0])  # Keeping, v = 0
    rho = {s: float(arch_cc.robustness(s, y)[0]) for s in arch_cc.SPECS}
    # d21 = d54 = 10 throughout: CC1 40 - 10; CC2 10 - 15; CC3 max(20 - 10, 10 - 40); CC4 10 - 8 (its
    # windows reach 115 s, cut at the trace's end); CC5 max(-(10 - 9), 10 - 9); CCx 10 - 7.5
    assert rho == pytest.approx({"CC1": 30.0, "CC2": -5.0, "CC3": 10.0, "CC4": 2.0, "CC5": 1.0, "CCx": 2.5})


def test_cc3_is_the_competitions_a_first_gap_opening_while_the_last_stays_under_40_m_falsifies_it():
    """CC3 as ARCH-COMP states it (FalStar's file of 2019 had <= 40 in the second disjunct, which nothing
    falsifies): d21 > 20 somewhere in [t, t + 20] and d54 < 40 all through it, for some t <= 80."""
    t = np.arange(1001) * arch_cc.SAMPLE_S
    y = np.tile([0.0, 10.0, 20.0, 30.0, 40.0], (1, 1001, 1)).astype(float)
    y[0, :, 0] = np.where((t >= 30) & (t <= 35), -15.0, 0.0)  # the first gap opens to 25 m for 5 s
    assert arch_cc.robustness("CC3", y)[0] == pytest.approx(max(20.0 - 25.0, 10.0 - 40.0))
    y[0, :, 4] = np.where((t >= 30) & (t <= 35), 75.0, 40.0)  # the last gap opening to 45 m then satisfies it
    assert arch_cc.robustness("CC3", y)[0] == pytest.approx(45.0 - 40.0)


def test_full_throttle_pulls_car_1_away_and_car_2_chases_it():
    y = arch_cc.simulate(np.r_[np.ones(20), np.zeros(20)])[0]
    # car 1: v' = -1, so y1 = -t^2 / 2 (Euler at 0.01 s: within a few cm at 2 s)
    assert y[20, 0] == pytest.approx(-2.0, abs=0.05)
    assert y[-1, 1] < 0.0 and y[-1, 1] - y[-1, 0] >= 5.0  # car 2 has followed, never closer than Braking allows


def test_the_input_instances():
    x = np.r_[np.linspace(0, 1, 20), np.zeros(20)]
    t = np.array([0.0, 4.99, 5.0, 99.9])
    throttle2, _ = arch_cc.inputs(x, 2, t)
    assert throttle2[0].tolist() == [0.0, 0.0, x[1], 1.0]  # held 5 s a value
    throttle1, _ = arch_cc.inputs(x, 1, t)
    assert throttle1[0, 0] == 0.0 and 0.0 < throttle1[0, 1] < x[1] and throttle1[0, 3] == pytest.approx(1.0, abs=0.01)


def test_bench_falsify_times_the_optimiser_a_campaign_makes():
    """tools/bench_falsify.py wraps the optimiser every campaign makes; it broke silently when campaigns
    moved where they make it."""
    from bench_falsify import timed_optimizer

    from d4sumo.search.campaign import Campaign
    from d4sumo.search.runner import run_campaign

    with timed_optimizer() as clock:
        run_campaign(Campaign(optimizer="bo", samples=12, seed=1))
    assert clock[0] > 0.0


def test_cc4_2019_the_formula_falcauns_figures_use_needs_dips_every_5_s_where_the_competitions_needs_20():
    """The last gap dipping to 6 m for 1 s every 15 s: within every 20 s window (CC4 falsified, -2), not
    within every 5 s one (CC4-2019, FalStar 2019's formula, satisfied by the standing gap, 10 - 8)."""
    t = np.arange(1001) * arch_cc.SAMPLE_S
    y = np.tile([0.0, 10.0, 20.0, 30.0, 40.0], (1, 1001, 1)).astype(float)
    y[0, :, 4] = np.where(t % 15.0 < 1.0, 36.0, 40.0)
    assert arch_cc.robustness("CC4", y)[0] == pytest.approx(-2.0)
    assert arch_cc.robustness("CC4-2019", y)[0] == pytest.approx(2.0)


def test_falcauns_published_cc4_counterexample_does_not_falsify_cc4_here():
    """FalCAuN's counterexample to its CC4 at ARCH-COMP 2024 (throttle 1 for 10 s then 0, brake 1;
    FalCAuN_ARCH2024_validation.csv) falsifies none of the CC4 formulas in this model at DT = 10 ms (finer
    steps raise its robustness to 2.3): the model's documented gap to Simulink's trajectories (arch_cc)."""
    x = np.r_[np.ones(2), np.zeros(18), np.ones(20)]
    y = arch_cc.simulate(x, 2)
    assert arch_cc.robustness("CC4", y)[0] == pytest.approx(0.873, abs=0.002)
    assert arch_cc.robustness("CC4-2019", y)[0] == pytest.approx(1.402, abs=0.002)


def test_the_chasing_cars_integrate_at_a_finer_step_on_request():
    """simulate(dt=...) checks how far a verdict moves with the integration step: the same samples every
    0.1 s, the same trajectory where no chart switches (car 1 alone moves under a constant push)."""
    x = np.r_[np.full(20, 0.5), np.zeros(20)]
    coarse, fine = arch_cc.simulate(x, 2), arch_cc.simulate(x, 2, dt=0.001)
    assert coarse.shape == fine.shape == (1, 1001, 5)
    assert np.allclose(coarse[0, :, 0], fine[0, :, 0], rtol=0, atol=0.3)  # y1 = -t^2 / 4; Euler is off by dt t / 4
    exact = -0.25 * 100.0**2
    assert abs(fine[0, -1, 0] - exact) < 0.2 * abs(coarse[0, -1, 0] - exact) < 0.1  # ten times finer, ten times closer


def test_the_interval_of_the_mean_simulations_holds_the_mean_narrows_with_runs_and_is_the_same_each_time():
    """bench_arch prints it beside the ten-run means the competition publishes: CC4's ten-run mean moves by
    a hundred and more between sets of seeds."""
    from bench_arch import mean_interval

    ten = [911, 803, 417, 324, 336, 939, 723, 553, 292, 222]
    low, high = mean_interval(ten)
    assert low < np.mean(ten) < high and high - low > 200  # a wide one: these runs spread from 222 to 939
    assert mean_interval(ten) == (low, high)
    forty_low, forty_high = mean_interval(ten * 4)
    assert low < forty_low < forty_high < high
    # failed runs count in the resampling, not in the mean (ARCH-COMP's mean is over the falsified runs)
    with_failures = mean_interval([None, 100, None, 300, 200])
    assert 100 <= with_failures[0] < with_failures[1] <= 300
    # under three falsified runs, none: one run's mean would print as an interval of no width
    assert mean_interval([None, None]) is None and mean_interval([None] * 9 + [1200]) is None


_FOUND = """
import json, sys
from types import SimpleNamespace

sys.path.insert(0, sys.argv[1])
import bench_arch

args = SimpleNamespace(**json.loads(sys.argv[2]))
bench_arch.use_benchmark(args.benchmark, args.instance)
print(json.dumps([(spec, o, [f for f, _, _ in r]) for spec, o, r in bench_arch.runs_by_pair(args, ["CC3", "CC1"], 40)]))
"""

#: bench_arch's runs of the test below, as its flags give them
ARCH_RUNS = {"jobs": 1, "benchmark": "arch-comp-cc", "instance": 2, "first_seed": 1, "runs": 3, "optimizers": ["auto", "random"]}


@made_ahead()
def arch_runs_alone(tmp_path_factory):
    """ARCH_RUNS's (spec, optimiser, simulations to falsify on each seed), run alone (--jobs 1) in a process of
    their own."""
    import json
    import subprocess

    tools = Path(__file__).resolve().parent.parent / "tools"
    done = subprocess.run([sys.executable, "-c", _FOUND, str(tools), json.dumps(ARCH_RUNS)], capture_output=True, text=True,
                          timeout=600)
    assert done.returncode == 0, done.stderr
    return [(spec, o, found) for spec, o, found in json.loads(done.stdout)]


def test_bench_arch_runs_on_worker_processes_give_the_runs_it_gives_alone(arch_runs_alone):
    """--jobs: the same seeds, the same simulations to falsify, in the same order."""
    from types import SimpleNamespace

    import bench_arch

    alone = SimpleNamespace(**ARCH_RUNS)
    bench_arch.use_benchmark(alone.benchmark, alone.instance)
    found_alone = arch_runs_alone
    on_workers = SimpleNamespace(**{**vars(alone), "jobs": 2})
    found_workers = [(spec, o, [f for f, _, _ in r]) for spec, o, r in bench_arch.runs_by_pair(on_workers, ["CC3", "CC1"], 40)]
    assert found_workers == found_alone and [pair[:2] for pair in found_alone] == [
        ("CC3", "auto"), ("CC3", "random"), ("CC1", "auto"), ("CC1", "random")]
    assert any(f is not None for _, _, found in found_alone for f in found)


BENCH_ARCH_REFUSED = [
    (["--optimizers", "bayes"], "--optimizers: 'bayes': search.optimizer: got 'bayes'; allowed: one of bo,"),
    (["--optimizers", "bo:xi"], "--optimizers: got 'bo:xi'; allowed: an optimiser's name, or name:key=value"),
    (["--optimizers", "bo:budget=3"], "search.bo.budget: got 3; allowed: a key of [search.bo]"),
    (["--benchmark", "arch-comp-cc", "--optimizers", "auto:stall=-3"], "search.auto.stall: got -3; allowed:"),
    (["--runs", "0"], "--runs: got 0; allowed: a whole number of at least 1"),
    (["--specs", "CC1"], "--specs: got 'CC1'; allowed: with --benchmark plateaus, one of gap, close, held"),
    (["--benchmark", "arch-comp-cc", "--held", "10", "--jobs", "2"], "--jobs: got 2; allowed: 1 with --held"),
]

TOOLS_REFUSED = [  # regression: each ended in a traceback (or ran on)
    ("bench_sweep.py", ["--set", "foo"], "--set: got 'foo'; allowed: KEY=VALUE"),
    ("bench_sweep.py", ["--batch", "100000"], "--batch: got 100000; allowed: a whole number in [1, 64]"),
    ("bench_sweep.py", ["--workers", "1", "0"], "--workers: got 0; allowed: a whole number in [1, 1024]"),
    ("check_invariants.py", ["1", "--batch", "100000"], "--batch: got 100000; allowed: a whole number in [0, 64]"),
    ("paper_page.py", ["--runs", "{file}"], "allowed: a folder for the sweeps' databases (this is a file)"),
    ("paper_page.py", ["--runs", "{tmp}/absent/runs"], "allowed: a folder in an existing folder"),
    ("profile_episode.py", ["--episodes", "0"], "--episodes: got 0; allowed: a whole number of at least 1"),
    ("bench_client.py", ["--workers", "10", "0"], "--workers: got 0; allowed: a whole number in [1, 100000]"),
    ("bench_client.py", ["--workers", "10", "4", "--clients", "5"], "--clients: got 5; allowed: a whole number in [1, 4]"),
    ("domain_vs_grid.py", ["--grid-db", "nowhere.sqlite"], "--grid-db: got 'nowhere.sqlite'; allowed: a database of "
                                                            "examples/sweeps/paper_nonparametric.toml"),
    ("domain_vs_grid.py", ["--samples", "0"], "--samples: got 0; allowed: a whole number in [1, 100000]"),
    ("bench_client.py", ["--episode-ms", "0"], "--episode-ms: got 0.0; allowed: a time in (0, 10000] ms"),
]


@made_ahead()
def refused(tmp_path_factory):
    """The tools run with each bad command line below, each a process of its own, side by side:
    {(script, argv): (the process, the folder its {tmp} and {file} are in)}. A folder holds one empty file."""
    import subprocess

    tools = Path(__file__).resolve().parent.parent / "tools"
    cases = [("bench_arch.py", argv) for argv, _ in BENCH_ARCH_REFUSED] + [(script, argv) for script, argv, _ in TOOLS_REFUSED]

    def run(script, argv):
        folder = tmp_path_factory.mktemp("refused")
        (folder / "file").write_text("")
        argv = [a.format(file=folder / "file", tmp=folder) for a in argv]
        return subprocess.run([sys.executable, str(tools / script), *argv], capture_output=True, text=True, timeout=60), folder

    done = side_by_side([lambda script=script, argv=argv: run(script, argv) for script, argv in cases])
    return {(script, tuple(argv)): result for (script, argv), result in zip(cases, done)}


@pytest.mark.parametrize("argv, said", BENCH_ARCH_REFUSED)
def test_bench_arch_refuses_bad_flags_in_one_line_before_any_run(argv, said, refused):
    """A misspelt optimiser ran the benchmark's first simulation, then ended in a traceback."""
    done, _ = refused["bench_arch.py", tuple(argv)]
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and said in done.stderr and "Traceback" not in done.stderr


@pytest.mark.parametrize("script, argv, said", TOOLS_REFUSED)
def test_the_tools_refuse_bad_flags_in_one_line(script, argv, said, refused):
    done, folder = refused[script, tuple(argv)]
    assert done.returncode == 2 and done.stdout == ""
    assert done.stderr.count("\n") == 1 and said in done.stderr and "Traceback" not in done.stderr
    assert sorted(p.name for p in folder.iterdir()) == ["file"]  # nothing made


def _children(pid: int) -> set[int]:
    found = set()
    for stat in Path("/proc").glob("[0-9]*/stat"):
        try:
            fields = stat.read_text().rsplit(")", 1)[1].split()
        except OSError:
            continue
        if int(fields[1]) == pid:
            found.add(int(stat.parent.name))
    return found


@pytest.mark.skipif(not Path("/proc").is_dir(), reason="reads /proc for the worker processes")
@pytest.mark.parametrize("sig, code", [(2, 130), (15, 143)])  # SIGINT (Ctrl-C), SIGTERM
def test_bench_arch_jobs_stop_with_it_on_ctrl_c_and_sigterm(sig, code):
    import os
    import signal
    import subprocess
    import time

    tools = Path(__file__).resolve().parent.parent / "tools"
    p = subprocess.Popen([sys.executable, str(tools / "bench_arch.py"), "--benchmark", "arch-comp-cc", "--specs", "CC4",
                          "--optimizers", "auto", "--runs", "6", "--jobs", "2"], stdout=subprocess.DEVNULL,
                         stderr=subprocess.PIPE, text=True, env={**os.environ, "PYTHONFAULTHANDLER": "1"},
                         preexec_fn=sigint_at_default)  # regression: under a background shell it ignored Ctrl-C
    try:
        deadline = time.monotonic() + 30
        while len(workers := _children(p.pid)) < 2 and time.monotonic() < deadline:  # the pool's workers (and tracker)
            time.sleep(0.2)
        assert len(workers) >= 2
        time.sleep(1.0)  # the runs under way
        os.kill(p.pid, sig)
        try:
            _, err = p.communicate(timeout=20)
        except subprocess.TimeoutExpired:  # show where it hangs: faulthandler prints every thread's stack
            p.send_signal(signal.SIGABRT)
            pytest.fail(f"no exit 20 s after signal {sig}:\n{p.communicate(timeout=20)[1]}")
    finally:
        p.kill()
    assert p.returncode == code and "Traceback" not in err
    deadline = time.monotonic() + 5
    while any(Path(f"/proc/{w}").exists() for w in workers) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(Path(f"/proc/{w}").exists() for w in workers)


@pytest.mark.sumo
def test_the_profile_sees_sumos_stepping_and_calls_and_loses_no_time(monkeypatch):
    """tools/profile_episode.py: the step loop calls SUMO's C functions without a Python frame, which a profiler
    does not see (its stepping counted nowhere); through the tool's frames every part is seen, and the parts add
    up to all the time profiled."""
    import cProfile
    import pstats

    from d4sumo.engine import calls, sumo

    monkeypatch.setattr(calls, "api_call", calls.api_call)  # restored after: the tool rebinds them
    monkeypatch.setattr(sumo, "simulation_step", sumo.simulation_step)
    monkeypatch.setattr(calls, "NATIVE", calls.NATIVE)
    import profile_episode
    profile_episode.seen_by_the_profiler()
    parts, total = profile_episode.profiled(profile_episode.episodes_job(1))
    assert parts["SUMO stepping"] > 1200 * 1e-6 and parts["libsumo calls"] > 0.0  # 1,200 steps
    assert parts["step loop and control laws in C"] > 0.0  # the paper's column: its loop and laws in C
    assert parts["step loop and trace"] > 0.0 and "storage" not in parts  # an episode stores nothing
    profile = cProfile.Profile()
    profile.enable()
    profile_episode.episodes_job(1)()
    profile.disable()
    every = sum(tottime for _, _, tottime, _, _ in pstats.Stats(profile).stats.values())
    assert sum(profile_episode.split(profile).values()) == pytest.approx(every, rel=1e-9)


def test_bench_client_drives_the_real_client_with_simulated_workers_to_the_same_samples_whatever_their_number(tmp_path):
    """tools/bench_client.py: d4sumo's sweep client, whole, against simulated workers. Every sample is played and
    stored once, the samples do not depend on how many workers played them (the optimisers are on the client), and
    more workers take less simulated time, each at most fully used."""
    import bench_client
    from d4sumo.search.store import Store
    from d4sumo.sweep import Sweep

    sweep = Sweep.load(bench_client.sweep_file(tmp_path, 6, 30, "random"))
    one = bench_client.run_simulated(sweep, tmp_path, 1, 0.001)
    many = bench_client.run_simulated(sweep, tmp_path, 6, 0.001)

    def samples(db):
        with Store(db, create=False) as store:
            return sorted((c.key, s.index, s.params, s.robustness, s.outcome) for c in store.campaigns()
                          for s in store.samples(c.id))

    assert one["episodes"] == many["episodes"] == 180
    assert samples(one["db"]) == samples(many["db"]) and len(samples(one["db"])) == 180
    assert 0.5 < one["utilisation"] <= 1 and 0 < many["utilisation"] <= 1
    assert many["wall_s"] < one["wall_s"] / 2
    parts = bench_client.run_parts(sweep, tmp_path, 6, 3, 0.001)  # --clients 3: sweep --part K/3, two workers each
    assert len(parts["dbs"]) == 3 and parts["episodes"] == 180 and 0 < parts["utilisation"] <= 1
    assert sorted(s for db in parts["dbs"] for s in samples(db)) == samples(one["db"])


@pytest.mark.sumo
def test_bench_batch_situation_plays_the_same_episodes_fixed_and_searched(capsys):
    """tools/bench_batch.py --situation: a campaign searching its setpoint and speed, each sample within nanometres of
    the fixed values, plays what the fixed campaign plays: its cost per sample is the situation's own."""
    import argparse

    import bench_batch
    from d4sumo.model.config import EpisodeConfig

    for keys in ([], ["controller.acc_kp", "vehicle.actuator_lag_s"]):  # (keys a batch carries per platoon)
        bench_batch.situation_cost(EpisodeConfig(start="steady", duration_s=20.0),
                                   argparse.Namespace(samples=12, repeats=1, batch=8, situation=keys))
        lines = capsys.readouterr().out.splitlines()
        assert len(lines) == 3 and all("(the same outcome, colliding pair and time: 12 of 12)" in line for line in lines[1:])
        assert all(k in lines[0] for k in keys)


def test_domain_vs_grid_finds_the_grid_cell_a_situation_lies_in():
    import domain_vs_grid

    assert domain_vs_grid.cell_of(7.4, 26.0) == (7.0, 25.0) and domain_vs_grid.cell_of(14.6, 29.0) == (15.0, 30.0)
    assert domain_vs_grid.cell_of(7.5, 22.5) == (7.0, 20.0)  # half way: the nearer first
    assert domain_vs_grid.cell_of(3.0, 20.0) == (3.0, 20.0)


def test_bench_boundary_scores_each_campaigns_map_against_the_reference(capsys, monkeypatch):
    """tools/bench_boundary.py: a small run prints each campaign's share of the domain on the wrong side, and the
    locating campaign's map is drawn from its locating samples alone."""
    import bench_boundary

    monkeypatch.setattr(sys, "argv", ["bench_boundary.py", "--samples", "16", "--seeds", "1", "--reference", "100"])
    bench_boundary.main()
    lines = capsys.readouterr().out.splitlines()
    assert lines[0].startswith("from rest: reference of 100 random samples")
    rows = {line.split("  ")[1].strip(): line for line in lines[2:5]}
    assert set(rows) == {"random", "boundary", "auto + boundary 0.5"}
    assert "(drawn from 16 samples)" in rows["boundary"] and "(drawn from 8 samples)" in rows["auto + boundary 0.5"]


def test_bench_peers_plays_each_peers_sample_as_the_campaigns_own_episode(tmp_path):
    """tools/bench_peers.py: a peer's sample i is the episode the d4sumo campaign plays as its sample i, at the peer's
    point; VerifAI's samplers speak over a pipe (here a stand-in sampler of uniform points, in this Python: the pipe
    and the signs are d4sumo's side), and PSY-TaLiRo's optimisers where it is installed (`.[peers]`)."""
    import importlib.util

    import bench_peers

    problem = {"scenario": {"duration_s": 20.0}}
    stand_in = tmp_path / "uniform.py"
    stand_in.write_text("import json, sys\nimport numpy as np\nrng = np.random.default_rng(int(sys.argv[4]))\n"
                        "for _ in range(int(sys.argv[3])):\n    print(json.dumps(rng.random(int(sys.argv[2])).tolist()), flush=True)\n"
                        "    rho = float(sys.stdin.readline())\n    assert rho == rho\n")
    monkey = bench_peers.HERE
    try:
        bench_peers.HERE = tmp_path
        (tmp_path / "peers_verifai.py").write_text(stand_in.read_text())
        played = bench_peers.verifai_run(problem, "random", 6, 3, sys.executable)
    finally:
        bench_peers.HERE = monkey
    own = bench_peers.Episodes(problem, 6, 3)
    for i, r in enumerate(played):  # each is the campaign's own sample i at that point
        again = own.evaluator(i, np.asarray(r.params))
        assert (again.robustness, again.outcome, again.collision) == (r.robustness, r.outcome, r.collision)
    assert len(played) == 6 and len({r.params for r in played}) == 6
    first, wins, distinct, kinds = bench_peers.scores(played, own.family, 6)
    assert wins == sum(r.outcome == "success" for r in played) and distinct <= wins and kinds <= wins
    assert first == (next(i for i, r in enumerate(played) if r.outcome == "success") + 1 if wins else 7)
    if importlib.util.find_spec("staliro") is not None:
        for optimizer in bench_peers.PSY_TALIRO:
            ran = bench_peers.psy_taliro_run(problem, optimizer, 6, 3)
            assert len(ran) == 6 and all(r.outcome != "error" for r in ran)


def test_the_baseline_leaves_out_a_key_0_2_refuses_only_where_the_file_sets_the_value_0_2_ran(tmp_path):
    """d4sumo 0.2 refuses a key it does not know: the paper's sweep files pin CE without noise, which 0.2's CE ran; the
    baseline leaves that key out for 0.2, and a key at another value stays (0.2 then says so)."""
    from bench_sweep import without

    grid = Path(__file__).resolve().parent.parent / "examples" / "sweeps" / "paper_parametric.toml"
    less = without(grid, tmp_path / "copy.toml", "search.ce.noise_fraction")
    assert less is not None and "noise_fraction" not in less.read_text() and "batch_size = 1" in less.read_text()
    other = tmp_path / "other.toml"
    other.write_text(grid.read_text().replace("noise_fraction = 0.0", "noise_fraction = 0.2"))
    assert without(other, tmp_path / "other-copy.toml", "search.ce.noise_fraction") is None
    assert without(grid, tmp_path / "c.toml", "search.ce.elite_fraction") is None  # not a key added later
