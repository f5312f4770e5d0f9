"""The sim arena's QR code landmarks and the sim robot's front camera: what it renders is read
back with zxing-cpp, as scan_barcode() does, so a robot in simulation finds its way by them."""

import io
import math

import numpy as np
import pytest
import zxingcpp
from PIL import Image

import rhal
from rhal.arena import ARENAS, Arena, Box, Landmark

FRONT = {"width": 640, "height": 480, "format": "jpeg", "fov": 62.0}


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


async def front_view_from(clock, pose, arena="square") -> bytes:
    """Where the sim robot gets by driving (it starts at the centre facing north)."""
    async with rhal.connect(f"sim://?arena={arena}", clock=clock) as bot:
        bot._pose = pose  # placed there: the arena's geometry, not the driving, is tested here
        return await bot.front_camera_jpeg()


@pytest.mark.parametrize("name", sorted(ARENAS))
def test_every_arena_has_named_codes_on_its_walls(name):
    arena = ARENAS[name]
    texts = [landmark.text for landmark in arena.landmarks]
    assert "home" in texts and len(set(texts)) == len(texts) == 4
    for landmark in arena.landmarks:
        on_wall = abs(landmark.x) == arena.half_width or abs(landmark.y) == arena.half_height
        assert on_wall and arena.clearance(landmark.x, landmark.y) == 0.0
        inward = (landmark.x + math.cos(landmark.facing), landmark.y + math.sin(landmark.facing))
        assert arena.clearance(*inward) > 0.5  # it faces into the arena


def test_the_front_camera_is_in_the_capabilities():
    caps = rhal.connect("sim://").capabilities()
    assert caps["front_camera"] == FRONT
    assert caps["camera"] == {"width": 320, "height": 240, "format": "jpeg"}  # the page's, kept


async def test_the_front_camera_needs_an_open_robot():
    with pytest.raises(rhal.RobotConnectionError):
        await rhal.connect("sim://").front_camera_jpeg()


@pytest.mark.parametrize("name", sorted(ARENAS))
async def test_each_code_reads_back_from_in_front_of_it(clock, name):
    for landmark in ARENAS[name].landmarks:
        for distance in (1.0, 2.5):
            jpeg = await front_view_from(clock, facing(landmark, distance), name)
            assert texts_in(jpeg) == [landmark.text], (landmark, distance)


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
    home = next(mark for mark in ARENAS["square"].landmarks if mark.text == "home")
    x, y, theta = facing(home, 1.5)
    assert texts_in(await front_view_from(clock, (x, y, theta + math.pi))) != ["home"]
    assert texts_in(await front_view_from(clock, (x, y, theta + math.radians(40)))) == []
    slanted = (home.x + 0.5, home.y + 1.5, math.atan2(-1.5, -0.5))  # 72 degrees off its face
    assert texts_in(await front_view_from(clock, slanted)) == []
    assert texts_in(await front_view_from(clock, facing(home, 0.45))) == []  # off the frame


async def test_a_box_in_front_hides_a_code(clock, monkeypatch):
    sign = Landmark("home", 0.0, 2.0, -math.pi / 2)
    crate = Box(-0.3, 0.8, 0.3, 1.1)
    monkeypatch.setitem(ARENAS, "open", Arena(2.0, 2.0, (), (sign,)))
    monkeypatch.setitem(ARENAS, "crate", Arena(2.0, 2.0, (crate,), (sign,)))
    start = (0.0, 0.0, math.pi / 2)
    assert texts_in(await front_view_from(clock, start, "open")) == ["home"]
    assert texts_in(await front_view_from(clock, start, "crate")) == []


async def test_the_top_view_marks_the_codes_on_the_walls(robot):
    # 56 px a metre from the centre pixel (120, 120), north up: home is at (-2, 0.3).
    image = Image.open(io.BytesIO(await robot.camera_jpeg())).convert("L")
    assert image.getpixel((9, round(120 - 0.3 * 56))) > 200  # white on the dark wall
    assert image.getpixel((9, round(120 + 1.0 * 56))) < 120  # the wall elsewhere
