"""The FMUs d4sumo ships: the paper's switching ACC as a source FMU (C, FMI 2.0 and 3.0), built for this
machine with fmpy's build (CMake and the C compiler), `build_switching_fmu`; ``d4sumo build-fmu`` on the
command line. Its law is ``switching.h``, the Python controller's operations in the same order: its
commands equal `control.SwitchingController`'s. Its variables are `VARIABLES` (in the order of
switching.h's value references), named as d4sumo's FMU followers read them (`model.fmu`).
"""

from __future__ import annotations

import shutil
import tempfile
import zipfile
from pathlib import Path
from xml.sax.saxutils import quoteattr

from ..errors import ConfigError, D4sumoError

SOURCES = Path(__file__).resolve().parent
MODEL_IDENTIFIER = "d4sumo_switching"
GUID = "{d4sumo-switching-1}"  # switching.h's D4SUMO_GUID
FMI_VERSIONS = (2, 3)
TIME_VR = 1000  # FMI 3.0's independent variable, which nobody reads or sets

#: (name, causality, start, unit, description), in the order of switching.h's value references
VARIABLES = (
    ("gap_m", "input", 1e9, "m", "the gap to the car ahead, bumper to bumper"),
    ("speed_mps", "input", 0.0, "m/s", "the car's speed"),
    ("lead_speed_mps", "input", 0.0, "m/s", "the speed of the car ahead"),
    ("command", "output", 0.0, "", "the pedal over the step: -1 full brake, 1 full throttle"),
    ("mode", "output", 0.0, "", "0 cruise control, 1 ACC"),
    ("setpoint_m", "parameter", 7.0, "m", "the gap the ACC keeps"),
    ("target_speed_mps", "parameter", 25.0, "m/s", "the cruise speed"),
    ("max_accel_mps2", "parameter", 3.5, "m/s2", "the car's acceleration at full throttle"),
    ("max_decel_mps2", "parameter", 8.0, "m/s2", "the car's deceleration at full brake"),
    ("cruise_kp", "parameter", 0.4, "", "the cruise PID's proportional gain [1/s]"),
    ("cruise_ki", "parameter", 0.01, "", "its integral gain [1/s2]"),
    ("cruise_kd", "parameter", 0.1, "", "its derivative gain"),
    ("cruise_integral_clamp", "parameter", 20.0, "m", "the bound on its integrated speed error"),
    ("cruise_output_limit_mps2", "parameter", 3.0, "m/s2", "the bound on its output"),
    ("acc_kp", "parameter", 0.9304, "", "the ACC's gain on the gap error [1/s2]"),
    ("acc_kv", "parameter", 2.1599, "", "its gain on the speed difference [1/s]"),
    ("eps_x_m", "parameter", 1.0, "m", "the hysteresis on the gap"),
    ("eps_v_mps", "parameter", 1.0, "m/s", "the hysteresis on the speed"),
)


def _model_description(version: int) -> str:
    if version == 2:
        rows = []
        for vr, (name, causality, start, unit, description) in enumerate(VARIABLES):
            variability = {"input": "continuous", "output": "discrete", "parameter": "fixed"}[causality]
            initial = ' initial="exact"' if causality != "input" else ""
            rows.append(f'    <ScalarVariable name="{name}" valueReference="{vr}" causality="{causality}" '
                        f'variability="{variability}"{initial} description={quoteattr(description)}>'
                        f'<Real start="{start!r}"/></ScalarVariable>')
        outputs = "".join(f'<Unknown index="{i + 1}"/>' for i, v in enumerate(VARIABLES) if v[1] == "output")
        return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="2.0" modelName="{MODEL_IDENTIFIER}" guid="{GUID}" generationTool="d4sumo"
    description="The paper's switching ACC (cruise control or ACC, with hysteresis), as d4sumo's switching controller"
    variableNamingConvention="flat" numberOfEventIndicators="0">
  <CoSimulation modelIdentifier="{MODEL_IDENTIFIER}" canHandleVariableCommunicationStepSize="true">
    <SourceFiles><File name="fmi2.c"/></SourceFiles>
  </CoSimulation>
  <DefaultExperiment startTime="0" stepSize="0.05"/>
  <ModelVariables>
{chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure>
    <Outputs>{outputs}</Outputs>
  </ModelStructure>
</fmiModelDescription>
"""
    rows = []
    for vr, (name, causality, start, unit, description) in enumerate(VARIABLES):
        extra = {"input": "", "output": ' variability="discrete" initial="exact"', "parameter": ' variability="fixed"'}[causality]
        rows.append(f'    <Float64 name="{name}" valueReference="{vr}" causality="{causality}"{extra} '
                    f'description={quoteattr(description)} start="{start!r}"/>')
    outputs = "".join(f'<Output valueReference="{vr}"/>' for vr, v in enumerate(VARIABLES) if v[1] == "output")
    return f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiModelDescription fmiVersion="3.0" modelName="{MODEL_IDENTIFIER}" instantiationToken="{GUID}" generationTool="d4sumo"
    description="The paper's switching ACC (cruise control or ACC, with hysteresis), as d4sumo's switching controller">
  <CoSimulation modelIdentifier="{MODEL_IDENTIFIER}" canHandleVariableCommunicationStepSize="true"/>
  <DefaultExperiment startTime="0" stepSize="0.05"/>
  <ModelVariables>
    <Float64 name="time" valueReference="{TIME_VR}" causality="independent" variability="continuous"/>
{chr(10).join(rows)}
  </ModelVariables>
  <ModelStructure>
    {outputs}
  </ModelStructure>
</fmiModelDescription>
"""


_BUILD_DESCRIPTION = f"""<?xml version="1.0" encoding="UTF-8"?>
<fmiBuildDescription fmiVersion="3.0">
  <BuildConfiguration modelIdentifier="{MODEL_IDENTIFIER}">
    <SourceFileSet language="C99"><SourceFile name="fmi3.c"/></SourceFileSet>
  </BuildConfiguration>
</fmiBuildDescription>
"""


def build_switching_fmu(out: str | Path, fmi_version: int = 2) -> Path:
    """Write the switching ACC as an FMU at ``out``: its sources, and its binary for this machine built by
    fmpy (CMake and the C compiler, no floating-point contraction: the Python's arithmetic)."""
    if fmi_version not in FMI_VERSIONS:
        raise ConfigError("--fmi", fmi_version, "2 or 3 (FMI 2.0 or 3.0)")
    out = Path(out)
    if out.suffix != ".fmu":
        raise ConfigError("--out", str(out), "a path ending in .fmu")
    if not out.parent.is_dir():
        raise ConfigError("--out", str(out), "a path in an existing folder")
    from fmpy.build import build_platform_binary

    with tempfile.TemporaryDirectory(prefix="d4sumo-fmu-") as tmp:
        root = Path(tmp) / "fmu"
        (root / "sources").mkdir(parents=True)
        (root / "modelDescription.xml").write_text(_model_description(fmi_version))
        shutil.copy(SOURCES / "switching.h", root / "sources")
        shutil.copy(SOURCES / f"fmi{fmi_version}.c", root / "sources")
        if fmi_version == 3:
            (root / "sources" / "buildDescription.xml").write_text(_BUILD_DESCRIPTION)
        build = Path(tmp) / "build"
        build.mkdir()
        try:
            _quietly(build_platform_binary, root, build, cmake_options={"CMAKE_C_FLAGS:STRING": "-ffp-contract=off"})
        except Exception as exc:  # CMake's, the compiler's, or fmpy's reading of what it builds
            raise D4sumoError(f"building the FMU failed (CMake and a C compiler are needed): {exc}") from None
        partial = out.with_name(out.name + ".partial")
        with zipfile.ZipFile(partial, "w", zipfile.ZIP_DEFLATED) as z:
            for path in sorted(root.rglob("*")):
                if path.is_file():  # no dates: the same sources and compiler make the same FMU, bit for bit
                    entry = zipfile.ZipInfo(path.relative_to(root).as_posix(), date_time=(1980, 1, 1, 0, 0, 0))
                    entry.compress_type, entry.external_attr = zipfile.ZIP_DEFLATED, 0o644 << 16
                    z.writestr(entry, path.read_bytes())
        partial.replace(out)  # never a half-written FMU
    return out


def _quietly(function, *args, **kwargs):
    """CMake's and the compiler's output, only where they fail; the CMake fmpy depends on first on the PATH
    (an environment's scripts need not be on it: ``.venv/bin/d4sumo`` run as it is)."""
    import contextlib
    import io
    import os
    import sys

    try:
        import cmake

        bin_dir = cmake.CMAKE_BIN_DIR
    except (ImportError, AttributeError):  # the system's, if any
        bin_dir = None
    path = os.environ.get("PATH", "")
    if bin_dir and bin_dir not in path.split(os.pathsep):
        os.environ["PATH"] = bin_dir + os.pathsep + path

    sys.stdout.flush()
    saved = os.dup(1), os.dup(2)
    with tempfile.TemporaryFile() as log:
        os.dup2(log.fileno(), 1)
        os.dup2(log.fileno(), 2)
        try:
            with contextlib.redirect_stdout(io.StringIO()):
                return function(*args, **kwargs)
        except Exception:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            log.seek(0)
            sys.stderr.write(log.read().decode(errors="replace")[-4000:])
            raise
        finally:
            os.dup2(saved[0], 1)
            os.dup2(saved[1], 2)
            os.close(saved[0])
            os.close(saved[1])
