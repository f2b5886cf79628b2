"""The situation searched with the attack (`search.situation`): ranges of the scenario's setpoint and speed
as more parameters of the search, stored with every sample and replayed exactly."""

from __future__ import annotations

import json

import numpy as np
import pytest

from d4sumo.cli import main
from d4sumo.errors import ConfigError
from d4sumo.inputs import campaign_of
from d4sumo.model.attacks.maneuvers import attack_plan
from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.search import situation
from d4sumo.search.campaign import Campaign
from d4sumo.search.store import Store


def test_a_campaign_stores_its_situation_as_a_database_reads_it_back_whatever_order_it_was_given_in():
    """Regression: given the start before the setpoint, the parameters were laid out start first, while the database
    (which stores a definition's keys sorted) gave them back setpoint first: a replay read one from the other."""
    for scenario in ({"start": ["rest", "steady"], "setpoint_m": [3, 10]}, {"speed_mps": [20, 30], "setpoint_m": [3, 10]}):
        given = campaign_of({"scenario": scenario})
        stored = json.loads(json.dumps(given.definition(), sort_keys=True))  # as the database keeps it
        read = Campaign.from_definition(stored, samples=given.samples)
        assert read == given and read.family().names == given.family().names


def test_a_campaign_without_ranges_is_what_it_was_and_one_with_them_stores_and_reads_them():
    plain = campaign_of({"scenario": {"setpoint_m": 5.0}})
    assert plain.situation == () and "situation" not in plain.definition() and plain.family().dimension == 9
    searched = campaign_of({"scenario": {"setpoint_m": [3, 10], "speed_mps": [20.0, 30]}})
    assert searched.situation == (("setpoint_m", 3.0, 10.0), ("speed_mps", 20.0, 30.0))
    assert searched.definition()["situation"] == {"setpoint_m": [3.0, 10.0], "speed_mps": [20.0, 30.0]}
    assert Campaign.from_definition(searched.definition()) == searched.replace(samples=100)
    family = searched.family()
    assert family.names[-2:] == ("setpoint_m", "speed_mps") and family.signals[-2:] == (1, 1)
    assert list(family.lower[-2:]) == [3.0, 20.0] and list(family.upper[-2:]) == [10.0, 30.0]


def test_a_samples_configuration_holds_its_situation_and_its_plan_the_attacks_alone():
    searched = campaign_of({"scenario": {"setpoint_m": [3, 10], "speed_mps": [20, 30]}})
    plain = campaign_of({})
    x = np.concatenate([np.full(9, 0.3), [4.25, 27.5]])
    config = searched.config_for(x)
    assert (config.setpoint_m, config.speed_mps) == (4.25, 27.5)
    assert config == EpisodeConfig(setpoint_m=4.25, speed_mps=27.5)
    assert np.array_equal(attack_plan(searched.family(), x, config).u, attack_plan(plain.family(), x[:9], config).u)
    assert plain.config_for(x[:9]) is plain.config


@pytest.mark.parametrize("scenario, message", [
    ({"setpoint_m": [5, 5]}, "scenario.setpoint_m: got [5, 5]; allowed: a range [low, high] with low below high (empty)"),
    ({"setpoint_m": [10, 3]}, "scenario.setpoint_m: got [10, 3]; allowed: a range [low, high] with low below high (reversed)"),
    ({"setpoint_m": [3, 5, 7]}, "scenario.setpoint_m: got [3, 5, 7]; allowed: a value, or a range [low, high] of two numbers in m"),
    ({"speed_mps": [20, "fast"]}, "allowed: a value, or a range [low, high] of two numbers in m/s"),
    ({"followers": [2, 4]}, "scenario.followers: got [2, 4]; allowed: a single value: the keys searched are scenario.setpoint_m "
                            "(a range), scenario.speed_mps (a range), scenario.start (choices), those a batch of episodes may vary"),
    ({"setpoint_m": [0, 5]}, "scenario.setpoint_m: got 0.0"),  # outside the key's own limits
    ({"speed_mps": [20, 80]}, "scenario.speed_mps: got 80.0"),
])
def test_a_bad_range_is_one_line_naming_its_key(scenario, message):
    with pytest.raises(ConfigError) as info:
        campaign_of({"scenario": scenario})
    assert message in str(info.value)


def test_followers_sumo_drives_take_one_speed_and_a_stored_situation_is_checked():
    config = EpisodeConfig(controller=ControllerConfig("sumo:ACC"))
    with pytest.raises(ConfigError, match="scenario.speed_mps: got \\[20.0, 30.0\\]; allowed: a single value with followers SUMO"):
        Campaign(config, situation=(("speed_mps", 20.0, 30.0),))
    assert Campaign(config, situation=(("setpoint_m", 3.0, 10.0),)).situation  # the setpoint varies in a batch
    with pytest.raises(ConfigError, match="situation"):
        situation.restored([3, 10])
    with pytest.raises(ConfigError, match="each key once"):
        Campaign(situation=(("setpoint_m", 3.0, 10.0), ("setpoint_m", 4.0, 5.0)))


@pytest.mark.sumo
def test_in_sumo_a_searched_situation_is_played_per_sample_in_batches_as_alone_and_replays_exactly(tmp_path, capsys):
    toml = tmp_path / "situation.toml"
    toml.write_text('[scenario]\nsetpoint_m = [3, 10]\nspeed_mps = [20, 30]\nstart = ["rest", "steady"]\nduration_s = 20.0\n\n'
                    '[search]\nsamples = 16\noptimizer = "random"\n')
    batched, alone = tmp_path / "batched.sqlite", tmp_path / "alone.sqlite"
    assert main(["falsify", "--config", str(toml), "--db", str(batched)]) == 0
    assert main(["falsify", "--config", str(toml), "--db", str(alone), "--batch", "1"]) == 0

    def samples(db):
        with Store(db, create=False) as store:
            return [(s.index, s.params, s.robustness, s.outcome, s.collision, s.min_gaps) for s in store.samples()]

    stored = samples(batched)
    assert stored == samples(alone) and len(stored) == 16
    situations = {params[-3:] for _, params, *_ in stored}  # the setpoint, the speed and the start, as the file gives them
    assert len(situations) == 16 and all(3 <= s <= 10 and 20 <= v <= 30 and 0 <= c <= 2 for s, v, c in situations)
    assert {c < 1 for _, _, c in situations} == {True, False}  # both starts, in one batch
    assert len({outcome for _, _, _, outcome, _, _ in stored}) > 1  # the situations play differently
    with Store(batched, create=False) as store:
        ids = [s.id for s in store.samples()]
    capsys.readouterr()
    for sample_id in ids[:4]:
        assert main(["replay", str(batched), str(sample_id), "--json"]) == 0
        replay = json.loads(capsys.readouterr().out)
        assert replay["reproduced"]
        scenario, played = replay["config"]["scenario"], replay["situation"]
        assert (scenario["setpoint_m"], scenario["speed_mps"], scenario["start"]) == (played["setpoint_m"], played["speed_mps"],
                                                                                      played["start"])
        assert len(replay["attack"]["values"]) == 9


def test_the_cli_refuses_a_bad_range_in_one_line_and_stores_nothing(tmp_path, capsys):
    db = tmp_path / "none.sqlite"
    assert main(["falsify", "--set", "scenario.setpoint_m=[10, 3]", "--db", str(db)]) == 2
    err = capsys.readouterr().err.strip().splitlines()
    assert err == ["d4sumo: error: scenario.setpoint_m: got [10, 3]; allowed: a range [low, high] with low below high (reversed)"]
    assert not db.exists()


@pytest.mark.sumo
def test_in_sumo_a_sample_without_the_attack_plays_in_the_samples_own_situation():
    from d4sumo.search.evaluator import Evaluator

    campaign = campaign_of({"scenario": {"setpoint_m": [3, 10], "start": "steady", "duration_s": 10.0}})
    evaluator = Evaluator(campaign)
    x = np.concatenate([np.zeros(9), [8.5]])
    episode = evaluator.without_attack(0, x)
    first_gap = episode.trace["pos_v0"][0] - campaign.config.vehicle.length_m - episode.trace["pos_v1"][0]
    assert first_gap == pytest.approx(8.5, abs=1e-6)  # from steady state: the sample's setpoint, not the range's low end
    with pytest.raises(ValueError, match="give its params"):
        evaluator.without_attack(0)
    played, per_sample = evaluator.without_attack_of({0: x})
    assert per_sample and played(0).trace["pos_v1"][0] == episode.trace["pos_v1"][0]


def test_the_start_is_searched_over_its_choices_each_an_equal_share_of_its_parameter():
    searched = campaign_of({"scenario": {"start": ["rest", "steady"], "setpoint_m": [3, 10]}})
    assert searched.situation == (("setpoint_m", 3.0, 10.0), ("start", ("rest", "steady")))  # in the order of their names
    assert searched.definition()["situation"] == {"setpoint_m": [3.0, 10.0], "start": ["rest", "steady"]}
    family = searched.family()
    assert family.names[-2:] == ("setpoint_m", "start") and (family.lower[-1], family.upper[-1]) == (0.0, 2.0)
    starts = [searched.config_for(np.concatenate([np.zeros(9), [5.0, v]])).start for v in (0.0, 0.999, 1.0, 2.0)]
    assert starts == ["rest", "rest", "steady", "steady"]  # its whole part; its top, the last


@pytest.mark.parametrize("scenario, message", [
    ({"start": ["rest"]}, "scenario.start: got ['rest']; allowed: a value, or a list of two or more choices of rest, steady"),
    ({"start": ["rest", "rest"]}, "scenario.start: got ['rest', 'rest']; allowed: a list of choices, each once"),
    ({"start": ["rest", "warmup"]}, "allowed: choices of rest, steady (the starts a batch may mix"),
])
def test_bad_choices_are_one_line_naming_the_key(scenario, message):
    with pytest.raises(ConfigError) as info:
        campaign_of({"scenario": scenario})
    assert message in str(info.value)


def test_an_episode_plays_one_situation_and_says_where_a_range_is_searched(capsys):
    assert main(["simulate", "--set", "scenario.setpoint_m=[3, 10]"]) == 2
    assert capsys.readouterr().err.strip() == ("d4sumo: error: scenario.setpoint_m: got [3, 10]; allowed: a single value: an "
                                               "episode plays one situation (falsify and sweep search a range or choices)")


@pytest.mark.sumo
def test_in_sumo_a_campaign_that_searches_its_situation_resumes_and_extends_as_one_run_whole(tmp_path):
    args = ["falsify", "--set", "scenario.setpoint_m=[3, 10]", "--set", 'scenario.start=["rest", "steady"]', "--duration", "20",
            "--optimizer", "random"]
    whole, parts = tmp_path / "whole.sqlite", tmp_path / "parts.sqlite"
    assert main([*args, "--samples", "12", "--db", str(whole)]) == 0
    assert main([*args, "--samples", "5", "--db", str(parts)]) == 0
    assert main([*args, "--samples", "12", "--db", str(parts)]) == 0  # extended: one campaign

    def samples(db):
        with Store(db, create=False) as store:
            return [(s.campaign_id, s.index, s.params, s.robustness, s.outcome) for s in store.samples()]

    assert samples(parts) == samples(whole) and len(samples(whole)) == 12
