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


# --- a platoon of different vehicles: [vehicle.vI] ------------------------------------------------

def test_a_cars_own_vehicle_table_lays_over_vehicle_and_round_trips():
    from d4sumo.model.world.vehicle import VehicleParams

    c = EpisodeConfig(vehicle=VehicleParams(max_decel_mps2=7.0),
                      vehicles={"v2": {"length_m": 12.0, "max_decel_mps2": 5.0, "vclass": "truck"}})
    assert [v.length_m for v in c.car_vehicles] == [4.5, 4.5, 12.0, 4.5]
    assert c.vehicle_of(2) == VehicleParams(length_m=12.0, max_decel_mps2=5.0, vclass="truck")
    assert c.vehicle_of(1) is c.vehicle and not c.batch_arrays  # the arrays play one vehicle for all
    stored = c.to_dict()["vehicle"]
    assert stored["v2"] == {"length_m": 12.0, "max_decel_mps2": 5.0, "vclass": "truck"} and stored["max_decel_mps2"] == 7.0
    assert EpisodeConfig.from_dict(c.to_dict()) == c


def test_a_uniform_platoon_keeps_its_stored_identity():
    """Campaigns stored before cars had tables of their own keep their definition, key for key."""
    assert EpisodeConfig().to_dict()["vehicle"] == {"length_m": 4.5, "max_accel_mps2": 3.5, "max_decel_mps2": 8.0,
                                                    "actuator_lag_s": 0.5}
    same = EpisodeConfig(vehicles={"v1": {"length_m": 4.5}})  # a table that changes nothing is dropped
    assert same == EpisodeConfig() and same.batch_arrays


@pytest.mark.parametrize("vehicles, field", [
    ({"v4": {"length_m": 12.0}}, "vehicle.v4"),
    ({"lead": {"length_m": 12.0}}, "vehicle.lead"),  # inlane has no benign lead
    ({"v2": {"length": 12.0}}, "vehicle.v2.length"),
    ({"v2": {"length_m": 50.0}}, "vehicle.v2.length_m"),
    ({"v2": {"vclass": "tram"}}, "vehicle.v2.vclass"),
    ({"v2": {"shape": "ship"}}, "vehicle.v2.shape"),
    ({"v2": 3}, "vehicle.v2"),
])
def test_a_vehicle_table_for_a_car_that_does_not_exist_or_a_bad_value_names_it(vehicles, field):
    with pytest.raises(ConfigError) as info:
        EpisodeConfig(vehicles=vehicles)
    assert info.value.field == field


def test_the_attacker_declares_its_own_brakes_by_default():
    c = EpisodeConfig(vehicles={"v0": {"max_decel_mps2": 6.0}})
    assert c.attacker_declared_decel_mps2 == 6.0


def test_the_collision_gap_is_stored_only_where_set_and_checked():
    assert "collision_gap_m" not in EpisodeConfig().to_dict()["scenario"]
    c = EpisodeConfig(collision_gap_m=0.05)
    assert c.to_dict()["scenario"]["collision_gap_m"] == 0.05 and EpisodeConfig.from_dict(c.to_dict()) == c
    with pytest.raises(ConfigError) as info:
        EpisodeConfig(collision_gap_m=-0.1)
    assert info.value.field == "scenario.collision_gap_m"


def test_a_pair_within_the_collision_gap_has_collided():
    from d4sumo.model.stepping.platoon import collisions_at

    pairs = [(0, 1, 0.04), (1, 2, 0.3)]
    assert collisions_at(1.0, pairs, [20.0, 15.46, 10.0], [5.0, 6.0, 6.0], ("v0", "v1", "v2")) == ()
    (hit,) = collisions_at(1.0, pairs, [20.0, 15.46, 10.0], [5.0, 6.0, 6.0], ("v0", "v1", "v2"), 0.05)
    assert hit.pair == "v0-v1"


def test_a_vehicle_key_given_a_table_is_that_key_refused_not_a_car():
    with pytest.raises(ConfigError) as info:
        EpisodeConfig.from_dict({"vehicle": {"shape": {"a": 1}}})
    assert info.value.field == "vehicle.shape"


def test_an_empty_route_is_refused_not_read_as_no_route():
    """Regression: `--set 'scenario.route=[]'` played the network's one chain of edges, as if no route were given."""
    with pytest.raises(ConfigError, match=r"^scenario.route: got \[\]; allowed: a list of one edge id or more"):
        EpisodeConfig.from_dict({"scenario": {"route": []}})
    assert EpisodeConfig.from_dict({"scenario": {}}).route == ()


def test_what_the_platoon_does_at_red_lights_is_checked_and_stored_only_on_a_road_of_ones_own():
    from pathlib import Path

    with pytest.raises(ConfigError, match=r"^scenario.signals: got 'stop'; allowed: one of obey, attacker_runs_red, ignore$"):
        EpisodeConfig(signals="stop")
    road = str(Path(__file__).resolve().parent.parent.parent / "examples" / "roads" / "three_edges")
    assert EpisodeConfig(network=road).to_dict()["scenario"]["signals"] == "obey"
    assert EpisodeConfig(network=road, signals="attacker_runs_red").to_dict()["scenario"]["signals"] == "attacker_runs_red"
    assert "signals" not in EpisodeConfig(network=road, signals="ignore").to_dict()["scenario"]  # as stored before 0.19
    # d4sumo's own roads have no lights: one configuration whatever is said, stored without the key
    assert EpisodeConfig(signals="ignore") == EpisodeConfig()
    assert "signals" not in EpisodeConfig().to_dict()["scenario"]


def test_where_the_platoon_joins_its_route_moves_every_car_and_is_stored_only_where_set():
    from d4sumo.model.attacks.maneuvers import maneuver_of

    here, there = EpisodeConfig(), EpisodeConfig(join_m=510.0)
    moved = [b.position_m - a.position_m for a, b in zip(maneuver_of(here).cars(), maneuver_of(there).cars())]
    assert moved == [500.0] * 4
    assert "join_m" not in here.to_dict()["scenario"] and there.to_dict()["scenario"]["join_m"] == 510.0
    with pytest.raises(ConfigError, match=r"^scenario.join_m: got -1; allowed: "):
        EpisodeConfig(join_m=-1)
