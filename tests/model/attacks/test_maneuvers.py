"""Maneuvers: where the cars start, which lanes a car covers, who follows whom. Pure code, no SUMO."""

from __future__ import annotations

import numpy as np
import pytest

from d4sumo.errors import ConfigError
from d4sumo.model.attacks.pedals import make_attack
from d4sumo.model.config import EpisodeConfig
from d4sumo.model.world.lanes import CAR_WIDTH_M, FREE_ROAD_GAP_M, occupied_lanes
from d4sumo.model.attacks.maneuvers import CutIn, CutOut, Maneuver, attack_plan, inert_parameters, maneuver_of
from d4sumo.model.stepping.platoon import Platoon, collisions_at
from d4sumo.model.stepping.trace import Episode
from d4sumo.search.campaign import Campaign
from d4sumo.search.spec import Specification, trace_signals

W = 3.2  # lane width [m]


def test_a_car_covers_the_lanes_its_body_overlaps_and_not_a_lane_it_only_touches():
    assert occupied_lanes(1.5 * W, W) == (1,)
    assert occupied_lanes(0.5 * W, W) == (0,)
    assert occupied_lanes(W, W) == (0, 1)  # on the line: in both
    touching = W + CAR_WIDTH_M / 2  # its right side exactly on the line between lanes 0 and 1
    assert occupied_lanes(touching, W) == (1,)
    assert occupied_lanes(touching - 1e-3, W) == (0, 1)


def test_a_cut_in_lines_up_a_benign_lead_and_the_platoon_with_the_attacker_beside_the_chosen_follower():
    config = EpisodeConfig(maneuver="cutin", cutin_follower=2, cutin_offset_m=1.5, start="steady")
    cars = CutIn(config).cars()
    assert [c.id for c in cars] == ["v0", "v1", "v2", "v3", "lead"] == list(config.vehicle_ids)
    by_id = {c.id: c for c in cars}
    assert [by_id[i].lane for i in ("lead", "v1", "v2", "v3")] == [0, 0, 0, 0] and by_id["v0"].lane == 1
    assert by_id["lead"].position_m - 4.5 - by_id["v1"].position_m == pytest.approx(7.0)  # the setpoint
    assert by_id["v0"].position_m - 4.5 - by_id["v2"].position_m == pytest.approx(1.5)  # rear bumper ahead of v2
    assert all(c.speed_mps == 25.0 for c in cars)


def test_a_cut_out_puts_the_obstacle_ahead_of_the_attacker_at_its_distance_and_speed():
    config = EpisodeConfig(maneuver="cutout", obstacle_distance_m=80.0, obstacle_speed_mps=5.0)
    cars = CutOut(config).cars()
    assert [c.id for c in cars] == ["v0", "v1", "v2", "v3", "obstacle"]
    assert cars[-1].position_m - 4.5 - cars[0].position_m == pytest.approx(80.0)
    assert cars[-1].speed_mps == 5.0 and cars[0].speed_mps == 0.0  # the platoon starts at rest


def test_who_follows_whom_changes_with_the_lanes_the_attacker_covers():
    config = EpisodeConfig(maneuver="cutin", followers=2)  # cars: v0, v1, v2, lead
    m = CutIn(config)
    positions = [80.0, 100.0, 70.0, 120.0]
    beside = m.pairs(positions, [(1,), (0,), (0,), (0,)])
    assert [(a, b) for a, b, _ in beside] == [(3, 1), (1, 2)]  # lead-v1, v1-v2: the attacker in lane 1 alone
    for lanes in ([(0, 1), (0,), (0,), (0,)], [(0,), (0,), (0,), (0,)]):  # crossing, then in
        pairs = m.pairs(positions, lanes)
        assert [(a, b) for a, b, _ in pairs] == [(3, 1), (1, 0), (0, 2)]
        assert dict(((a, b), g) for a, b, g in pairs)[(1, 0)] == 100.0 - 4.5 - 80.0
    assert Maneuver(EpisodeConfig(followers=2)).pairs([100.0, 90.0, 80.0]) == [(0, 1, 5.5), (1, 2, 5.5)]


def test_a_follower_answers_the_car_that_cut_in_front_of_it():
    config = EpisodeConfig(maneuver="cutin", followers=2, start="steady")
    platoon = Platoon(config, np.full(config.steps, np.nan), attacker_max_speed_mps=40.0)
    positions = [92.0, 100.0, 84.0, 111.5]  # v0 cut in 3.5 m ahead of v2; lead 7 m ahead of v1
    speeds = [25.0] * 4
    m = platoon.maneuver
    alone = platoon.advance(0, positions, speeds, m.pairs(positions, [(1,), (0,), (0,), (0,)]))
    platoon = Platoon(config, np.full(config.steps, np.nan), attacker_max_speed_mps=40.0)
    cut = platoon.advance(0, positions, speeds, m.pairs(positions, [(0,), (0,), (0,), (0,)]))
    assert platoon.commanded == (0, 1, 2, 3)
    assert alone[2] >= 25.0 - 1e-9  # v2 sees v1 far ahead: it cruises
    assert cut[2] < 25.0  # v2 brakes for the attacker 3.5 m ahead


def test_a_follower_with_nobody_ahead_in_its_lane_sees_a_free_road():
    config = EpisodeConfig(maneuver="cutout", followers=1, start="steady", obstacle_distance_m=3000.0)
    platoon = Platoon(config, np.full(config.steps, np.nan), attacker_max_speed_mps=40.0)
    positions, speeds = [200.0, 150.0, 3204.5], [25.0, 25.0, 0.0]
    out = platoon.advance(0, positions, speeds, [(2, 1, 3000.0)])  # the attacker has left; the obstacle far
    assert out[1] >= 25.0 - 1e-9 and out[2] == 0.0  # v1 cruises; the obstacle holds its speed


def test_collisions_and_outcomes_come_from_the_pairs():
    ids = ("v0", "v1", "v2", "lead")
    positions, speeds = [92.0, 100.0, 91.0, 111.5], [20.0, 25.0, 26.0, 25.0]
    pairs = CutIn(EpisodeConfig(maneuver="cutin", followers=2)).pairs(positions, [(0,), (0,), (0,), (0,)])
    hits = collisions_at(3.0, pairs, positions, speeds, ids)
    assert [c.pair for c in hits] == ["v0-v2"]  # the attacker cut in 1 m ahead of v2's front bumper: overlap
    assert hits[0].involves_attacker
    assert Episode(trace=None, collisions=hits).outcome == "attacker_crash"
    victims = collisions_at(3.0, [(1, 2, -0.1)], positions, speeds, ids)
    assert Episode(trace=None, collisions=victims).outcome == "success"


def test_the_lane_change_time_joins_the_attack_box_and_becomes_a_step():
    config = EpisodeConfig(maneuver="cutin", start="warmup", warmup_s=5.0)
    family = Campaign(config=config, attack="knots").family()
    assert family.name == "knots" and family.names[-1] == "t_lc_s" and family.dimension == 10
    assert family.upper[-1] == config.duration_s and family.signals == (9, 1)  # the knots, then a scalar
    x = np.zeros(10)
    x[-1] = 3.02  # the step nearest to 3.02 s after the attack's start (5 s)
    plan = attack_plan(family, x, config)
    assert plan.lane_change_step == 100 + 60
    assert np.isnan(plan.u[:100]).all() and (plan.u[100:] == 0.0).all()
    assert attack_plan(make_attack("knots"), np.zeros(9), EpisodeConfig()).lane_change_step is None
    assert Campaign(attack="knots").family().dimension == 9  # the paper's attack keeps its box


def test_maneuver_settings_are_checked_and_only_the_ones_in_use_are_part_of_the_campaign():
    for kwargs, field in (({"maneuver": "weave"}, "scenario.maneuver"),
                          ({"maneuver": "swerve", "swerve_knots": 0}, "scenario.swerve_knots"),
                          ({"maneuver": "swerve", "swerve_lanes": 1}, "scenario.swerve_lanes"),
                          ({"maneuver": "swerve", "duration_s": 1.0, "swerve_knots": 30}, "scenario.swerve_knots"),
                          ({"maneuver": "cutin", "cutin_follower": 4}, "scenario.cutin_follower"),
                          # regression: SUMO reads a negative start position from the road's end
                          ({"maneuver": "cutin", "cutin_follower": 3, "cutin_offset_m": -45.0}, "scenario.cutin_offset_m"),
                          ({"maneuver": "cutin", "lane_change_s": 1.01}, "scenario.lane_change_s"),
                          ({"maneuver": "cutout", "obstacle_speed_mps": 30.0}, "scenario.obstacle_speed_mps"),
                          ({"maneuver": "cutout", "obstacle_distance_m": 0.0}, "scenario.obstacle_distance_m"),
                          # from the 15 s warm-up the cruising attacker would reach a stopped car 150 m ahead
                          ({"maneuver": "cutout", "start": "warmup"}, "scenario.obstacle_distance_m")):
        with pytest.raises(ConfigError) as e:
            EpisodeConfig(**kwargs)
        assert e.value.field == field
    assert EpisodeConfig(maneuver="cutout", start="warmup", obstacle_distance_m=400.0).obstacle_distance_m == 400.0
    keys = set(EpisodeConfig().to_dict()["scenario"])
    assert keys == {"network", "followers", "setpoint_m", "speed_mps", "start", "step_s", "duration_s"}
    assert EpisodeConfig(cutin_offset_m=3.0).to_dict() == EpisodeConfig().to_dict()  # no effect: not stored
    assert EpisodeConfig(followers=1, cutin_follower=2).followers == 1  # no cut-in: its follower is not checked
    cutin = EpisodeConfig(maneuver="cutin").to_dict()["scenario"]
    assert {"maneuver", "cutin_follower", "cutin_offset_m", "lane_change_s"} <= set(cutin)
    assert "obstacle_speed_mps" not in cutin and "swerve_knots" not in cutin
    swerve = EpisodeConfig(maneuver="swerve", swerve_lanes=3).to_dict()["scenario"]
    assert {"maneuver", "lane_change_s", "swerve_knots", "swerve_lanes"} <= set(swerve) and "cutin_follower" not in swerve
    assert EpisodeConfig.from_dict(EpisodeConfig(maneuver="swerve", swerve_lanes=3).to_dict()).swerve_lanes == 3
    assert EpisodeConfig.from_dict(EpisodeConfig(maneuver="cutout", obstacle_speed_mps=3.0).to_dict()).obstacle_speed_mps == 3.0


def test_the_default_specification_of_a_lane_change_is_the_papers_over_whoever_follows_whom():
    spec = Specification(followers=3, step_s=0.05, maneuver="cutin")
    assert spec.formula == "(eventually(victim_gap <= 0.0)) and (always(attacker_gap > 0.0))"
    names = trace_signals(3, "cutin")
    assert {"gap_lead", "gap_v2", "y_v0", "victim_gap", "attacker_gap"} <= set(names) and "gap_1" not in names
    n = 5
    signals = {name: np.full(n, 5.0) for name in names}
    signals["victim_gap"] = np.array([5.0, 3.0, 1.0, -0.2, -0.2])
    signals["attacker_gap"] = np.array([FREE_ROAD_GAP_M, FREE_ROAD_GAP_M, 2.0, 0.5, 0.5])
    from d4sumo.model.stepping.trace import Trace

    assert spec.robustness(Trace(np.arange(n) * 0.05, signals, 3)) == pytest.approx(0.2)
    with pytest.raises(ConfigError, match=r"X = v0, v1, v2, v3, lead.*unknown: gap_1"):
        Specification(followers=3, step_s=0.05, maneuver="cutin", formula="eventually(gap_1 <= 0)")


def test_every_maneuver_has_its_class():
    for name, cls in (("inlane", Maneuver), ("cutin", CutIn), ("cutout", CutOut)):
        assert type(maneuver_of(EpisodeConfig(maneuver=name))) is cls


def test_a_lane_change_time_on_a_half_step_always_rounds_up():
    """Regression: floor(t / dt + 0.5) sent 1.075 s to step 21 (1.075 / 0.05 is 21.499999999999996) and
    1.025 s to step 21 too: which way a half step fell hinged on float rounding."""
    from d4sumo.model.attacks.maneuvers import lane_change_steps

    assert [lane_change_steps((k + 0.5) * 0.05, 0.05) for k in range(1200)] == list(range(1, 1201))
    assert lane_change_steps(1.074, 0.05) == 21 and lane_change_steps(1.076, 0.05) == 22


def test_a_platoon_of_different_lengths_starts_a_setpoint_behind_each_rear_bumper():
    config = EpisodeConfig(setpoint_m=5.0, vehicles={"v1": {"length_m": 12.0}, "v3": {"length_m": 8.0}})
    x = [car.position_m for car in maneuver_of(config).cars()]
    assert x[3] == 8.0 + 10.0  # the rearmost car's rear bumper 10 m from the road's start
    assert [x[i] - config.vehicle_of(i).length_m - x[i + 1] for i in range(3)] == pytest.approx([5.0, 5.0, 5.0])
    assert x[1] - x[2] == pytest.approx(12.0 + 5.0)  # the truck's length lies between v1's and v2's front bumpers
    assert [gap for _, _, gap in maneuver_of(config).pairs(x)] == pytest.approx([5.0, 5.0, 5.0])


def test_a_cut_ins_benign_lead_and_a_cut_outs_obstacle_have_their_own_vehicles():
    cutin = EpisodeConfig(maneuver="cutin", setpoint_m=5.0, vehicles={"lead": {"length_m": 10.0}, "v0": {"length_m": 6.0}})
    cars = {car.id: car for car in maneuver_of(cutin).cars()}
    assert cars["lead"].position_m - 10.0 - cars["v1"].position_m == pytest.approx(5.0)
    assert cars["v0"].position_m - 6.0 == pytest.approx(cars["v1"].position_m)  # its rear at v1's front, offset 0
    cutout = EpisodeConfig(maneuver="cutout", obstacle_distance_m=60.0, vehicles={"obstacle": {"length_m": 16.0}})
    cars = {car.id: car for car in maneuver_of(cutout).cars()}
    assert cars["obstacle"].position_m - 16.0 - cars["v0"].position_m == pytest.approx(60.0)


def test_a_swerving_attackers_lanes_are_parameters_read_as_their_whole_part_at_knots_spread_over_the_attack():
    """Issue 37: the attacker's lane over time is searched with its pedals. Each lane knot holds from its
    time on; a change is planned only where the lane differs, at the step nearest its time after the
    warm-up; the box's last value reads as the leftmost lane."""
    config = EpisodeConfig(maneuver="swerve", start="warmup", warmup_s=5.0, duration_s=40.0, swerve_knots=4, swerve_lanes=3)
    family = maneuver_of(config).family(make_attack("knots"))
    assert family.names[-4:] == ("lane_1", "lane_2", "lane_3", "lane_4") and family.signals == (9, 4)
    assert list(family.upper[-4:]) == [3.0] * 4 and list(family.lower[-4:]) == [0.0] * 4
    assert family.knot_times_s == [0.0, 10.0, 20.0, 30.0]
    x = np.zeros(13)
    x[9:] = [0.99, 2.5, 3.0, 1.0]  # lane 0 (no change), 2, 2 (the box's end: the leftmost), 1
    plan = attack_plan(family, x, config)
    assert family.lane_schedule(x) == [(10.0, 2), (30.0, 1)]
    assert plan.lane_changes == ((100 + 200, 2), (100 + 600, 1)) and plan.lane_change_step is None
    assert attack_plan(family, np.zeros(13), config).lane_changes == ()  # it never leaves the platoon's lane
    assert maneuver_of(config).cars()[0].lane == 0 and maneuver_of(config).lanes_for(config) == 3
    # the lanes are parameters like the pedals': a knot that changes nothing is said to be inert
    late = EpisodeConfig(maneuver="swerve", duration_s=40.0, swerve_knots=4)
    assert inert_parameters(maneuver_of(late).family(make_attack("constant")), late) == []
