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
    ({"followers": [2, 4]}, "scenario.followers: got [2, 4]; allowed: a single value: the number of followers is the campaign's"),
    ({"duration_s": [20, 40]}, "scenario.duration_s: got [20, 40]; allowed: a single value: the attack's signal and the "
                               "specification are made for one length of episode"),
    ({"setpoint_m": [0, 5]}, "scenario.setpoint_m: got 0;"),  # outside the key's own limits, as given
    ({"speed_mps": [20, 80]}, "scenario.speed_mps: got 80.0; allowed: a number in (0, 70] m/s"),  # (its high end, in a corner)
])
def test_a_bad_range_is_one_line_naming_its_key(scenario, message):
    with pytest.raises(ConfigError) as info:
        campaign_of({"scenario": scenario})
    assert message in str(info.value)


def test_a_stored_situation_is_checked():
    with pytest.raises(ConfigError, match="situation"):
        situation.restored([3, 10])
    with pytest.raises(ConfigError, match="each key once"):
        Campaign(situation=(("setpoint_m", 3.0, 10.0), ("setpoint_m", 4.0, 5.0)))
    with pytest.raises(ConfigError, match="v2v.loss: got \\[0.0, 1.5\\]|v2v.loss: got 1.5"):
        Campaign(EpisodeConfig(controller=ControllerConfig("cacc")), situation=(("v2v.loss", 0.0, 1.5),))


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


def test_any_numeric_key_of_the_tables_is_searched_stored_and_read_back_as_ranges_whole_numbers_and_choices():
    given = {"scenario": {"start": "steady"}, "controller": {"class": "cacc", "c1": [0.3, 0.7]},
             "v2v": {"loss": [0, 0.5], "seed": [0, 3], "latency_s": {"choices": [0, 0.1, 0.3]}},
             "radar": {"gap_noise_m": [0, 0.5]}, "vehicle": {"actuator_lag_s": [0.2, 0.8]}}
    searched = campaign_of(given)
    assert searched.situation == (("controller.c1", 0.3, 0.7), ("radar.gap_noise_m", 0.0, 0.5), ("v2v.latency_s", (0.0, 0.1, 0.3)),
                                  ("v2v.loss", 0.0, 0.5), ("v2v.seed", 0, 3), ("vehicle.actuator_lag_s", 0.2, 0.8))
    assert searched.definition()["situation"]["v2v.latency_s"] == {"choices": [0.0, 0.1, 0.3]}
    stored = json.loads(json.dumps(searched.definition(), sort_keys=True))
    assert Campaign.from_definition(stored, samples=searched.samples) == searched
    family = searched.family()
    assert list(family.lower[-6:]) == [0.3, 0.0, 0.0, 0.0, 0.0, 0.2] and list(family.upper[-6:]) == [0.7, 0.5, 3.0, 0.5, 4.0, 0.8]
    x = np.concatenate([np.zeros(family.dimension - 6), [0.55, 0.25, 1.2, 0.35, 3.99, 0.5]])
    config = searched.config_for(x)
    assert dict(config.controller.params)["c1"] == 0.55 and config.radar.gap_noise_m == 0.25
    assert (config.v2v.latency_s, config.v2v.loss, config.v2v.seed, config.vehicle.actuator_lag_s) == (0.1, 0.35, 3, 0.5)
    assert config == campaign_of({**given, "controller": {"class": "cacc", "c1": 0.55}, "vehicle": {"actuator_lag_s": 0.5},
                                  "v2v": {"loss": 0.35, "seed": 3, "latency_s": 0.1}, "radar": {"gap_noise_m": 0.25}}).config
    assert searched.config.radar is None  # the low corner senses the truth: no radar, as a campaign without one
    assert [searched.config_for(np.concatenate([x[:-2], [v, 0.5]])).v2v.seed for v in (0.0, 0.99, 1.0, 4.0)] == [0, 0, 1, 3]


def test_a_traffic_range_is_searched_over_levels_each_warmed_up_once():
    searched = campaign_of({"scenario": {"start": "steady"}, "traffic": {"vehicles_per_hour": [300, 1800]}})
    parameter = searched.family().parameters[-1]
    assert (parameter.name, parameter.low, parameter.high) == ("traffic.vehicles_per_hour", 0.0, float(situation.TRAFFIC_LEVELS))
    played = [searched.config_for(np.concatenate([np.zeros(9), [v]])).traffic.vehicles_per_hour for v in (0, 0.99, 1, 5.5, 10.2, 11)]
    assert played == [300.0, 300.0, 450.0, 1050.0, 1800.0, 1800.0]


@pytest.mark.parametrize("doc, message", [
    ({"v2v": {"seed": [0, 2.5]}, "controller": {"class": "cacc"}}, "v2v.seed: got [0.0, 2.5]; allowed: whole numbers: the key holds one"),
    ({"v2v": {"latency_s": {"choices": [0.1]}}, "controller": {"class": "cacc"}}, "v2v.latency_s: got {'choices': [0.1]}; allowed: a value, "
                                                                                  "a range [low, high], or {choices = [a, b, ...]}"),
    ({"v2v": {"latency_s": {"choices": [0.1, 0.1]}}, "controller": {"class": "cacc"}}, "v2v.latency_s: got [0.1, 0.1]; allowed: a list "
                                                                                       "of choices, each once"),
    ({"v2v": {"loss": [0, 1.5]}, "controller": {"class": "cacc"}}, "v2v.loss: got 1.5"),  # outside the key's own limits
    ({"radar": {"gap_noise_m": [0, 0.5], "seed": 4}}, "radar.seed: got 4; allowed: 0 (or left out) where the radar's ranges start at "
                                                      "the truth"),
    ({"controller": [{"class": "switching", "acc_kp": [0.1, 0.5]}, "switching", "switching"]}, "controller.v1.acc_kp"),
    ({"scenario": {"swerve_lanes": [1, 2], "maneuver": "swerve"}}, "scenario.swerve_lanes: got [1, 2]; allowed: a single value: the "
                                                                   "attack's box holds its lanes"),
])
def test_a_bad_search_of_another_table_is_one_line_naming_its_key(doc, message):
    with pytest.raises(ConfigError) as info:
        campaign_of(doc)
    assert message in str(info.value)


def test_an_episode_refuses_a_range_of_any_table(capsys):
    assert main(["simulate", "--set", "v2v.loss=[0, 0.5]", "--set", "controller.class=cacc"]) == 2
    assert capsys.readouterr().err.strip() == ("d4sumo: error: v2v.loss: got [0, 0.5]; allowed: a single value: an episode plays one "
                                               "situation (falsify and sweep search a range or choices)")


def _stored_samples(db):
    with Store(db, create=False) as store:
        return [(s.index, s.params, s.robustness, s.outcome, s.collision, s.min_gaps) for s in store.samples()]


@pytest.mark.sumo
@pytest.mark.parametrize("tables", [
    # keys a batch holds for all its episodes: each sample's configuration plays in a batch of its own key
    '[controller]\nclass = "cacc"\n\n[v2v]\nloss = [0, 0.6]\nlatency_s = {choices = [0, 0.1, 0.2]}\n\n[vehicle]\nactuator_lag_s = [0.2, 0.8]\n\n'
    '[radar]\ngap_noise_m = [0, 0.3]\n',
    # the speed where SUMO's models read it from their vehicle type, and one of their attributes
    '[controller]\nclass = "sumo:ACC"\ntau = [0.8, 1.6]\n',
])
def test_in_sumo_a_search_of_any_table_plays_in_batches_as_alone_and_replays_exactly(tmp_path, capsys, tables):
    toml = tmp_path / "situation.toml"
    toml.write_text('[scenario]\nstart = "steady"\nsetpoint_m = 5.0\nspeed_mps = [20, 30]\nduration_s = 15.0\n\n' + tables +
                    '\n[search]\nsamples = 12\noptimizer = "random"\n')
    batched, alone = tmp_path / "batched.sqlite", tmp_path / "alone.sqlite"
    assert main(["falsify", "--config", str(toml), "--db", str(batched)]) == 0
    assert main(["falsify", "--config", str(toml), "--db", str(alone), "--batch", "1"]) == 0
    stored = _stored_samples(batched)
    assert stored == _stored_samples(alone) and len({params for _, params, *_ in stored}) == 12
    capsys.readouterr()
    for sample_id in (1, 7):
        assert main(["replay", str(batched), str(sample_id), "--json"]) == 0
        replay = json.loads(capsys.readouterr().out)
        assert replay["reproduced"] and replay["situation"]["speed_mps"] == replay["config"]["scenario"]["speed_mps"]


@pytest.mark.sumo
def test_in_sumo_a_traffic_range_plays_its_levels_and_replays_exactly(tmp_path, capsys):
    db = tmp_path / "traffic.sqlite"
    assert main(["falsify", "--set", "scenario.start=steady", "--duration", "10", "--set", "traffic.vehicles_per_hour=[300, 1500]",
                 "--set", "traffic.warmup_s=20", "--samples", "4", "--optimizer", "random", "--db", str(db)]) == 0
    with Store(db, create=False) as store:
        campaign = Campaign.from_definition(store.campaigns()[0].definition)
        levels = {campaign.config_for(s.params).traffic.vehicles_per_hour for s in store.samples()}
        assert levels <= {300.0 + 120.0 * i for i in range(situation.TRAFFIC_LEVELS)} and len(levels) > 1
    capsys.readouterr()
    assert main(["replay", str(db), "2", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["reproduced"]


def test_the_guides_example_is_a_campaign_searching_every_kind():
    """docs/campaigns.md's example of a situation searched: a range, named choices, numeric choices, whole numbers."""
    import tomllib
    from pathlib import Path

    text = (Path(__file__).resolve().parents[2] / "docs" / "campaigns.md").read_text()
    block = text[text.index("## The situation searched with the attack"):]
    block = block[block.index("```toml") + len("```toml"):]
    campaign = campaign_of(tomllib.loads(block[:block.index("```")]))
    kinds = {e[0]: e for e in campaign.situation}
    assert kinds["start"] == ("start", ("rest", "steady")) and kinds["v2v.latency_s"] == ("v2v.latency_s", (0, 0.1, 0.3))
    assert kinds["v2v.seed"] == ("v2v.seed", 0, 9) and kinds["controller.c1"] == ("controller.c1", 0.3, 0.7)
    assert len(campaign.situation) == 9
