"""Crashes that are the traffic's doing: a campaign's episodes without the attack (`results.baseline`)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from d4sumo.model.stepping.trace import Collision
from d4sumo.results.baseline import baseline_text, campaign_baseline


def _episode(pair: str | None):
    if pair is None:
        return SimpleNamespace(outcome="no_crash", first_collision=None)
    leader, follower = pair.split("-")
    outcome = "attacker_crash" if "v0" in (leader, follower) else "success"
    return SimpleNamespace(outcome=outcome, first_collision=Collision(leader, follower, 12.5, 300.0, 20.0))


def test_one_traffic_for_all_samples_is_one_episode_without_the_attack_that_speaks_for_every_crash():
    played = []

    def without_attack(index):
        played.append(index)
        return _episode("traffic.3-v2")  # a traffic car's rear-end by v2: a success without any attack

    # the crash without the attack comes at 12.5 s: a success at 20 s is the traffic's doing, one at 8 s the attack's
    samples = [(0, "success", 20.0), (1, "no_crash", None), (2, "success", 8.0), (3, "attacker_crash", 15.0), (4, "success", 12.5)]
    b = campaign_baseline(without_attack, False, samples, step_s=0.05)
    assert played == [0] and (b.played, b.crashed) == (1, 1)
    assert b.kinds == {"follower into traffic": 1}
    assert b.traffics == {"success": 2} and b.crashes == {"success": 3, "attacker_crash": 1}
    assert baseline_text(b) == ("without the attack (the attacker only cruising, in the same traffic): 1 of 1 episode "
                                "crashed (1 follower into traffic) (traffic.3-v2 at 12.50 s); the traffic's doing: 2 of 3 "
                                "successes, 0 of 1 attacker crash")


def test_traffic_of_each_sample_own_plays_the_episode_of_each_crash_without_the_attack():
    outcomes = {0: "traffic.1-v0", 2: None, 3: "v1-v2"}
    played = []

    def without_attack(index):
        played.append(index)
        return _episode(outcomes[index])

    ticks = []
    b = campaign_baseline(without_attack, True, [(0, "attacker_crash", 30.0), (1, "no_crash", None), (2, "success", 30.0),
                                                 (3, "success", 30.0)], lambda: ticks.append(1))
    assert played == [0, 2, 3] and len(ticks) == 3  # the crashes' traffic only, each with a tick of the progress bar
    assert (b.played, b.crashed) == (3, 2)
    assert b.kinds == {"attacker into traffic": 1, "followers": 1}
    assert b.traffics == {"attacker_crash": 1, "success": 1}  # sample 2 crashed only under attack
    assert b.collision is None  # no one episode speaks for all
    quiet = campaign_baseline(lambda i: _episode(None), True, [(0, "no_crash", None)])
    assert quiet.played == 0 and baseline_text(quiet).endswith("no crash in 0 episodes")


@pytest.mark.sumo
@pytest.mark.parametrize("maneuver, message", [("cutin", ""), ("inlane", "offset")])
def test_without_the_attack_the_attacker_neither_changes_lanes_nor_lies_and_cruises_among_the_traffic(maneuver, message):
    from d4sumo.model.config import ControllerConfig, EpisodeConfig
    from d4sumo.search.campaign import Campaign
    from d4sumo.search.runner import Evaluator

    config = EpisodeConfig(network="highway_3lane_120kmh", start="steady", speed_mps=25.0, duration_s=20.0,
                           maneuver=maneuver, controller=ControllerConfig("cacc"),
                           traffic={"vehicles_per_hour": 600, "warmup_s": 40.0, "per_sample": True})
    evaluator = Evaluator(Campaign(config=config, message=message, message_field="speed"))
    episode = evaluator.without_attack(3)
    if maneuver == "cutin":  # it keeps its lane, beside the platoon's
        assert np.all(episode.trace["y_v0"] == episode.trace["y_v0"][0])
        assert "v0-v2" not in episode.min_gaps
    assert not any(name.startswith("sent_") for name in episode.trace.names)  # it tells the truth
    attacked = evaluator.simulate(3, np.ones(len(evaluator.family.names)))
    assert not np.array_equal(attacked.trace["speed_v0"], episode.trace["speed_v0"])
    again = evaluator.without_attack(3)  # the same traffic, the same episode
    assert np.array_equal(again.trace["gap_v0"], episode.trace["gap_v0"])
