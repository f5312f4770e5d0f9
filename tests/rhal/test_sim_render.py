"""The sim's server-drawn pictures of any world (rhal.sim_render, rhal.sim_front): the top view
puts each thing where the world says, at any arena size; the front camera sees inner walls,
turned boxes, painted floors and the codes on any wall, read back with zxing-cpp."""

import io
import math

import numpy as np
import pytest
import zxingcpp
from PIL import Image

from rhal.sim_render import PANEL, layout_for, render_front_view, render_top_view
from rhal.simulator.world import World

FRONT_SIZE, FOV = (640, 480), math.radians(62)
RADIUS = 0.15
FLOOR, WALL, BOX, ROBOT = (236, 236, 226), (60, 60, 60), (150, 100, 60), (30, 90, 220)

DRAWING = {
    "name": "drawing",
    "size": {"width": 6.0, "height": 4.0},
    "walls": [{"from": [-2.5, -1.5], "to": [-1.0, 0.0], "thickness": 0.1}],
    "boxes": [{"x": 1.5, "y": 1.0, "width": 1.0, "height": 0.4, "angle": math.pi / 4}],
    "lines": [
        {"points": [[0.5, -1.5], [2.5, -1.5], [2.5, -0.2]], "width": 0.06, "colour": "#d02020"}
    ],
    "zones": [
        {"name": "dock", "x": -2.2, "y": 1.4, "width": 1.2, "height": 0.8, "colour": "#40b040"},
        {"name": "bare", "x": 0.0, "y": 1.4, "width": 1.0, "height": 0.6},
    ],
    "start": [{"x": 0.5, "y": -0.5, "theta": math.pi / 2}],
}


def picture(jpeg: bytes) -> Image.Image:
    image = Image.open(io.BytesIO(jpeg))
    assert image.format == "JPEG"
    return image.convert("RGB")


def colour_at(image: Image.Image, world: World, x: float, y: float) -> tuple[int, int, int]:
    u, v = layout_for(world, image.size).pixel(x, y)
    return image.getpixel((round(u), round(v)))


def near(pixel, colour, tolerance=30) -> bool:
    return max(abs(a - b) for a, b in zip(pixel, colour, strict=True)) <= tolerance


def top_view(world, pose, size=(640, 480), range_m=0.8, bumper=False) -> Image.Image:
    return picture(render_top_view(world, pose, RADIUS, range_m, bumper, size))


def test_the_top_view_draws_each_thing_where_the_world_puts_it():
    world = World.from_doc(DRAWING)
    image = top_view(world, (0.5, -0.5, math.pi / 2), bumper=True)
    at = lambda x, y: colour_at(image, world, x, y)  # noqa: E731
    # The box is turned 45 degrees: along its long side is box, where its unturned shape
    # would reach is floor.
    assert near(at(1.5, 1.0), BOX) and near(at(1.5 + 0.3, 1.0 + 0.3), BOX)
    assert near(at(1.5 + 0.4, 1.0), FLOOR)
    # The inner wall runs north-east at 45 degrees, 10 cm thick.
    assert near(at(-1.75, -0.75), WALL) and near(at(-1.6, -0.6), WALL)
    assert near(at(-1.75 - 0.15, -0.75 + 0.15), FLOOR)
    # The line, 6 cm wide, east and then north.
    assert near(at(1.5, -1.5), (208, 32, 32)) and near(at(2.5, -0.8), (208, 32, 32))
    assert near(at(1.5, -1.35), FLOOR)
    # The painted zone (away from its name, written in its middle); the bare one's floor.
    assert near(at(-2.6, 1.65), (64, 176, 64)) and near(at(0.3, 1.5), FLOOR)
    # The robot, its range cone ahead (north, see-through red), the floor beside the cone.
    assert near(at(0.5 + 0.07, -0.5 - 0.05), ROBOT)  # beside its white heading line
    red, green, _ = at(0.5, 0.1)
    assert red > green + 40
    assert near(at(0.9, 0.1), FLOOR)
    # Its bumper pressed: a red rim.
    rim = at(0.5 - RADIUS + 0.01, -0.5)
    assert rim[0] > 150 and rim[2] < 120
    # Outside the arena: the panel's colour.
    assert near(image.getpixel((2, 2)), PANEL)


@pytest.mark.parametrize(
    ("width", "height", "below"),
    [
        (10.0, 3.0, True),
        (4.0, 4.0, False),
        (1.0, 1.0, False),
        (50.0, 1.0, True),
        (2.0, 30.0, False),
    ],
)
def test_the_top_view_fits_any_arena(width, height, below):
    doc = {
        "size": {"width": width, "height": height},
        "start": [{"x": width / 2 - 0.5, "y": height / 2 - 0.5, "theta": 0.0}],
    }
    world = World.from_doc(doc)
    size = (320, 240)
    layout = layout_for(world, size)
    assert layout.beside is not below
    west, north = layout.pixel(-world.half_width, world.half_height)
    east, south = layout.pixel(world.half_width, -world.half_height)
    assert 0 <= west < east <= (320 if below else 320 - 80)
    assert 0 <= north < south <= (240 - 30 if below else 240)
    # It fills the frame to the margin across or down; the panel is beside it or right under.
    across = west == pytest.approx(8) and east == pytest.approx((320 if below else 240) - 8)
    down = north == pytest.approx(8) and south == pytest.approx((240 - 30 if below else 240) - 8)
    assert across or down
    panel_x, panel_y = layout.panel
    if below:
        assert south + 8 < panel_y <= south + 12 and panel_y + 30 <= 240 + 3
        assert (north - 8) == pytest.approx(240 - (panel_y - 3 + 30), abs=1)  # centred
    else:
        assert panel_x > east + 8 and (north + south) / 2 == pytest.approx(120)
    image = top_view(world, world.start_pose, size=size, range_m=0.2)
    assert near(image.getpixel((round(west) + 5, round((north + south) / 2))), FLOOR)
    # The robot, drawn at least 3 px wide even in a 50 m world.
    u, v = (round(c) for c in layout.pixel(*world.start_pose[:2]))
    around = [image.getpixel((u + du, v + dv)) for du in range(-3, 4) for dv in range(-3, 4)]
    assert any(b > r + 60 for r, _, b in around)


def world_of(**things) -> World:
    """A 6 m x 4 m world with ``things`` (walls=[...], ...)."""
    doc = {"size": {"width": 6.0, "height": 4.0}, "start": [{"x": -1.5, "y": -1.5, "theta": 0.0}]}
    return World.from_doc({**doc, **things})


def test_a_square_world_fills_the_square_left_of_the_panel():
    # The layout test_camera and the robot page's readers rely on: 56 px a metre, centre (120,
    # 120), the readings beside it.
    layout = layout_for(world_of(size={"width": 4.0, "height": 4.0}), (320, 240))
    assert layout.beside and layout.scale == 56 and layout.centre == (120, 120)


# -- the front camera ---------------------------------------------------------------------------


def front(world: World, pose) -> Image.Image:
    return picture(render_front_view(world, pose, RADIUS, FRONT_SIZE, FOV))


def texts_in(image: Image.Image) -> list[str]:
    return [code.text for code in zxingcpp.read_barcodes(np.asarray(image.convert("L")))]


def looking_at(x: float, y: float, facing: float, distance: float):
    """The pose whose camera (on the nose) is ``distance`` m in front of (x, y), facing it."""
    back = distance + RADIUS
    return x + math.cos(facing) * back, y + math.sin(facing) * back, facing + math.pi


PARTITION = {"from": [0.0, -1.0], "to": [0.0, 1.5], "thickness": 0.1}
SHELF = {"text": "shelf", "x": -0.05, "y": 0.3, "facing": math.pi}  # on its west face
DOOR = {"text": "door", "x": 3.0, "y": 0.3, "facing": math.pi}  # on the arena's east wall


def test_a_code_on_an_inner_wall_reads_back_from_its_side_only():
    world = world_of(walls=[PARTITION], landmarks=[SHELF])
    for distance in (1.0, 2.0):
        assert texts_in(front(world, looking_at(-0.05, 0.3, math.pi, distance))) == ["shelf"]
    # From the east, the wall's other face: no code.
    assert texts_in(front(world, (1.5, 0.3, math.pi))) == []


def test_an_inner_wall_hides_a_code_behind_it():
    pose = looking_at(3.0, 0.3, math.pi, 4.0)
    assert texts_in(front(world_of(landmarks=[DOOR]), pose)) == ["door"]
    assert texts_in(front(world_of(walls=[PARTITION], landmarks=[DOOR]), pose)) == []
    # A wall that hides only part of the code's columns spoils it too; one beside it doesn't.
    beside = {"from": [1.5, -1.9], "to": [1.5, -0.5], "thickness": 0.1}
    assert texts_in(front(world_of(walls=[beside], landmarks=[DOOR]), pose)) == ["door"]
    partly = {"from": [1.5, -1.9], "to": [1.5, 0.3], "thickness": 0.1}
    assert texts_in(front(world_of(walls=[partly], landmarks=[DOOR]), pose)) == []


def test_a_turned_box_in_front_hides_a_code():
    pose = looking_at(3.0, 0.3, math.pi, 2.5)
    crate = {"x": 1.5, "y": 0.3, "width": 0.5, "height": 0.5, "angle": math.pi / 4}
    aside = {**crate, "y": -1.2}
    assert texts_in(front(world_of(boxes=[aside], landmarks=[DOOR]), pose)) == ["door"]
    assert texts_in(front(world_of(boxes=[crate], landmarks=[DOOR]), pose)) == []


def test_the_front_camera_sees_an_inner_wall_and_a_box_where_they_stand():
    height = FRONT_SIZE[1]
    focal = FRONT_SIZE[0] / 2 / math.tan(FOV / 2)
    pose = (-1.5 - RADIUS, 0.3, 0.0)  # the camera 1.5 m from the partition's face

    def bottom_row(distance: float) -> float:  # where the floor meets a face this far ahead
        return height / 2 + focal * 0.2 / distance

    column = FRONT_SIZE[0] // 2
    open_floor = front(world_of(), pose).getpixel((column, round(bottom_row(1.45) - 3)))
    walled = front(world_of(walls=[PARTITION]), pose)
    face = walled.getpixel((column, round(bottom_row(1.45) - 3)))
    assert not near(face, open_floor, 10)  # the wall's face, not the floor in front of it
    assert near(walled.getpixel((column, round(bottom_row(1.45) + 6))), open_floor, 12)
    # A box turned 45 degrees, a corner towards the camera 1 m ahead: a brown face there.
    crate = {"x": 0.0, "y": 0.3, "width": 0.5, "height": 0.5, "angle": math.pi / 4}
    corner = -0.25 * math.sqrt(2)
    boxed = front(world_of(boxes=[crate]), (corner - 1.0 - RADIUS, 0.3, 0.0))
    red, green, blue = boxed.getpixel((column, round(bottom_row(1.0) - 20)))
    assert red > green + 25 > blue + 25


def test_the_front_camera_sees_the_painted_floor():
    zone = {"name": "red", "x": -1.0, "y": 0.0, "width": 1.0, "height": 1.0, "colour": "#e03030"}
    line = {"points": [[-0.4, -1.0], [-0.4, 1.0]], "width": 0.1, "colour": "#000000"}
    pose = (-2.2 - RADIUS, 0.0, 0.0)  # the camera 2.2 m west of the line, facing east
    image = front(world_of(zones=[zone], lines=[line]), pose)
    focal = FRONT_SIZE[0] / 2 / math.tan(FOV / 2)

    def floor_pixel(distance: float):
        return image.getpixel((FRONT_SIZE[0] // 2, round(240 + focal * 0.2 / distance)))

    red, green, _ = floor_pixel(1.0)  # in the zone, 0.5 m past its west edge
    assert red > green + 60
    assert max(floor_pixel(1.8)) < 80  # on the line
    bare = front(world_of(), pose).getpixel((320, round(240 + focal * 0.2 / 0.6)))
    assert near(floor_pixel(0.6), bare, 8)  # before the zone: the floor as in a bare world


@pytest.mark.parametrize("theta", [0.0, 0.7, math.pi / 2, 2.5, math.pi, -1.2])
def test_the_painted_floor_is_where_the_camera_looks_from_any_heading(theta):
    # A small blue square on the floor 1 m ahead and 0.3 m to the right of the camera.
    camera = (0.2, -0.1)
    ahead, right = (math.cos(theta), math.sin(theta)), (math.sin(theta), -math.cos(theta))
    x = camera[0] + ahead[0] * 1.0 + right[0] * 0.3
    y = camera[1] + ahead[1] * 1.0 + right[1] * 0.3
    spot = {"name": "spot", "x": x, "y": y, "width": 0.2, "height": 0.2, "colour": "#2040e0"}
    pose = (camera[0] - RADIUS * ahead[0], camera[1] - RADIUS * ahead[1], theta)
    image = front(world_of(zones=[spot]), pose)
    focal = FRONT_SIZE[0] / 2 / math.tan(FOV / 2)
    red, _, blue = image.getpixel((round(320 + focal * 0.3), round(240 + focal * 0.2)))
    assert blue > red + 80


def test_only_the_built_in_worlds_words_are_translated():
    # The boxes world's zones are robotide's words (kitchen: cozinha in pt-BR); the same zones
    # in a teacher's world are the teacher's words, drawn as written.
    from rhal.simulator.worlds import BUILTIN

    built_in = World.from_doc(BUILTIN["boxes"])
    teachers = World.from_doc({**BUILTIN["boxes"], "name": "my-boxes"})
    pose = built_in.start_pose

    def drawn(world, language):
        return render_top_view(world, pose, RADIUS, 1.0, False, (320, 240), language=language)

    assert drawn(built_in, "en") == drawn(teachers, "en")
    assert drawn(built_in, "pt-br") != drawn(teachers, "pt-br")
    assert drawn(teachers, "pt-br") != drawn(teachers, "en")  # the panel's words still are


def test_what_is_prepared_per_world_is_shared_by_equal_worlds(monkeypatch):
    # Each personal sim loads its stored world anew: equal worlds share the prepared drawing.
    import rhal.sim_front

    built = []
    real = rhal.sim_front._scene
    monkeypatch.setattr(rhal.sim_front, "_scene", lambda world: built.append(world) or real(world))
    monkeypatch.setattr(rhal.sim_front, "_kept", type(rhal.sim_front._kept)())
    for _ in range(3):
        front(World.from_doc(DRAWING), World.from_doc(DRAWING).start_pose)
    front(World.from_doc({**DRAWING, "boxes": []}), World.from_doc(DRAWING).start_pose)
    assert len(built) == 2


def test_a_wall_across_the_whole_view_is_seen_though_its_ends_are_not():
    # Its ends are 62 degrees left and right of ahead, outside the 62-degree view.
    across = {"from": [0.0, -1.9], "to": [0.0, 1.9], "thickness": 0.1}
    pose = (-1.0 - 0.05 - RADIUS, 0.0, 0.0)
    focal = FRONT_SIZE[0] / 2 / math.tan(FOV / 2)
    row = round(FRONT_SIZE[1] / 2 + focal * 0.2 / 1.0 - 4)  # just above its foot, 1 m ahead
    walled, bare = front(world_of(walls=[across]), pose), front(world_of(), pose)
    for column in (5, 320, 635):
        assert not near(walled.getpixel((column, row)), bare.getpixel((column, row)), 10)
