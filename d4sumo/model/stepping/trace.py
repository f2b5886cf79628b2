"""What an episode produces: a Trace (times and named signals) and the collisions SUMO reported.

Signals (N followers; cars v0 = attacker, v1 .. vN, and in a cut-in `lead`, in a cut-out `obstacle`):
    pos_X         front-bumper position along the road [m]
    speed_X       speed [m/s]
    accel_X       realised acceleration over the last step [m/s^2]
    cmd_X         throttle/brake command applied from this sample on [-1, 1]
    gap_X         bumper gap from car X to the car ahead of it in its lane, whoever that is [m]
                  (1000 m with nobody ahead; a car changing lanes covers both)
    victim_gap    the smallest gap between two cars neither of which is the attacker [m] (among traffic, at a
                  collision inside a junction, the 2D clearance of the two bodies: `engine.junctions`)
    attacker_gap  the smallest gap between the attacker and the car ahead of or behind it [m]
    mode_vI       follower controller mode (0 cruise, 1 ACC), I >= 1, when the controller has one
    light_X       on a route through traffic lights the platoon obeys: the next light car X sees within 300 m
                  (2 red, 1 amber, 0 green or none)
The paper's maneuver (`inlane`: the attacker leads the platoon in its lane) also has
    gap_I         bumper gap between vI and vI+1, I = 0..N-1 (gap_0: attacker to v1) [m]
and the lane-changing ones (`cutin`, `cutout`)
    y_X           lateral position of the car's centre from the road's right edge [m]
"""

from __future__ import annotations

from dataclasses import dataclass, field
from itertools import chain
from typing import Mapping

import numpy as np

OUTCOMES = ("success", "attacker_crash", "no_crash")


def rows_array(rows: list[list[float]], width: int) -> np.ndarray:
    """Rows of ``width`` floats each (one a sample or a step) as a (rows, width) array: np.array(rows), at
    half its cost (it does not look into each row for its shape), which every episode pays at its end."""
    return np.fromiter(chain.from_iterable(rows), dtype=float, count=len(rows) * width).reshape(len(rows), width)


@dataclass(frozen=True)
class Trace:
    times_s: np.ndarray
    signals: Mapping[str, np.ndarray]
    followers: int

    def __getitem__(self, name: str) -> np.ndarray:
        return self.signals[name]

    def __len__(self) -> int:
        return int(self.times_s.size)

    @property
    def names(self) -> tuple[str, ...]:
        return tuple(self.signals)

    def window(self, start: int) -> "Trace":
        """The trace from sample ``start`` on, its clock restarted at 0; at least its last two samples
        (rtamt needs two)."""
        start = min(start, len(self) - 2)
        if start <= 0:
            return self
        return Trace(self.times_s[start:] - self.times_s[start], {k: v[start:] for k, v in self.signals.items()},
                     self.followers)

    def gaps(self) -> np.ndarray:
        """Bumper gaps, shape (samples, N): column i is gap_i."""
        return np.column_stack([self.signals[f"gap_{i}"] for i in range(self.followers)])


@dataclass(frozen=True)
class Collision:
    """A collision: ``follower`` ran into ``leader`` (the car just ahead of it in a lane; in a cut-in, the
    attacker may also land on a car beside it, the one ahead counting as the leader)."""

    leader: str
    follower: str
    time_s: float
    position_m: float  # along the road: the follower's front bumper
    speed_diff_kmh: float  # follower speed minus leader speed at the collision

    @property
    def pair(self) -> str:
        return f"{self.leader}-{self.follower}"

    @property
    def involves_attacker(self) -> bool:
        return "v0" in (self.leader, self.follower)

    def to_dict(self) -> dict:
        # Full precision (the time only loses the step count's float noise): what is stored must
        # agree with the trace exactly, and printing rounds anyway.
        return {"pair": self.pair, "time_s": round(self.time_s, 9), "position_m": self.position_m,
                "speed_diff_kmh": self.speed_diff_kmh}


@dataclass(frozen=True)
class Episode:
    """One simulated episode; it ends at the first collision (later data are not physical)."""

    trace: Trace
    collisions: tuple[Collision, ...] = field(default=())
    #: the minimum gap of every pair of cars that followed each other in a lane ("v1-v2": metres), from the
    #: attack's start: the window the specification scores and the outcome counts
    min_gaps: Mapping[str, float] | None = None
    #: the same during a warm-up before the attack (None without one)
    warmup_min_gaps: Mapping[str, float] | None = None
    #: among traffic, the collisions of two traffic cars SUMO reported during the episode, as (time [s],
    #: the car that ran into the other, that car): none of the platoon's, and in no verdict
    traffic_collisions: tuple[tuple[float, str, str], ...] = ()
    #: in a replay that wrote its FCD on a route through traffic lights: each signal's stop line along the route [m],
    #: its light's id and its state at each step's start (SUMO's link state letters, one a step), for the figures
    signals: tuple[tuple[float, str, str], ...] = ()

    @property
    def first_collision(self) -> Collision | None:
        return self.collisions[0] if self.collisions else None

    def first_collision_record(self) -> dict | None:
        """The first collision as a sample stores it (pair, time, position, speed difference), or None."""
        return self.collisions[0].to_dict() if self.collisions else None

    @property
    def outcome(self) -> str:
        """success: followers collided and the attacker is untouched; attacker_crash; no_crash."""
        if not self.collisions:
            return "no_crash"
        if any(c.involves_attacker for c in self.collisions):
            return "attacker_crash"
        return "success"

    def min_gaps_with_warmup_m(self) -> dict[str, float]:
        """The minimum gaps over the whole episode, a warm-up included: what d4sumo 0.11 and before stored."""
        gaps = self.min_gaps_m()
        for pair, gap in (self.warmup_min_gaps or {}).items():
            gaps[pair] = min(gaps.get(pair, gap), gap)
        return gaps

    def min_gaps_m(self) -> dict[str, float]:
        if self.min_gaps is not None:
            return dict(self.min_gaps)
        gaps = self.trace.gaps()
        return {f"v{i}-v{i + 1}": float(gaps[:, i].min()) for i in range(self.trace.followers)}
