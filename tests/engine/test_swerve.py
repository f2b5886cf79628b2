"""The swerving attacker (issue 37), for real in SUMO: its lanes over time are the plan's, it can cut in
between followers that the in-lane attack cannot crash, and batches equal episodes alone."""

from __future__ import annotations

import pytest
from conftest import assert_same_episode, random_plans

from d4sumo.engine.simulation import simulate, simulate_batch
from d4sumo.model.attacks.pedals import make_attack
from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.model.attacks.maneuvers import attack_plan, maneuver_of
from d4sumo.model.world.lanes import occupied_lanes

pytestmark = pytest.mark.sumo

#: against the time-gap controller, which the paper's in-lane attack does not crash: from steady state the
#: attacker leaves the lane at once, comes back at 6.65 s, leaves and comes back twice more
TIMEGAP = EpisodeConfig(maneuver="swerve", start="steady", controller=ControllerConfig("timegap"), duration_s=40.0)
CUT_IN_PARAMS = [0.733, -0.491, -0.25, -0.045, -0.905, -0.962, 0.138, 0.0, 0.259,  # the knots
                 1.757, 0.277, 1.792, 0.419, 1.845, 0.317]  # lane_1 .. lane_6: 1, 0, 1, 0, 1, 0


def test_a_swerving_attacker_cuts_in_between_followers_that_the_in_lane_attack_cannot_crash(tmp_path):
    family = maneuver_of(TIMEGAP).family(make_attack("knots"))
    plan = attack_plan(family, CUT_IN_PARAMS, TIMEGAP)
    assert plan.lane_changes == ((0, 1), (133, 0), (267, 1), (400, 0), (533, 1), (667, 0))
    episode = simulate(TIMEGAP, plan)
    assert episode.outcome == "success"
    first = episode.first_collision
    assert (first.leader, first.follower) == ("v2", "v3") and 13.0 < first.time_s < 13.1
    # the attacker's lane at every sample is the plan's, the change taking scenario.lane_change_s (2 s)
    y = episode.trace["y_v0"]
    lanes = [occupied_lanes(v, 3.2) for v in y]
    t = episode.trace.times_s
    assert lanes[0] == (0,) and all(lane == (1,) for lane, ts in zip(lanes, t) if 2.1 < ts < 6.6)
    assert all(lane == (0,) for lane, ts in zip(lanes, t) if 8.75 < ts < 13.3)  # back in, before the crash
    # the paper's in-lane attack, with the same pedals, crashes the attacker itself: v1 hits it
    inlane = EpisodeConfig(start="steady", controller=ControllerConfig("timegap"), duration_s=40.0)
    assert simulate(inlane, attack_plan(make_attack("knots"), CUT_IN_PARAMS[:9], inlane)).outcome == "attacker_crash"


@pytest.mark.parametrize("episodes", [3, 9])  # played alone, and by the batch's arrays
def test_swerving_episodes_in_a_batch_equal_them_alone(road, episodes):
    config = EpisodeConfig(maneuver="swerve", start="steady", duration_s=30.0, swerve_lanes=3, followers=4)
    plans = random_plans(config, episodes, seed=11)
    assert sum(len(p.lane_changes) for p in plans) >= episodes
    for batched, plan in zip(simulate_batch(config, plans), plans):
        assert_same_episode(batched, simulate(config, plan, road=road))


def test_simulate_says_the_lane_changes_the_attacker_made_before_the_episode_ended(capsys):
    import json

    from d4sumo.cli import main

    argv = ["simulate", "--maneuver", "swerve", "--start", "steady", "--duration", "40", "--controller", "timegap",
            "--knots=" + ",".join(map(str, CUT_IN_PARAMS))]
    assert main([*argv, "--json"]) == 0
    summary = json.loads(capsys.readouterr().out)
    # the third change (to lane 1 at 13.35 s) was planned after the crash at 13.05 s: not played
    assert summary["lane_changes"] == [{"time_s": 0.0, "lane": 1}, {"time_s": pytest.approx(6.65), "lane": 0}]
    assert main(argv) == 0
    assert "attacker's lane changes: to lane 1 at 0.00 s, to lane 0 at 6.65 s\n" in capsys.readouterr().out


@pytest.mark.parametrize("lane_change_s, knots, most", [(2.0, 19, True), (1.0, 38, True), (0.0, 40, False)])
def test_every_planned_lane_change_begins_at_its_step_and_knots_closer_than_a_change_are_refused(lane_change_s, knots, most):
    """Regression: with lane knots as far apart as a change takes (2 s), SUMO played the first change alone,
    not the plan searched. Knots a change and a step apart play as planned; closer ones are refused."""
    from d4sumo.errors import ConfigError

    config = EpisodeConfig(maneuver="swerve", start="steady", duration_s=40.0, swerve_knots=knots, lane_change_s=lane_change_s)
    family = maneuver_of(config).family(make_attack("constant"))
    x = [0.0] + [1.5 if j % 2 == 0 else 0.5 for j in range(knots)]  # lane 1, 0, 1, 0, ..
    plan = attack_plan(family, x, config)
    y = simulate(config, plan).trace["y_v0"]
    began = [k for k in range(1, len(y)) if y[k] != y[k - 1] and (k == 1 or y[k - 1] == y[k - 2])]
    assert began == [k + 1 for k, _ in plan.lane_changes] and len(began) == knots  # it moves in the step after
    if most:  # one knot more is refused, naming the most that fit
        with pytest.raises(ConfigError, match=rf"scenario.swerve_knots: got {knots + 1}; allowed: at most {knots} over the 40 s"):
            EpisodeConfig(maneuver="swerve", duration_s=40.0, swerve_knots=knots + 1, lane_change_s=lane_change_s)


def test_a_jump_of_two_lanes_is_two_changes_and_its_knots_are_spaced_for_both():
    """Regression: knots one change apart were accepted with three lanes, and a plan 0, 2, 0, 2 played as
    1, 2, 1, 2: SUMO moves one lane a change. Knots must now be two changes apart, and such a plan plays."""
    from d4sumo.errors import ConfigError

    with pytest.raises(ConfigError, match=r"scenario.swerve_knots: got 9; allowed: at most 4 over the 20 s attack: "
                                          r"lane knots at least 2 lane changes"):
        EpisodeConfig(maneuver="swerve", swerve_lanes=3, swerve_knots=9, duration_s=20.0)
    config = EpisodeConfig(maneuver="swerve", start="steady", swerve_lanes=3, swerve_knots=4, duration_s=20.0)
    family = maneuver_of(config).family(make_attack("constant"))
    plan = attack_plan(family, [0.0, 2.5, 0.5, 2.5, 0.5], config)
    assert plan.lane_changes == ((0, 2), (100, 0), (200, 2), (300, 0))
    y = simulate(config, plan).trace["y_v0"]
    lanes = [occupied_lanes(v, 3.2) for v in y]
    assert [lanes[k] for k in (99, 199, 299, 399)] == [(2,), (0,), (2,), (0,)]  # each jump done before the next knot
