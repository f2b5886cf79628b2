"""Shared fixtures. Tests that run SUMO carry the `sumo` marker and use it for real."""

from __future__ import annotations

import contextlib
import functools
import shutil
import sys
import threading

import numpy as np
import pytest

from d4sumo.model.attacks.pedals import make_attack
from d4sumo.model.config import EpisodeConfig

#: Knots found by search that make v3 hit v2 from rest at the default setpoint (attacker untouched).
SUCCESS_KNOTS = [0.46, -0.65, 0.73, 0.08, -0.4, -0.15, -0.94, -0.75, 0.34]
#: Knots that make v1 hit the attacker.
ATTACKER_CRASH_KNOTS = [-1, 1, 1, -1, 1, -1, -1, 1, -1]


def sigint_at_default() -> None:
    """A child's ``preexec_fn``: Ctrl-C at its default. A shell running the tests in the background hands its
    children SIGINT ignored, and a process started so never sees a Ctrl-C sent to it."""
    import signal

    signal.signal(signal.SIGINT, signal.SIG_DFL)


def side_by_side(calls):
    """Call each of ``calls`` (independent of one another, each typically a whole command run as a process of
    its own) at once, as many together as this process has cores (one core fewer when made ahead, beside the
    tests); their results in order. An exception in one is raised here."""
    from concurrent.futures import ThreadPoolExecutor

    from d4sumo.sweep.workers import usable_cores

    cores = usable_cores()
    lanes = max(1, cores - 1) if threading.current_thread().name == _AHEAD_THREAD else max(2, cores)
    with ThreadPoolExecutor(max_workers=lanes) as pool:
        futures = [pool.submit(call) for call in calls]
        return [f.result() for f in futures]


# --- fixtures made ahead ---------------------------------------------------------------------------------
#
# Most tests run in this process, on one core. A fixture whose making is only commands (processes of their
# own, checked by the tests that use it, timed by nothing) is `made_ahead`: when the session starts, a thread
# begins making those the selected tests use, in the order they use them, on the core the tests leave idle.
# It makes them only beside the tests of engine/, model/, results/ and search/ (none of which times
# anything or looks at other processes); any other test (kills, signals, time limits, process ids) first
# waits until the thread is done (making those it has not begun itself). A test that needs a fixture the
# thread has not begun makes it itself.

_AHEAD_THREAD = "made-ahead"
_AHEAD_BESIDE = ("engine", "model", "results", "search")  # the folders of tests/ the thread runs beside
_MADE: dict[tuple[str, str], "_Made"] = {}  # (module, fixture name) -> its making
_ahead: list[tuple] = []  # (the thread, the makings it was given, tmp_path_factory)


class _Made:
    """One fixture's value, made once: by the thread, or by the first test that needs it."""

    def __init__(self, make):
        self.make = make
        self._lock = threading.Lock()
        self._begun = False
        self._done = threading.Event()
        self._value = self._error = None

    def begin(self, tmp_path_factory) -> None:
        """Make it here, unless it is made or being made already."""
        with self._lock:
            if self._begun:
                return
            self._begun = True
        try:
            self._value = self.make(tmp_path_factory)
        except Exception as exc:  # raised in the tests that use it
            self._error = exc
        except BaseException as exc:  # Ctrl-C: the session stops
            self._error = exc
            raise
        finally:
            self._done.set()

    def value(self, tmp_path_factory):
        self.begin(tmp_path_factory)
        self._done.wait()
        if self._error is not None:
            raise self._error
        return self._value


def made_ahead(scope: str = "module"):
    """A fixture (of ``scope``) whose value ``make(tmp_path_factory)`` gives, made ahead when the session starts.
    ``make`` may run commands and write files under ``tmp_path_factory`` only: it runs beside other tests."""

    def wrap(make):
        key = (make.__module__, make.__name__)
        _MADE[key] = _Made(make)

        @functools.wraps(make)
        def fixture(tmp_path_factory):
            return _MADE[key].value(tmp_path_factory)

        return pytest.fixture(scope=scope)(fixture)

    return wrap


@pytest.fixture(scope="session", autouse=True)
def _make_ahead(request, tmp_path_factory):
    """Begins making the `made_ahead` fixtures the selected tests use. At the session's end (early, on a
    failure with -x), nothing more is begun, and what is being made is waited for."""
    wanted = []
    for item in request.session.items:
        for name in item.fixturenames:
            for key in ((getattr(item.module, "__name__", None), name), (__name__, name)):
                if key in _MADE and _MADE[key] not in wanted:
                    wanted.append(_MADE[key])
    stop = threading.Event()

    def make():
        for made in wanted:
            if stop.is_set():
                return
            made.begin(tmp_path_factory)

    thread = threading.Thread(target=make, name=_AHEAD_THREAD, daemon=True)
    _ahead.append((thread, wanted, tmp_path_factory))
    thread.start()
    yield
    stop.set()
    thread.join()


def pytest_runtest_call(item):
    """A test outside the folders the thread runs beside first makes what the thread has not begun, and waits
    until the thread is done."""
    from pathlib import Path

    if _ahead and _ahead[0][0].is_alive():
        here = Path(__file__).parent
        if not any(Path(item.path).is_relative_to(here / folder) for folder in _AHEAD_BESIDE):
            thread, wanted, tmp_path_factory = _ahead[0]
            for made in wanted:
                made.begin(tmp_path_factory)
            thread.join()


def knots_signal(values, config: EpisodeConfig) -> np.ndarray:
    return make_attack("knots").signal(values, np.arange(config.steps) * config.step_s)


def random_plans(config: EpisodeConfig, count: int, seed: int = 0, family: str = "knots"):
    """Attack plans drawn uniformly from the campaign's box (a lane change time too, for a lateral maneuver)."""
    from d4sumo.model.attacks.maneuvers import attack_plan, maneuver_of

    box = maneuver_of(config).family(make_attack(family))
    rng = np.random.default_rng(seed)
    return [attack_plan(box, box.lower + rng.random(box.lower.size) * (box.upper - box.lower), config) for _ in range(count)]


def assert_same_episode(batched, alone) -> None:
    """Bit for bit: every signal, the collision record, the minimum gaps, the outcome."""
    assert batched.outcome == alone.outcome
    assert batched.collisions == alone.collisions
    assert batched.min_gaps_m() == alone.min_gaps_m()
    assert batched.trace.names == alone.trace.names
    assert np.array_equal(batched.trace.times_s, alone.trace.times_s)
    for name in alone.trace.names:
        assert np.array_equal(batched.trace[name], alone.trace[name]), name


@pytest.fixture(scope="session")
def road():
    from d4sumo.engine.scenarios import build_road

    return build_road("highway_4lane")


SMALL_SWEEP = """
name = "fixture"
[grid]
setpoint_m = [5.0, 7.0]
speed_mps = [20.0, 25.0]
start = ["rest", "steady"]
attack = ["knots"]
optimizer = ["random"]
seed = [0]
[search]
samples = 12
"""


@made_ahead(scope="session")
def small_db(tmp_path_factory):
    """A small real results database: 8 knot campaigns of 12 samples, simulated in SUMO (the sweep run on one
    worker by `d4sumo sweep`)."""
    import subprocess
    import sys

    folder = tmp_path_factory.mktemp("small_db")
    path = folder / "sweep.toml"
    path.write_text(SMALL_SWEEP)
    db = folder / "results.sqlite"
    done = subprocess.run([sys.executable, "-m", "d4sumo.cli", "sweep", str(path), "--db", str(db), "--workers", "1", "--quiet"],
                          capture_output=True, text=True, timeout=600)
    assert done.returncode == 0, done.stderr
    return db


@pytest.fixture(scope="session")
def switching_fmus(tmp_path_factory) -> dict:
    """The paper's switching controller as d4sumo ships it, built as FMUs for this machine: {2: FMI 2.0's
    path, 3: FMI 3.0's}."""
    from d4sumo.fmus import build_switching_fmu

    folder = tmp_path_factory.mktemp("fmus")
    return {v: build_switching_fmu(folder / f"switching{v}.fmu", v) for v in (2, 3)}


@pytest.fixture(scope="session")
def asam_opendrive_checker():
    """ASAM's OpenDRIVE checker (asam-qc-opendrive), in an environment of its own: it pins numpy < 2, which
    d4sumo's FMU library cannot share. Made once a machine, in d4sumo's cache; returns check(xodr) -> the
    issues it found, by checker."""
    import os
    import subprocess
    import sys
    from pathlib import Path
    from xml.etree import ElementTree as ET

    base = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    env = base / "d4sumo" / "checkers" / "asam-qc-opendrive-1.0.0"
    checker = env / "bin" / "qc_opendrive"
    if not checker.is_file():
        subprocess.run([sys.executable, "-m", "venv", str(env)], check=True)
        made = subprocess.run([str(env / "bin" / "pip"), "install", "-q", "asam-qc-opendrive==1.0.0"], capture_output=True, text=True)
        if made.returncode != 0:
            pytest.fail(f"ASAM's OpenDRIVE checker could not be installed (pip: {made.stderr.strip()[-500:]})")

    def check(xodr: Path, tmp: Path) -> dict[str, list[str]]:
        result, config = tmp / "xodr.xqar", tmp / "xodr-config.xml"
        config.write_text(f'<?xml version="1.0" encoding="UTF-8"?><Config><Param name="InputFile" value="{xodr}"/>'
                          f'<CheckerBundle application="xodrBundle"><Param name="resultFile" value="{result}"/>'
                          "</CheckerBundle></Config>")
        subprocess.run([str(checker), "-c", str(config)], check=True, capture_output=True, cwd=tmp)
        found = {c.get("checkerId"): [i.get("description") for i in c.iter("Issue")]
                 for c in ET.parse(result).getroot().iter("Checker")}
        assert "check_asam_xodr_xml_valid_schema" in found  # it ran its checks
        return found

    return check


@contextlib.contextmanager
def dask_elsewhere(tmp_path, workers: int = 1):
    """A Dask scheduler and ``workers`` workers started as their own processes, each in a folder of its own
    under ``tmp_path`` (scheduler, worker1, ...) with a cache of its own: they see nothing of the client's
    folder. Yields (the scheduler's address, the workers' processes); all are killed on the way out."""
    import json
    import os
    import signal
    import subprocess
    import sys
    import time
    from pathlib import Path

    dask = str(Path(sys.executable).parent / "dask")
    scheduler_file = tmp_path / "scheduler.json"
    procs = []

    def spawn(args, folder):
        folder.mkdir()
        env = {**os.environ, "XDG_CACHE_HOME": str(folder / "cache")}
        procs.append(subprocess.Popen([dask, *args], cwd=folder, env=env, stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL, start_new_session=True))
        return procs[-1]

    try:
        spawn(["scheduler", "--host", "127.0.0.1", "--port", "0", "--no-dashboard", "--scheduler-file", str(scheduler_file)],
              tmp_path / "scheduler")
        deadline = time.time() + 60
        while not scheduler_file.exists() and time.time() < deadline:
            time.sleep(0.2)
        address = json.loads(scheduler_file.read_text())["address"]
        yield address, [spawn(["worker", address, "--nthreads", "1", "--no-dashboard"], tmp_path / f"worker{i}")
                        for i in range(1, workers + 1)]
    finally:
        for p in procs:
            try:
                os.killpg(p.pid, signal.SIGKILL)
            except ProcessLookupError:
                pass


#: whether libsumo's own C++ calls (`engine.calls.native_calls`) must be had here: on Linux, where a C++ compiler built
#: them at install (without one, pip goes on without them and the loop in C calls libsumo as the Python does)
NATIVE_CALLS_EXPECTED = sys.platform.startswith("linux") and any(shutil.which(c) for c in ("c++", "g++", "clang++"))

