"""SUMO's car-following models as controllers: names and attributes from SUMO's installed schema (no
SUMO process runs here)."""

from __future__ import annotations

import pytest

from d4sumo.errors import ConfigError
from d4sumo.model.controllers import carfollowing
from d4sumo.model.config import ControllerConfig, EpisodeConfig

LISTED = ("ACC", "CACC", "CC", "IDM", "EIDM", "Krauss")


def test_the_schema_declares_the_models_users_simulate_acc_with():
    models = carfollowing.models()
    for name in LISTED:
        assert name in models
    assert "speedControlGain" in models["ACC"] and "speedControlGain" not in models["IDM"]
    assert "tau" in models["ACC"]  # common to every model, though the schema lists it for some only
    assert not set(carfollowing.SET_BY_D4SUMO) & set(models["CC"])


def test_a_sumo_controller_resolves_its_table_with_d4sumos_defaults():
    c = ControllerConfig("sumo:ACC", (("tau", 1.2), ("speedControlGain", -0.3)))
    assert c.sumo_model == "ACC"
    assert dict(c.params) == {"tau": 1.2, "speedControlGain": -0.3}
    assert dict(ControllerConfig("sumo:Krauss").params) == {"sigma": 0.0}  # deterministic drivers by default
    assert ControllerConfig("sumo:Krauss", (("sigma", 0.5),)).label == "sumo:Krauss(sigma=0.5)"
    assert c.label == "sumo:ACC(speedControlGain=-0.3, tau=1.2)"
    assert ControllerConfig("sumo:ACC", (("tau", 1),)) == ControllerConfig("sumo:ACC", (("tau", 1.0),))
    assert dict(ControllerConfig("sumo:CC").params)["active_controller"] == "ACC"


@pytest.mark.parametrize("cls, params, field, allowed", [
    ("sumo:FOO", (), "controller.class", "one of sumo:ACC"),
    ("sumo:IDM", (("speedControlGain", 1.0),), "controller.speedControlGain", "an attribute SUMO's IDM model reads"),
    ("sumo:ACC", (("bogus", 1.0),), "controller.bogus", "an attribute SUMO's ACC model reads"),
    ("sumo:ACC", (("accel", 3.0),), "controller.accel", "vehicle.max_accel_mps2"),
    ("sumo:ACC", (("length", 5.0),), "controller.length", "vehicle.length_m"),
    ("sumo:CC", (("lanesCount", 3),), "controller.lanesCount", "the road's lanes"),
    ("sumo:ACC", (("tau", -1.0),), "controller.tau", "a number >= 0"),
    ("sumo:ACC", (("decel", 0.0),), "controller.decel", "a number > 0"),
    ("sumo:Krauss", (("sigma", 1.5),), "controller.sigma", "a number >= 0 and <= 1"),
    ("sumo:ACC", (("tau", "fast"),), "controller.tau", "a number >= 0"),
    ("sumo:W99", (("cc1", "abc"),), "controller.cc1", "a number"),
    ("sumo:ACC", (("speed_mode", 31),), "controller.speed_mode", "an attribute SUMO's ACC model reads"),
    ("sumo:ACC", (("sigma", 0.5),), "controller.sigma", "an attribute SUMO's ACC model reads"),
    ("sumo:CC", (("active_controller", "FAKED_CACC"),), "controller.active_controller", "DRIVER, ACC, CACC, PLOEG, CONSENSUS, FLATBED"),
    ("sumo:ACC", (("active_controller", "ACC"),), "controller.active_controller", "an attribute"),
])
def test_what_sumo_would_ignore_or_refuse_is_a_clear_error(cls, params, field, allowed):
    with pytest.raises(ConfigError) as err:
        ControllerConfig(cls, params)
    assert err.value.field == field
    assert allowed in err.value.allowed


def test_a_mixed_platoon_has_one_controller_per_follower():
    mixed = EpisodeConfig.from_dict({"controller": [{"class": "sumo:ACC", "tau": 0.8}, "switching", "sumo:IDM"]})
    with pytest.raises(ConfigError) as err:  # a Python follower's parameters name their follower too
        EpisodeConfig.from_dict({"controller": ["sumo:ACC", {"class": "switching", "tau": 0.8}, "sumo:IDM"]})
    assert err.value.field == "controller.v2.tau"
    with pytest.raises(ConfigError) as err:
        EpisodeConfig.from_dict({"controller": ["sumo:ACC", "switching", "sumo:idm"]})
    assert err.value.field == "controller.v3.class"
    assert [c.cls for c in mixed.controllers] == ["sumo:ACC", "switching", "sumo:IDM"]
    assert mixed.sumo_driven
    assert mixed.system_label == "sumo:ACC(tau=0.8) / switching / sumo:IDM"
    assert EpisodeConfig.from_dict(mixed.to_dict()) == mixed
    with pytest.raises(ConfigError, match="one per follower \\(3: --controller A,B,C or \\[\\[controller\\]\\] tables\\)"):
        EpisodeConfig.from_dict({"controller": ["sumo:ACC", "switching"]})
    with pytest.raises(ConfigError) as err:
        EpisodeConfig.from_dict({"controller": ["sumo:ACC", {"class": "sumo:IDM", "bogus": 1}, "switching"]})
    assert err.value.field == "controller.v2.bogus"
    # the same controller for every follower is one table: the same campaign as [controller]
    same = EpisodeConfig.from_dict({"controller": ["sumo:IDM"] * 3})
    assert same == EpisodeConfig.from_dict({"controller": {"class": "sumo:IDM"}})
    assert isinstance(same.to_dict()["controller"], dict)


def test_what_the_attacker_declares_is_stored_only_where_a_sumo_model_reads_it():
    paper = EpisodeConfig()
    assert paper.attacker_declared_decel_mps2 == paper.vehicle.max_decel_mps2  # honest by default
    assert "attacker_declared_decel_mps2" not in paper.to_dict()["scenario"]  # old campaigns keep their identity
    sumo = EpisodeConfig(controller=ControllerConfig("sumo:Krauss"), attacker_declared_decel_mps2=3.0)
    assert sumo.to_dict()["scenario"]["attacker_declared_decel_mps2"] == 3.0
    assert EpisodeConfig.from_dict(sumo.to_dict()) == sumo
    with pytest.raises(ConfigError) as err:
        EpisodeConfig(controller=ControllerConfig("sumo:Krauss"), attacker_declared_decel_mps2=0.0)
    assert err.value.field == "scenario.attacker_declared_decel_mps2"


def test_an_action_step_is_a_whole_number_of_steps():
    # SUMO would round 0.07 s to one 0.05 s step, silently
    with pytest.raises(ConfigError) as err:
        EpisodeConfig.from_dict({"controller": ["switching", {"class": "sumo:ACC", "actionStepLength": 0.07}, "switching"]})
    assert err.value.field == "controller.v2.actionStepLength" and "0.05 s" in err.value.allowed
    assert dict(EpisodeConfig(controller=ControllerConfig("sumo:ACC", (("actionStepLength", 0.5),))).controller.params)
    with pytest.raises(ConfigError):
        EpisodeConfig(controller=ControllerConfig("sumo:ACC", (("actionStepLength", 0.5),)), step_s=0.2)


def test_vtype_attributes_are_written_as_sumo_reads_them():
    attrs = carfollowing.vtype_attributes("CC", {"tau": 0.5, "active_controller": "ACC", "xi": 1}, lanes=4)
    assert attrs == {"carFollowModel": "CC", "lanesCount": "4", "tau": "0.5", "xi": "1"}
    assert carfollowing.runtime_parameters("CC", {"active_controller": "DRIVER"}, 25.0) == \
        {"carFollowModel.ccac": "0", "carFollowModel.ccds": "25.0"}
    assert carfollowing.runtime_parameters("ACC", {}, 25.0) == {}
    assert carfollowing.vtype_attributes("EIDM", {"vehdynamics": True})["vehdynamics"] == "true"
