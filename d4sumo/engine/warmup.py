"""The traffic at the end of its warm-up: played alone once, in a process of its own, and kept as SUMO's saved
state in d4sumo's cache (`traffic_state`); every episode of the configuration loads it and meets the same
traffic. A density SUMO cannot insert and traffic that crashes on its own are refused in one line."""

from __future__ import annotations

import gzip
import hashlib
import os
import re
import subprocess
import tempfile
import time
from pathlib import Path
from xml.sax.saxutils import escape as xml_escape, unescape as xml_unescape

from ..cache import default_cache_dir
from ..errors import ConfigError, SumoError
from ..model.config import EpisodeConfig
from ..sumohome import sumo_binary
from .calls import simulation_step
from .command import sumo_command, traffic_files
from .scenarios import Road


#: the version of the warm-up d4sumo saves: a cached state of another is warmed up again (2: its key holds every option
#: its SUMO is started with, where 1 took a lane-changing attacker's warm-up for an in-lane one's, whichever came first)
TRAFFIC_STATE = 2
#: a flow's or a vehicle's element in SUMO's saved state that does not say its insertion checks: its id
_UNCHECKED = re.compile(rb'<(?:flowState|vehicle) id="([^"]*)"(?![^>]*\binsertionChecks=)')


def traffic_state(config: EpisodeConfig, road: Road) -> Path | None:
    """The traffic at the end of its warm-up (`traffic.TrafficParams`), as SUMO's saved state (its
    vehicles, flows and random streams), or None without traffic. Every episode of the configuration loads
    it and so meets the same traffic; it is warmed up once per SUMO build, road, demand, seed, step and
    warm-up, and kept in d4sumo's cache (a warm-up of 300 s costs as much as five 60 s episodes).

    The warm-up plays the traffic alone. A density SUMO cannot insert (more than two vehicles per lane, and
    a tenth of the demand, still waiting to enter at its end) and a collision among the traffic are refused:
    neither is the platoon's doing."""
    if config.traffic is None:
        return None
    demands = traffic_files(config, road)
    sumo = sumo_binary("sumo")
    cmd = sumo_command(config, road, demand_files=demands) + ["--save-state.rng", "true", "--save-state.precision", "17"]
    key = "\0".join([f"{sumo}:{os.stat(sumo).st_mtime_ns}", str(TRAFFIC_STATE), road.net_file.name, ",".join(d.name for d in demands),
                     str(config.traffic.seed), repr(config.step_s), repr(config.traffic.warmup_s),
                     # what else its SUMO loads: a .sumocfg's additional files and options change the traffic
                     *([config.additional_sha256] if config.additional else []), *(f"{k}={v}" for k, v in config.sumo_options),
                     *(["insertion-checks", "a process of its own"] if config.traffic.insertion_checks else []),
                     # and every option it is started with (a lane-changing attacker's lanechange.duration changes how the
                     # traffic changes lanes too): files by their names, which say their content, wherever the cache is
                     *(",".join(Path(p).name for p in arg.split(",")) if os.sep in arg else arg for arg in cmd[1:])])
    folder = Path(default_cache_dir()).parent / "traffic-states"
    path = folder / f"{hashlib.sha256(key.encode()).hexdigest()[:16]}.xml.gz"
    if path.is_file():
        try:  # used now: the last a full cache lets go (`_prune`)
            os.utime(path)
        except OSError:  # a cache one may read, not write
            pass
        return path
    try:
        folder.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(dir=folder, suffix=".xml.gz")
        os.close(fd)
    except OSError as exc:
        raise SumoError(f"cannot write the traffic's warm-up under {folder}: {exc.strerror or exc}") from None
    try:
        _warm_up_alone(cmd, config, road, tmp)
        if config.traffic.insertion_checks:
            _keep_insertion_checks(Path(tmp), demands)
        os.replace(tmp, path)
    finally:
        if os.path.exists(tmp):
            os.unlink(tmp)
    _prune(folder, TRAFFIC_STATES_KEPT)
    return path


#: the traffic warm-ups the cache keeps, the most recently used (a few kB each): a campaign whose samples each meet
#: traffic of their own warms up one a sample
TRAFFIC_STATES_KEPT = 4096
#: a cached file used this recently is never let go [s]: another process may be about to load it
IN_USE_S = 3600.0


def _prune(folder: Path, kept: int) -> None:
    """The cache ``folder`` down to its ``kept`` most recently used files, none used within `IN_USE_S`."""
    try:
        files = [(f.stat().st_mtime, f) for f in folder.iterdir() if f.is_file()]
    except OSError:
        return
    if len(files) <= kept:
        return
    now = time.time()
    for used, f in sorted(files)[:len(files) - kept]:
        if now - used > IN_USE_S:
            try:
                f.unlink()
            except OSError:  # another process let it go first
                pass


def _warm_up_alone(cmd: list[str], config: EpisodeConfig, road: Road, state: str) -> None:
    """The warm-up, its state saved to ``state``, in a process of its own: SUMO's stream of random numbers for
    the demand it reads (a flow's random headways) counts its draws across the simulations of a process, and
    the saved state holds that count, which its loading replays; a state saved in a process that ran other
    simulations before met other traffic once loaded (the gap to the car ahead of the attacker 38.9 m, not
    55.4 m). A fresh process saves the same state on every machine."""
    import pickle
    import sys

    with tempfile.TemporaryDirectory() as work:
        given, said = Path(work, "given.pickle"), Path(work, "said.pickle")
        given.write_bytes(pickle.dumps((os.getpid(), cmd, config, road, state)))
        code = "import sys; from d4sumo.engine.warmup import _warm_up_here; _warm_up_here(sys.argv[1], sys.argv[2])"
        done = subprocess.run([sys.executable, "-c", code, str(given), str(said)], capture_output=True, text=True)
        if not said.is_file():
            last = (done.stderr.strip().splitlines() or [f"exit {done.returncode}"])[-1]
            raise SumoError(f"the traffic's warm-up failed: {last}")
        outcome = pickle.loads(said.read_bytes())
    if outcome is not None:
        kind, what = outcome
        raise ConfigError(*what) if kind == "config" else SumoError(what)


def _warm_up_here(given: str, said: str) -> None:
    """`_warm_up_alone`'s process: plays the warm-up, saves its state, and says how it ended (None: saved)."""
    import pickle

    import libsumo

    from ..processes import die_with_parent

    parent, cmd, config, road, state = pickle.loads(Path(given).read_bytes())
    die_with_parent(parent)
    outcome = None
    try:
        libsumo.start(cmd)
        try:
            _warm_up(libsumo, config, road)
            libsumo.simulation.saveState(state)
        finally:
            libsumo.close()
    except ConfigError as exc:
        outcome = ("config", (exc.field, exc.given, exc.allowed))
    except libsumo.TraCIException as exc:
        outcome = ("sumo", f"SUMO failed in the traffic's warm-up: {exc}")
    Path(said).write_bytes(pickle.dumps(outcome))


def _keep_insertion_checks(state: Path, demands: list[Path]) -> None:
    """SUMO's saved state drops what the demand says of its flows' and vehicles' insertion checks (1.28), and
    the episode inserts with none (the platoon's cars are placed where they are put): each flow and vehicle
    in the state is given back its demand's (`traffic.demand_xml`: all of them where a user's sets none; a
    flow's vehicle, its flow's), so that a car entering after the warm-up does not land on the one before it."""
    import xml.etree.ElementTree as ET

    checks = {e.get("id"): e.get("insertionChecks", "all") for demand in demands for e in ET.parse(demand).getroot() if e.get("id")}

    def given(match: re.Match) -> bytes:
        vid = xml_unescape(match.group(1).decode())
        value = checks.get(vid) or checks.get(vid.rpartition(".")[0]) or "all"
        return match.group(0) + f' insertionChecks="{xml_escape(value)}"'.encode()

    with gzip.open(state, "rb") as f:
        text = f.read()
    with gzip.open(state, "wb") as f:
        f.write(_UNCHECKED.sub(given, text))


def _warm_up(api, config: EpisodeConfig, road: Road) -> None:
    traffic = config.traffic
    step = simulation_step(api)
    departed = 0
    for _ in range(int(round(traffic.warmup_s / config.step_s))):
        step()
        departed += api.simulation.getDepartedNumber()
        if api.simulation.getCollidingVehiclesNumber():
            crashed = api.simulation.getCollidingVehiclesIDList()
            raise ConfigError("traffic", traffic.label, f"traffic that does not crash on its own on {road.name} ({', '.join(crashed[:2])} "
                                                        f"collided at {api.simulation.getTime():g} s of its warm-up, before the platoon joined)")
    # Poisson arrivals queue for a moment now and then; a density beyond what the road takes queues for good
    waiting = len(api.simulation.getPendingVehicles())
    if waiting > 2 * len(road.through_lanes) and waiting > 0.1 * (departed + waiting):
        raise ConfigError("traffic.vehicles_per_hour", traffic.vehicles_per_hour,
                          f"a density SUMO can insert on {road.name}: {waiting} of {departed + waiting} vehicles still waited "
                          f"to enter after the {traffic.warmup_s:g} s warm-up")
