"""The sim's sensor models: the range cone, the sonar ring, the floor sensor and the zone."""

import math

import pytest

import rhal

R = 0.15


def post_world(post_x: float, post_y: float) -> dict:
    """An empty 4 m square with a wall stub from (0, 1) north and a 2 cm post."""
    return {
        "size": {"width": 4, "height": 4},
        "walls": [{"from": [0, 1], "to": [0, 2], "thickness": 0.05}],
        "boxes": [{"x": post_x, "y": post_y, "width": 0.02, "height": 0.02}],
        "start": [{"x": -1.5, "y": -1.5, "theta": 0}],
    }


async def test_the_cone_sees_a_thin_wall_end_the_robot_touches(clock):
    # The wall's end (its square cap's corner at (0.025, 0.975)) touches the robot 5 degrees
    # left of ahead: the middle ray passes beside it, the cone does not.
    bearing = math.radians(95)
    x, y = 0.025 - R * math.cos(bearing), 0.975 - R * math.sin(bearing)
    async with rhal.connect("sim://", world=post_world(-1.0, -1.0), clock=clock) as bot:
        await bot.reset((x, y, math.pi / 2))
        readings = await bot.sensors()
        assert bot.world.ray_distance(x, y, math.pi / 2, 4.0) > 1.0  # one ray misses it
    assert readings["range"] == pytest.approx(R, abs=2e-3)
    assert readings["bumper"] is True


async def test_a_corner_between_two_rays_still_echoes(clock):
    # A 2 cm post 1.5 m away, 1.9 degrees off: between the rays at 0 and 3.75 degrees.
    off = math.radians(1.9)
    post = (1.5 * math.cos(off) - 1.0, 1.5 * math.sin(off) - 1.5)
    async with rhal.connect("sim://", world=post_world(*post), clock=clock) as bot:
        await bot.reset((-1.0, -1.5, 0.0))
        assert await bot.sensor("range") == pytest.approx(1.5 - 0.01, abs=0.02)


async def test_readings_stay_between_the_minimum_and_the_maximum(clock):
    doc = {"size": {"width": 20, "height": 4}, "start": [{"x": -9, "y": 0, "theta": 0}],
           "robot": {"range": {"min": 0.2, "max": 3.0}}}  # fmt: skip
    async with rhal.connect("sim://", world=doc, clock=clock) as bot:
        assert await bot.sensor("range") == 3.0  # the far wall is 19 m away
        await bot.reset((-9.0, 0.0, math.pi))
        assert await bot.sensor("range") == pytest.approx(1.0)  # the west wall
        await bot.reset((-9.85, 0.0, math.pi))  # touching the west wall: 0.15 m < the minimum
        assert await bot.sensor("range") == 0.2


async def test_a_single_ray_when_the_cone_is_zero(clock):
    async with rhal.connect("sim://?range_cone_deg=0", clock=clock) as bot:
        await bot.reset((0.0, 0.0, math.pi / 4))  # at the box's corner region, NE
        assert await bot.sensor("range") == pytest.approx(0.8 * math.sqrt(2))
        assert bot.capabilities()["sim"]["range"]["cone_deg"] == 0.0


async def test_sonar_ring_and_floor_sensor_on_the_line_world(clock):
    async with rhal.connect("sim://?world=line&sonar=90,0,-90", clock=clock) as bot:
        start = await bot.sensors()  # at (0, -0.8) facing east, on the line's south straight
        await bot.drive(0.2, 0.0)
        clock.advance(2.0)
        along = await bot.sensors()
        await bot.drive(0.0, 1.0)
        clock.advance(math.pi / 2)
        turned = await bot.sensors()  # facing north: the sensor 0.1 m off the line
        caps = bot.capabilities()
    assert start["sonar"] == pytest.approx([1.5 + 0.8, 2.0, 1.5 - 0.8])
    assert start["floor"] == {"colour": "black", "light": 6}
    assert along["floor"] == {"colour": "black", "light": 6}
    assert along["sonar"][1] == pytest.approx(2.0 - 0.4)
    assert turned["floor"] == {"colour": "white", "light": 94}
    assert turned["sonar"] == pytest.approx([2.0 + 0.4, 1.5 + 0.8, 2.0 - 0.4])
    assert caps["sensors"]["sonar"]["angles"] == [90.0, 0.0, -90.0]
    assert caps["sensors"]["floor"] == {"unit": {"colour": "name", "light": "%"}}


async def test_the_maze_robot_has_its_ring_and_the_zone_is_read(clock):
    async with rhal.connect("sim://?world=maze", clock=clock) as bot:
        readings = await bot.sensors()
        await bot.reset((2.0, 2.0, 0.0))
        goal = await bot.sensors()
    assert len(readings["sonar"]) == 5 and readings["zone"] == "start"
    assert readings["sonar"][4] == pytest.approx(0.5)  # the south wall, to its right
    assert goal["zone"] == "goal" and goal["floor"]["colour"] == "green"


async def test_zone_is_null_outside_every_zone(robot):
    assert (await robot.sensors())["zone"] is None


async def test_a_robot_standing_still_is_not_sensed_again(robot, clock, monkeypatch):
    calls = []
    range_at = robot._sensing.range_at
    monkeypatch.setattr(robot._sensing, "range_at", lambda *a: calls.append(a) or range_at(*a))
    for _ in range(100):
        clock.advance(0.01)
        await robot.sensors()
    assert len(calls) == 1
    await robot.drive(0.0, 1.0)
    clock.advance(0.1)
    await robot.sensors()
    assert len(calls) == 2
