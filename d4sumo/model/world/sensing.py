"""What a follower senses of the car ahead: its radar, and the observation a controller may ask for.

Pure code, no SUMO. The world senses the truth (who is ahead in the follower's lane, the bumper gap, its
speed: `maneuvers`); the follower's `Radar` turns it into what the car's controller gets, as an ACC's
radar does:
- a range: a car ahead beyond it is not seen (a free road: `lanes.FREE_ROAD_GAP_M`, and the car's
  own speed for the speed ahead, as with nobody ahead);
- noise: Gaussian, on the gap and on the speed of the car ahead, drawn from a generator seeded by the
  [radar] table's seed and the car: the same sequence of draws in every episode of a configuration, one
  pair for each reading of a car in range (the noise at a step depends on how many readings came before), so
  a replay reproduces it;
- latency: the controller gets the reading of ``latency_s`` ago (a whole number of steps; the first
  reading until there is one that old); its own speed it knows at once.

The perfect radar (no [radar] table) is the world's truth: nothing is wrapped, every earlier episode is
bit for bit what it was. The verdicts (gaps, collisions, the specification) always read the truth.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from collections import deque
from dataclasses import dataclass
from typing import Any, Callable, NamedTuple

import numpy as np

from ...errors import check_int, check_number, table_of
from .lanes import FREE_ROAD_GAP_M


@dataclass(frozen=True)
class RadarParams:
    """A follower's radar, the [radar] table: its range, its noise and its latency (see the module)."""

    range_m: float = math.inf  # a car ahead farther than this is not seen
    gap_noise_m: float = 0.0  # standard deviation of the noise on the gap
    speed_noise_mps: float = 0.0  # standard deviation of the noise on the speed of the car ahead
    latency_s: float = 0.0  # how old the reading the controller gets is
    seed: int = 0  # the noise's: every episode of the configuration meets the same

    def __post_init__(self) -> None:
        fix = lambda name, value: object.__setattr__(self, name, value)  # noqa: E731 (frozen dataclass)
        if self.range_m != math.inf:  # unlimited, the default (TOML writes it inf)
            fix("range_m", check_number("radar.range_m", self.range_m, 0.0, 1e4, "metres, or inf (unlimited)", low_open=True))
        fix("gap_noise_m", check_number("radar.gap_noise_m", self.gap_noise_m, 0.0, 50.0, "metres (a standard deviation)"))
        fix("speed_noise_mps", check_number("radar.speed_noise_mps", self.speed_noise_mps, 0.0, 20.0,
                                            "m/s (a standard deviation)"))
        fix("latency_s", check_number("radar.latency_s", self.latency_s, 0.0, 5.0, "seconds"))
        fix("seed", check_int("radar.seed", self.seed, 0, 2**32 - 1))

    @classmethod
    def from_table(cls, table: Any) -> "RadarParams":
        return table_of(cls, table, "radar")

    def to_dict(self) -> dict:
        """As a definition stores it: what differs from the perfect radar (an infinite range is no number TOML has)."""
        defaults = RadarParams()
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)
                if getattr(self, f.name) != getattr(defaults, f.name)}

    @property
    def label(self) -> str:
        """What differs from the perfect radar, in a few words: ``gap_noise_m=0.5, latency_s=0.2``."""
        return ", ".join(f"{k}={v:g}" for k, v in self.to_dict().items())

    @property
    def perfect(self) -> bool:
        """Whether it senses the truth: no range, no noise, no latency."""
        return self.range_m == math.inf and not self.gap_noise_m and not self.speed_noise_mps and not self.latency_s


class Observation(NamedTuple):
    """What a follower's controller knows at a step, the one thing every controller is given (`observe`), a
    read-only value: its own speed (and its acceleration over its last step), what its radar measures of the
    car ahead in its lane (``leader``: whether there is one in range; without, the gap is a free road's and
    the speed ahead the car's own), and, in a platoon that exchanges V2V beacons (`v2v`), the newest beacon it
    received from the platoon's leader and from the car ahead of it in the platoon (None until one has
    arrived; for v1 both are the leader's), every newest beacon it received by sender (``messages``, a
    read-only mapping), and where and when it is (its GPS: ``position_m`` along the road, its front
    bumper's, and ``time_s``, the step's start), which a controller that places itself among the beacons'
    positions reads. ``matched``: whether the car its radar sees is the one whose beacons ``front_message``
    holds. It is not where another car is between them (a traffic car that cut in, a maneuver's car): a
    cooperative controller then follows what its radar sees with its ACC, as CACC systems do
    (`v2v.ChannelParams.match_radar`)."""

    speed_mps: float
    gap_m: float
    lead_speed_mps: float
    leader: bool
    accel_mps2: float = 0.0
    leader_message: Any = None
    front_message: Any = None
    messages: Any = None
    position_m: float = 0.0
    time_s: float = 0.0
    matched: bool = True

    @property
    def relative_speed_mps(self) -> float:
        """The speed of the car ahead relative to its own (negative: closing in), as a radar measures it."""
        return self.lead_speed_mps - self.speed_mps


#: an Observation made from its every field, as the step loop makes one for every follower at every step:
#: a third of the cost of calling the class
_made = functools.partial(tuple.__new__, Observation)


class Radar:
    """One follower's radar in one episode: ``observe(gap, own speed, speed ahead)`` (the truth) -> the
    `Observation` its controller gets."""

    def __init__(self, params: RadarParams, step_s: float, car: int):
        self.params = params
        self.rng = np.random.default_rng([params.seed, car])
        delay = int(round(params.latency_s / step_s))
        self.readings: deque[tuple[float, float, bool]] = deque(maxlen=delay + 1)

    def observe(self, gap_m: float, speed_mps: float, lead_speed_mps: float) -> Observation:
        p = self.params
        if gap_m > p.range_m or gap_m >= FREE_ROAD_GAP_M:  # nobody ahead within its range
            reading = (FREE_ROAD_GAP_M, speed_mps, False)
        else:
            if p.gap_noise_m:
                gap_m += float(self.rng.normal(0.0, p.gap_noise_m))
            if p.speed_noise_mps:
                lead_speed_mps += float(self.rng.normal(0.0, p.speed_noise_mps))
            reading = (gap_m, lead_speed_mps, True)
        self.readings.append(reading)
        gap, lead, seen = self.readings[0]  # the oldest kept: latency_s ago, or the first
        return _made((speed_mps, gap, lead if seen else speed_mps, seen, 0.0, None, None, None, 0.0, 0.0, True))


def sensed_command(observe: Callable[[Observation], float], params: RadarParams | None, step_s: float, car: int,
                   beacons: bool = False) -> Callable[..., float]:
    """A follower's command from the truth (gap, own speed, speed ahead): the `Observation` its controller's
    ``observe`` is given, through its radar where it is not the perfect one. With ``beacons`` (a platoon that
    exchanges V2V beacons) it also takes the car's own acceleration, its inbox (a read-only view of
    `v2v.Channel.inbox`), its position, the time and whether its radar sees the car
    ahead of it in the platoon (`Observation.matched`)."""
    radar = Radar(params, step_s, car) if params is not None and not params.perfect else None
    if beacons:
        front = car - 1

        def listening(gap: float, own: float, lead: float, accel: float, inbox, position: float, time: float,
                      matched: bool = True) -> float:
            if radar is not None:
                o = radar.observe(gap, own, lead)
                gap, lead, seen = o.gap_m, o.lead_speed_mps, o.leader
            else:
                seen = gap < FREE_ROAD_GAP_M
            return observe(_made((own, gap, lead, seen, accel, inbox.get(0), inbox.get(front), inbox, position, time, matched)))

        return listening
    if radar is None:
        return lambda gap, own, lead: observe(_made((own, gap, lead, gap < FREE_ROAD_GAP_M, 0.0, None, None, None, 0.0,
                                                     0.0, True)))
    return lambda gap, own, lead: observe(radar.observe(gap, own, lead))
