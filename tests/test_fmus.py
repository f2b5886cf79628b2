"""The FMUs d4sumo ships: the switching controller's sources, built for this machine (no SUMO)."""

from __future__ import annotations

import re
import zipfile

import pytest

from d4sumo.errors import ConfigError
from d4sumo.fmus import SOURCES, VARIABLES, build_switching_fmu
from d4sumo.model.controllers.control import SwitchingParams
from d4sumo.model.world.vehicle import VehicleParams


def test_the_variables_are_the_value_references_of_the_c_law_and_their_starts_are_d4sumo_defaults():
    enum = re.search(r"enum \{(.*?)N_VARIABLES", (SOURCES / "switching.h").read_text(), re.S).group(1)
    names = [n.lower() for n in re.findall(r"VR_(\w+)", enum)]
    assert names == [v[0] for v in VARIABLES]
    defaults = {**SwitchingParams().__dict__, "max_accel_mps2": VehicleParams().max_accel_mps2,
                "max_decel_mps2": VehicleParams().max_decel_mps2, "setpoint_m": 7.0, "target_speed_mps": 25.0}
    for name, causality, start, _, _ in VARIABLES:
        if causality == "parameter":
            assert start == defaults[name], name
    block = re.search(r"defaults\[N_VARIABLES\] = \{(.*?)\};", (SOURCES / "switching.h").read_text(), re.S).group(1)
    c_defaults = dict(re.findall(r"\[VR_(\w+)\] = ([-\w.]+)", block))
    constants = {"MODE_CC": "0.0"}
    assert {k.lower(): float(constants.get(v, v)) for k, v in c_defaults.items()} == {v[0]: v[2] for v in VARIABLES}


def test_each_fmi_version_builds_a_binary_for_this_machine_and_the_same_sources_build_the_same_fmu(switching_fmus, tmp_path):
    import fmpy
    from fmpy import read_model_description

    for version, path in switching_fmus.items():
        folder = fmpy.platform if version == 2 else fmpy.platform_tuple
        with zipfile.ZipFile(path) as z:
            assert f"binaries/{folder}/d4sumo_switching{fmpy.sharedLibraryExtension}" in z.namelist()
        description = read_model_description(str(path))  # validated against FMI's schema by fmpy
        assert description.fmiVersion.startswith(str(version)) and description.coSimulation is not None
    again = build_switching_fmu(tmp_path / "again.fmu", 2)
    assert again.read_bytes() == switching_fmus[2].read_bytes()
    assert not list(tmp_path.glob("*.partial"))


@pytest.mark.parametrize("fmi, out, field", [(4, "a.fmu", "--fmi"), (2, "a.zip", "--out"), (2, "missing/a.fmu", "--out")])
def test_what_cannot_be_built_gets_one_line_and_writes_nothing(tmp_path, fmi, out, field):
    with pytest.raises(ConfigError) as info:
        build_switching_fmu(tmp_path / out, fmi)
    assert info.value.field == field and not list(tmp_path.iterdir())


def test_the_fmu_holds_its_sources_for_other_machines(switching_fmus):
    with zipfile.ZipFile(switching_fmus[3]) as z:
        names = z.namelist()
    assert {"sources/fmi3.c", "sources/switching.h", "sources/buildDescription.xml", "modelDescription.xml"} <= set(names)
