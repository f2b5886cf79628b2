"""The V2V channel and the cooperative controllers that read it: pure code, no SUMO."""

from __future__ import annotations

import math

import numpy as np
import pytest

from d4sumo.errors import ConfigError
from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.model.controllers.cacc import ConsensusCACC, ConsensusParams, PathCACC, PathParams, PloegCACC, PloegParams
from d4sumo.model.world.sensing import Observation
from d4sumo.model.stepping.platoon import Platoon
from d4sumo.model.world.v2v import Channel, ChannelParams, Message
from d4sumo.model.world.vehicle import VehicleParams

STEP = 0.05


def _play(channel: Channel, steps: int, cars: int = 4) -> list[dict]:
    seen = []
    for k in range(steps):
        channel.send(k, [100.0 - 10 * i + k for i in range(cars)], [25.0] * cars, [0.1 * i for i in range(cars)])
        seen.append({i: dict(channel.inbox(i)) for i in range(1, cars)})
    return seen


def test_beacons_come_every_interval_from_the_leader_and_the_car_ahead_latency_steps_late():
    seen = _play(Channel(ChannelParams(beacon_interval_s=0.1, latency_s=0.15), STEP, 4), 10)
    assert seen[2] == {1: {}, 2: {}, 3: {}}  # sent at step 0, due at step 3
    inbox = seen[3][3]
    assert set(inbox) == {0, 2} and inbox[2] == Message(2, 0.0, 80.0, 25.0, 0.2)
    assert seen[4][3][2].time_s == 0.0 and seen[5][3][2].time_s == 0.1  # the next beacon, sent at step 2
    assert set(seen[5][1]) == {0}  # v1's leader is the car ahead


def test_lost_beacons_are_drawn_from_the_seed_and_the_pair_the_same_every_time():
    params = ChannelParams(loss=0.5, seed=3)
    first = _play(Channel(params, STEP, 4), 400)
    assert first == _play(Channel(params, STEP, 4), 400)
    newest = [inbox[3][2].time_s for inbox in first if 2 in inbox[3]]
    gaps = np.diff(sorted(set(newest)))
    assert gaps.max() > 0.1 + 1e-9  # some were lost
    other = _play(Channel(ChannelParams(loss=0.5, seed=4), STEP, 4), 400)
    assert other != first


@pytest.mark.parametrize("table, field", [({"beacon_interval_s": 0}, "v2v.beacon_interval_s"), ({"loss": 1.5}, "v2v.loss"),
                                          ({"latency": 0.1}, "v2v.latency"), ({"seed": -1}, "v2v.seed")])
def test_a_bad_channel_gets_one_line(table, field):
    with pytest.raises(ConfigError) as info:
        ChannelParams.from_table(table)
    assert info.value.field == field


def test_a_cooperative_platoon_gets_plexe_default_channel_and_a_channel_needs_a_listener():
    config = EpisodeConfig(controller=ControllerConfig("cacc"))
    assert config.v2v == ChannelParams() and config.to_dict()["v2v"]["beacon_interval_s"] == 0.1
    assert EpisodeConfig.from_dict(config.to_dict()) == config and not config.batch_arrays
    assert "v2v" not in EpisodeConfig().to_dict()  # no listener, no channel: earlier campaigns keep their identity
    with pytest.raises(ConfigError) as info:
        EpisodeConfig(v2v={"loss": 0.1})
    assert info.value.field == "v2v"
    with pytest.raises(ConfigError) as info:
        EpisodeConfig(controller=ControllerConfig("cacc"), v2v={"latency_s": 0.12})
    assert info.value.field == "v2v.latency_s"


def test_the_path_cacc_is_rajamani_law_with_plexe_gains():
    vehicle = VehicleParams()
    cacc = PathCACC(PathParams(), setpoint_m=5.0, target_speed_mps=25.0, vehicle=vehicle, step_s=STEP)
    ahead, leader = Message(2, 0.0, 0.0, 24.0, -1.0), Message(0, 0.0, 0.0, 23.0, -2.0)
    a = cacc.desired_acceleration(4.0, 25.0, ahead, leader)
    # Plexe's alphas at C1 = 0.5, xi = 1, omega_n = 0.2: 0.5, 0.5, -0.3, -0.1, -0.04
    assert a == pytest.approx(0.5 * -1.0 + 0.5 * -2.0 - 0.3 * 1.0 - 0.1 * 2.0 - 0.04 * 1.0)
    obs = Observation(25.0, 4.0, 24.0, True, 0.0, leader, ahead)
    assert cacc.observe(obs) == pytest.approx(a / vehicle.max_decel_mps2)
    assert cacc.observe(Observation(25.0, 4.0, 24.0, True)) == 0.0  # no beacon yet: nothing asked


def test_ploeg_integrates_its_command_as_plexe_does():
    vehicle = VehicleParams()
    ploeg = PloegCACC(PloegParams(), setpoint_m=2.0, target_speed_mps=25.0, vehicle=vehicle, step_s=STEP)
    ahead = Message(1, 0.0, 0.0, 24.0, -1.0)
    u = 0.0
    for _ in range(3):
        ploeg.observe(Observation(25.0, 14.0, 24.0, True, 0.5, None, ahead))
        u += (-u + 0.2 * (14.0 - (2.0 + 0.5 * 25.0)) + 0.7 * (24.0 - 25.0 - 0.5 * 0.5) - 1.0) / 0.5 * STEP
        assert ploeg.u == pytest.approx(u)
    assert math.isclose(ploeg.observe(Observation(25.0, 14.0, 24.0, True)), 0.0)


def test_a_consensus_follower_hears_every_car_ahead_and_the_others_the_leader_and_the_car_ahead():
    channel = Channel(ChannelParams(), STEP, 4, lengths=[5.0, 4.0, 12.0, 5.0], hear_all=frozenset({3}))
    channel.send(0, [100.0, 90.0, 80.0, 60.0], [25.0] * 4, [0.0] * 4)
    assert sorted(channel.inbox(3)) == [0, 1, 2] and sorted(channel.inbox(2)) == [0, 1]
    assert channel.inbox(3)[2].length_m == 12.0


def test_the_consensus_law_is_plexe_with_its_gains_and_positions_predicted_to_when_it_acts():
    """v2 of a platoon whose cars are 4 m long, the leader at 25 m/s, beacons 0.1 s old; Plexe's law
    (MSCFModel_CC::_consensus) with b 1800, K[2][0] 80, K[2][1] 860, h 0.8 s, divided by 1000."""
    vehicle = VehicleParams()
    law = ConsensusCACC(ConsensusParams(), setpoint_m=15.0, target_speed_mps=30.0, vehicle=vehicle, step_s=STEP)
    leader, ahead = Message(0, 1.0, 200.0, 25.0, 0.0, 4.0), Message(1, 1.0, 160.0, 24.0, 0.0, 4.0)
    own_x, own_v, now = 120.0, 26.0, 1.1
    acting, x = now + STEP, own_x + own_v * STEP
    spacing = 0.8 * 25.0 + 15.0
    to_leader = (200.0 + (acting - 1.0) * 25.0 - x) - 2 * (spacing + 4.0)
    to_ahead = (160.0 + (acting - 1.0) * 24.0 - x) - (spacing + 4.0)
    expected = -1.8 * (own_v - 25.0) + (0.08 * to_leader + 0.86 * to_ahead) / 2
    assert law.desired_acceleration(own_x, own_v, now, {0: leader, 1: ahead}) == pytest.approx(expected)
    obs = Observation(own_v, 35.0, 24.0, True, 0.0, leader, ahead, {0: leader, 1: ahead}, own_x, now)
    assert law.observe(obs) == pytest.approx(max(-1.0, expected / vehicle.max_decel_mps2))
    assert law.observe(Observation(own_v, 35.0, 24.0, True, 0.0, leader, None, {0: leader}, own_x, now)) == 0.0  # not all yet
    v1 = law.desired_acceleration(own_x, own_v, now, {0: leader})  # v1: the leader alone, with K[1][0] 460
    assert v1 == pytest.approx(-1.8 * (own_v - 25.0) + 0.46 * ((200.0 + (acting - 1.0) * 25.0 - x) - (spacing + 4.0)))


def test_the_fallback_takes_over_while_the_car_ahead_beacon_and_the_radar_disagree():
    vehicle = VehicleParams()
    cacc = PathCACC(PathParams(fallback_mps=1.0), setpoint_m=5.0, target_speed_mps=25.0, vehicle=vehicle, step_s=STEP)
    ahead, leader = Message(0, 0.0, 0.0, 30.0, 0.0), Message(0, 0.0, 0.0, 30.0, 0.0)
    lying = Observation(25.0, 5.0, 25.0, True, 0.0, leader, ahead)  # the radar sees 25 m/s, the beacon says 30
    acc = -(25.0 - 25.0 + 0.1 * (1.2 * 25.0 + 2.0 - 5.0)) / 1.2
    assert cacc.observe(lying) == pytest.approx(acc / vehicle.max_decel_mps2) and cacc.mode == 1.0
    honest = Observation(24.9, 5.0, 30.0, True, 0.0, leader, ahead)  # 0.1 m/s under its target speed
    assert cacc.desired_acceleration(5.0, 24.9, ahead, leader) > 2.0
    assert cacc.observe(honest) == pytest.approx(0.1 / STEP / vehicle.max_accel_mps2)  # to the target speed, no faster
    assert cacc.mode == 0.0
    free = Observation(20.0, 1000.0, 20.0, False, 0.0, leader, ahead)  # nobody ahead: it cruises, at most 1.5 m/s^2
    assert cacc.observe(free) == pytest.approx(1.5 / vehicle.max_accel_mps2)
    assert not hasattr(PathCACC(PathParams(), setpoint_m=5.0, target_speed_mps=25.0, vehicle=vehicle, step_s=STEP), "mode")


def test_a_sumo_consensus_platoon_of_more_cars_than_plexe_holds_gets_one_line():
    consensus = ControllerConfig("sumo:CC", (("active_controller", "CONSENSUS"),))
    EpisodeConfig(controller=consensus, followers=7)
    with pytest.raises(ConfigError) as info:
        EpisodeConfig(controller=consensus, followers=8)
    assert info.value.field == "scenario.followers" and "at most 7" in info.value.allowed


@pytest.mark.parametrize("cls, params", [(PathCACC, PathParams), (PloegCACC, PloegParams), (ConsensusCACC, ConsensusParams)])
def test_a_cooperative_follower_whose_radar_sees_another_car_than_the_beacons_falls_back_to_its_acc(cls, params):
    """A traffic car (or a maneuver's) cut in between it and the car whose beacons it reads: it follows what its
    radar sees with its ACC at its fallback headway, as CACC systems do, and its mitigation's mode says so."""
    vehicle = VehicleParams()
    ahead, leader = Message(0, 0.0, 52.0, 20.0, 2.0, 4.0), Message(0, 0.0, 52.0, 20.0, 2.0, 4.0)
    inbox = {0: leader}
    acc = -(24.0 - 20.0 + 0.1 * (1.5 * 24.0 + 2.0 - 8.0)) / 1.5  # Rajamani's Eq. 6.18 on the car 8 m ahead at 20 m/s
    law = cls(params(fallback_mps=5.0, fallback_headway_s=1.5), setpoint_m=5.0, target_speed_mps=25.0, vehicle=vehicle, step_s=STEP)
    cut_in = Observation(24.0, 8.0, 20.0, True, 0.0, leader, ahead, inbox, 40.0, 1.0, matched=False)
    assert law.observe(cut_in) == pytest.approx(acc / vehicle.max_decel_mps2) and law.mode == 1.0
    matched = Observation(24.0, 8.0, 20.0, True, 0.0, leader, ahead, inbox, 40.0, 1.0)  # the beacons' car 8 m ahead: its law
    assert law.observe(matched) != pytest.approx(acc / vehicle.max_decel_mps2)
    plain = cls(params(), setpoint_m=5.0, target_speed_mps=25.0, vehicle=vehicle, step_s=STEP)  # no mitigation: the same ACC
    assert plain.observe(Observation(24.0, 8.0, 20.0, True, 0.0, leader, ahead, inbox, 40.0, 1.0, matched=False)) == \
        pytest.approx(-(4.0 + 0.1 * (1.2 * 24.0 - 6.0)) / 1.2 / vehicle.max_decel_mps2)


def test_a_cooperative_follower_behind_a_traffic_car_that_cut_in_reads_the_beacons_only_with_match_radar():
    """A traffic car cut in ahead of v2 (a cacc): with ``match_radar`` (the default) v2 follows it with its ACC; without,
    it keeps reading v1's beacons, as d4sumo 0.19 had it. v1, behind the attacker, reads its beacons all along."""
    positions, speeds = [100.0, 90.5, 78.0, 86.0], [25.0] * 4  # v0, v1, v2, and a traffic car (index 3) 3.5 m ahead of v2
    pairs = [(0, 1, 5.0), (1, 3, 0.0), (3, 2, 3.5)]
    commands = {}
    for match in (True, False):
        config = EpisodeConfig(followers=2, start="steady", controller=ControllerConfig("cacc"), traffic={},
                               v2v=ChannelParams(match_radar=match))
        platoon = Platoon(config, np.full(config.steps, np.nan), attacker_max_speed_mps=40.0)
        for k in range(2):  # the first beacons arrive
            platoon.advance(k, positions, speeds, pairs)
        commands[match] = platoon.commands[-1][1:3]
    acc = -(0.1 * (1.2 * 25.0 + 2.0 - 3.5)) / 1.2  # v2's ACC on the traffic car 3.5 m ahead at its own speed
    assert commands[True][1] == pytest.approx(acc / VehicleParams().max_decel_mps2)
    assert commands[False][1] != pytest.approx(commands[True][1])
    assert commands[True][0] == commands[False][0]  # v1 sees the attacker, whose beacons it reads


def test_match_radar_is_stored_among_traffic_and_read_back_as_0_19_had_it():
    among = EpisodeConfig(followers=2, start="steady", controller=ControllerConfig("cacc"), traffic={})
    assert among.to_dict()["v2v"]["match_radar"] is True
    assert "match_radar" not in EpisodeConfig(followers=2, start="steady", controller=ControllerConfig("cacc"), traffic={},
                                              v2v=ChannelParams(match_radar=False)).to_dict()["v2v"]  # as 0.19 stored it
    for alone in (EpisodeConfig(followers=2, controller=ControllerConfig("cacc"), v2v=ChannelParams(match_radar=False)),
                  EpisodeConfig(followers=2, start="steady", maneuver="cutin", controller=ControllerConfig("cacc"))):
        assert alone.v2v.match_radar and "match_radar" not in alone.to_dict()["v2v"]  # nothing comes between: one identity
        assert Platoon(alone, np.full(alone.steps, np.nan), 40.0)._match is False
    with pytest.raises(ConfigError) as info:
        ChannelParams(match_radar="yes")
    assert info.value.field == "v2v.match_radar"
