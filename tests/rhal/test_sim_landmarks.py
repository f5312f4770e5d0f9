"""The sim worlds' QR code landmarks and the sim robot's front camera: what it renders is read
back with zxing-cpp, as scan_barcode() does, so a robot in simulation finds its way by them."""

import io
import math

import numpy as np
import pytest
import zxingcpp
from PIL import Image

import rhal
from rhal.simulator.world import Landmark
from rhal.simulator.worlds import BUILTIN, load

FRONT = {"width": 640, "height": 480, "format": "jpeg", "fov": 62.0}
WITH_CODES = sorted(name for name, doc in BUILTIN.items() if doc.get("landmarks"))


def codes_in(jpeg: bytes) -> list[zxingcpp.Barcode]:
    image = Image.open(io.BytesIO(jpeg))
    assert image.format == "JPEG" and image.size == (640, 480)
    return zxingcpp.read_barcodes(np.asarray(image.convert("L")))


def texts_in(jpeg: bytes) -> list[str]:
    return [code.text for code in codes_in(jpeg)]


def facing(landmark: Landmark, distance: float) -> tuple[float, float, float]:
    """The pose `distance` m in front of a landmark, looking at it."""
    x = landmark.x + math.cos(landmark.facing) * distance
    y = landmark.y + math.sin(landmark.facing) * distance
    return x, y, landmark.facing + math.pi


async def front_view_from(clock, pose, world="square") -> bytes:
    """What the sim robot sees, placed at ``pose`` in ``world`` (a name or a document)."""
    async with rhal.connect("sim://", world=world, clock=clock) as bot:
        await bot.reset(pose)
        return await bot.front_camera_jpeg()


def test_the_old_arenas_keep_their_named_codes_on_their_walls():
    for name in ("boxes", "square"):
        world = load(name)
        texts = [landmark.text for landmark in world.landmarks]
        assert "home" in texts and len(set(texts)) == len(texts) == 4
        for landmark in world.landmarks:
            assert abs(landmark.x) == world.half_width or abs(landmark.y) == world.half_height
            inward = (
                landmark.x + math.cos(landmark.facing),
                landmark.y + math.sin(landmark.facing),
            )
            assert world.clearance(*inward) > 0.5  # it faces into the arena


def test_the_front_camera_is_in_the_capabilities():
    caps = rhal.connect("sim://").capabilities()
    assert caps["front_camera"] == FRONT
    assert caps["camera"] == {"width": 320, "height": 240, "format": "jpeg"}  # the page's, kept


async def test_the_front_camera_needs_an_open_robot():
    with pytest.raises(rhal.RobotConnectionError):
        await rhal.connect("sim://").front_camera_jpeg()


@pytest.mark.parametrize("name", WITH_CODES)
async def test_each_code_reads_back_from_in_front_of_it(clock, name):
    world = load(name)
    for landmark in world.landmarks:
        for distance in (1.0, 2.5):
            pose = facing(landmark, distance)
            in_sight = world.ray_distance(*pose, 9.0) > distance - 0.01
            if world.clearance(*pose[:2]) < world.robot.radius or not in_sight:
                continue  # no room there, or a wall between (the maze's corridors, the rooms)
            jpeg = await front_view_from(clock, pose, name)
            assert texts_in(jpeg) == [landmark.text], (landmark, distance)


@pytest.mark.parametrize("name", sorted(BUILTIN))
async def test_every_world_is_seen_from_its_start_poses_in_every_direction(clock, name):
    # Its walls, boxes and painted floor in view from any heading (the floor's perspective map
    # included: it has a pole at the horizon).
    world = load(name)
    for x, y, _ in world.start:
        for eighth in range(8):
            image = Image.open(
                io.BytesIO(await front_view_from(clock, (x, y, eighth * math.pi / 4), name))
            )
            assert image.size == (640, 480)


async def test_from_the_start_the_robot_sees_the_kitchen_ahead_to_the_left(robot):
    (code,) = codes_in(await robot.front_camera_jpeg())
    assert code.text == "kitchen" and code.format == zxingcpp.BarcodeFormat.QRCode
    corners = code.position
    assert corners.top_right.x < 320  # the kitchen is at x = -0.5 m: left of straight ahead


async def test_the_view_follows_the_robot(robot, drive_for):
    await drive_for(0.0, 1.0, math.pi / 2)  # face west, towards home
    assert texts_in(await robot.front_camera_jpeg()) == ["home"]
    await drive_for(0.0, 1.0, math.pi)  # face east
    assert texts_in(await robot.front_camera_jpeg()) == ["lab"]


async def test_a_code_is_not_seen_from_behind_or_beside_it_or_too_close(clock):
    home = next(mark for mark in load("square").landmarks if mark.text == "home")
    x, y, theta = facing(home, 1.5)
    assert texts_in(await front_view_from(clock, (x, y, theta + math.pi))) != ["home"]
    assert texts_in(await front_view_from(clock, (x, y, theta + math.radians(40)))) == []
    slanted = (home.x + 0.5, home.y + 1.5, math.atan2(-1.5, -0.5))  # 72 degrees off its face
    assert texts_in(await front_view_from(clock, slanted)) == []
    assert texts_in(await front_view_from(clock, facing(home, 0.45))) == []  # off the frame


def world_with(**things) -> dict:
    """A 4 m x 4 m world document with a code on its north wall and ``things``."""
    sign = {"text": "home", "x": 0.0, "y": 2.0, "facing": -math.pi / 2}
    start = [{"x": 0.0, "y": 0.0, "theta": math.pi / 2}]
    return {"size": {"width": 4.0, "height": 4.0}, "landmarks": [sign], "start": start, **things}


async def test_a_box_in_front_hides_a_code_turned_or_not(clock):
    start = (0.0, 0.0, math.pi / 2)
    assert texts_in(await front_view_from(clock, start, world_with())) == ["home"]
    for angle in (0.0, 0.5):
        crate = {"x": 0.0, "y": 0.95, "width": 0.6, "height": 0.3, "angle": angle}
        assert texts_in(await front_view_from(clock, start, world_with(boxes=[crate]))) == []


async def test_a_code_on_an_inner_wall_reads_back_and_the_wall_hides_the_one_behind(clock):
    # A wall across the room, 10 cm thick, its south face at y = 0.95, a code on that face.
    wall = {"from": [-1.0, 1.0], "to": [1.0, 1.0], "thickness": 0.1}
    shelf = {"text": "shelf", "x": 0.5, "y": 0.95, "facing": -math.pi / 2, "height": 0.3}
    doc = world_with(walls=[wall], landmarks=[shelf, world_with()["landmarks"][0]])
    assert texts_in(await front_view_from(clock, (0.5, -0.5, math.pi / 2), doc)) == ["shelf"]
    # home, on the north wall behind it, is hidden; round the wall's end it is seen.
    assert texts_in(await front_view_from(clock, (-0.3, -0.5, math.pi / 2), doc)) == []
    beyond = (-0.6, 1.3, math.atan2(2.0 - 1.3, 0.6))
    assert texts_in(await front_view_from(clock, beyond, doc)) == ["home"]


async def test_the_top_view_marks_the_codes_on_the_walls(robot):
    # 56 px a metre from the centre pixel (120, 120), north up: home is at (-2, 0.3).
    image = Image.open(io.BytesIO(await robot.camera_jpeg())).convert("L")
    assert image.getpixel((9, round(120 - 0.3 * 56))) > 200  # white on the dark wall
    assert image.getpixel((9, round(120 + 1.0 * 56))) < 120  # the wall elsewhere
