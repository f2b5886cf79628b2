"""Cars as rectangles (`bodies`): the signed clearance of two bodies and which one ran into the other."""

from __future__ import annotations

import math

import pytest

from d4sumo.model.world.bodies import Body, body_gap_m, struck_by


def car(x, y, angle, length=4.5, width=1.8):
    return Body(x, y, angle, length, width)


def test_two_cars_one_behind_the_other_are_as_far_apart_as_their_bumpers():
    east = 90.0  # SUMO's angle: clockwise from north
    assert body_gap_m(car(10.0, 0.0, east), car(20.0, 0.0, east)) == pytest.approx(20.0 - 4.5 - 10.0)
    assert body_gap_m(car(20.0, 0.0, east), car(10.0, 0.0, east)) == pytest.approx(5.5)


def test_an_overlap_is_negative_by_the_least_depth_to_part_them():
    east = 90.0
    # 0.3 m into the rear bumper of the car ahead
    assert body_gap_m(car(15.8, 0.0, east), car(20.0, 0.0, east)) == pytest.approx(-0.3)
    # side by side, 0.25 m into each other across
    assert body_gap_m(car(10.0, 0.0, east), car(10.0, 1.55, east)) == pytest.approx(-0.25)


def test_a_car_crossing_in_front_is_measured_at_its_side():
    # one heading north whose front is 0.5 m short of the side of one heading east across its way
    north, east = 0.0, 90.0
    crossing = car(12.0, 0.0, east)  # body from x 7.5 to 12, y -0.9 to 0.9
    assert body_gap_m(car(10.0, -1.4, north), crossing) == pytest.approx(0.5)
    assert body_gap_m(car(10.0, -0.6, north), crossing) == pytest.approx(-0.3)  # its front 0.3 m into the side


def test_corners_apart_on_a_diagonal_are_their_euclidean_distance():
    # two axis-aligned cars whose nearest corners are 3 m and 4 m apart: 5 m
    a = car(0.0, 0.0, 90.0)  # x -4.5..0, y -0.9..0.9
    b = car(3.0 + 4.5, 0.9 + 4.0 + 0.9, 90.0)  # x 3..7.5, y 4.9..6.7
    assert body_gap_m(a, b) == pytest.approx(5.0)
    assert body_gap_m(b, a) == pytest.approx(5.0)


def test_touching_is_no_overlap():
    east = 90.0
    assert body_gap_m(car(15.5, 0.0, east), car(20.0, 0.0, east)) == pytest.approx(0.0, abs=1e-12)
    assert not body_gap_m(car(15.5, 0.0, east), car(20.0, 0.0, east)) < -1e-12


def test_a_turned_car_is_turned():
    # a car heading north-east, its front at the origin: its rear corner lies back along the heading
    c = car(0.0, 0.0, 45.0, length=4.0, width=2.0)
    rear_centre = ((c.corners()[2][0] + c.corners()[3][0]) / 2, (c.corners()[2][1] + c.corners()[3][1]) / 2)
    assert rear_centre == pytest.approx((-4.0 / math.sqrt(2), -4.0 / math.sqrt(2)))
    # a body on itself parts least across: its width
    assert body_gap_m(c, car(0.0, 0.0, 45.0, length=4.0, width=2.0)) == pytest.approx(-2.0)


def test_the_car_whose_front_is_in_the_others_side_ran_into_it():
    north, east = 0.0, 90.0
    striking, struck = car(10.0, -0.6, north), car(12.0, 0.0, east)
    assert struck_by(striking, struck) == 0
    assert struck_by(struck, striking) == 1
    # rear-ending: the follower's front is at the leader's rear
    assert struck_by(car(20.0, 0.0, east), car(15.8, 0.0, east)) == 1
