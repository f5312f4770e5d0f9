import io
import math

import pytest
from PIL import Image

import rhal
from rhal.sim_render import layout_for
from rhal.simulator.world import World

# The frame's documented layout: the 4 m arena fills the left 240 px square with an 8 px
# margin, north up, so the arena centre is pixel (120, 120) and a metre is 56 px.
CENTRE = 120
PX_PER_M = (240 - 2 * 8) / 4


def decode(jpeg: bytes) -> Image.Image:
    image = Image.open(io.BytesIO(jpeg))
    assert image.format == "JPEG"
    return image.convert("RGB")


def robot_blue_centroid(image: Image.Image, least: int = 100) -> tuple[float, float]:
    points = [
        (x, y)
        for y in range(image.height)
        for x in range(image.width)
        if (pixel := image.getpixel((x, y)))[2] > 150 and pixel[0] < 110 and pixel[1] < 160
    ]
    assert len(points) > least, "the robot should be a visible blue disc"
    return (sum(x for x, _ in points) / len(points), sum(y for _, y in points) / len(points))


async def test_camera_is_a_320_by_240_jpeg(robot):
    image = decode(await robot.camera_jpeg())
    assert image.size == (320, 240)


async def test_camera_shows_the_robot_at_the_centre(robot):
    x, y = robot_blue_centroid(decode(await robot.camera_jpeg()))
    assert x == pytest.approx(CENTRE, abs=3)
    assert y == pytest.approx(CENTRE, abs=3)


async def test_camera_follows_the_robot(robot, drive_for):
    await drive_for(0.0, -1.0, math.pi / 2)  # face east
    await drive_for(0.5, 0.0, 2.0)  # one metre east
    await robot.stop()
    x, y = robot_blue_centroid(decode(await robot.camera_jpeg()))
    assert x == pytest.approx(CENTRE + PX_PER_M, abs=3)
    assert y == pytest.approx(CENTRE, abs=3)


async def test_camera_needs_an_open_robot():
    with pytest.raises(rhal.RobotConnectionError):
        await rhal.connect("sim://").camera_jpeg()


async def test_camera_fits_a_wide_world_with_the_robot_where_it_is(clock):
    # 10 m x 3 m: the map goes above the readings, 30.4 px a metre.
    doc = {"size": {"width": 10.0, "height": 3.0}, "start": [{"x": 3.0, "y": -1.0, "theta": 0.0}]}
    async with rhal.connect("sim://", world=doc, clock=clock) as bot:
        image = decode(await bot.camera_jpeg())
    layout = layout_for(World.from_doc(doc), image.size)
    assert not layout.beside and layout.scale == pytest.approx(30.4)
    x, y = robot_blue_centroid(image, least=30)
    assert (x, y) == pytest.approx(layout.pixel(3.0, -1.0), abs=1.5)
