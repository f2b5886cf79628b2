"""The episode configuration: defaults, validation, TOML round trip."""

from __future__ import annotations

import pytest

from d4sumo.config import EpisodeConfig, load_toml
from d4sumo.errors import ConfigError


def test_defaults_are_the_specs():
    c = EpisodeConfig()
    assert (c.network, c.followers, c.setpoint_m, c.speed_mps, c.start) == ("highway_4lane", 3, 7.0, 25.0, "rest")
    assert (c.step_s, c.duration_s, c.steps) == (0.05, 60.0, 1200)
    assert c.vehicle.length_m == 4.5 and c.vehicle.actuator_lag_s == 0.5
    params = dict(c.controller.params)
    assert params["acc_kp"] == 0.9304 and params["acc_kv"] == 2.1599 and params["cruise_kp"] == 0.4
    assert c.vehicle_ids == ("v0", "v1", "v2", "v3")


def test_round_trip_through_the_resolved_tables():
    c = EpisodeConfig(setpoint_m=5.0, start="steady", followers=4)
    assert EpisodeConfig.from_dict(c.to_dict()) == c


def test_overrides_win_over_the_file(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text('[scenario]\nsetpoint_m = 9\nspeed_mps = 20\n[controller]\nacc_kp = 1.1\n')
    c = EpisodeConfig.from_dict(load_toml(path), {"scenario.setpoint_m": 3.0})
    assert c.setpoint_m == 3.0 and c.speed_mps == 20 and dict(c.controller.params)["acc_kp"] == 1.1


@pytest.mark.parametrize(
    "changes, field",
    [
        (dict(setpoint_m=-1.0), "scenario.setpoint_m"),
        (dict(setpoint_m=0.0), "scenario.setpoint_m"),
        (dict(followers=0), "scenario.followers"),
        (dict(followers=11), "scenario.followers"),
        (dict(followers=2.5), "scenario.followers"),
        (dict(start="moving"), "scenario.start"),
        (dict(speed_mps=float("nan")), "scenario.speed_mps"),
        (dict(step_s=0.0), "scenario.step_s"),
    ],
)
def test_bad_values_name_the_field(changes, field):
    with pytest.raises(ConfigError) as info:
        EpisodeConfig(**changes)
    assert info.value.field == field


def test_unknown_keys_and_tables_are_refused(tmp_path):
    with pytest.raises(ConfigError, match="scenario.setpont_m"):
        EpisodeConfig.from_dict({"scenario": {"setpont_m": 3}})
    path = tmp_path / "c.toml"
    path.write_text("[scenaro]\nx = 1\n")
    with pytest.raises(ConfigError, match="scenaro"):
        load_toml(path)


def test_malformed_toml_says_where(tmp_path):
    path = tmp_path / "c.toml"
    path.write_text("[scenario]\nsetpoint_m = = 3\n")
    with pytest.raises(ConfigError, match="valid TOML"):
        load_toml(path)
