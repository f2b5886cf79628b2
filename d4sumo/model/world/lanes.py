"""Who is in which lane: the lanes a car covers from where its centre is, and the pairs (leader, follower,
bumper gap) of cars next to each other in each lane, with the one arithmetic every follower's leader, every
collision and every gap of a trace come from (`maneuvers`, and `engine.neighbours` among traffic). Pure code.
"""

from __future__ import annotations

import math
from typing import Sequence

#: the gap a car with nobody ahead in its lane sees [m]: beyond any ACC's range, and finite for rtamt
FREE_ROAD_GAP_M = 1000.0
#: car width [m] (SUMO's passenger car): how much of a lane a car changing lanes covers
CAR_WIDTH_M = 1.8
#: a car occupies a lane when it overlaps it by more than this [m]: a body exactly on the line does not
LANE_TOLERANCE_M = 1e-6

Pair = tuple[int, int, float]  # (leader index, follower index, bumper gap [m])


def occupied_lanes(y_m: float, lane_width_m: float) -> tuple[int, ...]:
    """The lanes a car whose centre is ``y_m`` from the road's right edge covers."""
    half = CAR_WIDTH_M / 2.0
    left, right = y_m + half, y_m - half  # the body's edges
    low = max(0, math.floor(right / lane_width_m))
    high = math.floor(left / lane_width_m)
    if low == high:  # within one lane (nearly every car, nearly always): the overlap is the body's width or the lane's
        top, bottom = (low + 1) * lane_width_m, low * lane_width_m
        return (low,) if (top if top < left else left) - (bottom if bottom > right else right) > LANE_TOLERANCE_M else ()
    # min(a, b) is b < a and b or a, max(a, b) b > a and b or a: the same floats, without a call each
    return tuple(j for j in range(low, high + 1)
                 if (((j + 1) * lane_width_m if (j + 1) * lane_width_m < left else left)
                     - (j * lane_width_m if j * lane_width_m > right else right)) > LANE_TOLERANCE_M)


def lane_pairs(positions: Sequence[float], lanes: Sequence[tuple[int, ...]], lengths_m: Sequence[float],
               apart: int | None = None) -> list[Pair]:
    """(leader, follower, gap) of the cars next to each other in each lane they cover, frontmost first;
    ``apart``: cars from this index on are others' (traffic), and a pair of two of them is left out."""
    by_lane: dict[int, list[int]] = {}
    for i, covered in enumerate(lanes):
        for lane in covered:
            by_lane.setdefault(lane, []).append(i)
    found = set()
    for cars in by_lane.values():
        cars.sort(key=lambda i: (-positions[i], i))
        found.update(zip(cars, cars[1:]))
    if apart is not None:
        found = {(a, b) for a, b in found if a < apart or b < apart}
    return sorted(((a, b, positions[a] - lengths_m[a] - positions[b]) for a, b in found), key=lambda p: (-positions[p[1]], p))
