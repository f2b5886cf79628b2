"""Attacks that lie over the air: falsified V2V beacons (`v2v`). Pure code, no SUMO.

Every car of a cooperative platoon broadcasts beacons of its state (`v2v.Channel`). A message attack
rewrites those of one car, ``attack.message_sender``: the attacker that leads the platoon (0, the
default; every follower reads its beacons), or an insider, a follower vK that drives as its controller
says but lies to the car behind it (which reads its beacons as the car ahead's). It rewrites them from a
searched time after the attack's start on, in the field it names (``attack.message_field``: accel, speed
or position; a beacon's time is always the true one):

    offset    field + c                                  msg_value, msg_start_s
    scaling   field x s                                  msg_factor, msg_start_s
    sinusoid  field + A sin(2 pi f (t - start))          msg_amplitude, msg_frequency_hz, msg_start_s
    delay     every field as it was d seconds before     msg_delay_s, msg_start_s
    replay    the beacons of the w seconds before the start, sent again in a loop
                                                         msg_window_s, msg_start_s
    jam       no beacon for w seconds                    msg_duration_s, msg_start_s
    knots     the acceleration it reports, as knots over the attack (the knots family's, read as a pedal:
              -1 full brake, 1 full throttle of the sender's vehicle)  msg_m0 ..

The parameters follow the attacker's pedal family's in the campaign's box (`MessageAttack`): the
optimiser searches the lie and the driving together, one cyber-physical attack. The followers' verdicts
read the truth; only what they are told is false.
"""

from __future__ import annotations

import dataclasses
import math
import numpy as np

from ..errors import ConfigError
from .attacks import AttackFamily, Parameter, attack_signal, make_attack
from .maneuvers import EpisodeSettings, ManeuverAttack, maneuver_of
from .v2v import Message

MESSAGE_ATTACKS = ("offset", "scaling", "sinusoid", "delay", "replay", "jam", "knots")
MESSAGE_FIELDS = ("accel", "speed", "position")
#: the [attack] keys of a message attack
MESSAGE_KEYS = ("message", "message_field", "message_sender")
#: how far an offset (or a sinusoid's amplitude) may move each field, in its units
FIELD_BOUNDS = {"accel": (8.0, "m/s^2"), "speed": (15.0, "m/s"), "position": (30.0, "m")}
_ATTRIBUTE = {"accel": "accel_mps2", "speed": "speed_mps", "position": "position_m"}


class MessageAttack(ManeuverAttack):
    """The attacker's pedal family (and its maneuver's parameters) plus the parameters of its falsified
    beacons (see the module); its signal is the pedals'."""

    def __init__(self, box: AttackFamily, kind: str, field: str, window_s: float, options: dict, sender: int = 0):
        if kind not in MESSAGE_ATTACKS:
            raise ConfigError("attack.message", kind, f"one of {', '.join(MESSAGE_ATTACKS)}")
        if field not in MESSAGE_FIELDS:
            raise ConfigError("attack.message_field", field, f"one of {', '.join(MESSAGE_FIELDS)}")
        bound, unit = FIELD_BOUNDS[field]
        start = Parameter("msg_start_s", 0.0, float(window_s), "s")
        self.knots = make_attack("knots", options) if kind == "knots" else None
        added = {
            "offset": (Parameter("msg_value", -bound, bound, unit), start),
            "scaling": (Parameter("msg_factor", 0.0, 3.0), start),
            "sinusoid": (Parameter("msg_amplitude", 0.0, bound, unit), Parameter("msg_frequency_hz", 0.05, 1.0, "Hz"), start),
            "delay": (Parameter("msg_delay_s", 0.0, 3.0, "s"), start),
            "replay": (Parameter("msg_window_s", 0.5, 10.0, "s"), start),
            "jam": (Parameter("msg_duration_s", 0.0, float(window_s), "s"), start),
            "knots": tuple(dataclasses.replace(p, name=f"msg_{p.name}") for p in (self.knots.parameters if self.knots else ())),
        }[kind]
        super().__init__(box, added, (len(added),))
        self.box, self.kind, self.field, self.sender = box, kind, field, sender
        self.message_first = self._first_added  # the parameters of the lie start here

    def describe(self) -> dict:
        d = super().describe()
        d.update(message=self.kind, message_field=self.field)
        if self.sender:
            d.update(message_sender=self.sender)
        return d

    def pedal_params(self, params) -> np.ndarray:
        return self.check(params)[:self._first_added]

    def falsifier(self, params, config: EpisodeSettings) -> "BeaconFalsifier":
        x = self.check(params)[self._first_added:]
        values = dict(zip((p.name for p in self.parameters[self._first_added:]), x))
        accel = None
        if self.kind == "knots":
            u = attack_signal(self.knots, x, steps=config.steps, step_s=config.step_s, start_step=config.attack_start_step)
            v = config.vehicle_of(self.sender)
            accel = np.where(u >= 0.0, u * v.max_accel_mps2, u * v.max_decel_mps2)  # NaN outside the attack: the truth
        return BeaconFalsifier(self.kind, self.field, values, config.step_s, config.attack_start_step, accel, self.sender)


class BeaconFalsifier:
    """One episode's lie: ``(step, the sender's true beacon)`` -> the beacon it sends (None: it sends
    none). It keeps the true beacons it was given, for the attacks that send old ones."""

    def __init__(self, kind: str, field: str, values: dict, step_s: float, attack_start_step: int,
                 accel: np.ndarray | None = None, sender: int = 0):
        self.kind, self.attribute, self.values, self.step_s = kind, _ATTRIBUTE[field], values, step_s
        self.sender = sender  # the car whose beacons it rewrites: 0 the attacker, K an insider follower vK
        self.start = attack_start_step + int(round(values.get("msg_start_s", 0.0) / step_s))
        self.accel = accel
        self.true: dict[int, Message] = {}

    def _at(self, k: int) -> Message:
        """The newest true beacon at or before step k (the first, before any)."""
        earlier = [j for j in self.true if j <= k]
        return self.true[max(earlier)] if earlier else self.true[min(self.true)]

    def __call__(self, k: int, message: Message) -> Message | None:
        self.true[k] = message
        if self.kind == "knots":
            a = self.accel[k] if k < len(self.accel) else math.nan
            return message if a != a else dataclasses.replace(message, accel_mps2=float(a))
        if k < self.start:
            return message
        v, name = self.values, self.attribute
        if self.kind == "jam":
            return None if k < self.start + int(round(v["msg_duration_s"] / self.step_s)) else message
        if self.kind in ("delay", "replay"):
            if self.kind == "delay":
                old = self._at(k - int(round(v["msg_delay_s"] / self.step_s)))
            else:
                window = max(1, int(round(v["msg_window_s"] / self.step_s)))
                old = self._at(self.start - window + (k - self.start) % window)
            return dataclasses.replace(message, position_m=old.position_m, speed_mps=old.speed_mps, accel_mps2=old.accel_mps2)
        true = getattr(message, name)
        if self.kind == "offset":
            lie = true + v["msg_value"]
        elif self.kind == "scaling":
            lie = true * v["msg_factor"]
        else:  # sinusoid
            lie = true + v["msg_amplitude"] * math.sin(2.0 * math.pi * v["msg_frequency_hz"] * (k - self.start) * self.step_s)
        return dataclasses.replace(message, **{name: lie})


def lie_label(message: str, field: str, sender: int = 0) -> str:
    """A message attack in a few words: ``a lie (offset on its speed)``, ``a lie (offset on insider v2's speed)``."""
    whose = f"insider v{sender}'s" if sender else "its"
    if message == "jam":  # no beacon at all: no field of one
        return f"a lie (jam of {whose} beacons)"
    return f"a lie ({message} on {whose} {field})"


def attack_box(config, longitudinal: AttackFamily, message: str = "", field: str = "accel",
               options: dict | None = None, sender: int = 0) -> AttackFamily:
    """An episode's attack box: the pedal family, with what its maneuver adds (`maneuvers`), and with a
    message attack on the beacons of car ``sender`` (0 the attacker, K an insider follower vK) where
    ``message`` names one; that is refused where there are no beacons (a platoon that exchanges none),
    where nobody reads the sender's, or where the attacker changes lanes (this version)."""
    box = maneuver_of(config).family(longitudinal)
    if not message:
        if not box.dimension:
            raise ConfigError("attack.family", longitudinal.name, "with a message attack (attack.message): alone, the "
                                                                  "attacker only cruises, which is no attack")
        return box
    kind = message
    if not isinstance(kind, str) or kind not in MESSAGE_ATTACKS:
        raise ConfigError("attack.message", kind, f"one of {', '.join(MESSAGE_ATTACKS)}")
    if config.v2v is None:
        raise ConfigError("attack.message", kind, "a platoon that exchanges V2V beacons (a follower whose controller "
                                                  "reads them: cacc, ploeg, consensus, or sumo:CC with a cooperative active_controller)")
    if config.maneuver_class.lateral:
        raise ConfigError("attack.message", kind, "the in-lane attacker (scenario.maneuver inlane)")
    if isinstance(sender, bool) or not isinstance(sender, int) or not 0 <= sender < config.followers:
        raise ConfigError("attack.message_sender", sender, f"0 (the attacker) or an insider follower 1 .. {config.followers - 1} "
                                                           "(a car with a follower behind it)")
    if sender and config.listening(sender + 1) is False:
        raise ConfigError("attack.message_sender", sender, f"a follower whose follower v{sender + 1} reads its beacons "
                                                           f"(v{sender + 1}'s controller reads none)")
    return MessageAttack(box, kind, field, config.duration_s, dict(options or {}), sender)
