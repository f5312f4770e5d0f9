"""The simulated robot's front camera: what a camera on its nose would see.

A pinhole camera ``FRONT_CAMERA_HEIGHT`` above the floor looks straight ahead with the
horizontal field of view it is given. One ray per pixel column is cast against the world's
wall faces (the arena's, and both sides and ends of each inner wall) and box faces, at any
angle; the nearest wall fills its column from the floor to ``WALL_HEIGHT`` and a nearer box
to ``BOX_HEIGHT`` (walls and boxes are each of one height, so the nearest of each hides the
rest). The floor shows the world's painted lines and coloured zones: a texture of the floor
seen from above is mapped onto it by the plane's perspective. Each landmark's QR code (made
with zxing-cpp's writer) is drawn in true perspective on its wall, hidden where a nearer wall
or box stands in front, and as sharp as the frame's pixels allow, so a code far away or seen
at a slant is as hard to read as for a real camera.

What is the same every frame (faces, colours, the floor texture) is prepared once per world
(``per_world``): a sim's world does not change while it runs.
"""

from __future__ import annotations

import functools
import math
import threading
from collections import OrderedDict
from typing import TYPE_CHECKING, NamedTuple

import numpy as np
import zxingcpp
from PIL import Image, ImageChops, ImageDraw

if TYPE_CHECKING:
    from rhal.simulator.world import World

FRONT_CAMERA_HEIGHT = 0.2  # m above the floor
WALL_HEIGHT = 0.6  # m
BOX_HEIGHT = 0.35  # m
NEAR = 0.02  # m: nothing nearer than this to the lens is drawn
ROOM = (205, 212, 220)  # above the walls
FLOOR_PAINT = (200, 192, 176)  # the bare floor, as lit far away; nearer is darker
FLOOR_NEAR_LIGHT = 0.72  # the floor's light at the frame's bottom row, of its far light
FLOOR_TEXTURE_PX = 1024  # the longest side of a world's floor texture (3 MB, kept per world)
FLOOR_TEXTURE_MAX_SCALE = 256  # px a metre, for small worlds
# Faces running east-west (a north or a south face) are lit, north-south ones shaded, others
# between: a corner shows as a change of shade.
WALL_SHADES = ((182, 178, 166), (160, 166, 176))
BOX_SHADES = ((150, 100, 60), (122, 80, 46))
SIGN = (250, 250, 250)
INK = (20, 20, 20)
CHUNK = 256  # faces cast against at once: bounds the memory of a world of 500 walls
HIDDEN_MARGIN = 0.01  # m: a code this much behind a nearer surface counts as hidden


def rgb(colour: str) -> tuple[int, int, int]:
    """'#rrggbb' as a tuple."""
    return int(colour[1:3], 16), int(colour[3:5], 16), int(colour[5:7], 16)


# -- what is kept per world ------------------------------------------------------------------

_kept: OrderedDict = OrderedDict()
_kept_lock = threading.Lock()
KEEP = 16  # prepared drawings kept: a server's sims are in a few worlds


def per_world(build, world: World, *key):
    """``build(world, *key)``, made once for the last few worlds drawn. Worlds are frozen and
    compared by value, so personal sims in the same stored world share it (frames are drawn in
    worker threads: hence the lock)."""
    name = (build.__name__, world, *key)
    with _kept_lock:
        if name in _kept:
            _kept.move_to_end(name)
            return _kept[name]
    value = build(world, *key)
    with _kept_lock:
        _kept[name] = value
        while len(_kept) > KEEP:
            _kept.popitem(last=False)
    return value


class Placed(NamedTuple):
    """A landmark as drawn: its centre moved onto the face of its wall."""

    text: str
    x: float
    y: float
    facing: float
    size: float
    height: float
    face: np.ndarray  # (1, 4): the code's bottom edge as a segment, for hiding it


class Scene(NamedTuple):
    walls: np.ndarray  # (N, 4) faces x1, y1, x2, y2
    wall_colours: np.ndarray  # (N, 3)
    boxes: np.ndarray
    box_colours: np.ndarray
    landmarks: tuple[Placed, ...]
    floor: Image.Image | None  # the painted floor from above, None if bare
    floor_scale: float  # its px a metre


def _scene(world: World) -> Scene:
    hw, hh = world.half_width, world.half_height
    outer = [(-hw, -hh, hw, -hh), (hw, -hh, hw, hh), (hw, hh, -hw, hh), (-hw, hh, -hw, -hh)]
    walls = np.array(outer + _faces(wall.corners() for wall in world.walls), dtype=float)
    boxes = np.array(_faces(box.corners() for box in world.boxes), dtype=float).reshape(-1, 4)
    thickest = max((wall.thickness for wall in world.walls), default=0.0)
    landmarks = tuple(_place(mark, walls, boxes, thickest) for mark in world.landmarks)
    floor, floor_scale = _floor_texture(world)
    return Scene(
        walls,
        _shades(walls, WALL_SHADES),
        boxes,
        _shades(boxes, BOX_SHADES),
        landmarks,
        floor,
        floor_scale,
    )


def _faces(rectangles) -> list[tuple[float, float, float, float]]:
    faces = []
    for corners in rectangles:
        for i in range(4):
            faces.append((*corners[i], *corners[(i + 1) % 4]))
    return faces


def _shades(faces: np.ndarray, shades) -> np.ndarray:
    along_x = (faces[:, 2] - faces[:, 0]) ** 2
    length = along_x + (faces[:, 3] - faces[:, 1]) ** 2
    lit = np.divide(along_x, length, out=np.ones_like(length), where=length > 0)[:, None]
    return (np.array(shades[1]) + (np.array(shades[0]) - shades[1]) * lit).astype(np.float32)


def _place(mark, walls: np.ndarray, boxes: np.ndarray, thickest: float) -> Placed:
    """Wherever the document puts a landmark on its wall (on its face, or on its middle line
    inside a thick wall), draw it on the face, just in front: looking back from a little in
    front of it finds that face."""
    nx, ny = math.cos(mark.facing), math.sin(mark.facing)
    back_off = thickest / 2 + 0.02
    start = (mark.x + nx * back_off, mark.y + ny * back_off)
    reach = min(
        _cast(faces, start, np.array([-nx]), np.array([-ny]))[0][0] for faces in (walls, boxes)
    )
    x, y = mark.x, mark.y
    if reach <= back_off + 0.05:
        x, y = start[0] - nx * (reach - 0.002), start[1] - ny * (reach - 0.002)
    half = mark.size / 2 * 1.02  # a little wider: the code's blurred rim is not cut off
    face = np.array([[x + ny * half, y - nx * half, x - ny * half, y + nx * half]])
    return Placed(mark.text, x, y, mark.facing, mark.size, mark.height, face)


def _floor_texture(world: World) -> tuple[Image.Image | None, float]:
    """The floor's paint seen from above, north up, or None when the floor is bare. Drawn at
    twice the size and halved, so that edges are smooth where the camera enlarges them."""
    zones = [zone for zone in world.zones if zone.colour]
    if not zones and not world.lines:
        return None, 1.0
    scale = min(FLOOR_TEXTURE_MAX_SCALE, FLOOR_TEXTURE_PX / max(world.width, world.height))
    size = (max(1, round(world.width * scale)), max(1, round(world.height * scale)))
    texture = Image.new("RGB", (2 * size[0], 2 * size[1]), FLOOR_PAINT)
    draw = ImageDraw.Draw(texture)
    hw, hh = world.half_width, world.half_height

    def to_pixel(x: float, y: float) -> tuple[float, float]:
        return (x + hw) * 2 * scale, (hh - y) * 2 * scale

    for zone in zones:
        west_north = to_pixel(zone.x - zone.width / 2, zone.y + zone.height / 2)
        east_south = to_pixel(zone.x + zone.width / 2, zone.y - zone.height / 2)
        draw.rectangle((*west_north, *east_south), fill=rgb(zone.colour))
    for line in world.lines:
        width = max(2, round(line.width * 2 * scale))
        points = [to_pixel(*point) for point in line.points]
        draw.line(points, fill=rgb(line.colour), width=width, joint="curve" if width > 2 else None)
    return texture.reduce(2), scale


# -- a frame -----------------------------------------------------------------------------------


def front_view(
    world: World, pose: tuple[float, float, float], radius: float, size: tuple[int, int], fov: float
) -> Image.Image:
    scene = per_world(_scene, world)
    width, height = size
    x, y, theta = pose
    camera = (x + radius * math.cos(theta), y + radius * math.sin(theta))
    focal = (width / 2) / math.tan(fov / 2)
    centre = (width / 2, height / 2)
    # One ray per pixel column; a positive offset is to the right, i.e. clockwise.
    offsets = np.arctan((np.arange(width) + 0.5 - centre[0]) / focal)
    cos_offsets = np.cos(offsets)
    directions = theta - offsets
    dx, dy = np.cos(directions), np.sin(directions)
    half_view = math.atan(centre[0] / focal) + 0.01
    walls = _in_view(scene.walls, camera, theta, half_view)
    boxes = _in_view(scene.boxes, camera, theta, half_view)
    wall_t, wall_face = _cast(scene.walls[walls], camera, dx, dy)
    box_t, box_face = _cast(scene.boxes[boxes], camera, dx, dy)

    pixels = _backdrop(scene, camera, theta, focal, size)
    wall_depth = np.maximum(wall_t * cos_offsets, NEAR)
    colours = scene.wall_colours[walls][wall_face]
    pixels = _paint_band(pixels, wall_depth, WALL_HEIGHT, focal, centre[1], colours)
    image = Image.fromarray(pixels, "RGB")
    for landmark in scene.landmarks:  # boxes, drawn next, hide what they stand in front of
        _draw_landmark(image, landmark, camera, theta, focal, centre, (dx, dy), wall_t)
    in_front = box_t < wall_t
    if in_front.any():
        box_depth = np.maximum(np.where(in_front, box_t, np.inf) * cos_offsets, NEAR)
        colours = scene.box_colours[boxes][box_face]
        pixels = _paint_band(np.array(image), box_depth, BOX_HEIGHT, focal, centre[1], colours)
        image = Image.fromarray(pixels, "RGB")
    return image


def _in_view(faces: np.ndarray, camera, theta: float, half_view: float) -> np.ndarray:
    """Which faces may be in view: all but those with both ends behind the lens, or both
    beyond the same edge of the view (a world of 500 walls has most of its faces elsewhere)."""
    px = faces[:, 0::2] - camera[0]  # (N, 2): both ends
    py = faces[:, 1::2] - camera[1]

    def left_of(angle: float) -> np.ndarray:  # > 0: left of the line along ``angle``
        return math.cos(angle) * py - math.sin(angle) * px

    behind = ((math.cos(theta) * px + math.sin(theta) * py) <= 0).all(axis=1)
    beyond_left = (left_of(theta + half_view) > 0).all(axis=1)
    beyond_right = (left_of(theta - half_view) < 0).all(axis=1)
    return ~(behind | beyond_left | beyond_right)


def _cast(faces: np.ndarray, origin, dx: np.ndarray, dy: np.ndarray):
    """Distance along each ray (unit ``dx``, ``dy``) from ``origin`` to the nearest face it
    meets (inf: none), and that face's index."""
    nearest = np.full(dx.shape, np.inf)
    which = np.zeros(dx.shape, dtype=np.intp)
    if not len(faces):
        return nearest, which
    dx, dy = dx[:, None], dy[:, None]
    columns = np.arange(dx.shape[0])
    with np.errstate(divide="ignore", invalid="ignore"):
        for first in range(0, len(faces), CHUNK):
            x1, y1, x2, y2 = faces[first : first + CHUNK].T
            ex, ey = x2 - x1, y2 - y1
            px, py = x1 - origin[0], y1 - origin[1]
            # origin + t (dx, dy) = (x1, y1) + s (ex, ey), solved by cross products.
            across = dx * ey - dy * ex
            t = (px * ey - py * ex) / across
            s = (px * dy - py * dx) / across
            t = np.where((t > 0) & (s >= 0) & (s <= 1), t, np.inf)
            face = np.argmin(t, axis=1)
            t = t[columns, face]
            closer = t < nearest
            nearest = np.where(closer, t, nearest)
            which = np.where(closer, face + first, which)
    return nearest, which


def _floor_top(height: int) -> int:
    """The first row drawn from the floor's texture: the one after the horizon's, where the
    floor is finitely far (and the perspective map has no pole at its origin)."""
    return height // 2 + 1


@functools.lru_cache(maxsize=8)
def _light(size: tuple[int, int]) -> Image.Image:
    """The floor's light from ``_floor_top`` down, row by row, as a picture to multiply by."""
    width, height = size
    below = (np.arange(_floor_top(height), height) + 0.5 - height / 2) / (height / 2)
    light = 1.0 - (1.0 - FLOOR_NEAR_LIGHT) * np.clip(below, 0.0, 1.0)
    rows = np.round(255 * light).astype(np.uint8)
    return Image.fromarray(np.repeat(np.repeat(rows[:, None, None], width, 1), 3, 2), "RGB")


@functools.lru_cache(maxsize=8)
def _bare(size: tuple[int, int]) -> np.ndarray:
    """The room above the horizon and a bare floor below it."""
    width, height = size
    top = _floor_top(height)
    pixels = np.empty((height, width, 3), dtype=np.uint8)
    pixels[: height // 2] = ROOM
    pixels[height // 2 : top] = FLOOR_PAINT
    floor = ImageChops.multiply(Image.new("RGB", (width, height - top), FLOOR_PAINT), _light(size))
    pixels[top:] = np.asarray(floor)
    pixels.flags.writeable = False
    return pixels


def _backdrop(scene: Scene, camera, theta: float, focal: float, size) -> np.ndarray:
    """The room and the floor, its paint in perspective: the floor is a plane, so the map from
    a frame pixel below the horizon to the floor texture is a homography."""
    bare = _bare(size)
    if scene.floor is None:
        return bare
    width, height = size
    top = _floor_top(height)
    forward, right = (math.cos(theta), math.sin(theta)), (math.sin(theta), -math.cos(theta))
    texture, scale = scene.floor, scene.floor_scale
    pixels, spots = [], []
    for distance, across in ((0.5, -1.0), (0.5, 1.0), (5.0, -1.0), (5.0, 1.0)):
        pixels.append(
            (
                width / 2 + focal * across / distance,
                height / 2 + focal * FRONT_CAMERA_HEIGHT / distance - top,
            )
        )
        x = camera[0] + forward[0] * distance + right[0] * across
        y = camera[1] + forward[1] * distance + right[1] * across
        spots.append((texture.width / 2 + x * scale, texture.height / 2 - y * scale))
    floor = texture.transform(
        (width, height - top),
        Image.Transform.PERSPECTIVE,
        perspective(pixels, spots),
        Image.Resampling.BILINEAR,
        fillcolor=FLOOR_PAINT,
    )
    out = bare.copy()
    out[top:] = np.asarray(ImageChops.multiply(floor, _light(size)))
    return out


def _paint_band(pixels, depth, top_height, focal, centre_v, colours) -> np.ndarray:
    """Paint, in each column, the rows between the floor and ``top_height`` at ``depth`` (inf:
    nothing there); a copy if ``pixels`` is read-only."""
    out = pixels if pixels.flags.writeable else pixels.copy()
    height = out.shape[0]
    # Rows whose centre (row + 0.5) is in [top, bottom): a slice a column, far cheaper than
    # a mask over the whole frame.
    top = centre_v - focal * (top_height - FRONT_CAMERA_HEIGHT) / depth
    bottom = centre_v + focal * FRONT_CAMERA_HEIGHT / depth
    first = np.clip(np.ceil(top - 0.5), 0, height).astype(int)
    last = np.clip(np.ceil(bottom - 0.5), 0, height).astype(int)
    # Farther is dimmer, a little: it helps the eye, not the decoder.
    light = np.clip(1.05 - 0.06 * depth, 0.75, 1.0)[:, None]
    shaded = (colours * light).astype(np.uint8)
    for column in np.flatnonzero(last > first):
        out[first[column] : last[column], column] = shaded[column]
    return out


def _draw_landmark(image, landmark: Placed, camera, theta, focal, centre, rays, nearest) -> None:
    """Paste the landmark's code in perspective, if the camera faces its printed side, but
    not in the columns where a nearer wall stands in front of it."""
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
    us, vs = [u for u, _ in corners], [v for _, v in corners]
    left, top = max(0, math.floor(min(us))), max(0, math.floor(min(vs)))
    right_px, bottom = min(image.width, math.ceil(max(us))), min(image.height, math.ceil(max(vs)))
    if left >= right_px or top >= bottom:
        return  # off the frame
    span = max(math.dist(corners[i], corners[(i + 1) % 4]) for i in range(4))
    # Beyond 1024 px (a code filling the frame) its modules are large: bilinear is sharp enough.
    texture = _code_texture(landmark.text, max(4, min(1024, round(span))))
    n = texture.width
    local = [(u - left, v - top) for u, v in corners]
    warped = texture.transform(
        (right_px - left, bottom - top),
        Image.Transform.PERSPECTIVE,
        perspective(local, [(0, 0), (n, 0), (n, n), (0, n)]),
        Image.Resampling.BILINEAR,
    )
    dx, dy = rays
    code_t, _ = _cast(landmark.face, camera, dx[left:right_px], dy[left:right_px])
    hidden = nearest[left:right_px] < code_t - HIDDEN_MARGIN
    if hidden.any():
        alpha = np.array(warped.getchannel("A"))
        alpha[:, hidden] = 0
        warped.putalpha(Image.fromarray(alpha, "L"))
    image.paste(warped, (left, top), warped)


@functools.lru_cache(maxsize=64)
def _code_modules(text: str) -> Image.Image:
    """The QR code for ``text`` with its quiet zone, one pixel per module, opaque."""
    code = zxingcpp.create_barcode(text, zxingcpp.BarcodeFormat.QRCode)
    modules = np.asarray(code.to_image(scale=1, add_quiet_zones=True))
    ink = np.where(modules < 128, INK[0], SIGN[0]).astype(np.uint8)
    return Image.fromarray(np.stack([ink, ink, ink, np.full_like(ink, 255)], axis=-1), "RGBA")


def _code_texture(text: str, pixels: int) -> Image.Image:
    """The code about ``pixels`` wide: crisp when enlarged, averaged when made smaller, as a
    lens would."""
    width = _code_modules(text).width
    if pixels >= width:
        return _code_enlarged(text, -(-pixels // width))
    return _code_reduced(text, pixels)


@functools.lru_cache(maxsize=8)  # up to 4 MB each
def _code_enlarged(text: str, scale: int) -> Image.Image:
    modules = _code_modules(text)
    return modules.resize((modules.width * scale,) * 2, Image.Resampling.NEAREST)


@functools.lru_cache(maxsize=256)
def _code_reduced(text: str, pixels: int) -> Image.Image:
    return _code_modules(text).resize((pixels, pixels), Image.Resampling.BOX)


def perspective(image_points, texture_points) -> tuple[float, ...]:
    """Pillow's PERSPECTIVE coefficients: for a frame pixel, where to read the texture."""
    rows, values = [], []
    for (u, v), (tx, ty) in zip(image_points, texture_points, strict=True):
        rows.append([u, v, 1, 0, 0, 0, -tx * u, -tx * v])
        rows.append([0, 0, 0, u, v, 1, -ty * u, -ty * v])
        values.extend((tx, ty))
    return tuple(np.linalg.solve(np.array(rows), np.array(values)).tolist())
