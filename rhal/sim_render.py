"""Draw the simulated robot's cameras, as JPEG bytes: what the server still draws of a sim (for
pages without scripts and the Robot API's ``snapshot()``; the browser draws the live view).

The camera (the robot page's picture) looks down on the world, north up, scaled to fit beside
or, for a wide world, above a panel that prints the main readings; a 4 m square world fills
the square on the left (side = frame height) with an 8 px margin. It draws zones (their names
written on them), painted lines, boxes, inner walls, the landmarks on the walls, the robot
with its range beam as a cone, and its bumper (a red rim) when pressed.

The front camera is in rhal.sim_front. Pillow is imported here, and this module only when a
frame is first asked for.
"""

from __future__ import annotations

import functools
import io
import math
from dataclasses import dataclass
from typing import TYPE_CHECKING

from PIL import Image, ImageDraw, ImageFont

from rhal.kinematics import compass_heading
from rhal.sim_front import front_view, per_world, rgb
from rhal.sim_words import word

if TYPE_CHECKING:
    from rhal.simulator.world import Landmark, World

MARGIN = 8
PANEL_SIDE = 80  # px: the panel's width beside the map
PANEL_BELOW = 30  # px: its height under a map that fits better that way
FLOOR = (236, 236, 226)
WALL = (60, 60, 60)
BOX = (150, 100, 60)
BOX_EDGE = (110, 72, 42)
ZONE_EDGE = (170, 170, 160)  # a zone with no paint: its outline only
ROBOT = (30, 90, 220)
HEADING = (255, 255, 255)
RAY = (230, 40, 40)
BEAM_ALPHA = 70  # of 255: the range cone is see-through
PANEL = (32, 32, 32)
TEXT = (230, 230, 230)
SIGN = (250, 250, 250)
INK = (20, 20, 20)
MIN_ROBOT_PX = 3  # a robot in a 50 m world stays visible
MIN_LABELLED_PX = 16  # a zone drawn narrower is not named


def render_top_view(
    world: World,
    pose: tuple[float, float, float],
    radius: float,
    range_m: float,
    bumper: bool,
    size: tuple[int, int],
    language: str = "en",
    cone_deg: float | None = None,
) -> bytes:
    """The world from above, its words (the built-in worlds' room names, the panel's labels)
    in ``language`` (rhal.sim_words); ``range_m`` is the range reading, from the centre, drawn
    as a cone ``cone_deg`` wide (by default the world's robot's)."""
    background, layout = per_world(_still_layer, world, size, language)
    image = background.copy()
    x, y, theta = pose
    cone = math.radians(world.robot.cone_deg if cone_deg is None else cone_deg)
    _draw_beam(image, layout, pose, range_m, cone)
    _draw_robot(ImageDraw.Draw(image), layout, pose, radius, bumper)
    readings = [
        f"{word(language, 'hdg')} {compass_heading(theta):5.1f}",
        f"{word(language, 'rng')} {range_m:4.2f} m",
        f"x {x:+.2f} m",
        f"y {y:+.2f} m",
        word(language, "BUMP") if bumper else "",
    ]
    if layout.beside:
        text = "\n".join(readings)
    else:
        text = "   ".join(readings[:2] + readings[4:]) + "\n" + "   ".join(readings[2:4])
    ImageDraw.Draw(image).multiline_text(layout.panel, text, fill=TEXT, font=_font())
    buffer = io.BytesIO()
    image.save(buffer, "JPEG", quality=80)
    return buffer.getvalue()


def render_front_view(
    world: World, pose: tuple[float, float, float], radius: float, size: tuple[int, int], fov: float
) -> bytes:
    """What a camera on the robot's nose sees, as JPEG bytes; ``fov`` in radians."""
    image = front_view(world, pose, radius, size, fov)
    buffer = io.BytesIO()
    image.save(buffer, "JPEG", quality=90)
    return buffer.getvalue()


# -- the top view -------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Layout:
    """Where the world goes in the frame: ``scale`` px a metre, the world origin's pixel, and
    the panel's top left corner (beside the map or under it)."""

    scale: float
    centre: tuple[float, float]
    panel: tuple[int, int]
    beside: bool

    def pixel(self, x: float, y: float) -> tuple[float, float]:
        return self.centre[0] + x * self.scale, self.centre[1] - y * self.scale


def layout_for(world: World, size: tuple[int, int]) -> Layout:
    """Beside or under the map, whichever lets the world be drawn larger."""
    width, height = size

    def fit(area_width: int, area_height: int) -> float:
        return min(
            (area_width - 2 * MARGIN) / world.width, (area_height - 2 * MARGIN) / world.height
        )

    beside, under = fit(width - PANEL_SIDE, height), fit(width, height - PANEL_BELOW)
    if beside >= under:
        centre = ((width - PANEL_SIDE) / 2, height / 2)
        return Layout(beside, centre, (width - PANEL_SIDE + 6, MARGIN), True)
    # The map with the panel right under it, the two centred in the frame's height.
    map_height = world.height * under + 2 * MARGIN
    above = (height - map_height - PANEL_BELOW) / 2
    centre = (width / 2, above + map_height / 2)
    return Layout(under, centre, (MARGIN, round(above + map_height + 3)), False)


@functools.lru_cache(maxsize=1)
def _font() -> ImageFont.FreeTypeFont | ImageFont.ImageFont:
    """DejaVu Sans (Debian's fonts-dejavu-core) writes a teacher's zone names with their
    accents, and Greek and Cyrillic; Pillow's own font has ASCII only."""
    try:
        return ImageFont.truetype("DejaVuSans.ttf", 10)
    except OSError:
        return ImageFont.load_default()


def _still_layer(world: World, size: tuple[int, int], language: str):
    """All that does not move, drawn once per world, size and language."""
    layout = layout_for(world, size)
    scale, to_pixel = layout.scale, layout.pixel
    image = Image.new("RGB", size, PANEL)
    draw = ImageDraw.Draw(image)
    hw, hh = world.half_width, world.half_height
    arena = (*to_pixel(-hw, hh), *to_pixel(hw, -hh))
    draw.rectangle(arena, fill=FLOOR)
    for zone in world.zones:
        corners = (
            *to_pixel(zone.x - zone.width / 2, zone.y + zone.height / 2),
            *to_pixel(zone.x + zone.width / 2, zone.y - zone.height / 2),
        )
        if zone.colour:
            draw.rectangle(corners, fill=rgb(zone.colour))
        else:
            draw.rectangle(corners, outline=ZONE_EDGE, width=1)
    for line in world.lines:
        points = [to_pixel(*point) for point in line.points]
        width = max(1, round(line.width * scale))
        draw.line(points, fill=rgb(line.colour), width=width, joint="curve" if width > 2 else None)
    for box in world.boxes:
        draw.polygon([to_pixel(*corner) for corner in box.corners()], fill=BOX, outline=BOX_EDGE)
    for wall in world.walls:
        draw.polygon([to_pixel(*corner) for corner in wall.corners()], fill=WALL, outline=WALL)
        if wall.thickness * scale < 2:  # too thin to see in a large world: 2 px
            draw.line((*to_pixel(*wall.start), *to_pixel(*wall.end)), fill=WALL, width=2)
    # Square wall ends reach past the arena's walls: trim them off.
    left, top, right, bottom = arena
    for outside in (
        (0, 0, size[0], top),
        (0, bottom, size[0], size[1]),
        (0, 0, left, size[1]),
        (right, 0, size[0], size[1]),
    ):
        draw.rectangle(outside, fill=PANEL)
    # 3 px, or 1 in an arena drawn a few pixels deep (50 m x 1 m)
    draw.rectangle(
        arena, outline=WALL, width=3 if min(world.width, world.height) * scale > 40 else 1
    )

    label = _labeller(world, language)
    zone_names = {zone.name for zone in world.zones}
    for landmark in world.landmarks:
        _mark_landmark(draw, landmark, layout, None if landmark.text in zone_names else label)
    for zone in world.zones:  # named at the top, clear of a robot starting at its middle
        if zone.width * scale < MIN_LABELLED_PX:
            continue  # a speck in a large world: its name would hide its neighbours
        ink = INK if zone.colour is None or _luma(rgb(zone.colour)) > 110 else SIGN
        name = label(zone.name)
        at = to_pixel(zone.x, zone.y + zone.height / 2)
        half = _font().getlength(name) / 2 + 4  # kept inside the arena's walls
        u = min(max(at[0], arena[0] + half), arena[2] - half)
        draw.text((u, at[1] + 5), name, fill=ink, font=_font(), anchor="mt")
    return image, layout


def _labeller(world: World, language: str):
    """Robotide's own words are translated (the built-in worlds' room names); a world's own
    text (a teacher's zone names and codes) is drawn as written."""
    from rhal.simulator.worlds import BUILTIN

    if world.name not in BUILTIN:
        return lambda text: text
    return lambda text: word(language, text)


def _luma(colour: tuple[int, int, int]) -> float:
    return 0.299 * colour[0] + 0.587 * colour[1] + 0.114 * colour[2]


def _mark_landmark(draw: ImageDraw.ImageDraw, landmark: Landmark, layout: Layout, label) -> None:
    """A landmark seen from above: a white strip on its wall and, unless a zone of the same
    name says it already, its name just inside."""
    normal = (math.cos(landmark.facing), math.sin(landmark.facing))
    half = landmark.size / 2
    ends = [
        layout.pixel(landmark.x - normal[1] * half * k, landmark.y + normal[0] * half * k)
        for k in (-1, 1)
    ]
    draw.line((*ends[0], *ends[1]), fill=SIGN, width=3)
    if label is None:
        return
    # Anchored on the side that touches the wall: l(eft), r(ight), t(op) or b(ottom).
    if abs(normal[0]) >= abs(normal[1]):
        anchor = "lm" if normal[0] > 0 else "rm"
    else:
        anchor = "mb" if normal[1] > 0 else "mt"
    inside = 5 / layout.scale  # 5 px
    at = layout.pixel(landmark.x + normal[0] * inside, landmark.y + normal[1] * inside)
    draw.text(at, label(landmark.text), fill=INK, font=_font(), anchor=anchor)


def _draw_beam(image: Image.Image, layout: Layout, pose, range_m: float, cone: float) -> None:
    """The range sensor's cone from the robot's centre to the range read, see-through."""
    x, y, theta = pose
    reach = max(0.0, min(range_m, 1e3)) * layout.scale
    if reach < 1:
        return
    cx, cy = layout.pixel(x, y)
    bounds = (cx - reach, cy - reach, cx + reach, cy + reach)
    # Pillow's angles run clockwise from east, the image's y being down.
    ahead, spread = -math.degrees(theta), max(math.degrees(cone), 1.0) / 2
    mask = Image.new("L", image.size, 0)
    ImageDraw.Draw(mask).pieslice(bounds, ahead - spread, ahead + spread, fill=BEAM_ALPHA)
    image.paste(RAY, (0, 0, *image.size), mask)
    draw = ImageDraw.Draw(image)
    draw.pieslice(bounds, ahead - spread, ahead + spread, outline=RAY, width=1)


def _draw_robot(draw: ImageDraw.ImageDraw, layout: Layout, pose, radius, bumper: bool) -> None:
    x, y, theta = pose
    cx, cy = layout.pixel(x, y)
    r = max(MIN_ROBOT_PX, radius * layout.scale)
    nose = (cx + r * math.cos(theta), cy - r * math.sin(theta))
    draw.ellipse(
        (cx - r, cy - r, cx + r, cy + r), fill=ROBOT, outline=RAY if bumper else ROBOT, width=2
    )
    draw.line((cx, cy, *nose), fill=HEADING, width=2)
