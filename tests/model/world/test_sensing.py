"""What a follower senses: the perfect radar is the truth untouched; a radar's range, noise and latency
act on what the controller gets, never on the verdicts; a controller may ask for the observation."""

from __future__ import annotations

import dataclasses
import math
from types import MappingProxyType

import numpy as np
import pytest
from conftest import knots_signal

from d4sumo.engine.ballistic import integrate
from d4sumo.errors import ConfigError
from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.model.controllers.control import SwitchingController, register_controller
from d4sumo.model.world.lanes import FREE_ROAD_GAP_M
from d4sumo.model.world.sensing import Observation, Radar, RadarParams, sensed_command

KNOTS = [0.2, -0.5, 0.3, -0.8, 0.5, 0.5, 0.5, 0.5, 0.5]  # one every 6 s, the last held


def truth(o):
    return o


def test_the_perfect_radar_hands_the_controller_the_truth_as_a_read_only_observation():
    """No [radar] table, or one that changes nothing: the truth, so every earlier episode stays bit for bit."""
    for params in (None, RadarParams()):
        o = sensed_command(truth, params, 0.05, 1)(12.5, 20.0, 18.0)
        assert o == Observation(20.0, 12.5, 18.0, True) and type(o) is Observation
        assert sensed_command(truth, params, 0.05, 1)(FREE_ROAD_GAP_M, 20.0, 20.0).leader is False
        with pytest.raises(AttributeError):
            o.gap_m = 3.0  # a value: a controller cannot change what another reads
    inbox = {0: "beacon"}
    o = sensed_command(truth, None, 0.05, 1, beacons=True)(12.5, 20.0, 18.0, 0.5, MappingProxyType(inbox), 40.0, 1.0)
    assert o.leader_message == o.front_message == "beacon" and o.accel_mps2 == 0.5 and (o.position_m, o.time_s) == (40.0, 1.0)
    with pytest.raises(TypeError):
        o.messages[1] = "a beacon of one's own"  # the channel's inbox, read only
    assert EpisodeConfig(radar=RadarParams(range_m=math.inf)).radar is None
    assert EpisodeConfig(radar={"seed": 3}).to_dict() == EpisodeConfig().to_dict()


def test_a_car_beyond_the_range_is_not_seen_and_one_within_is_measured_as_it_is():
    radar = Radar(RadarParams(range_m=100.0), 0.05, car=1)
    assert radar.observe(99.0, 20.0, 18.0) == Observation(20.0, 99.0, 18.0, True)
    assert radar.observe(101.0, 20.0, 18.0) == Observation(20.0, FREE_ROAD_GAP_M, 20.0, False)
    assert radar.observe(FREE_ROAD_GAP_M, 20.0, 20.0).leader is False  # nobody ahead at all
    assert Observation(20.0, 50.0, 18.0, True).relative_speed_mps == -2.0


def test_latency_hands_the_reading_of_whole_steps_ago_and_the_first_until_there_is_one():
    radar = Radar(RadarParams(latency_s=0.15), 0.05, car=1)  # three steps
    seen = [radar.observe(float(gap), 20.0 + gap, 30.0 + gap) for gap in range(10, 16)]
    assert [o.gap_m for o in seen] == [10.0, 10.0, 10.0, 10.0, 11.0, 12.0]
    assert [o.lead_speed_mps for o in seen] == [40.0, 40.0, 40.0, 40.0, 41.0, 42.0]
    assert [o.speed_mps for o in seen] == [20.0 + g for g in range(10, 16)]  # its own speed: at once


def test_noise_is_seeded_by_the_table_and_the_car_and_has_the_standard_deviation_asked():
    def draws(seed, car):
        radar = Radar(RadarParams(gap_noise_m=0.5, speed_noise_mps=0.2, seed=seed), 0.05, car)
        return np.array([[o.gap_m - 50.0, o.lead_speed_mps - 20.0] for o in (radar.observe(50.0, 20.0, 20.0) for _ in range(4000))])

    a = draws(0, 1)
    assert np.array_equal(a, draws(0, 1))  # a replay meets the same noise
    assert not np.array_equal(a, draws(0, 2)) and not np.array_equal(a, draws(1, 1))
    assert a.std(axis=0) == pytest.approx([0.5, 0.2], rel=0.05) and abs(a.mean(axis=0)).max() < 0.02


class ObservingController(SwitchingController):
    """A user's controller that asks for the observation: it brakes fully whenever the radar sees a car
    closing in within 20 m, else it is the paper's controller on what the radar measured."""

    seen: list = []

    def observe(self, o: Observation) -> float:
        ObservingController.seen.append(o)
        if o.leader and o.gap_m < 20.0 and o.relative_speed_mps < 0.0:
            return -1.0
        return self.command(o.gap_m, o.speed_mps, o.lead_speed_mps)


def test_a_controller_with_observe_gets_the_observation_through_the_radar():
    register_controller("test-observing", ObservingController)
    config = EpisodeConfig(controller=ControllerConfig("test-observing"), start="steady", duration_s=10.0,
                           radar=RadarParams(range_m=7.5))
    ObservingController.seen = []
    integrate(config, knots_signal(KNOTS, config))
    assert ObservingController.seen and {o.leader for o in ObservingController.seen} == {True, False}
    assert all(o.gap_m <= 7.5 for o in ObservingController.seen if o.leader)


def test_a_late_noisy_radar_changes_the_episode_and_plays_the_same_twice():
    """The paper's controller on a radar 0.2 s late with 0.5 m of noise lets v1 hit the attacker where the
    truth keeps every gap: the radar acts on the commands, the verdict reads the truth."""
    base = EpisodeConfig(start="steady")
    radar = dataclasses.replace(base, radar=RadarParams(range_m=150.0, gap_noise_m=0.5, latency_s=0.2))
    u = knots_signal(KNOTS, base)
    assert integrate(base, u).outcome == "no_crash"
    late = integrate(radar, u)
    assert late.outcome == "attacker_crash" and late.first_collision.follower == "v1"
    again = integrate(radar, u)
    assert again.collisions == late.collisions and np.array_equal(again.trace["speed_v1"], late.trace["speed_v1"])
    assert not radar.batch_arrays  # its platoons are commanded one by one, each with its own radars


def test_a_radar_is_part_of_the_campaign_and_bad_tables_are_one_line():
    config = EpisodeConfig(radar={"gap_noise_m": 0.5, "latency_s": 0.1})
    stored = config.to_dict()
    assert stored["radar"] == {"gap_noise_m": 0.5, "latency_s": 0.1}
    assert EpisodeConfig.from_dict(stored) == config and "radar: gap_noise_m=0.5, latency_s=0.1" in config.system_label
    for table, field in (({"latency_s": 0.07}, "radar.latency_s"), ({"noise": 1.0}, "radar.noise"),
                         ({"range_m": -1.0}, "radar.range_m"), ({"gap_noise_m": "x"}, "radar.gap_noise_m"),
                         ({"seed": 1.5}, "radar.seed")):
        with pytest.raises(ConfigError) as e:
            EpisodeConfig(radar=table)
        assert e.value.field == field
    with pytest.raises(ConfigError, match="radar: got .*; allowed: a platoon with a follower a Python controller commands"):
        EpisodeConfig(controller=ControllerConfig("sumo:ACC"), radar={"gap_noise_m": 1.0})
    mixed = EpisodeConfig(followers=2, controller=(ControllerConfig("sumo:ACC"), ControllerConfig("switching")),
                          radar={"gap_noise_m": 1.0})
    assert mixed.radar is not None  # the Python follower's radar


@pytest.mark.sumo
def test_in_sumo_a_radars_episodes_in_a_batch_equal_them_alone_and_a_campaign_replays_exactly(tmp_path, road, capsys):
    from conftest import assert_same_episode, random_plans

    from d4sumo.cli import main
    from d4sumo.engine.simulation import simulate, simulate_batch

    config = EpisodeConfig(start="steady", duration_s=20.0, radar=RadarParams(range_m=120.0, gap_noise_m=0.3,
                                                                              speed_noise_mps=0.1, latency_s=0.1))
    plans = random_plans(config, 6, seed=2)
    for batched, plan in zip(simulate_batch(config, plans), plans):
        assert_same_episode(batched, simulate(config, plan, road=road))
    db = tmp_path / "radar.sqlite"
    assert main(["falsify", "--start", "steady", "--set", "radar.gap_noise_m=0.5", "--set", "radar.latency_s=0.2",
                 "--optimizer", "random", "--samples", "6", "--db", str(db), "--quiet"]) == 0
    for sample in ("1", "6"):
        assert main(["replay", str(db), sample]) == 0
        assert "reproduces the stored sample exactly" in capsys.readouterr().out


def test_the_example_controller_of_the_docs_runs_behind_a_radar(monkeypatch):
    """docs/sensing.md's complete example, examples/controllers/radar_acc.py, as a user runs it."""
    from pathlib import Path

    monkeypatch.syspath_prepend(str(Path(__file__).resolve().parents[3] / "examples" / "controllers"))
    config = EpisodeConfig(controller=ControllerConfig("radar_acc:RadarACC", (("time_gap_s", 1.5),)), start="steady",
                           duration_s=30.0, radar=RadarParams(range_m=150.0, latency_s=0.2))
    episode = integrate(config, knots_signal(KNOTS, config))
    assert episode.outcome == "no_crash"
    # it keeps a time gap (7 m + 1.5 s x its speed), not the 7 m it started at: 25 m behind the attacker by 4 s
    assert max(episode.trace["gap_v1"][:100]) > 25.0 and episode.trace["gap_v1"][0] == 7.0
