"""The episode configuration: defaults, validation, TOML round trip."""

from __future__ import annotations

import pytest

from d4sumo.errors import ConfigError
from d4sumo.model.config import EpisodeConfig


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


def test_unknown_keys_are_refused():
    with pytest.raises(ConfigError, match="scenario.setpont_m"):
        EpisodeConfig.from_dict({"scenario": {"setpont_m": 3}})


def test_warmup_must_be_a_whole_number_of_steps():
    with pytest.raises(ConfigError, match="scenario.warmup_s"):
        EpisodeConfig(start="warmup", warmup_s=15.02)


def test_a_step_is_checked_only_against_the_times_the_episode_reads():
    """`--step 0.03` once blamed scenario.lane_change_s (2 s, 66.7 steps) on an episode without a lane
    change; the warm-up's length is read only with a warm-up."""
    assert EpisodeConfig(step_s=0.03).steps == 2000
    assert EpisodeConfig(step_s=0.07, warmup_s=15.0).start == "rest"
    with pytest.raises(ConfigError, match=r"scenario.lane_change_s: got 2.0; allowed: a whole number of steps of 0.03 s"):
        EpisodeConfig(step_s=0.03, maneuver="cutin")
    with pytest.raises(ConfigError, match="scenario.warmup_s"):
        EpisodeConfig(step_s=0.07, start="warmup", warmup_s=15.0)
