"""What the platoon's cars tell each other: V2V beacons over a channel, the [v2v] table. Pure code, no SUMO.

Every car of the platoon (the attacker v0 leads it) broadcasts a beacon of its state every
``beacon_interval_s``: who sent it, when, its position along the road, its speed, its acceleration
over the last step and its length. A follower receives the beacons of the platoon's leader and of the car
ahead of it in the platoon (the topology of Plexe's CACC and Ploeg's), or of every car ahead of it (a
consensus controller's, which sums over them), each ``latency_s`` after it was sent
(a whole number of steps), and loses each with probability ``loss``, drawn from a generator seeded by
the table's seed and the pair of cars: every episode of a configuration loses the same beacons, and a
replay loses them again. A cooperative controller reads the newest beacon of each (`Observation`).

The beacons are the truth the world sensed (`sensing` reads the same); what a car does with a lost or a
late one is its controller's. No [v2v] table: no messages, every earlier episode unchanged.
"""

from __future__ import annotations

import dataclasses
from collections import deque
from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ... import ledger
from ...errors import ConfigError, check_int, check_number, table_of


@dataclass(frozen=True)
class ChannelParams:
    """The V2V channel, the [v2v] table (see the module)."""

    beacon_interval_s: float = 0.1  # Plexe's default: ten beacons a second
    latency_s: float = 0.0  # from a beacon's sending to its delivery
    loss: float = 0.0  # the probability that a beacon is lost
    seed: int = 0  # the losses': every episode of the configuration loses the same beacons
    #: among traffic, a follower reads the beacons of the car ahead of it in the platoon only while its radar sees that
    #: car; where a traffic car cut in between them it falls back to its ACC, as CACC systems do
    #: (`sensing.Observation.matched`). False: it reads them whatever its radar sees, as d4sumo 0.19
    #: and before had it (`ledger`), for study
    match_radar: bool = True
    #: in a lane-changing maneuver (cut-in, cut-out, swerve) too, as d4sumo 0.20.0 had it: there the attacker leads
    #: the platoon's beacons from the next lane, so a follower behind the maneuver's other car fell back from the
    #: start (crashes without an attack). Never stored as a key: a campaign 0.20.0 ran so holds ``match_radar``
    #: without traffic (`config.EpisodeConfig.others_cut_in`)
    match_in_maneuvers: bool = False

    def __post_init__(self) -> None:
        fix = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731 (frozen dataclass)
        fix("beacon_interval_s", check_number("v2v.beacon_interval_s", self.beacon_interval_s, 0.0, 10.0, "seconds", low_open=True))
        fix("latency_s", check_number("v2v.latency_s", self.latency_s, 0.0, 5.0, "seconds"))
        fix("loss", check_number("v2v.loss", self.loss, 0.0, 1.0, "(a probability)"))
        fix("seed", check_int("v2v.seed", self.seed, 0, 2**32 - 1))
        for name in ("match_radar", "match_in_maneuvers"):
            if not isinstance(getattr(self, name), bool):
                raise ConfigError(f"v2v.{name}", getattr(self, name), "true or false")

    @classmethod
    def from_table(cls, table: Any) -> "ChannelParams":
        return table_of(cls, table, "v2v")

    def to_dict(self) -> dict:
        """As a definition stores it: every key (the channel is part of the system under test); ``match_radar``
        where it is not what campaigns stored before it was a key hold (`ledger`); ``match_in_maneuvers`` never (the
        episode's definition says it: `definition.stored`)."""
        return ledger.stored("v2v", {f.name: getattr(self, f.name) for f in dataclasses.fields(self) if f.name != "match_in_maneuvers"})

    @property
    def label(self) -> str:
        """In a few words: ``beacons 0.1 s, latency 0.2 s, loss 0.1``."""
        text = f"beacons {self.beacon_interval_s:g} s"
        if self.latency_s:
            text += f", latency {self.latency_s:g} s"
        if self.loss:
            text += f", loss {self.loss:g}"
        if not self.match_radar:
            text += ", beacons read whatever the radar sees"
        return text



@dataclass(slots=True)  # made for every car at every beacon: not frozen, whose construction costs thrice
class Message:
    """A beacon: who sent it (the car's index, 0 the attacker that leads the platoon), when [s], and its
    position along the road [m] (its front bumper's), speed [m/s], acceleration over its last step
    [m/s^2] and length [m] (as Plexe's beacons carry it)."""

    sender: int
    time_s: float
    position_m: float
    speed_mps: float
    accel_mps2: float
    length_m: float = 0.0


class Channel:
    """One episode's V2V channel: ``send(k, positions, speeds, accelerations)`` at each step's start, then
    ``inbox(i)``, the newest beacon follower ``i`` received from each of its sources (the platoon's leader
    and the car ahead of it; every car ahead for the followers in ``hear_all``). ``lengths``: each car's."""

    def __init__(self, params: ChannelParams, step_s: float, cars: int, falsify=None, lengths=None,
                 hear_all: frozenset[int] = frozenset()):
        self.params = params
        #: a message attack's falsifier of one car's beacons (`messages.BeaconFalsifier`: the attacker's, or an
        #: insider's), or None
        self.falsify = falsify
        self.liar = falsify.sender if falsify is not None else None
        self.step_s = step_s
        self.every = max(1, int(round(params.beacon_interval_s / step_s)))
        self.delay = int(round(params.latency_s / step_s))
        self.lengths = [float(x) for x in lengths] if lengths is not None else [0.0] * cars
        self.sources = {i: tuple(range(i)) if i in hear_all else tuple(dict.fromkeys((0, i - 1)))  # the leader, the car ahead
                        for i in range(1, cars)}
        self.senders = sorted({s for sources in self.sources.values() for s in sources})
        #: each link's losses (made only where beacons are lost: a generator costs as much as a hundred steps' beacons)
        self.rngs = ({(s, i): np.random.default_rng([params.seed, s, i]) for i, srcs in self.sources.items() for s in srcs}
                     if params.loss else {})
        self.in_flight: deque[tuple[int, int, Message]] = deque()  # (step delivered, receiver, beacon)
        self.newest: dict[int, dict[int, Message]] = {i: {} for i in self.sources}
        self.direct = not self.delay and not params.loss
        #: with no latency and no loss, each beacon straight into its receivers' inboxes: (sender, their inboxes)
        self._routes = [(s, [self.newest[i] for i, srcs in self.sources.items() if s in srcs]) for s in self.senders]
        self.sent: list[tuple[int, Message | None]] = []  # under a message attack: the liar's beacons as sent

    def send(self, k: int, positions, speeds, accelerations) -> None:
        """Step ``k``'s beacons (every ``beacon_interval_s``), and the deliveries due at it."""
        if k % self.every == 0:
            lengths, time_s = self.lengths, k * self.step_s
            if self.direct and self.falsify is None:  # no latency, no loss, no lie: every beacon arrives as it is sent
                for s, inboxes in self._routes:
                    beacon = Message(s, time_s, float(positions[s]), float(speeds[s]), float(accelerations[s]), lengths[s])
                    for inbox in inboxes:
                        inbox[s] = beacon
                return
            beacons = {s: Message(s, time_s, float(positions[s]), float(speeds[s]), float(accelerations[s]), lengths[s])
                       for s in self.senders}
            if self.falsify is not None:  # the liar's, as it chooses to send it (None: not at all)
                liar = self.liar
                beacons[liar] = self.falsify(k, beacons[liar])
                self.sent.append((k, beacons[liar]))
            if self.direct:
                for s, inboxes in self._routes:
                    if beacons[s] is not None:
                        for inbox in inboxes:
                            inbox[s] = beacons[s]
                return
            for i, sources in self.sources.items():
                for s in sources:
                    if self.params.loss and self.rngs[s, i].random() < self.params.loss:
                        continue
                    if beacons[s] is not None:
                        self.in_flight.append((k + self.delay, i, beacons[s]))
        while self.in_flight and self.in_flight[0][0] <= k:
            _, i, message = self.in_flight.popleft()
            self.newest[i][message.sender] = message

    def inbox(self, i: int) -> Mapping[int, Message]:
        return self.newest[i]
