import math

import pytest

from rhal.kinematics import advance_pose, compass_heading, normalize_angle, theta_from_heading


@pytest.mark.parametrize(
    ("theta", "expected"),
    [(0.0, 0.0), (math.pi, math.pi), (-math.pi, math.pi), (3 * math.pi, math.pi),
     (2 * math.pi + 0.5, 0.5), (-2 * math.pi - 0.5, -0.5)],
)  # fmt: skip
def test_normalize_angle_lands_in_half_open_interval(theta, expected):
    assert normalize_angle(theta) == pytest.approx(expected)


@pytest.mark.parametrize(
    ("theta", "heading"),
    [(math.pi / 2, 0.0), (0.0, 90.0), (-math.pi / 2, 180.0), (math.pi, 270.0),
     (math.pi / 4, 45.0), (3 * math.pi / 4, 315.0)],
)  # fmt: skip
def test_compass_heading_is_clockwise_from_north(theta, heading):
    assert compass_heading(theta) == pytest.approx(heading)
    assert normalize_angle(theta_from_heading(heading)) == pytest.approx(normalize_angle(theta))


def test_compass_heading_never_reaches_360():
    assert compass_heading(math.pi / 2 + 1e-17) == 0.0
    assert 0.0 <= compass_heading(math.pi / 2 + 1e-15) < 360.0


def test_straight_line_moves_along_theta():
    x, y, theta = advance_pose(1.0, 2.0, 0.0, 0.5, 0.0, 4.0)
    assert (x, y, theta) == pytest.approx((3.0, 2.0, 0.0))


def test_turning_on_the_spot_keeps_position():
    x, y, theta = advance_pose(1.0, 2.0, 0.0, 0.0, 1.0, math.pi / 2)
    assert (x, y, theta) == pytest.approx((1.0, 2.0, math.pi / 2))


@pytest.mark.parametrize("angular", [0.7, -0.7, 1e-7, 2.0])
def test_arc_matches_closed_form(angular):
    x0, y0, th0, v, t = 0.3, -0.2, 1.1, 0.4, 3.0
    x, y, theta = advance_pose(x0, y0, th0, v, angular, t)
    radius = v / angular
    assert x == pytest.approx(x0 + radius * (math.sin(th0 + angular * t) - math.sin(th0)))
    assert y == pytest.approx(y0 - radius * (math.cos(th0 + angular * t) - math.cos(th0)))
    assert theta == pytest.approx(normalize_angle(th0 + angular * t))


def test_arc_in_pieces_equals_arc_in_one_go():
    pose = (0.0, 0.0, 0.3)
    for _ in range(10):
        pose = advance_pose(*pose, 0.5, 1.3, 0.1)
    assert pose == pytest.approx(advance_pose(0.0, 0.0, 0.3, 0.5, 1.3, 1.0))
