"""Draw the simulated robot's cameras, as JPEG bytes.

The camera (the robot page's view) looks down on the arena: the arena fills the square on the
left (side = frame height), centred, north up, with an 8 px margin; a panel on the right prints
the main readings; landmarks are marked on the walls with their text.

The front camera is what a camera on the robot's nose would see: a pinhole camera at
``FRONT_CAMERA_HEIGHT`` looking straight ahead, with the horizontal field of view it is given.
Walls and boxes are ray cast per column; each landmark's QR code (made with zxing-cpp's writer)
is drawn in true perspective on its wall, boxes in front hide it, and it is as sharp as the
frame's pixels allow, so a code far away or seen at a slant is as hard to read as for a real
camera. Pillow, numpy and zxing-cpp are imported here, and this module only when a frame is
first asked for.
"""

from __future__ import annotations

import functools
import io
import math

import numpy as np
import zxingcpp
from PIL import Image, ImageDraw, ImageFont

from rhal.arena import Arena, Landmark
from rhal.kinematics import compass_heading
from rhal.sim_words import word

MARGIN = 8
FLOOR = (236, 236, 226)
WALL = (60, 60, 60)
BOX = (150, 100, 60)
ROBOT = (30, 90, 220)
HEADING = (255, 255, 255)
RAY = (230, 40, 40)
PANEL = (32, 32, 32)
TEXT = (230, 230, 230)
SIGN = (250, 250, 250)
INK = (20, 20, 20)

# The front camera, on the robot's nose.
FRONT_CAMERA_HEIGHT = 0.2  # m above the floor
WALL_HEIGHT = 0.6  # m
BOX_HEIGHT = 0.35  # m
NEAR = 0.02  # m: nothing nearer than this to the lens is drawn
ROOM = (205, 212, 220)  # above the walls
FLOOR_NEAR, FLOOR_FAR = np.array((150, 140, 120)), np.array((200, 192, 176))
WALL_SHADES = {"north": (176, 180, 168), "east": (160, 166, 176), "south": (184, 176, 164),
               "west": (168, 172, 160)}  # fmt: skip
BOX_SHADES = ((150, 100, 60), (122, 80, 46))  # north and south faces, east and west faces


def render_top_view(
    arena: Arena,
    pose: tuple[float, float, float],
    radius: float,
    range_m: float,
    bumper: bool,
    size: tuple[int, int],
    language: str = "en",
) -> bytes:
    """The arena from above, its words (the rooms' names, the panel's labels) in ``language``
    (rhal.sim_words)."""
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

    for landmark in arena.landmarks:
        _mark_landmark(draw, landmark, to_pixel, scale, word(language, landmark.text))

    lines = [
        f"{word(language, 'hdg')} {compass_heading(theta):5.1f}",
        f"{word(language, 'rng')} {range_m:4.2f} m",
        f"x {x:+.2f} m",
        f"y {y:+.2f} m",
        word(language, "BUMP") if bumper else "",
    ]
    draw.multiline_text(
        (height + 6, MARGIN), "\n".join(lines), fill=TEXT, font=ImageFont.load_default()
    )

    buffer = io.BytesIO()
    image.save(buffer, "JPEG", quality=80)
    return buffer.getvalue()


def _mark_landmark(
    draw: ImageDraw.ImageDraw, landmark: Landmark, to_pixel, scale: float, label: str
) -> None:
    """A landmark seen from above: a white strip on its wall and its name just inside."""
    normal = (math.cos(landmark.facing), math.sin(landmark.facing))
    half = landmark.size / 2
    ends = [
        to_pixel(landmark.x - normal[1] * half * k, landmark.y + normal[0] * half * k)
        for k in (-1, 1)
    ]
    draw.line((*ends[0], *ends[1]), fill=SIGN, width=3)
    # Anchored on the side that touches the wall: l(eft), r(ight), t(op) or b(ottom).
    anchor = {(1, 0): "lm", (-1, 0): "rm", (0, 1): "mb", (0, -1): "mt"}[
        (round(normal[0]), round(normal[1]))
    ]
    inside = 5 / scale  # 5 px
    at = to_pixel(landmark.x + normal[0] * inside, landmark.y + normal[1] * inside)
    draw.text(at, label, fill=INK, font=ImageFont.load_default(), anchor=anchor)


# -- the front camera ---------------------------------------------------------------------------


def render_front_view(
    arena: Arena, pose: tuple[float, float, float], radius: float, size: tuple[int, int], fov: float
) -> bytes:
    """What a camera on the robot's nose sees, as JPEG bytes; ``fov`` in radians."""
    image = front_view(arena, pose, radius, size, fov)
    buffer = io.BytesIO()
    image.save(buffer, "JPEG", quality=90)
    return buffer.getvalue()


def front_view(
    arena: Arena, pose: tuple[float, float, float], radius: float, size: tuple[int, int], fov: float
) -> Image.Image:
    width, height = size
    x, y, theta = pose
    camera = (x + radius * math.cos(theta), y + radius * math.sin(theta))
    focal = (width / 2) / math.tan(fov / 2)
    centre_u, centre_v = width / 2, height / 2
    # One ray per pixel column; a positive offset is to the right, i.e. clockwise.
    offsets = np.arctan((np.arange(width) + 0.5 - centre_u) / focal)
    cos_offsets = np.cos(offsets)
    directions = theta - offsets
    dx, dy = np.cos(directions), np.sin(directions)
    wall_t, wall_names = _walls_hit(arena, camera, dx, dy)
    box_t, box_lit = _boxes_hit(arena, camera, dx, dy)

    rows = np.arange(height)[:, None] + 0.5
    pixels = np.empty((height, width, 3), dtype=np.float32)
    # Floor below the horizon, lighter with distance; the room above it.
    below = np.clip((rows - centre_v) / (height / 2), 0.0, 1.0)
    floor = FLOOR_FAR + (FLOOR_NEAR - FLOOR_FAR) * below
    pixels[:] = np.where((rows > centre_v)[:, :, None], floor[:, None, :], ROOM)
    wall_depth = np.maximum(wall_t * cos_offsets, NEAR)
    _fill_band(pixels, rows, wall_depth, WALL_HEIGHT, focal, centre_v, _wall_colours(wall_names))
    image = Image.fromarray(pixels.astype(np.uint8), "RGB")
    for landmark in arena.landmarks:
        _draw_landmark(image, landmark, camera, theta, focal, (centre_u, centre_v))
    in_front = box_t < wall_t
    if in_front.any():
        pixels = np.asarray(image).astype(np.float32)
        box_depth = np.maximum(np.where(in_front, box_t, np.inf) * cos_offsets, NEAR)
        colours = np.where(box_lit[:, None], BOX_SHADES[0], BOX_SHADES[1])
        _fill_band(pixels, rows, box_depth, BOX_HEIGHT, focal, centre_v, colours)
        image = Image.fromarray(pixels.astype(np.uint8), "RGB")
    return image


def _walls_hit(arena: Arena, origin, dx: np.ndarray, dy: np.ndarray):
    """Distance along each ray to the wall it meets, and which wall that is."""
    x, y = origin
    with np.errstate(divide="ignore", invalid="ignore"):
        tx = np.where(dx > 0, arena.half_width - x, -arena.half_width - x) / dx
        ty = np.where(dy > 0, arena.half_height - y, -arena.half_height - y) / dy
    tx = np.where(np.isfinite(tx) & (tx >= 0), tx, np.inf)
    ty = np.where(np.isfinite(ty) & (ty >= 0), ty, np.inf)
    east_west = np.where(dx > 0, "east", "west")
    north_south = np.where(dy > 0, "north", "south")
    names = np.where(tx < ty, east_west, north_south)
    return np.minimum(tx, ty), names


def _boxes_hit(arena: Arena, origin, dx: np.ndarray, dy: np.ndarray):
    """Distance along each ray to the nearest box it enters (inf: none), and whether the face
    it meets is a north or south one: those are drawn lighter, so a box's corners show."""
    x, y = origin
    nearest = np.full(dx.shape, np.inf)
    lit = np.zeros(dx.shape, dtype=bool)
    with np.errstate(divide="ignore", invalid="ignore"):
        for box in arena.boxes:
            x1, x2 = (box.west - x) / dx, (box.east - x) / dx
            y1, y2 = (box.south - y) / dy, (box.north - y) / dy
            x_near, x_far = np.minimum(x1, x2), np.maximum(x1, x2)
            y_near, y_far = np.minimum(y1, y2), np.maximum(y1, y2)
            # A ray parallel to a pair of faces is inside that slab or misses the box.
            inside_x = (box.west <= x) & (x <= box.east)
            inside_y = (box.south <= y) & (y <= box.north)
            x_near = np.where(dx == 0, np.where(inside_x, -np.inf, np.inf), x_near)
            x_far = np.where(dx == 0, np.where(inside_x, np.inf, -np.inf), x_far)
            y_near = np.where(dy == 0, np.where(inside_y, -np.inf, np.inf), y_near)
            y_far = np.where(dy == 0, np.where(inside_y, np.inf, -np.inf), y_far)
            enter = np.maximum(x_near, y_near)
            leave = np.minimum(x_far, y_far)
            hit = (enter <= leave) & (leave >= 0)
            distance = np.where(hit, np.maximum(enter, 0.0), np.inf)
            closer = distance < nearest
            nearest = np.where(closer, distance, nearest)
            lit = np.where(closer, x_near < y_near, lit)  # entered through a south/north face
    return nearest, lit


def _wall_colours(names: np.ndarray) -> np.ndarray:
    colours = np.empty((names.size, 3), dtype=np.float32)
    for name, shade in WALL_SHADES.items():
        colours[names == name] = shade
    return colours


def _fill_band(pixels, rows, depth, top_height, focal, centre_v, colours) -> None:
    """Paint, in each column, the rows between the floor and ``top_height`` at ``depth``."""
    top = centre_v - focal * (top_height - FRONT_CAMERA_HEIGHT) / depth
    bottom = centre_v + focal * FRONT_CAMERA_HEIGHT / depth
    band = (rows >= top[None, :]) & (rows < bottom[None, :])
    # Farther is dimmer, a little: it helps the eye, not the decoder.
    light = np.clip(1.05 - 0.06 * depth, 0.75, 1.0)[:, None]
    shaded = np.broadcast_to(colours * light, (pixels.shape[1], 3))
    pixels[band] = np.broadcast_to(shaded[None, :, :], pixels.shape)[band]


def _draw_landmark(image: Image.Image, landmark: Landmark, camera, theta, focal, centre) -> None:
    """Paste the landmark's code in perspective, if the camera faces its printed side."""
    normal = (math.cos(landmark.facing), math.sin(landmark.facing))
    if (camera[0] - landmark.x) * normal[0] + (camera[1] - landmark.y) * normal[1] <= 0:
        return  # behind its wall
    along = (-normal[1], normal[0])  # the code's left-to-right, seen from the front
    half = landmark.size / 2
    forward = (math.cos(theta), math.sin(theta))
    right = (math.sin(theta), -math.cos(theta))
    corners = []
    for side, up in ((-1, 1), (1, 1), (1, -1), (-1, -1)):  # top left, clockwise
        px = landmark.x + along[0] * half * side - camera[0]
        py = landmark.y + along[1] * half * side - camera[1]
        depth = px * forward[0] + py * forward[1]
        if depth < NEAR:
            return  # partly behind the lens
        u = centre[0] + focal * (px * right[0] + py * right[1]) / depth
        v = centre[1] - focal * (landmark.height + half * up - FRONT_CAMERA_HEIGHT) / depth
        corners.append((u, v))
    us = [u for u, _ in corners]
    vs = [v for _, v in corners]
    if max(us) < 0 or min(us) > image.width or max(vs) < 0 or min(vs) > image.height:
        return
    span = max(math.dist(corners[i], corners[(i + 1) % 4]) for i in range(4))
    texture = _code_texture(landmark.text, max(4, min(2048, round(span))))
    n = texture.width
    coefficients = _perspective(corners, [(0, 0), (n, 0), (n, n), (0, n)])
    warped = texture.transform(
        image.size, Image.Transform.PERSPECTIVE, coefficients, Image.Resampling.BILINEAR
    )
    mask = Image.new("L", texture.size, 255).transform(
        image.size, Image.Transform.PERSPECTIVE, coefficients, Image.Resampling.BILINEAR
    )
    image.paste(warped, (0, 0), mask)


@functools.lru_cache(maxsize=64)
def _code_module_image(text: str) -> Image.Image:
    """The QR code for ``text`` with its quiet zone, one pixel per module."""
    code = zxingcpp.create_barcode(text, zxingcpp.BarcodeFormat.QRCode)
    modules = np.asarray(code.to_image(scale=1, add_quiet_zones=True))
    ink = np.where(modules < 128, INK[0], SIGN[0]).astype(np.uint8)
    return Image.fromarray(np.stack([ink] * 3, axis=-1), "RGB")


@functools.lru_cache(maxsize=256)
def _code_texture(text: str, pixels: int) -> Image.Image:
    """The code about ``pixels`` wide: crisp when enlarged, averaged when made smaller, as a
    lens would."""
    modules = _code_module_image(text)
    if pixels >= modules.width:
        scale = -(-pixels // modules.width)
        return modules.resize((modules.width * scale,) * 2, Image.Resampling.NEAREST)
    return modules.resize((pixels, pixels), Image.Resampling.BOX)


def _perspective(image_points, texture_points) -> tuple[float, ...]:
    """Pillow's PERSPECTIVE coefficients: for a frame pixel, where to read the texture."""
    rows, values = [], []
    for (u, v), (tx, ty) in zip(image_points, texture_points, strict=True):
        rows.append([u, v, 1, 0, 0, 0, -tx * u, -tx * v])
        rows.append([0, 0, 0, u, v, 1, -ty * u, -ty * v])
        values.extend((tx, ty))
    return tuple(np.linalg.solve(np.array(rows), np.array(values)).tolist())
