"""Draw the simulated robot's camera: a top-down view of its arena, as JPEG bytes.

Layout of the frame: the arena fills the square on the left (side = frame height), centred,
north up, with an 8 px margin; a panel on the right prints the main readings. Pillow is imported
here, and this module only when a camera frame is first asked for.
"""

from __future__ import annotations

import io
import math

from PIL import Image, ImageDraw, ImageFont

from rhal.arena import Arena
from rhal.kinematics import compass_heading

MARGIN = 8
FLOOR = (236, 236, 226)
WALL = (60, 60, 60)
BOX = (150, 100, 60)
ROBOT = (30, 90, 220)
HEADING = (255, 255, 255)
RAY = (230, 40, 40)
PANEL = (32, 32, 32)
TEXT = (230, 230, 230)


def render_top_view(
    arena: Arena,
    pose: tuple[float, float, float],
    radius: float,
    range_m: float,
    bumper: bool,
    size: tuple[int, int],
) -> bytes:
    height = size[1]
    image = Image.new("RGB", size, PANEL)
    draw = ImageDraw.Draw(image)
    scale = (height - 2 * MARGIN) / (2 * max(arena.half_width, arena.half_height))
    centre = height / 2

    def to_pixel(x: float, y: float) -> tuple[float, float]:
        return centre + x * scale, centre - y * scale

    north_west = to_pixel(-arena.half_width, arena.half_height)
    south_east = to_pixel(arena.half_width, -arena.half_height)
    draw.rectangle((*north_west, *south_east), fill=FLOOR, outline=WALL, width=3)
    for box in arena.boxes:
        draw.rectangle((*to_pixel(box.west, box.north), *to_pixel(box.east, box.south)), fill=BOX)

    x, y, theta = pose
    ahead_x, ahead_y = math.cos(theta), math.sin(theta)
    centre_px = to_pixel(x, y)
    nose_px = to_pixel(x + ahead_x * radius, y + ahead_y * radius)
    hit_px = to_pixel(x + ahead_x * range_m, y + ahead_y * range_m)
    draw.line((*nose_px, *hit_px), fill=RAY, width=1)
    r = radius * scale
    disc = (centre_px[0] - r, centre_px[1] - r, centre_px[0] + r, centre_px[1] + r)
    draw.ellipse(disc, fill=ROBOT, outline=RAY if bumper else ROBOT, width=2)
    draw.line((*centre_px, *nose_px), fill=HEADING, width=2)

    lines = [
        f"hdg {compass_heading(theta):5.1f}",
        f"rng {range_m:4.2f} m",
        f"x {x:+.2f} m",
        f"y {y:+.2f} m",
        "BUMP" if bumper else "",
    ]
    draw.multiline_text(
        (height + 6, MARGIN), "\n".join(lines), fill=TEXT, font=ImageFont.load_default()
    )

    buffer = io.BytesIO()
    image.save(buffer, "JPEG", quality=80)
    return buffer.getvalue()
