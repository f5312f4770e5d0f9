"""The jam test of issue 30: from 20 poses touching walls, box faces and corners of the boxes
world, drive forward 2 s then back 1 s. The robot never stays stuck (it slides along what it
meets at an angle and backs away when told), never gets inside anything (checked every 50 ms
of simulated time, against geometry written out here, not the simulator's), and its bumper
reads pressed exactly while it touches.

Run against the driver before the simulator package it fails: touching anything blocked all
forward motion there, so nothing met at an angle was slid along.
"""

import math

import pytest

R = 0.15  # the robot's radius
HALF = 2.0  # the arena's walls at x, y = +-2
BOXES = ((0.8, 0.5, 1.3, 1.0), (-1.5, -1.3, -0.9, -0.7))  # west, south, east, north
TICK = 0.05  # s of simulated time between reads
SPEED = 0.3  # m/s
D = R / math.sqrt(2)
deg = math.radians


def clearance(x: float, y: float) -> float:
    """Distance from the robot's centre to the nearest surface of the boxes world."""
    nearest = min(HALF - abs(x), HALF - abs(y))
    for west, south, east, north in BOXES:
        dx = max(west - x, 0.0, x - east)
        dy = max(south - y, 0.0, y - north)
        if dx == 0.0 and dy == 0.0:
            return -1.0  # inside
        nearest = min(nearest, math.hypot(dx, dy))
    return nearest


# (x, y, theta, what, slides): touching a surface; ``slides`` when it meets it at an angle and
# so must move along it; head-on into a face, a corner or a box's corner it stays put.
POSES = [
    (0.0, 1.85, deg(90), "north wall head-on", False),
    (-0.5, 1.85, deg(60), "north wall 30 degrees off", True),
    (0.5, 1.85, deg(120), "north wall 30 degrees off, westward", True),
    (1.85, 0.0, deg(0), "east wall head-on", False),
    (1.85, -0.5, deg(30), "east wall 30 degrees off", True),
    (0.3, -1.85, deg(-110), "south wall 20 degrees off", True),
    (-1.85, 0.5, deg(160), "west wall 20 degrees off", True),
    (1.85, 1.85, deg(45), "north-east corner", False),
    (-1.85, 1.85, deg(90), "north-west corner, facing north", False),
    (-1.85, -1.85, deg(180), "south-west corner, facing west", False),
    (1.85, -1.85, deg(-45), "south-east corner", False),
    (0.65, 0.75, deg(0), "box's west face head-on", False),
    (0.65, 0.6, deg(30), "box's west face 30 degrees off", True),
    (1.05, 0.35, deg(90), "box's south face head-on", False),
    (0.9, 0.35, deg(60), "box's south face 30 degrees off", True),
    (1.3 + D, 1.0 + D, deg(225), "box's north-east corner head-on", False),
    (0.8 - D, 0.5 - D, deg(55), "box's south-west corner, 10 degrees off", True),
    (-0.75, -1.0, deg(200), "other box's east face 20 degrees off", True),
    (-1.2, -0.55, deg(-70), "other box's north face 20 degrees off", True),
    (-0.9 + R * math.cos(deg(30)), -0.7 + R * math.sin(deg(30)), deg(220),
     "other box's north-east corner, 10 degrees off", True),
]  # fmt: skip


async def place(robot, pose) -> None:
    try:
        await robot.reset(pose)
    except TypeError:  # the driver before reset() took a pose
        robot._pose = pose


async def drive(robot, clock, linear: float, seconds: float, trace: list) -> None:
    await robot.drive(linear, 0.0)
    for _ in range(round(seconds / TICK)):
        clock.advance(TICK)
        readings = await robot.sensors()
        x, y = readings["position"]["x"], readings["position"]["y"]
        trace.append((x, y, readings["bumper"]))


@pytest.mark.parametrize(("x", "y", "theta", "what", "slides"), POSES, ids=[p[3] for p in POSES])
async def test_it_never_jams_nor_passes_through(robot, clock, x, y, theta, what, slides):
    assert clearance(x, y) == pytest.approx(R, abs=1e-9), "the pose touches something"
    await place(robot, (x, y, theta))
    assert (await robot.sensors())["bumper"] is True, "touching: the bumper is pressed"
    forward, back = [], []
    await drive(robot, clock, SPEED, 2.0, forward)
    await drive(robot, clock, -SPEED, 1.0, back)
    for px, py, bumper in forward + back:
        assert clearance(px, py) >= R - 1e-6, f"inside something at ({px:.4f}, {py:.4f})"
        gap = clearance(px, py) - R
        if gap < 1e-4:
            assert bumper, f"touching at ({px:.4f}, {py:.4f}) but the bumper is not pressed"
        if gap > 2e-3:
            assert not bumper, f"{gap * 1000:.1f} mm clear at ({px:.4f}, {py:.4f}), bumper pressed"
    moved = math.dist((x, y), forward[-1][:2])
    if slides:
        assert moved > 0.1, f"met at an angle, it slid only {moved:.3f} m in 2 s"
    else:
        assert moved < 0.05, f"head-on it should stay put, it moved {moved:.3f} m"
    backed = math.dist(forward[-1][:2], back[-1][:2])
    assert backed > 0.2, f"backing away for 1 s at {SPEED} m/s it moved only {backed:.3f} m"
    *_, end_bumper = back[-1]
    # Backed off, the bumper is released; only backing along a wall (out of a corner) keeps it.
    along_a_wall = what.endswith("corner, facing north") or what.endswith("facing west")
    assert end_bumper is along_a_wall
