"""Differential-drive kinematics and the angle conventions every RHAL driver reports in.

World frame: x east, y north, in metres; ``theta`` counter-clockwise from +x (east), in radians
normalised to (-pi, pi]. Compass ``heading``: degrees clockwise from north, in [0, 360).
So theta = pi/2 is heading 0 (north) and theta = 0 is heading 90 (east).
"""

import math


def normalize_angle(theta: float) -> float:
    """The same angle in (-pi, pi]."""
    angle = math.remainder(theta, math.tau)
    return math.pi if angle == -math.pi else angle


def compass_heading(theta: float) -> float:
    """Degrees clockwise from north, in [0, 360), for a world-frame ``theta``."""
    heading = (90.0 - math.degrees(theta)) % 360.0
    # A tiny negative number modulo 360 rounds to 360.0 itself.
    return 0.0 if heading >= 360.0 else heading


def theta_from_heading(heading: float) -> float:
    """World-frame ``theta`` for a compass heading in degrees."""
    return normalize_angle(math.radians(90.0 - heading))


def advance_pose(
    x: float, y: float, theta: float, linear: float, angular: float, dt: float
) -> tuple[float, float, float]:
    """Pose after ``dt`` seconds at constant speeds, integrated exactly along the arc.

    The robot moves along the chord of the arc, which points at the mean heading; writing the
    chord as ``linear * dt * sinc(angular * dt / 2)`` stays exact as ``angular`` goes to 0.
    """
    half_turn = angular * dt / 2.0
    chord = linear * dt * _sinc(half_turn)
    mean_heading = theta + half_turn
    return (
        x + chord * math.cos(mean_heading),
        y + chord * math.sin(mean_heading),
        normalize_angle(theta + 2.0 * half_turn),
    )


def _sinc(u: float) -> float:
    # Taylor series near 0, where sin(u) / u loses precision; the next term is below 1e-17.
    return 1.0 - u * u / 6.0 if abs(u) < 1e-4 else math.sin(u) / u
