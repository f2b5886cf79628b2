"""An FMU as a follower's controller: ``fmu:path/to/acc.fmu``, an FMI 2.0 or 3.0 co-simulation FMU stepped
at every step of the episode through fmpy (each follower its own instance).

What d4sumo gives it and reads back, matched by name (`SIGNALS`): at every step its inputs ``gap_m``,
``speed_mps`` and ``lead_speed_mps`` (what the follower's radar measured), then one ``doStep`` over the
step, then its output: ``command`` (the pedal in [-1, 1]) or ``acceleration_mps2`` (the car's pedal map
turns it into one). Before its initialisation, wherever it has them (a parameter or an input):
``setpoint_m``, ``target_speed_mps``, ``max_accel_mps2``, ``max_decel_mps2`` from the scenario and the
follower's vehicle. A follower's [controller] table maps other names (``gap_m = "distance"``) and sets
the FMU's own parameters by name (``acc_kp = 1.2``); an output ``mode`` is recorded in the trace.

The campaign's identity holds the FMU's content (``fmu_sha256``): a changed FMU is another system, never
replayed as a stored campaign's. Every FMU a campaign runs is kept by its content (`kept`): a stored
campaign whose path names no file from where it is replayed (a relative path, from another folder; a file
moved or deleted), or a file that has changed since, loads that copy; where none is kept, a changed file
is refused. Reading a database never loads an FMU
(`plugins.names_only`). An FMU that ships only its C sources is built for this machine, once (fmpy's
build: CMake and a C compiler). Unpacked and kept FMUs are in ``~/.cache/d4sumo/fmus``.
"""

from __future__ import annotations

import ctypes
import dataclasses
import functools
import hashlib
import logging
import math
import os
import shutil
import tempfile
import weakref
import zipfile
from pathlib import Path

from ...cache import cache_folder
from ...errors import ConfigError
from ...files import file_sha256
from .plugins import ControllerImportError, NotImported, may_import
from ..world.vehicle import VehicleParams, acceleration_to_command

PREFIX = "fmu:"
#: d4sumo's inputs, set at every step
INPUTS = ("gap_m", "speed_mps", "lead_speed_mps")
#: set once, before initialisation, where the FMU has them
CONSTANTS = ("setpoint_m", "target_speed_mps", "max_accel_mps2", "max_decel_mps2")
#: what d4sumo reads back: the pedal, or an acceleration; and a mode to record
OUTPUTS = ("command", "acceleration_mps2")
MODE = "mode"
SIGNALS = (*INPUTS, *CONSTANTS, *OUTPUTS, MODE)
SHA_KEY = "fmu_sha256"

log = logging.getLogger(__name__)


def is_fmu(name: object) -> bool:
    return isinstance(name, str) and name.startswith(PREFIX)


def _cache_dir() -> Path:
    return cache_folder("fmus")


@dataclasses.dataclass(frozen=True)
class Variable:
    name: str
    vr: int
    causality: str
    start: float


class Fmu:
    """One FMU file, read and unpacked (its binary for this machine built from its sources where it ships
    only those): its FMI version, model identifier, real variables by name and shared library."""

    def __init__(self, name: str, path: Path, sha256: str, unzipdir: Path, description):
        self.name, self.path, self.sha256, self.unzipdir = name, path, sha256, unzipdir
        self.description = description
        self.version = 2 if description.fmiVersion.startswith("2") else 3
        self.identifier = description.coSimulation.modelIdentifier
        self.token = description.guid
        self.variables = {v.name: Variable(v.name, v.valueReference, v.causality, float(v.start) if v.start is not None else 0.0)
                          for v in description.modelVariables if v.type in ("Real", "Float64")}
        self._library = None

    def library(self):
        """fmpy's wrapper of the shared library, loaded once a process: instances are made from it."""
        if self._library is None:
            from fmpy.fmi2 import FMU2Slave
            from fmpy.fmi3 import FMU3Slave

            cls = FMU2Slave if self.version == 2 else FMU3Slave
            self._library = cls(guid=self.token, unzipDirectory=str(self.unzipdir), modelIdentifier=self.identifier,
                                instanceName=self.identifier)
        return self._library


@functools.lru_cache(maxsize=None)
def _load(name: str, path: str, sha256: str) -> Fmu:
    """The FMU ``name`` names (its file at ``path``, of content ``sha256``), checked and unpacked once."""
    given = name[len(PREFIX):]
    if not zipfile.is_zipfile(path):
        raise ConfigError("controller.class", name, "an FMU: a zip archive holding a modelDescription.xml "
                                                   f"({given} is not a zip archive)")
    from fmpy import read_model_description

    try:
        description = read_model_description(path, validate=False)
    except Exception as exc:
        raise ConfigError("controller.class", name, f"an FMU with a modelDescription.xml fmpy reads ({type(exc).__name__}: {exc})") from None
    if description.coSimulation is None:
        raise ConfigError("controller.class", name, "a co-simulation FMU (this one is for model exchange only: it has no "
                                                   "solver of its own to step)")
    import fmpy

    # the binary FMI's standard names for this machine (fmpy's own reading takes either version's folder)
    folder = fmpy.platform if description.fmiVersion.startswith("2") else fmpy.platform_tuple
    identifier = description.coSimulation.modelIdentifier
    with zipfile.ZipFile(path) as z:
        names = z.namelist()
    binary = f"binaries/{folder}/{identifier}{fmpy.sharedLibraryExtension}" in names
    sources = any(n.startswith("sources/") and n.endswith((".c", ".cpp")) for n in names)
    if not binary and not sources:
        has = sorted({n.split("/")[1] for n in names if n.startswith("binaries/") and n.count("/") >= 2})
        raise ConfigError("controller.class", name, f"an FMU with a binary for this machine (binaries/{folder}/{identifier}"
                                                   f"{fmpy.sharedLibraryExtension}) or its C sources (this one has binaries "
                                                   f"for {', '.join(has) or 'no machine'} and no sources)")
    unzipdir = _cache_dir() / sha256[:24]
    if not unzipdir.is_dir():
        _unpack(path, unzipdir, not binary, name)
    if Path(path) != kept(sha256):
        try:
            _keep(Path(path).read_bytes(), sha256)
        except OSError:  # a cache that cannot be written keeps nothing: the FMU is still where it is
            pass
    return Fmu(name, Path(path), sha256, unzipdir, description)


def kept(sha256: str) -> Path:
    """Where this machine keeps the FMU of content ``sha256``: each one a campaign ran here, and each one a
    Dask client shipped to this worker."""
    return _cache_dir() / "by-content" / f"{sha256}.fmu"


def _keep(data: bytes, sha256: str) -> Path:
    """The FMU's bytes kept by their content (written whole, then moved in place: once, whoever is first)."""
    path = kept(sha256)
    if not path.is_file():
        path.parent.mkdir(parents=True, exist_ok=True)
        partial = path.with_name(f"{path.name}.{os.getpid()}.partial")
        partial.write_bytes(data)
        partial.replace(path)
    return path


def _unpack(path: str, unzipdir: Path, build: bool, name: str) -> None:
    """Unpack (and build) into a folder of its own, then move it in place: another process unpacking the
    same FMU at the same time finds either nothing or the whole of it."""
    unzipdir.parent.mkdir(parents=True, exist_ok=True)
    work = Path(tempfile.mkdtemp(prefix=".unpack-", dir=unzipdir.parent))
    try:
        with zipfile.ZipFile(path) as z:
            z.extractall(work)
        if build:
            from fmpy.build import build_platform_binary

            from ...fmus import _quietly

            with tempfile.TemporaryDirectory() as b:
                try:
                    _quietly(build_platform_binary, work, b)
                except Exception as exc:
                    raise ConfigError("controller.class", name, f"an FMU whose C sources build here (CMake and a C compiler): "
                                                               f"{type(exc).__name__}: {exc}") from None
        try:
            work.rename(unzipdir)
        except OSError:  # another process was first: its copy is the same
            pass
    finally:
        shutil.rmtree(work, ignore_errors=True)


#: on a Dask worker: the FMUs a client shipped (`receive`), by name, as files of this machine
_SHIPPED: dict[str, Path] = {}
#: the kept FMUs loaded in place of a missing file (said once a process)
_SAID: set[tuple[str, str]] = set()


def shipment(config) -> tuple[tuple[str, bytes], ...]:
    """The files of the FMUs an episode configuration's followers run, by name: what a client sends the
    workers of a Dask sweep, which need not see its disk."""
    names = sorted({c.cls for c in config.controllers if is_fmu(c.cls)})
    return tuple((name, fmu_of(name).path.read_bytes()) for name in names)


def receive(fmus: tuple[tuple[str, bytes], ...]) -> None:
    """On a worker: the FMUs a client shipped, kept as files in the cache and found by their names."""
    for name, data in fmus:
        _SHIPPED[name] = _keep(data, hashlib.sha256(data).hexdigest())


def fmu_of(name: str, sha256: str | None = None) -> Fmu:
    """The FMU a controller name ``fmu:PATH`` names, as its file is now (on a Dask worker: as the client
    shipped it). ``sha256``: the content a stored campaign ran, loaded as this machine kept it where
    the path names no file."""
    given = name[len(PREFIX):]
    path = _SHIPPED.get(name) or Path(given).expanduser()
    if not path.is_file():
        if sha256 and kept(sha256).is_file() and not path.is_dir():
            _say_kept(name, sha256, f"no file {given} here")
            path = kept(sha256)
        else:
            what = "no path given" if not given else f"{given} is a folder" if path.is_dir() else f"no file {given} here"
            raise ControllerImportError(name, "an FMU file", f"{what} (a path from the current folder, or absolute)")
    content = file_sha256(path)
    if sha256 and content != sha256 and kept(sha256).is_file():  # the file here changed since: the campaign's own copy
        _say_kept(name, sha256, f"{given} here has changed since the campaign ran")
        path, content = kept(sha256), sha256
    return _load(name, str(path.resolve()), content)


def _say_kept(name: str, sha256: str, why: str) -> None:
    """Why the copy of the FMU the campaign ran is loaded: once a process (a report replays many samples)."""
    if (name, sha256) not in _SAID:
        _SAID.add((name, sha256))
        log.warning("%s: loading the copy of the FMU the campaign ran, kept in %s", why, kept(sha256).parent)


def fmu_controller(name: str, params=()) -> type:
    """The controller class of the FMU ``name`` names (``fmu:PATH``): its Params hold the FMU's content
    hash, the names its signals map to and the FMU's parameters. ``params``: a stored campaign's (its
    ``fmu_sha256`` finds the FMU it ran where the path names none)."""
    if not may_import():
        raise NotImported("controller.class", name, "a controller read by its name only (nothing is loaded here)")
    return _controller_class(fmu_of(name, dict(params).get(SHA_KEY)))


@functools.lru_cache(maxsize=None)
def _controller_class(fmu: Fmu) -> type:
    names = fmu.variables
    own = [v for v in names.values() if v.causality == "parameter" and v.name not in CONSTANTS]
    fields = [(SHA_KEY, str, dataclasses.field(default=fmu.sha256))]
    # its outputs' defaults are settled with the table (None: not given): an acceleration mapped alone is read
    fields += [(s, str, dataclasses.field(default=None if s in OUTPUTS else s if s in names else "")) for s in SIGNALS]
    fields += [(v.name, float, dataclasses.field(default=v.start)) for v in own]

    def post_init(self) -> None:
        command, acceleration = self.command, self.acceleration_mps2
        if command is None:  # an acceleration mapped in the table is what it reads, whatever its other outputs
            command = "" if acceleration else "command" if "command" in names else ""
        if acceleration is None:
            acceleration = "acceleration_mps2" if "acceleration_mps2" in names else ""
        object.__setattr__(self, "command", command)
        object.__setattr__(self, "acceleration_mps2", acceleration)
        if getattr(self, SHA_KEY) != fmu.sha256:
            raise ControllerImportError(fmu.name, f"the FMU the campaign ran ({SHA_KEY} {getattr(self, SHA_KEY)[:16]}...)",
                                        f"{fmu.path} has changed since (its sha256 is now {fmu.sha256[:16]}...): another "
                                        "system, which this campaign did not run")
        for signal, causalities in ((s, ("input",)) for s in INPUTS):
            mapped = getattr(self, signal)
            if not mapped:
                raise ConfigError(f"controller.{signal}", "", f"the name of the FMU's input that takes {signal} "
                                                              f"(its inputs: {_names(names, 'input')})")
            _check_name(names, signal, mapped, causalities)
        for signal in CONSTANTS:
            if getattr(self, signal):
                _check_name(names, signal, getattr(self, signal), ("input", "parameter"))
        for signal in (*OUTPUTS, MODE):
            if getattr(self, signal):
                _check_name(names, signal, getattr(self, signal), ("output",))
        if not any(getattr(self, s) for s in OUTPUTS):
            raise ConfigError("controller.command", "", f"the name of the FMU's output that gives the command, or (as "
                              f"acceleration_mps2) the acceleration (its outputs: {_names(names, 'output')})")
        for v in own:
            value = getattr(self, v.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ConfigError(f"controller.{v.name}", value, "a number (a parameter of the FMU)")
            object.__setattr__(self, v.name, float(value))

    params = dataclasses.make_dataclass("Params", fields, frozen=True, namespace={"__post_init__": post_init})
    return type("FmuController", (FmuController,), {"Params": params, "fmu": fmu, "parameters": tuple(v.name for v in own)})


def _names(names: dict, causality: str) -> str:
    return ", ".join(sorted(n for n, v in names.items() if v.causality == causality)) or "none"


def _check_name(names: dict, signal: str, mapped: object, causalities: tuple[str, ...]) -> None:
    if not isinstance(mapped, str) or mapped not in names or names[mapped].causality not in causalities:
        kind = " or ".join(causalities)
        raise ConfigError(f"controller.{signal}", mapped, f"the name of a real {kind} of the FMU "
                                                          f"({', '.join(_names(names, c) for c in causalities)})")


class FmuController:
    """One follower's instance of the FMU, stepped once a step (see the module)."""

    fmu: Fmu
    parameters: tuple[str, ...] = ()

    def __init__(self, params, *, setpoint_m: float, target_speed_mps: float, vehicle: VehicleParams, step_s: float):
        fmu, lib = self.fmu, self.fmu.library()
        self.vehicle, self.step_s, self.time_s = vehicle, step_s, 0.0
        vr = {n: v.vr for n, v in fmu.variables.items()}
        scenario = {"setpoint_m": setpoint_m, "target_speed_mps": target_speed_mps,
                    "max_accel_mps2": vehicle.max_accel_mps2, "max_decel_mps2": vehicle.max_decel_mps2}
        start = [(vr[getattr(params, s)], value) for s, value in scenario.items() if getattr(params, s)]
        start += [(vr[name], getattr(params, name)) for name in self.parameters]
        self._acceleration = not params.command
        outputs = [params.command or params.acceleration_mps2] + ([params.mode] if params.mode else [])
        self.has_mode = bool(params.mode)
        self._in_vr = (ctypes.c_uint32 * 3)(*(vr[getattr(params, s)] for s in INPUTS))
        self._in = (ctypes.c_double * 3)()
        self._out_vr = (ctypes.c_uint32 * len(outputs))(*(vr[o] for o in outputs))
        self._out = (ctypes.c_double * len(outputs))()
        self._n_out = len(outputs)
        f = lib._functions
        if fmu.version == 2:
            from fmpy.fmi2 import fmi2CoSimulation, fmi2False

            resources = (fmu.unzipdir / "resources").as_uri().encode()
            handle = lib.fmi2Instantiate(fmu.identifier.encode(), fmi2CoSimulation, fmu.token.encode(), resources,
                                         ctypes.byref(_callbacks()), fmi2False, fmi2False)
            if not handle:
                raise ConfigError("controller.class", fmu.name, "an FMU that instantiates (fmi2Instantiate failed)")
            self._finalizer = weakref.finalize(self, _free, lib, handle, 2)
            lib.fmi2SetupExperiment(handle, fmi2False, 0.0, 0.0, fmi2False, 0.0)
            self._set(lib.fmi2SetReal, handle, start)
            lib.fmi2EnterInitializationMode(handle)
            lib.fmi2ExitInitializationMode(handle)
            self._set_real, self._do_step, self._get_real = f["fmi2SetReal"], f["fmi2DoStep"], f["fmi2GetReal"]
        else:
            from fmpy.fmi3 import fmi3False, fmi3InstanceEnvironment, fmi3IntermediateUpdateCallback, fmi3ValueReference

            self._callbacks = (_fmi3_logger(), fmi3IntermediateUpdateCallback())  # kept from the garbage collector
            resources = (str(fmu.unzipdir / "resources") + os.sep).encode()
            handle = lib.fmi3InstantiateCoSimulation(fmu.identifier.encode(), fmu.token.encode(), resources, fmi3False,
                                                     fmi3False, fmi3False, fmi3False, (fmi3ValueReference * 0)(), 0,
                                                     fmi3InstanceEnvironment(), *self._callbacks)
            if not handle:
                raise ConfigError("controller.class", fmu.name, "an FMU that instantiates (fmi3InstantiateCoSimulation failed)")
            self._finalizer = weakref.finalize(self, _free, lib, handle, 3)
            self._set(lambda h, vrs, n, values: lib.fmi3SetFloat64(h, vrs, n, values, n), handle, start)
            lib.fmi3EnterInitializationMode(handle, fmi3False, 0.0, 0.0, fmi3False, 0.0)
            lib.fmi3ExitInitializationMode(handle)
            self._flags = tuple(ctypes.c_bool() for _ in range(3))
            self._last = ctypes.c_double()
            self._set_real, self._do_step, self._get_real = f["fmi3SetFloat64"], f["fmi3DoStep"], f["fmi3GetFloat64"]
        self._handle = handle
        if self.has_mode:  # recorded in the trace (`mode_vI`) where the FMU has a mode output
            self.mode = 0.0

    @staticmethod
    def _set(set_real, handle, values: list[tuple[int, float]]) -> None:
        if values:
            vrs = (ctypes.c_uint32 * len(values))(*(v for v, _ in values))
            set_real(handle, vrs, len(values), (ctypes.c_double * len(values))(*(x for _, x in values)))

    def observe(self, o) -> float:
        """The FMU's step on the three numbers its inputs take: what the radar measured (gap, speed ahead), its own speed."""
        h, t, values = self._handle, self.time_s, self._in
        values[0], values[1], values[2] = o.gap_m, o.speed_mps, o.lead_speed_mps
        if self.fmu.version == 2:
            status = self._set_real(h, self._in_vr, 3, values)
            status = status if status > 1 else self._do_step(h, t, self.step_s, 1)
            status = status if status > 1 else self._get_real(h, self._out_vr, self._n_out, self._out)
        else:
            status = self._set_real(h, self._in_vr, 3, values, 3)
            if status <= 1:
                flags = self._flags
                status = self._do_step(h, t, self.step_s, True, ctypes.byref(flags[0]), ctypes.byref(flags[1]),
                                       ctypes.byref(flags[2]), ctypes.byref(self._last))
                if status <= 1 and flags[1].value:
                    raise RuntimeError(f"the FMU asked to terminate the simulation at {t:g} s")
            status = status if status > 1 else self._get_real(h, self._out_vr, self._n_out, self._out, self._n_out)
        if status > 1:
            raise RuntimeError(f"an FMI call failed at {t:g} s (status {status}: "
                               f"{['ok', 'warning', 'discard', 'error', 'fatal', 'pending'][min(status, 5)]})")
        self.time_s = t + self.step_s
        out = self._out
        if self.has_mode:
            self.mode = out[1]
        u = out[0]
        return acceleration_to_command(u, self.vehicle) if self._acceleration else u


def _free(lib, handle, version: int) -> None:
    """An instance's end (its library stays loaded for the next)."""
    try:
        (lib.fmi2FreeInstance if version == 2 else lib.fmi3FreeInstance)(handle)
    except Exception:  # freeing never fails an episode
        pass


@functools.lru_cache(maxsize=None)
def _callbacks():
    from fmpy.fmi2 import defaultCallbacks

    return defaultCallbacks


@functools.lru_cache(maxsize=None)
def _fmi3_logger():
    from fmpy.fmi3 import fmi3LogMessageCallback, printLogMessage

    return fmi3LogMessageCallback(printLogMessage)
