"""Leg paths: exact arcs, continuity, the bearings2d manoeuvre and the radar2d legs."""

import numpy as np
import pytest

from tma.errors import ConfigError
from tma.families.bearings2d.scenario import Config, epochs, observer_path
from tma.maths.path import LegPath


def test_default_path_timing_and_courses():
    path = observer_path(Config())
    assert path.duration_s == pytest.approx(1200.0, abs=1e-9)
    starts = [s.t0_s for s in path.segments]
    np.testing.assert_allclose(starts, [0, 180, 360, 660, 1020], atol=1e-9)
    courses = np.rad2deg(path.course(np.array([100.0, 500.0, 1100.0, 840.0])))
    np.testing.assert_allclose(courses % 360, [0.0, 270.0, 90.0, 0.0], atol=1e-9)
    assert epochs(Config(), path).size == 601


def test_arcs_are_exact_circles_of_radius_573m():
    path = observer_path(Config())
    expected_radius = 5.0 / np.deg2rad(0.5)
    assert expected_radius == pytest.approx(572.9578, abs=1e-4)
    for seg in path.segments:
        if seg.rate_rad_s == 0:
            continue
        t = seg.t0_s + np.linspace(0, seg.duration_s, 101)
        x, y = path.position(t)
        # centre lies a radius to the side of the start point, perpendicular to the course
        side = np.sign(seg.rate_rad_s)
        cx = seg.x0_m + side * expected_radius * np.cos(seg.course0_rad)
        cy = seg.y0_m - side * expected_radius * np.sin(seg.course0_rad)
        np.testing.assert_allclose(np.hypot(x - cx, y - cy), expected_radius, rtol=1e-12)


def test_position_continuous_and_speed_exact():
    path = observer_path(Config())
    for seg in path.segments[1:]:
        before, after = path.position(np.array([seg.t0_s - 1e-9, seg.t0_s]))
        assert np.hypot(before[0] - before[1], after[0] - after[1]) < 1e-6
    t = np.linspace(0.5, 1199.5, 2000)
    h = 1e-4
    x1, y1 = path.position(t - h)
    x2, y2 = path.position(t + h)
    speed = np.hypot(x2 - x1, y2 - y1) / (2 * h)
    np.testing.assert_allclose(speed, 5.0, rtol=1e-6)
    c = path.course(t)
    np.testing.assert_allclose((x2 - x1) / (2 * h), 5.0 * np.sin(c), atol=1e-5)


def test_turn_through_north_goes_right():
    path = observer_path(Config())
    t = np.array([660.0 + 180.0])  # halfway through the 270 -> 90 turn
    assert np.rad2deg(path.course(t))[0] % 360 == pytest.approx(0.0, abs=1e-9)


def test_bad_legs_are_rejected():
    with pytest.raises(ConfigError, match="direction"):
        LegPath(0, 0, 5, [{"course_deg": 0, "duration_s": 10},
                               {"turn_to_deg": 90, "rate_deg_s": 1, "direction": "up"}])
    with pytest.raises(ConfigError, match="first leg needs course_deg"):
        LegPath(0, 0, 5, [{"duration_s": 10}])
    with pytest.raises(ConfigError, match="not both"):
        LegPath(0, 0, 5, [{"course_deg": 0, "duration_s": 1},
                          {"turn_to_deg": 9, "turn_radius_m": 9, "direction": "left"}])


def test_radius_turn_and_course_keeping_legs():
    legs = [{"duration_s": 45.0}, {"turn_radius_m": 300.0, "duration_s": 45.0,
                                   "direction": "left"}, {"duration_s": 30.0}]
    path = LegPath(0, 0, 10.0, legs, initial_course_deg=90.0)  # heading +x
    x, y = path.position(np.array([45.0, 90.0]))
    assert (x[0], y[0]) == pytest.approx((450.0, 0.0))
    turned = 10.0 * 45.0 / 300.0  # rad, to the left (counter-clockwise)
    assert (x[1], y[1]) == pytest.approx((450 + 300 * np.sin(turned),
                                          300 * (1 - np.cos(turned))))
    assert np.rad2deg(path.course(np.array([100.0])))[0] == pytest.approx(
        90 - np.rad2deg(turned))
