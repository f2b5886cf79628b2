"""Cars as rectangles in the plane, for collisions no lane sees: a car crossing, merging or turning
inside a junction meets the platoon on another lane than its own. Pure code, no SUMO.

A body is what SUMO's FCD says of a car: its front bumper's centre (x, y) [m], its heading (SUMO's
angle: degrees clockwise from north), its length and width [m]; the rectangle reaches ``length``
back from the front bumper along the heading, ``width / 2`` to each side. `body_gap_m` is the signed
clearance of two bodies: the distance between them where they are apart, minus the depth of their
overlap where they overlap (the least distance one must move for them to part). A collision is a
clearance below the collision gap (`EpisodeConfig.collision_gap_m`; 0: any overlap), as a bumper gap
is on a lane.
"""

from __future__ import annotations

import math
from typing import NamedTuple


class Body(NamedTuple):
    x_m: float  # front bumper's centre
    y_m: float
    angle_deg: float  # SUMO's: clockwise from north
    length_m: float
    width_m: float

    def corners(self) -> tuple[tuple[float, float], ...]:
        """Front left, front right, rear right, rear left."""
        a = math.radians(self.angle_deg)
        hx, hy = math.sin(a), math.cos(a)  # heading
        lx, ly = -hy, hx  # to the left of it
        w, L = self.width_m / 2.0, self.length_m
        fx, fy, rx, ry = self.x_m, self.y_m, self.x_m - hx * L, self.y_m - hy * L
        return ((fx + lx * w, fy + ly * w), (fx - lx * w, fy - ly * w), (rx - lx * w, ry - ly * w), (rx + lx * w, ry + ly * w))


def _axes(corners) -> list[tuple[float, float]]:
    (ax, ay), (bx, by), (cx, cy) = corners[:3]
    out = []
    for ux, uy in ((bx - ax, by - ay), (cx - bx, cy - by)):
        norm = math.hypot(ux, uy)
        out.append((ux / norm, uy / norm) if norm > 0 else (1.0, 0.0))
    return out


def _segment_distance(px: float, py: float, a, b) -> float:
    dx, dy = b[0] - a[0], b[1] - a[1]
    span = dx * dx + dy * dy
    t = 0.0 if span == 0 else max(0.0, min(1.0, ((px - a[0]) * dx + (py - a[1]) * dy) / span))
    return math.hypot(px - a[0] - t * dx, py - a[1] - t * dy)


def _outside_distance(points, corners) -> float:
    """The least distance from any of ``points`` to the outline ``corners`` (of a convex polygon)."""
    edges = list(zip(corners, corners[1:] + corners[:1]))
    return min(_segment_distance(px, py, a, b) for px, py in points for a, b in edges)


def body_gap_m(first: Body, second: Body) -> float:
    """The signed clearance of two bodies [m]: > 0 apart (their distance), < 0 overlapping (minus the
    depth of the overlap along the axis where it is least: separating axis theorem), 0 touching."""
    p, q = first.corners(), second.corners()
    depth = math.inf
    for ux, uy in _axes(p) + _axes(q):
        a = [x * ux + y * uy for x, y in p]
        b = [x * ux + y * uy for x, y in q]
        overlap = min(max(a), max(b)) - max(min(a), min(b))
        if overlap <= 0.0:  # a separating axis: apart (or touching)
            return min(_outside_distance(p, q), _outside_distance(q, p))
        depth = min(depth, overlap)
    return -depth


def _inside_or_distance(x: float, y: float, body: Body) -> float:
    """How far the point is from the body (0 inside it)."""
    c = body.corners()
    a = math.radians(body.angle_deg)
    hx, hy = math.sin(a), math.cos(a)
    along = (x - body.x_m) * hx + (y - body.y_m) * hy  # 0 at the front bumper, -length at the rear
    across = (x - body.x_m) * -hy + (y - body.y_m) * hx
    if -body.length_m <= along <= 0.0 and abs(across) <= body.width_m / 2.0:
        return 0.0
    return _outside_distance([(x, y)], c)


def struck_by(first: Body, second: Body) -> int:
    """Which of two touching bodies ran into the other: 0 the first, 1 the second. It is the one whose front
    bumper is nearer the other's body (in a crossing, the one that hit the other's side); a tie: the first."""
    d_first = _inside_or_distance(first.x_m, first.y_m, second)
    d_second = _inside_or_distance(second.x_m, second.y_m, first)
    return 1 if d_second < d_first else 0
