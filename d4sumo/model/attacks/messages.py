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

Each kind is a class (`Lie`: its parameters, the beacon it sends), registered by name in `LIES`, as the
pedal families are in `attacks`: a new kind is a subclass and `register_lie`.
"""

from __future__ import annotations

import dataclasses
import math
import numpy as np

from ...errors import ConfigError
from .pedals import AttackFamily, Parameter, attack_signal, make_attack
from .maneuvers import EpisodeSettings, ManeuverAttack, maneuver_of
from ..world.v2v import Message

MESSAGE_FIELDS = ("accel", "speed", "position")
#: the [attack] keys of a message attack
MESSAGE_KEYS = ("message", "message_field", "message_sender")
#: how far an offset (or a sinusoid's amplitude) may move each field, in its units
FIELD_BOUNDS = {"accel": (8.0, "m/s^2"), "speed": (15.0, "m/s"), "position": (30.0, "m")}
_ATTRIBUTE = {"accel": "accel_mps2", "speed": "speed_mps", "position": "position_m"}


class Lie:
    """One kind of message attack (see the module): its parameters, and the beacon it sends at each step from
    its start on. A new kind is a subclass, registered in `LIES` under its ``name``."""

    name = ""

    def __init__(self, options: dict):
        self.options = options

    def parameters(self, field: str, window_s: float) -> tuple[Parameter, ...]:
        """Its own parameters, then its start, after the attack's start (within the attack's ``window_s``)."""
        return (*self.own(field, window_s), Parameter("msg_start_s", 0.0, float(window_s), "s"))

    def own(self, field: str, window_s: float) -> tuple[Parameter, ...]:
        return ()

    def accelerations(self, x, config: EpisodeSettings, sender: int) -> np.ndarray | None:
        """What it reports at each step, where it reports a signal of its own over the attack (`Knots`); else None."""
        return None

    def told(self, f: "BeaconFalsifier", k: int, message: Message) -> Message | None:
        """The beacon sent at step ``k`` for the sender's true one (None: none)."""
        return message if k < f.start else self.lie(f, k, message)

    def lie(self, f: "BeaconFalsifier", k: int, message: Message) -> Message | None:
        raise NotImplementedError


class _FieldLie(Lie):
    """A lie that rewrites the one field of each beacon from its true value."""

    def lie(self, f, k, message):
        name = f.attribute
        return dataclasses.replace(message, **{name: self.value(getattr(message, name), f.values)})

    def value(self, true: float, v: dict) -> float:
        raise NotImplementedError


class Offset(_FieldLie):
    name = "offset"

    def own(self, field, window_s):
        bound, unit = FIELD_BOUNDS[field]
        return (Parameter("msg_value", -bound, bound, unit),)

    def value(self, true, v):
        return true + v["msg_value"]


class Scaling(_FieldLie):
    name = "scaling"

    def own(self, field, window_s):
        return (Parameter("msg_factor", 0.0, 3.0),)

    def value(self, true, v):
        return true * v["msg_factor"]


class Sinusoid(Lie):
    name = "sinusoid"

    def own(self, field, window_s):
        bound, unit = FIELD_BOUNDS[field]
        return Parameter("msg_amplitude", 0.0, bound, unit), Parameter("msg_frequency_hz", 0.05, 1.0, "Hz")

    def lie(self, f, k, message):  # the time since its start, in whole steps as the episode counts them
        name, v = f.attribute, f.values
        lie = getattr(message, name) + v["msg_amplitude"] * math.sin(2.0 * math.pi * v["msg_frequency_hz"] * (k - f.start) * f.step_s)
        return dataclasses.replace(message, **{name: lie})


class _OldBeacon(Lie):
    """A lie that sends an earlier true beacon's position, speed and acceleration."""

    def lie(self, f, k, message):
        old = f.at(self.step_of(f, k))
        return dataclasses.replace(message, position_m=old.position_m, speed_mps=old.speed_mps, accel_mps2=old.accel_mps2)

    def step_of(self, f, k: int) -> int:
        raise NotImplementedError


class Delay(_OldBeacon):
    name = "delay"

    def own(self, field, window_s):
        return (Parameter("msg_delay_s", 0.0, 3.0, "s"),)

    def step_of(self, f, k):
        return k - int(round(f.values["msg_delay_s"] / f.step_s))


class Replay(_OldBeacon):
    name = "replay"

    def own(self, field, window_s):
        return (Parameter("msg_window_s", 0.5, 10.0, "s"),)

    def step_of(self, f, k):
        window = max(1, int(round(f.values["msg_window_s"] / f.step_s)))
        return f.start - window + (k - f.start) % window


class Jam(Lie):
    name = "jam"

    def own(self, field, window_s):
        return (Parameter("msg_duration_s", 0.0, float(window_s), "s"),)

    def lie(self, f, k, message):
        return None if k < f.start + int(round(f.values["msg_duration_s"] / f.step_s)) else message


class Knots(Lie):
    """The acceleration it reports, as knots over the attack (the knots family's, read as a pedal of the sender's
    vehicle); the truth outside the attack. It has no start of its own: its knots span the attack."""

    name = "knots"

    def __init__(self, options: dict):
        super().__init__(options)
        self.family = make_attack("knots", options)

    def parameters(self, field, window_s):
        return tuple(dataclasses.replace(p, name=f"msg_{p.name}") for p in self.family.parameters)

    def accelerations(self, x, config: EpisodeSettings, sender: int) -> np.ndarray:
        """What it reports at each step: NaN outside the attack (the truth)."""
        u = attack_signal(self.family, x, steps=config.steps, step_s=config.step_s, start_step=config.attack_start_step)
        v = config.vehicle_of(sender)
        return np.where(u >= 0.0, u * v.max_accel_mps2, u * v.max_decel_mps2)

    def told(self, f, k, message):
        a = f.accel[k] if k < len(f.accel) else math.nan
        return message if a != a else dataclasses.replace(message, accel_mps2=float(a))


#: the message attacks by name (`Lie`): `attack.message` names one, `register_lie` adds one
LIES: dict[str, type[Lie]] = {cls.name: cls for cls in (Offset, Scaling, Sinusoid, Delay, Replay, Jam, Knots)}
#: d4sumo's own message attacks, by name
MESSAGE_ATTACKS = tuple(LIES)


def register_lie(cls: type[Lie]) -> type[Lie]:
    """Make a message attack available under its ``name`` (a class decorator); names are never silently replaced."""
    if not cls.name or LIES.get(cls.name, cls) is not cls:
        raise ValueError(f"message attack {cls.name!r}: a name of its own (taken: {', '.join(LIES)})")
    LIES[cls.name] = cls
    return cls


def make_lie(kind: str, options: dict | None = None) -> Lie:
    if not isinstance(kind, str) or kind not in LIES:
        raise ConfigError("attack.message", kind, f"one of {', '.join(LIES)}")
    return LIES[kind](dict(options or {}))


class MessageAttack(ManeuverAttack):
    """The attacker's pedal family (and its maneuver's parameters) plus the parameters of its falsified
    beacons (see the module); its signal is the pedals'."""

    def __init__(self, box: AttackFamily, kind: str, field: str, window_s: float, options: dict, sender: int = 0):
        lie = make_lie(kind, options)
        if field not in MESSAGE_FIELDS:
            raise ConfigError("attack.message_field", field, f"one of {', '.join(MESSAGE_FIELDS)}")
        added = lie.parameters(field, window_s)
        super().__init__(box, added, (len(added),))
        self.box, self.kind, self.field, self.sender, self.lie = box, kind, field, sender, lie
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
        accel = self.lie.accelerations(x, config, self.sender)
        return BeaconFalsifier(self.kind, self.field, values, config.step_s, config.attack_start_step, accel, self.sender,
                               lie=self.lie)


class BeaconFalsifier:
    """One episode's lie: ``(step, the sender's true beacon)`` -> the beacon it sends (None: it sends
    none). It keeps the true beacons it was given, for the attacks that send old ones."""

    def __init__(self, kind: str, field: str, values: dict, step_s: float, attack_start_step: int,
                 accel: np.ndarray | None = None, sender: int = 0, lie: Lie | None = None):
        self.kind, self.attribute, self.values, self.step_s = kind, _ATTRIBUTE[field], values, step_s
        self.lie = lie if lie is not None else make_lie(kind)
        self.sender = sender  # the car whose beacons it rewrites: 0 the attacker, K an insider follower vK
        self.start = attack_start_step + int(round(values.get("msg_start_s", 0.0) / step_s))
        self.accel = accel
        self.true: dict[int, Message] = {}

    def at(self, k: int) -> Message:
        """The newest true beacon at or before step k (the first, before any)."""
        earlier = [j for j in self.true if j <= k]
        return self.true[max(earlier)] if earlier else self.true[min(self.true)]

    def __call__(self, k: int, message: Message) -> Message | None:
        self.true[k] = message
        return self.lie.told(self, k, message)


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
    make_lie(kind)  # one of the message attacks, or one line
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
