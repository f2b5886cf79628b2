"""Stored samples read as records: through the one reader of stored campaigns, with its defaults."""

from __future__ import annotations

import dataclasses

from d4sumo.model.config import EpisodeConfig
from d4sumo.results.records import Record, load_records, system_label


def _record(params, time_s=10.0, **changes):
    names = tuple(f"m{i}" for i in range(9)) + (("t_lc_s",) if len(params) == 10 else ())  # a lane change time: by name
    r = Record("db", 0, 0, "n", 3, 7.0, 25.0, "rest", "knots", "bo", 0, 6.0, tuple(params), 0.1, "success",
               "v1-v2", time_s, 100.0, 10.0, param_names=names[:len(params)])
    return dataclasses.replace(r, **changes)


def test_records_read_stored_campaigns_through_the_one_reader_with_its_defaults(tmp_path):
    """A warm-up campaign stored without warmup_s (an earlier version's) starts its attack at the
    default 15 s, from EpisodeConfig's defaults, not from a copy of them here."""
    from d4sumo.search.campaign import Campaign, open_store

    definition = Campaign(config=EpisodeConfig(start="warmup", warmup_s=15.0, step_s=0.1)).definition()
    del definition["config"]["scenario"]["warmup_s"]
    with open_store(tmp_path / "r.sqlite") as store:
        cid = store.open_campaign(definition, 1)
        store.add_sample(cid, 0, (0.0,) * 9, -1.0, "no_crash", None, {"v0-v1": 7.0}, 0.1, None)
    (record,) = load_records([tmp_path / "r.sqlite"])
    assert (record.attack_start_s, record.end_s, record.step_s, record.start) == (15.0, 75.0, 0.1, "warmup")


def test_the_lane_change_is_marked_only_when_it_began_before_the_episode_ended():
    """Regression: figures marked the lane change at t_lc_s even when the crash had ended the episode first."""
    changed = _record([0] * 9 + [4.0], time_s=30.0, start="warmup", attack_start_s=15.0, maneuver="cutout")
    ended_first = _record([0] * 9 + [20.0], time_s=30.0, start="warmup", attack_start_s=15.0, maneuver="cutout")
    no_crash = _record([0] * 9 + [20.0], time_s=None, maneuver="cutout")
    assert changed.lane_change_at_s == 19.0 and ended_first.lane_change_at_s is None and no_crash.lane_change_at_s == 20.0
    # as played: 15.03 s after a 15 s warm-up is step 601 (30.05 s), after a collision at the end of step 600
    rounded = _record([0] * 9 + [15.03], time_s=30.05, start="warmup", attack_start_s=15.0, maneuver="cutout", end_s=75.0)
    assert rounded.lane_change_at_s is None
    assert _record([0] * 9 + [60.0], time_s=None, maneuver="cutout").lane_change_at_s is None  # past the episode
    assert _record([0] * 9, time_s=30.0).lane_change_at_s is None  # the paper's maneuver changes no lane


def test_a_swerving_attackers_lane_changes_and_knots_are_read_apart_from_its_lanes(tmp_path):
    """Regression: the cluster figure read a swerving attacker's lanes as knots after the last one; its
    lane changes were never marked. Its records know which parameters are the knots, and when each lane
    change began, those before the episode ended."""
    from d4sumo.search.campaign import Campaign, open_store

    config = EpisodeConfig(maneuver="swerve", start="warmup", warmup_s=5.0, duration_s=40.0, swerve_knots=4)
    with open_store(tmp_path / "r.sqlite") as store:
        cid = store.open_campaign(Campaign(config=config).definition(), 2)
        lanes = (1.5, 0.5, 0.5, 1.2)  # lane 1 at 0 s, back to 0 at 10 s, out again at 30 s
        store.add_sample(cid, 0, (0.1,) * 9 + lanes, 0.5, "success", {"pair": "v1-v2", "time_s": 25.0, "position_m": 300.0,
                                                                       "speed_diff_kmh": 20.0}, {"v1-v2": -0.1}, 0.1, None)
        store.add_sample(cid, 1, (0.1,) * 9 + lanes, -1.0, "no_crash", None, {"v1-v2": 5.0}, 0.1, None)
    crashed, survived = load_records([tmp_path / "r.sqlite"])
    assert crashed.signal_params == (0.1,) * 9 and crashed.swerve_change_steps == (100, 300, 700)
    assert crashed.lane_changes_at_s == (5.0, 15.0) and survived.lane_changes_at_s == (5.0, 15.0, 35.0)
    assert _record([0] * 10, maneuver="cutout").signal_params == (0,) * 10  # built by hand: every parameter


def test_the_system_under_test_is_named_without_importing_a_users_controller():
    assert system_label({"controller": [{"class": "sumo:ACC", "tau": 0.5}, {"class": "switching"}, "sumo:IDM"]}) \
        == "sumo:ACC(tau=0.5) / switching / sumo:IDM"
    assert system_label({"controller": {"class": "nowhere.module:Ctl", "gain": 1}}) == "nowhere.module:Ctl(gain=1)"
