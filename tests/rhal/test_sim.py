import json
import math

import pytest

import rhal

RADIUS = 0.15


async def test_it_starts_at_the_centre_facing_north(robot):
    readings = await robot.sensors()
    assert readings["position"] == pytest.approx({"x": 0.0, "y": 0.0, "theta": math.pi / 2})
    assert readings["heading"] == 0.0
    assert readings["velocity"] == {"linear": 0.0, "angular": 0.0}
    assert readings["odometry"] == {"distance": 0.0}
    assert readings["bumper"] is False
    assert readings["battery"] == 100.0
    assert readings["time"] == 0.0


async def test_readings_are_json_and_match_capabilities(robot, drive_for):
    readings = await drive_for(0.3, 0.4, 1.5)
    assert json.loads(json.dumps(readings)) == readings
    assert set(readings) == set(robot.capabilities()["sensors"])


async def test_straight_line_north(drive_for):
    readings = await drive_for(0.5, 0.0, 2.0)
    assert readings["position"]["x"] == pytest.approx(0.0, abs=1e-12)
    assert readings["position"]["y"] == pytest.approx(1.0)
    assert readings["heading"] == pytest.approx(0.0)
    assert readings["odometry"]["distance"] == pytest.approx(1.0)
    assert readings["range"] == pytest.approx(1.0)
    assert readings["velocity"] == {"linear": 0.5, "angular": 0.0}
    assert readings["time"] == pytest.approx(2.0)


async def test_reverse_drives_south_and_still_counts_distance(drive_for):
    readings = await drive_for(-0.25, 0.0, 2.0)
    assert readings["position"]["y"] == pytest.approx(-0.5)
    assert readings["heading"] == pytest.approx(0.0)
    assert readings["odometry"]["distance"] == pytest.approx(0.5)


async def test_positive_angular_turns_counter_clockwise_to_west(drive_for):
    readings = await drive_for(0.0, 1.0, math.pi / 2)
    assert readings["heading"] == pytest.approx(270.0)
    position = readings["position"]
    assert (position["x"], position["y"]) == (0.0, 0.0)
    assert abs(position["theta"]) == pytest.approx(math.pi)  # either side of the +-pi seam
    assert readings["odometry"]["distance"] == 0.0


async def test_negative_angular_turns_clockwise_to_east(drive_for):
    readings = await drive_for(0.0, -1.0, math.pi / 2)
    assert readings["heading"] == pytest.approx(90.0)
    assert readings["position"]["theta"] == pytest.approx(0.0)


@pytest.mark.parametrize("seconds", [0.5, 2.0, 7.0, 1000.0])
async def test_arc_matches_closed_form(drive_for, seconds):
    # Radius 0.4 m curving west from the centre: a circle clear of walls and boxes.
    linear, angular, theta0 = 0.2, 0.5, math.pi / 2
    readings = await drive_for(linear, angular, seconds)
    theta = theta0 + angular * seconds
    radius = linear / angular
    position = readings["position"]
    assert position["x"] == pytest.approx(radius * (math.sin(theta) - math.sin(theta0)), abs=1e-9)
    assert position["y"] == pytest.approx(-radius * (math.cos(theta) - math.cos(theta0)), abs=1e-9)
    assert math.cos(position["theta"]) == pytest.approx(math.cos(theta), abs=1e-9)
    assert math.sin(position["theta"]) == pytest.approx(math.sin(theta), abs=1e-9)
    assert -math.pi < position["theta"] <= math.pi
    assert readings["odometry"]["distance"] == pytest.approx(linear * seconds)
    assert readings["bumper"] is False


async def test_many_small_reads_agree_with_one_big_step(robot, clock, drive_for):
    await robot.drive(0.3, -0.6)
    for _ in range(300):
        clock.advance(0.01)
        await robot.sensors()
    stepped = await robot.sensors()
    assert stepped["position"] == pytest.approx(
        {"x": 0.5 * (1 - math.cos(1.8)), "y": 0.5 * math.sin(1.8), "theta": math.pi / 2 - 1.8}
    )


@pytest.mark.parametrize(
    ("turn", "expected"),
    [(0.0, 2.0), (-math.pi / 2, 2.0), (math.pi, 2.0), (math.pi / 2, 2.0),
     # The cone is 15 degrees wide: its right edge meets the box's west face (x = 0.8) first,
     (-math.pi / 4, 0.8 / math.cos(math.radians(37.5))),
     # and the south-west box's north-east corner is inside it.
     (3 * math.pi / 4, math.hypot(0.9, 0.7))],
)  # fmt: skip
async def test_range_measures_from_the_centre_to_walls_and_boxes(drive_for, turn, expected):
    readings = await drive_for(0.0, math.copysign(1.0, turn), abs(turn))
    assert readings["range"] == pytest.approx(expected)


async def test_range_is_capped_at_its_maximum(clock):
    async with rhal.connect("sim://?arena=square", clock=clock) as bot:
        await bot.drive(0.0, 1.0)  # turn to face south-west
        clock.advance(3 * math.pi / 4)
        await bot.drive(0.5, 0.0)  # into the corner
        clock.advance(60)
        cornered = await bot.sensors()
        await bot.drive(0.0, 2.0)  # about turn to face the far corner
        clock.advance(math.pi / 2)
        readings = await bot.sensors()
    assert cornered["position"]["x"] == pytest.approx(-2.0 + RADIUS, abs=1e-5)
    assert cornered["position"]["y"] == pytest.approx(-2.0 + RADIUS, abs=1e-5)
    assert readings["heading"] == pytest.approx(45.0)
    assert readings["range"] == 4.0
    assert bot.capabilities()["sensors"]["range"]["max"] == 4.0


async def test_wall_stops_the_robot_and_presses_the_bumper(robot, clock, drive_for):
    readings = await drive_for(0.5, 0.0, 10.0)
    assert readings["position"]["y"] == pytest.approx(2.0 - RADIUS, abs=1e-5)
    assert readings["position"]["y"] <= 2.0 - RADIUS
    assert readings["bumper"] is True
    assert readings["velocity"] == {"linear": 0.0, "angular": 0.0}
    assert readings["odometry"]["distance"] == pytest.approx(2.0 - RADIUS, abs=1e-5)
    assert readings["range"] == pytest.approx(RADIUS, abs=1e-5)

    clock.advance(5.0)
    assert (await robot.sensors())["position"] == readings["position"]


async def test_pushing_again_into_the_wall_does_not_penetrate(drive_for):
    await drive_for(0.5, 0.0, 10.0)
    readings = await drive_for(0.5, 0.0, 10.0)
    assert readings["position"]["y"] <= 2.0 - RADIUS
    assert readings["bumper"] is True


async def test_backing_off_releases_the_bumper(drive_for):
    await drive_for(0.5, 0.0, 10.0)
    readings = await drive_for(-0.5, 0.0, 1.0)
    assert readings["position"]["y"] == pytest.approx(2.0 - RADIUS - 0.5, abs=1e-5)
    assert readings["bumper"] is False
    assert readings["velocity"]["linear"] == -0.5


async def test_turning_against_the_wall_is_allowed(drive_for):
    await drive_for(0.5, 0.0, 10.0)
    readings = await drive_for(0.0, 1.0, math.pi / 2)
    assert readings["heading"] == pytest.approx(270.0)
    assert readings["bumper"] is True


async def test_a_huge_time_step_slides_round_a_box_into_the_corner(drive_for):
    await drive_for(0.0, -1.0, math.pi / 4)  # face north-east, at the box
    readings = await drive_for(0.5, 0.0, 1e6)
    # Along the box's west face, round its corner, along the north wall: pinned in the corner.
    assert readings["position"]["x"] == pytest.approx(2.0 - RADIUS, abs=1e-5)
    assert readings["position"]["y"] == pytest.approx(2.0 - RADIUS, abs=1e-5)
    assert readings["bumper"] is True
    assert readings["velocity"]["linear"] == 0.0


async def test_meeting_a_box_at_an_angle_slides_along_its_face(drive_for):
    await drive_for(0.0, 1.0, 3 * math.pi / 4)  # face south-west, at the other box
    # The diagonal meets the box's east face (x = -0.9) at y = -0.75: 1.06 m, 2.12 s at 0.5 m/s.
    readings = await drive_for(0.5, 0.0, 2.5)
    assert readings["position"]["x"] == pytest.approx(-0.9 + RADIUS, abs=1e-5)
    # Then it slides south along the face at 0.5 cos 45 m/s.
    slid = (2.5 - 0.75 * math.sqrt(2) / 0.5) * 0.5 * math.cos(math.pi / 4)
    assert readings["position"]["y"] == pytest.approx(-0.75 - slid, abs=1e-4)
    assert readings["bumper"] is True
    assert readings["velocity"]["linear"] == pytest.approx(0.5 * math.cos(math.pi / 4), abs=1e-6)


@pytest.mark.parametrize("seconds", [5.0, 1e6])
async def test_one_long_step_does_not_jump_over_a_box(robot, drive_for, seconds):
    await drive_for(0.0, 1.0, 3 * math.pi / 4)  # face south-west, at the other box
    readings = await drive_for(0.5, 0.0, seconds)
    x, y = readings["position"]["x"], readings["position"]["y"]
    assert robot.world.clearance(x, y) >= RADIUS - 1e-6
    assert x >= -0.9 + RADIUS - 1e-6 or y <= -1.3 - RADIUS + 1e-6  # east of it or south of it
    if seconds > 100:  # round it and along the south wall into the corner
        assert (x, y) == pytest.approx((-2.0 + RADIUS, -2.0 + RADIUS), abs=1e-5)


async def test_a_huge_time_step_does_not_tunnel_through_a_wall(drive_for):
    readings = await drive_for(-0.5, 0.0, 1e9)
    assert readings["position"]["y"] == pytest.approx(-2.0 + RADIUS, abs=1e-5)


async def test_battery_drains_with_distance(drive_for):
    readings = await drive_for(0.5, 0.0, 2.0)
    assert 99.0 < readings["battery"] < 100.0


async def test_reset_returns_to_the_start(robot, drive_for):
    await drive_for(0.5, 1.0, 3.0)
    await robot.reset()
    readings = await robot.sensors()
    assert readings["position"] == pytest.approx({"x": 0.0, "y": 0.0, "theta": math.pi / 2})
    assert readings["velocity"] == {"linear": 0.0, "angular": 0.0}
    assert readings["odometry"]["distance"] == 0.0
    assert readings["battery"] == 100.0


async def test_stop_halts_motion(robot, clock, drive_for):
    await drive_for(0.5, 0.0, 1.0)
    await robot.stop()
    clock.advance(1.0)
    readings = await robot.sensors()
    assert readings["position"]["y"] == pytest.approx(0.5)
    assert readings["velocity"] == {"linear": 0.0, "angular": 0.0}


async def test_sensor_reads_one_value(robot):
    assert await robot.sensor("range") == pytest.approx(2.0)
    assert await robot.sensor("heading") == 0.0


async def test_unknown_sensor_is_not_supported(robot):
    with pytest.raises(rhal.NotSupportedError, match=r"sim robot has no sensor 'lidar'.*range"):
        await robot.sensor("lidar")


def test_capabilities_describe_the_sim():
    bot = rhal.connect("sim://?max_linear=0.3")
    caps = bot.capabilities()
    assert json.loads(json.dumps(caps)) == caps
    assert caps["kind"] == "sim"
    assert caps["drive"] == {"max_linear": 0.3, "max_angular": 2.0}
    assert caps["sensors"]["heading"] == {"unit": "deg"}
    assert caps["sensors"]["range"] == {"unit": "m", "max": 4.0}
    assert {"position", "velocity", "odometry", "bumper", "battery", "time"} <= set(caps["sensors"])
    assert caps["camera"] == {"width": 320, "height": 240, "format": "jpeg"}
    caps["sensors"].clear()
    assert bot.capabilities()["sensors"], "callers must not be able to change capabilities"


def test_unknown_arena_is_refused():
    with pytest.raises(ValueError, match="boxes"):
        rhal.connect("sim://?arena=moon")


async def test_square_arena_has_no_boxes(clock):
    async with rhal.connect("sim://?arena=square", clock=clock) as bot:
        await bot.drive(0.0, -1.0)
        clock.advance(math.pi / 4)
        # The cone's edges meet the walls before its middle reaches the far corner.
        assert await bot.sensor("range") == pytest.approx(2.0 / math.cos(math.radians(37.5)))
