"""Attacks that lie over the air: the attacker's falsified V2V beacons. Pure code, no SUMO."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from d4sumo.errors import ConfigError
from d4sumo.model.attacks.pedals import make_attack
from d4sumo.model.config import ControllerConfig, EpisodeConfig
from d4sumo.model.attacks.maneuvers import attack_plan, inert_parameters
from d4sumo.model.attacks.messages import BeaconFalsifier, attack_box
from d4sumo.model.world.v2v import Message
from d4sumo.search.campaign import Campaign

STEP = 0.05
COOPERATIVE = EpisodeConfig(controller=ControllerConfig("cacc"), start="steady", duration_s=20.0)


def _truth(k: int) -> Message:
    return Message(0, k * STEP, 100.0 + k, 25.0 + 0.01 * k, 0.5)


def _lies(kind: str, field: str, values: dict, steps: int = 60, accel=None) -> list:
    f = BeaconFalsifier(kind, field, {"msg_start_s": 1.0, **values}, STEP, 0, accel)
    return [f(k, _truth(k)) for k in range(0, steps, 2)]  # a beacon every 0.1 s


def test_each_lie_tells_the_truth_before_its_start_then_rewrites_its_field():
    start = 10  # 1 s: the sixth beacon, step 20
    offset = _lies("offset", "speed", {"msg_value": -5.0})
    assert offset[:start] == [_truth(k) for k in range(0, 20, 2)]
    assert offset[start] == Message(0, 1.0, 120.0, 25.2 - 5.0, 0.5)
    assert _lies("scaling", "accel", {"msg_factor": 3.0})[start].accel_mps2 == 1.5
    sine = _lies("sinusoid", "position", {"msg_amplitude": 2.0, "msg_frequency_hz": 0.5})
    assert sine[start + 5].position_m == pytest.approx(130.0 + 2.0 * math.sin(2 * math.pi * 0.5 * 0.5))
    delayed = _lies("delay", "accel", {"msg_delay_s": 0.5})[start + 2]  # at step 24: the beacon of step 14
    assert (delayed.time_s, delayed.position_m, delayed.speed_mps) == (24 * STEP, 114.0, pytest.approx(25.14))
    replayed = _lies("replay", "speed", {"msg_window_s": 0.4})  # the 0.4 s before the start, again and again
    assert [m.position_m for m in replayed[start:start + 6]] == [112.0, 114.0, 116.0, 118.0, 112.0, 114.0]
    jammed = _lies("jam", "accel", {"msg_duration_s": 0.5})
    assert jammed[start:start + 5] == [None] * 5 and jammed[start + 5] == _truth(30)  # 0.5 s: five beacons


def test_the_knots_lie_reports_the_acceleration_of_its_knots_during_the_attack():
    accel = np.full(60, np.nan)
    accel[30:] = -8.0
    lies = _lies("knots", "accel", {}, accel=accel)
    assert lies[14] == _truth(28) and lies[15].accel_mps2 == -8.0 and lies[15].speed_mps == _truth(30).speed_mps


def test_a_message_attack_adds_its_parameters_after_the_pedals_and_plans_its_lie():
    box = attack_box(COOPERATIVE, make_attack("knots"), "offset", "speed")
    assert box.names[9:] == ("msg_value", "msg_start_s") and box.upper[9] == 15.0
    x = np.zeros(box.dimension)
    x[9], x[10] = -5.0, 2.0
    plan = attack_plan(box, x, COOPERATIVE)
    assert np.array_equal(plan.u, attack_plan(make_attack("knots"), x[:9], COOPERATIVE).u, equal_nan=True)
    assert plan.beacons(0, _truth(0)) == _truth(0) and plan.beacons(40, _truth(40)).speed_mps == _truth(40).speed_mps - 5.0
    assert 9 not in inert_parameters(box, COOPERATIVE) and 10 not in inert_parameters(box, COOPERATIVE)
    campaign = Campaign(config=COOPERATIVE, message="offset", message_field="speed", optimizer="random")
    stored = campaign.definition()
    assert stored["attack"]["message"] == "offset" and Campaign.from_definition(stored) == campaign
    assert "message" not in Campaign(config=COOPERATIVE).definition()["attack"]  # earlier campaigns keep their identity


def test_an_insider_lies_in_its_own_beacons_and_its_campaign_stores_who_it_is():
    box = attack_box(COOPERATIVE, make_attack("knots"), "offset", "speed", sender=2)
    x = np.zeros(box.dimension)
    x[9], x[10] = 4.0, 0.0
    plan = attack_plan(box, x, COOPERATIVE)
    assert plan.beacons.sender == 2 and box.describe()["message_sender"] == 2
    insider = Message(2, 2.0, 50.0, 25.0, 0.0)
    assert plan.beacons(40, insider).speed_mps == 29.0
    campaign = Campaign(config=COOPERATIVE, message="offset", message_field="speed", message_sender=2, optimizer="random")
    stored = campaign.definition()
    assert stored["attack"]["message_sender"] == 2 and Campaign.from_definition(stored) == campaign
    leader = Campaign(config=COOPERATIVE, message="offset", message_field="speed", optimizer="random").definition()
    assert "message_sender" not in leader["attack"]  # the attacker's lies keep their campaigns' identity


@pytest.mark.parametrize("sender, allowed", [
    (3, "an insider follower 1 .. 2"),  # v3 is the last: nobody reads its beacons
    (-1, "an insider follower 1 .. 2"),
    (True, "an insider follower 1 .. 2"),
])
def test_an_insider_that_nobody_hears_gets_one_line(sender, allowed):
    with pytest.raises(ConfigError) as info:
        attack_box(COOPERATIVE, make_attack("knots"), "offset", "speed", sender=sender)
    assert info.value.field == "attack.message_sender" and allowed in info.value.allowed


def test_an_insider_whose_follower_reads_no_beacons_gets_one_line():
    mixed = EpisodeConfig(controller=(ControllerConfig("cacc"), ControllerConfig("cacc"), ControllerConfig("switching")),
                          start="steady", duration_s=20.0)
    attack_box(mixed, make_attack("knots"), "offset", "speed", sender=1)
    with pytest.raises(ConfigError) as info:
        attack_box(mixed, make_attack("knots"), "offset", "speed", sender=2)
    assert info.value.field == "attack.message_sender" and "v3" in info.value.allowed


@pytest.mark.parametrize("config, message, field, where", [
    (EpisodeConfig(), "offset", "accel", "attack.message"),  # nobody listens: no beacons to falsify
    (COOPERATIVE, "spoof", "accel", "attack.message"),
    (COOPERATIVE, "offset", "heading", "attack.message_field"),
])
def test_a_message_attack_that_cannot_be_gets_one_line(config, message, field, where):
    with pytest.raises(ConfigError) as info:
        attack_box(config, make_attack("knots"), message, field)
    assert info.value.field == where


def test_a_message_attack_of_ones_own_is_a_class_registered_by_its_name():
    """Message attacks are classes with a registry, as pedal families are: a new one is a subclass of `Lie` and one
    registration; it then plays through the campaign's box like d4sumo's own."""
    from d4sumo.model.config import ControllerConfig, EpisodeConfig
    from d4sumo.model.attacks.messages import LIES, Lie, attack_box, register_lie
    from d4sumo.model.attacks.pedals import make_attack

    class Freeze(Lie):
        """From its start on, the first true beacon of the attack, again and again."""

        name = "freeze"

        def lie(self, f, k, message):
            return f.at(f.start)

    register_lie(Freeze)
    try:
        with pytest.raises(ValueError):
            register_lie(type("Other", (Lie,), {"name": "offset"}))  # a name is never silently replaced
        config = EpisodeConfig(controller=ControllerConfig("cacc"), start="steady")
        box = attack_box(config, make_attack("knots"), "freeze", "speed")
        assert box.names[-1] == "msg_start_s" and len(box.names) == 10
        falsify = box.falsifier([0.0] * 9 + [1.0], config)
        first = Message(0, 1.0, 10.0, 25.0, 0.0, 4.5)
        told = [falsify(k, dataclasses.replace(first, time_s=k * 0.05, speed_mps=25.0 + k)) for k in range(40)]
        start = config.attack_start_step + 20
        assert [m.speed_mps for m in told[:start]] == [25.0 + k for k in range(start)]
        assert all(m.speed_mps == 25.0 + start for m in told[start:])
    finally:
        del LIES["freeze"]
    with pytest.raises(ConfigError) as info:
        attack_box(config, make_attack("knots"), "freeze", "speed")
    assert info.value.field == "attack.message" and "offset" in info.value.allowed
