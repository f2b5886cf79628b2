"""The [traffic] table and the demand SUMO reads from it: pure code, no SUMO."""

from __future__ import annotations

import dataclasses

import xml.etree.ElementTree as ET

import pytest

from d4sumo.errors import ConfigError
from d4sumo.model.config import EpisodeConfig
from d4sumo.model.stepping.platoon import followers_of
from d4sumo.model.stepping.recording import assemble_trace
from d4sumo.model.world.traffic import TrafficParams, demand_xml
from d4sumo.search.spec import Specification

import numpy as np


def test_the_demand_is_a_poisson_flow_per_lane_of_the_given_types_with_sumo_own_insertion_checks():
    params = TrafficParams(vehicles_per_hour=1800, types={"car": {"share": 3, "speedDev": 0.1},
                                                         "truck": {"share": 1, "vClass": "truck", "carFollowModel": "IDM"}})
    root = ET.fromstring(demand_xml(params, ["a", "b"], [0, 2], 500.0))
    types = {t.get("id"): t.attrib for t in root.iter("vType")}
    assert types["traffic_truck"] == {"id": "traffic_truck", "carFollowModel": "IDM", "vClass": "truck"}
    assert types["traffic_car"]["speedDev"] == "0.1"
    distribution = root.find("vTypeDistribution")
    assert distribution.get("vTypes") == "traffic_car traffic_truck" and distribution.get("probabilities") == "0.75 0.25"
    assert root.find("route").get("edges") == "a b"
    flows = root.findall("flow")
    assert [f.get("departLane") for f in flows] == ["0", "2"]
    assert all(f.get("period") == "exp(0.5)" and f.get("insertionChecks") == "all" and f.get("end") == "500.0" for f in flows)


def test_the_default_traffic_is_sumo_default_passenger_car():
    root = ET.fromstring(demand_xml(TrafficParams(), ["a"], [0], 100.0))
    assert [t.attrib for t in root.iter("vType")] == [{"id": "traffic_car"}]


@pytest.mark.parametrize("table, field", [
    ({"vehicles_per_hour": 0}, "traffic.vehicles_per_hour"),
    ({"vehicles_per_hour": 4000}, "traffic.vehicles_per_hour"),
    ({"warmup_s": -1}, "traffic.warmup_s"),
    ({"seed": -1}, "traffic.seed"),
    ({"density": 3}, "traffic.density"),
    ({"types": {"car": {"share": 0}}}, "traffic.types.car.share"),
    ({"types": {"car": {"id": "x"}}}, "traffic.types.car.id"),
    ({"types": {"car": {"tau": [1]}}}, "traffic.types.car.tau"),
    ({"types": {"1car": {}}}, "traffic.types.1car"),
    ({"types": "car"}, "traffic.types"),
])
def test_bad_traffic_tables_name_their_field(table, field):
    with pytest.raises(ConfigError) as info:
        TrafficParams.from_table(table)
    assert info.value.field == field


def test_traffic_is_stored_only_where_there_is_some_and_round_trips():
    alone = EpisodeConfig(start="steady")
    assert "traffic" not in alone.to_dict()
    with_traffic = EpisodeConfig(start="steady", traffic={"vehicles_per_hour": 900, "types": {"car": {"tau": 1.2}}})
    stored = with_traffic.to_dict()
    assert stored["traffic"] == {"vehicles_per_hour": 900.0, "warmup_s": 60.0, "clear_m": 50.0, "seed": 0,
                                 "insertion_checks": True, "types": {"car": {"tau": 1.2}}}
    assert EpisodeConfig.from_dict(stored) == with_traffic
    assert with_traffic.world_label == "traffic 900 veh/h/lane of car, seed 0"
    # traffic as 0.16 played it is another experiment: its label, and so the report's rows, say so
    unchecked = dataclasses.replace(with_traffic.traffic, insertion_checks=False)
    assert unchecked.label == "900 veh/h/lane of car, seed 0, entering unchecked"
    assert not with_traffic.batch_arrays  # each episode meets its traffic alone


@pytest.mark.parametrize("scenario, field", [
    ({"start": "rest"}, "scenario.start"),
    ({"start": "steady", "step_s": 0.1, "traffic": {"warmup_s": 10.05}}, "traffic.warmup_s"),
])
def test_traffic_is_refused_where_this_version_cannot_play_it(scenario, field):
    with pytest.raises(ConfigError) as info:
        EpisodeConfig(**{"start": "steady", "traffic": {}, **scenario})
    assert info.value.field == field


def test_a_follower_that_hits_a_traffic_car_is_a_victim_and_the_default_specification_says_so():
    """With traffic the trace's gaps are whoever was ahead; a follower's crash into a traffic car counts as the
    followers' crash (victim_gap), an attacker's into one as the attacker's (attacker_gap): the outcome's rule."""
    config = EpisodeConfig(start="steady", followers=2, traffic={})
    n = len(config.vehicle_ids)  # a traffic car is index n in the recorded pairs
    pairs = [[(n, 0, 50.0), (0, 1, 10.0), (1, 2, 10.0)],
             [(n, 0, 50.0), (0, 1, 10.0), (n, 2, 2.0), (1, n, 3.0)],  # a traffic car cut in ahead of v2
             [(n, 0, 40.0), (0, 1, 9.0), (n, 2, -0.1), (1, n, 2.0)]]  # and v2 hit it
    times = np.arange(3) * config.step_s
    x = np.array([[100.0, 90.0, 80.0]] * 3)
    commands = np.zeros((2, 3))
    trace, min_gaps, _ = assemble_trace(config, followers_of(config), (0, 1, 2), times, x, x * 0 + 25, commands, None, pairs, None)
    assert min_gaps == {"traffic-v0": 40.0, "v0-v1": 9.0, "v1-v2": 10.0, "traffic-v2": -0.1, "v1-traffic": 2.0}
    assert trace["gap_v2"].tolist() == [10.0, 2.0, -0.1] and trace["gap_1"].tolist() == [10.0, 2.0, -0.1]
    assert trace["victim_gap"].tolist() == [10.0, 2.0, -0.1]
    assert trace["attacker_gap"].tolist() == [10.0, 10.0, 9.0]
    spec = Specification(followers=2, step_s=config.step_s, traffic=True)
    assert "victim_gap" in spec.formula
    assert spec.robustness(trace) == pytest.approx(0.1)  # a success: v2 crashed, the attacker untouched


def test_a_user_demand_keeps_its_elements_its_vehicles_named_as_traffic_and_inserted_with_checks(tmp_path):
    demand = tmp_path / "demand.rou.xml"
    demand.write_text('<routes><vType id="slow" maxSpeed="20"/><route id="r" edges="a b"/>'
                      '<flow id="main-1" type="slow" route="r" begin="0" end="100" vehsPerHour="900"/>'
                      '<vehicle id="v1" route="r" depart="3" insertionChecks="none"/></routes>')
    params = TrafficParams(demand=str(demand))
    assert params.vehicles_per_hour is None and params.demand == (str(demand),) and len(params.demand_sha256) == 64
    root = ET.fromstring(demand_xml(params, ["a", "b"], [0], 100.0))
    assert [e.tag for e in root] == ["vType", "route", "flow", "vehicle"]  # no flow of d4sumo's beside it
    flow, vehicle = root.find("flow"), root.find("vehicle")
    assert flow.get("id") == "traffic.main_1" and flow.get("insertionChecks") == "all"
    assert vehicle.get("id") == "traffic.v1" and vehicle.get("insertionChecks") == "none"  # the user's own choice
    assert params.to_dict() == {"warmup_s": 60.0, "clear_m": 50.0, "seed": 0, "demand": [str(demand)],
                                "demand_sha256": params.demand_sha256, "insertion_checks": True,
                                "junction_collisions": True,  # (left out by EpisodeConfig on d4sumo's own roads)
                                "edging_sensed": True}  # (and this one for an attacker that keeps its lane)
    both = TrafficParams(demand=str(demand), vehicles_per_hour=300)
    assert len(ET.fromstring(demand_xml(both, ["a", "b"], [0, 1], 100.0)).findall("flow")) == 3
    demand.write_text(demand.read_text().replace("900", "1800"))  # another demand: other traffic
    with pytest.raises(ConfigError) as info:
        demand_xml(params, ["a", "b"], [0], 100.0)
    assert info.value.field == "traffic.demand" and "changed" in info.value.allowed


@pytest.mark.parametrize("text, words", [("<routes><flow id='a'", "parses"), ("<additional/>", "root <routes>")])
def test_a_demand_file_that_is_no_route_file_gets_one_line(tmp_path, text, words):
    demand = tmp_path / "demand.rou.xml"
    demand.write_text(text)
    with pytest.raises(ConfigError) as info:
        demand_xml(TrafficParams(demand=str(demand)), ["a"], [0], 100.0)
    assert info.value.field == "traffic.demand" and words in info.value.allowed
    with pytest.raises(ConfigError) as info:
        TrafficParams(demand=str(tmp_path / "missing.rou.xml"))
    assert info.value.field == "traffic.demand" and "readable" in info.value.allowed


def test_per_sample_traffic_gives_each_sample_its_own_seed_and_the_same_one_again():
    config = EpisodeConfig(start="steady", traffic={"seed": 3, "per_sample": True})
    seeds = [config.for_sample(i).traffic.seed for i in range(50)]
    assert len(set(seeds)) == 50 and seeds == [config.for_sample(i).traffic.seed for i in range(50)]
    assert seeds[0] != 3 and config.to_dict()["traffic"]["per_sample"] is True
    assert config.traffic.label.endswith("seed 3 per sample")
    same = EpisodeConfig(start="steady", traffic={"seed": 3})
    assert same.for_sample(7) is same and "per_sample" not in same.to_dict()["traffic"]
    with pytest.raises(ConfigError) as info:
        TrafficParams(per_sample="yes")
    assert info.value.field == "traffic.per_sample"


def test_edging_sensed_is_stored_only_where_the_attacker_changes_lanes_and_a_table_without_it_plays_as_0_21():
    """A key of 0.22: a lane-changing attacker's campaign stores it; one in lane, where it changes nothing, stores
    what 0.21 stored; a stored table without it is played as 0.21 sensed the traffic."""
    from d4sumo import ledger
    from d4sumo.model.config import EpisodeConfig

    inlane = EpisodeConfig(start="steady", traffic={"vehicles_per_hour": 600})
    swerve = EpisodeConfig(maneuver="swerve", start="steady", traffic={"vehicles_per_hour": 600})
    assert "edging_sensed" not in inlane.to_dict()["traffic"] and not inlane.traffic.edging_sensed
    assert swerve.to_dict()["traffic"]["edging_sensed"] is True and swerve.traffic.edging_sensed
    stored = swerve.to_dict()["traffic"]
    del stored["edging_sensed"]
    assert ledger.restored("traffic", stored)["edging_sensed"] is False
    assert EpisodeConfig.from_dict(swerve.to_dict()) == swerve
