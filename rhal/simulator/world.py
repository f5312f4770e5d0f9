"""A sim world: the JSON document (format 1) as a validated, frozen ``World``.

Frame: x east, y north, metres, origin at the arena's centre; angles counter-clockwise from +x in
radians. The arena is a rectangle centred on the origin with walls on its four sides (implicit).
Inner walls are thick segments: the rectangle ``thickness`` wide around the segment, reaching
``thickness / 2`` past each end (square caps, so walls that meet at a point close the corner).
Boxes are rectangles turned by ``angle`` about their centre. Lines are painted on the floor, zones
are named floor rectangles (painted when they have a colour), landmarks are QR codes on walls.

``World.from_doc`` checks a document and says what is wrong in plain words with the place in the
document (``WorldError.path``, e.g. ``walls[2].to``); ``World.to_doc`` gives it back normalised
(every default filled in), and ``from_doc(to_doc())`` is the same world. The geometry the
simulator needs on every step (obstacle edges as one numpy array) is built once per world.
"""

from __future__ import annotations

import colorsys
import math
import re
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from rhal.simulator.geometry import Edges

FORMAT = 1
LIMITS = {"walls": 500, "boxes": 200, "lines": 100, "zones": 50, "landmarks": 50, "start": 20}
MAX_LINE_POINTS = 500
SIZE_RANGE = (1.0, 50.0)  # m, each side of the arena
FLOOR_COLOUR = "#ffffff"
#: Colour names the floor sensor reports, by hue (degrees) up to which each holds.
HUE_NAMES = ((15, "red"), (40, "orange"), (70, "yellow"), (165, "green"), (195, "cyan"),
             (255, "blue"), (290, "purple"), (345, "pink"), (360, "red"))  # fmt: skip
LANDMARK_REACH = 0.05  # m: a landmark stands on a wall when a wall is this close to it

Point = tuple[float, float]
Pose = tuple[float, float, float]


class WorldError(ValueError):
    """A world document that cannot be used: ``path`` says where, the message what and why."""

    def __init__(self, path: str, message: str) -> None:
        super().__init__(message)
        self.path = path
        self.message = message


# -- the parts -----------------------------------------------------------------------------


@dataclass(frozen=True)
class Wall:
    start: Point
    end: Point
    thickness: float = 0.05

    def corners(self) -> tuple[Point, Point, Point, Point]:
        """The wall's thick rectangle, square caps included, counter-clockwise."""
        (x1, y1), (x2, y2) = self.start, self.end
        length = math.hypot(x2 - x1, y2 - y1)
        half = self.thickness / 2
        ux, uy = ((x2 - x1) / length, (y2 - y1) / length) if length else (1.0, 0.0)
        nx, ny = -uy * half, ux * half  # across the wall
        ax, ay = x1 - ux * half, y1 - uy * half
        bx, by = x2 + ux * half, y2 + uy * half
        return ((ax - nx, ay - ny), (bx - nx, by - ny), (bx + nx, by + ny), (ax + nx, ay + ny))


@dataclass(frozen=True)
class Box:
    x: float
    y: float
    width: float
    height: float
    angle: float = 0.0

    def corners(self) -> tuple[Point, Point, Point, Point]:
        """The box's corners, counter-clockwise from the south-west one before turning."""
        c, s = math.cos(self.angle), math.sin(self.angle)
        w, h = self.width / 2, self.height / 2
        return tuple(
            (self.x + dx * c - dy * s, self.y + dx * s + dy * c)
            for dx, dy in ((-w, -h), (w, -h), (w, h), (-w, h))
        )  # type: ignore[return-value]

    # Its bounding box, so code drawing axis-aligned boxes (rhal.sim_render) can read it.
    @property
    def west(self) -> float:
        return min(x for x, _ in self.corners())

    @property
    def east(self) -> float:
        return max(x for x, _ in self.corners())

    @property
    def south(self) -> float:
        return min(y for _, y in self.corners())

    @property
    def north(self) -> float:
        return max(y for _, y in self.corners())


@dataclass(frozen=True)
class Landmark:
    """A square QR code on a wall: ``x, y`` the centre of the printed square on the wall's face,
    ``facing`` the direction of its normal into free space, ``size`` its side and ``height``
    the height of its centre above the floor (m)."""

    text: str
    x: float
    y: float
    facing: float
    size: float = 0.4
    height: float = 0.3


@dataclass(frozen=True)
class Line:
    points: tuple[Point, ...]
    width: float = 0.03
    colour: str = "#000000"


@dataclass(frozen=True)
class Zone:
    name: str
    x: float
    y: float
    width: float
    height: float
    colour: str | None = None

    def contains(self, x: float, y: float) -> bool:
        return abs(x - self.x) <= self.width / 2 and abs(y - self.y) <= self.height / 2


@dataclass(frozen=True)
class RobotSpec:
    """The world's robot: its size and sensors (docs/simulator.md describes the models)."""

    radius: float = 0.15
    cone_deg: float = 15.0
    rays: int = 5
    min_range: float = 0.03
    max_range: float = 4.0
    sonar: tuple[float, ...] = ()  # degrees CCW from ahead
    floor_sensor: bool = False

    def to_doc(self) -> dict[str, Any]:
        return {
            "radius": self.radius,
            "range": {
                "cone_deg": self.cone_deg,
                "rays": self.rays,
                "min": self.min_range,
                "max": self.max_range,
            },
            "sonar": list(self.sonar),
            "floor_sensor": self.floor_sensor,
        }


# -- the world -----------------------------------------------------------------------------


@dataclass(frozen=True)
class World:
    name: str
    title: str
    width: float
    height: float
    walls: tuple[Wall, ...] = ()
    boxes: tuple[Box, ...] = ()
    landmarks: tuple[Landmark, ...] = ()
    lines: tuple[Line, ...] = ()
    zones: tuple[Zone, ...] = ()
    start: tuple[Pose, ...] = ((0.0, 0.0, math.pi / 2),)
    robot: RobotSpec = field(default_factory=RobotSpec)
    #: obstacle edges (N, 4): x1, y1, x2, y2, the arena's own walls first
    segments: np.ndarray = field(init=False, repr=False, compare=False)
    #: the same edges with their directions and lengths worked out (rhal.simulator.geometry)
    edges: Edges = field(init=False, repr=False, compare=False)
    #: obstacles as convex quadrilaterals (M, 4, 2), counter-clockwise: walls, then boxes
    quads: np.ndarray = field(init=False, repr=False, compare=False)
    _quad_edges: tuple[np.ndarray, ...] = field(init=False, repr=False, compare=False)
    #: painted line pieces, their half widths and the index of the line each is part of
    _strokes: tuple[Edges, np.ndarray, np.ndarray] = field(init=False, repr=False, compare=False)

    def __post_init__(self) -> None:
        hw, hh = self.half_width, self.half_height
        outer = [(-hw, -hh, hw, -hh), (hw, -hh, hw, hh), (hw, hh, -hw, hh), (-hw, hh, -hw, -hh)]
        quads = [_ccw(wall.corners()) for wall in self.walls] + [
            _ccw(box.corners()) for box in self.boxes
        ]
        edges = [(*q[i], *q[(i + 1) % 4]) for q in quads for i in range(4)]
        object.__setattr__(self, "segments", np.array(outer + edges, dtype=float))
        object.__setattr__(self, "edges", Edges(self.segments))
        corners = np.array(quads, dtype=float).reshape(-1, 4, 2)
        object.__setattr__(self, "quads", corners)
        following = np.roll(corners, -1, axis=1)
        object.__setattr__(
            self,
            "_quad_edges",
            (corners[..., 0], corners[..., 1], following[..., 0] - corners[..., 0],
             following[..., 1] - corners[..., 1]),
        )  # fmt: skip
        strokes, halves, owners = [], [], []
        for index, line in enumerate(self.lines):
            for a, b in zip(line.points, line.points[1:], strict=False):
                strokes.append((*a, *b))
                halves.append(line.width / 2)
                owners.append(index)
        object.__setattr__(
            self,
            "_strokes",
            (
                Edges(np.array(strokes, dtype=float).reshape(-1, 4)),
                np.array(halves, dtype=float),
                np.array(owners, dtype=int),
            ),
        )

    @property
    def half_width(self) -> float:
        return self.width / 2

    @property
    def half_height(self) -> float:
        return self.height / 2

    @property
    def start_pose(self) -> Pose:
        return self.start[0]

    # -- geometry --------------------------------------------------------------------------

    def clearance(self, x: float, y: float) -> float:
        """Distance from a point to the nearest obstacle surface (walls, boxes, the arena's
        walls); negative inside an obstacle or outside the arena."""
        nearest = self.edges.nearest(x, y)
        if self.inside_obstacle(x, y) or abs(x) > self.half_width or abs(y) > self.half_height:
            return -nearest
        return nearest

    def inside_obstacle(self, x: float, y: float) -> bool:
        """True if the point is strictly inside a wall or a box."""
        if not len(self.quads):
            return False
        ax, ay, ex, ey = self._quad_edges
        cross = ex * (y - ay) - ey * (x - ax)
        return bool((cross > 0).all(axis=1).any())

    def ray_distance(self, x: float, y: float, theta: float, max_range: float) -> float:
        """Distance along ``theta`` from a point to the first obstacle surface, at most
        ``max_range``."""
        hits = self.edges.ray_hits(x, y, np.array([theta]))
        return float(min(hits[0], max_range))

    def zone_at(self, x: float, y: float) -> str | None:
        """The name of the zone the point is in (the last listed, on top), or None."""
        for zone in reversed(self.zones):
            if zone.contains(x, y):
                return zone.name
        return None

    def floor_at(self, x: float, y: float) -> tuple[str, str, int]:
        """(colour name, "#rrggbb", light %) of the floor at a point: a painted line over a
        painted zone over the white floor."""
        colour = FLOOR_COLOUR
        for zone in reversed(self.zones):
            if zone.colour and zone.contains(x, y):
                colour = zone.colour
                break
        strokes, halves, owners = self._strokes
        if len(strokes):
            on = strokes.distances(x, y) <= halves
            if on.any():
                colour = self.lines[int(owners[on].max())].colour  # the last drawn is on top
        return colour_name(colour), colour, light_percent(colour)

    # -- documents -------------------------------------------------------------------------

    @classmethod
    def from_doc(cls, doc: Any) -> World:
        """The world a document describes; WorldError says what is wrong and where."""
        return _parse(doc)

    def to_doc(self) -> dict[str, Any]:
        """The world as a normalised document (every default filled in)."""
        return {
            "format": FORMAT,
            "name": self.name,
            "title": self.title,
            "size": {"width": self.width, "height": self.height},
            "walls": [
                {"from": list(w.start), "to": list(w.end), "thickness": w.thickness}
                for w in self.walls
            ],
            "boxes": [
                {"x": b.x, "y": b.y, "width": b.width, "height": b.height, "angle": b.angle}
                for b in self.boxes
            ],
            "landmarks": [
                {
                    "text": m.text,
                    "x": m.x,
                    "y": m.y,
                    "facing": m.facing,
                    "size": m.size,
                    "height": m.height,
                }
                for m in self.landmarks
            ],  # fmt: skip
            "lines": [
                {
                    "points": [list(p) for p in line.points],
                    "width": line.width,
                    "colour": line.colour,
                }
                for line in self.lines
            ],  # fmt: skip
            "zones": [
                {"name": z.name, "x": z.x, "y": z.y, "width": z.width, "height": z.height}
                | ({"colour": z.colour} if z.colour else {})
                for z in self.zones
            ],
            "start": [{"x": x, "y": y, "theta": theta} for x, y, theta in self.start],
            "robot": self.robot.to_doc(),
        }


def colour_name(colour: str) -> str:
    """The plain name of ``#rrggbb``: black, white or grey when it is dull, else its hue's
    (red, orange, brown, yellow, green, cyan, blue, purple, pink)."""
    hue, saturation, value = colorsys.rgb_to_hsv(*(c / 255 for c in _rgb(colour)))
    if value < 0.2:
        return "black"
    if saturation < 0.15:
        return "white" if value > 0.8 else "grey" if value > 0.35 else "black"
    degrees = hue * 360
    name = next(name for top, name in HUE_NAMES if degrees < top or top == 360)
    return "brown" if name == "orange" and value < 0.6 else name


def light_percent(colour: str) -> int:
    """What a downward light sensor reads over ``#rrggbb``: 6 (black) to 94 (white) %, from the
    colour's relative luminance (no sensor sees pure 0 or 100)."""
    linear = [
        (c / 255) / 12.92 if c <= 10 else ((c / 255 + 0.055) / 1.055) ** 2.4 for c in _rgb(colour)
    ]
    luminance = 0.2126 * linear[0] + 0.7152 * linear[1] + 0.0722 * linear[2]
    return round(6 + 88 * luminance)


def _rgb(colour: str) -> tuple[int, int, int]:
    return int(colour[1:3], 16), int(colour[3:5], 16), int(colour[5:7], 16)


def _ccw(corners: tuple[Point, ...]) -> list[Point]:
    """The corners counter-clockwise (the inside test assumes it)."""
    (ax, ay), (bx, by), (cx, cy) = corners[0], corners[1], corners[2]
    if (bx - ax) * (cy - ay) - (by - ay) * (cx - ax) < 0:
        return list(reversed(corners))
    return list(corners)


# -- parsing and validation ----------------------------------------------------------------

_COLOUR = re.compile(r"^#[0-9a-fA-F]{6}$")
_TOP_KEYS = {"format", "name", "title", "size", "walls", "boxes", "landmarks", "lines", "zones",
             "start", "robot", "description", "id"}  # fmt: skip


def _parse(doc: Any) -> World:
    _mapping(doc, "", "the world")
    fmt = doc.get("format", FORMAT)
    if fmt != FORMAT or isinstance(fmt, bool):
        raise WorldError("format", f"this is a world of format {fmt!r}; only format 1 is known")
    name = _text(doc.get("name", "world"), "name", "the world's name", 60)
    title = _text(doc.get("title", name), "title", "the world's title", 200)
    size = _mapping(doc.get("size"), "size", "the arena's size")
    _keys(size, {"width", "height"}, "size")
    width = _number(size.get("width"), "size.width", "the arena's width", *SIZE_RANGE)
    height = _number(size.get("height"), "size.height", "the arena's height", *SIZE_RANGE)
    arena = _Arena(width / 2, height / 2)
    robot = _robot(doc.get("robot", {}))
    if "start" not in doc:  # none given: the centre, facing north
        doc = {**doc, "start": [{"x": 0.0, "y": 0.0, "theta": math.pi / 2}]}
    world = World(
        name=name,
        title=title,
        width=width,
        height=height,
        walls=tuple(_items(doc, "walls", lambda d, p, n: _wall(d, p, n, arena))),
        boxes=tuple(_items(doc, "boxes", lambda d, p, n: _box(d, p, n, arena))),
        landmarks=tuple(_items(doc, "landmarks", lambda d, p, n: _landmark(d, p, n, arena))),
        lines=tuple(_items(doc, "lines", lambda d, p, n: _line(d, p, n, arena))),
        zones=tuple(_items(doc, "zones", lambda d, p, n: _zone(d, p, n, arena))),
        start=tuple(_items(doc, "start", lambda d, p, n: _start(d, p, n, arena))),
        robot=robot,
    )
    if not world.start:
        raise WorldError("start", "the world needs at least one start pose")
    _unique_zone_names(world)
    _check_places(world)
    return world


@dataclass(frozen=True)
class _Arena:
    half_width: float
    half_height: float

    def check_inside(self, point: Point, path: str, what: str) -> None:
        x, y = point
        if x > self.half_width + 1e-9:
            self._outside(path, what, "x", x, "east", self.half_width)
        if x < -self.half_width - 1e-9:
            self._outside(path, what, "x", x, "west", -self.half_width)
        if y > self.half_height + 1e-9:
            self._outside(path, what, "y", y, "north", self.half_height)
        if y < -self.half_height - 1e-9:
            self._outside(path, what, "y", y, "south", -self.half_height)

    @staticmethod
    def _outside(path: str, what: str, axis: str, value: float, side: str, at: float) -> None:
        raise WorldError(
            path,
            f"{what} outside the arena ({axis} {value:.2f} m, the arena's {side} wall is at "
            f"{axis} {at:.2f} m)",
        )


def _items(doc: dict, key: str, parse: Any) -> list:
    items = doc.get(key, [])
    if not isinstance(items, list):
        raise WorldError(key, f"{key} must be a list, not {_kind(items)}")
    if len(items) > LIMITS[key]:
        raise WorldError(key, f"a world has at most {LIMITS[key]} {key}; this one has {len(items)}")
    return [parse(item, f"{key}[{index}]", index + 1) for index, item in enumerate(items)]


def _wall(doc: Any, path: str, number: int, arena: _Arena) -> Wall:
    _mapping(doc, path, f"wall {number}")
    _keys(doc, {"from", "to", "thickness"}, path)
    start = _point(doc.get("from"), f"{path}.from", f"wall {number}'s start")
    end = _point(doc.get("to"), f"{path}.to", f"wall {number}'s end")
    thickness = _number(
        doc.get("thickness", 0.05), f"{path}.thickness", f"wall {number}'s thickness", 0.01, 1.0
    )
    arena.check_inside(start, f"{path}.from", f"wall {number} starts")
    arena.check_inside(end, f"{path}.to", f"wall {number} ends")
    if math.dist(start, end) < 0.01:
        raise WorldError(path, f"wall {number} is shorter than 1 cm (its ends are the same point)")
    return Wall(start, end, thickness)


def _box(doc: Any, path: str, number: int, arena: _Arena) -> Box:
    _mapping(doc, path, f"box {number}")
    _keys(doc, {"x", "y", "width", "height", "angle"}, path)
    what = f"box {number}"
    box = Box(
        x=_number(doc.get("x"), f"{path}.x", f"{what}'s x"),
        y=_number(doc.get("y"), f"{path}.y", f"{what}'s y"),
        width=_number(doc.get("width"), f"{path}.width", f"{what}'s width", 0.01, 50.0),
        height=_number(doc.get("height"), f"{path}.height", f"{what}'s height", 0.01, 50.0),
        angle=_number(doc.get("angle", 0.0), f"{path}.angle", f"{what}'s angle"),
    )
    for corner in box.corners():
        arena.check_inside(corner, path, f"{what} reaches")
    return box


def _landmark(doc: Any, path: str, number: int, arena: _Arena) -> Landmark:
    _mapping(doc, path, f"landmark {number}")
    _keys(doc, {"text", "x", "y", "facing", "size", "height"}, path)
    what = f"landmark {number}"
    mark = Landmark(
        text=_text(doc.get("text"), f"{path}.text", f"{what}'s text", 200),
        x=_number(doc.get("x"), f"{path}.x", f"{what}'s x"),
        y=_number(doc.get("y"), f"{path}.y", f"{what}'s y"),
        facing=_number(doc.get("facing"), f"{path}.facing", f"{what}'s facing"),
        size=_number(doc.get("size", 0.4), f"{path}.size", f"{what}'s size", 0.05, 2.0),
        height=_number(doc.get("height", 0.3), f"{path}.height", f"{what}'s height", 0.0, 3.0),
    )
    arena.check_inside((mark.x, mark.y), path, f"{what} is")
    return mark


def _line(doc: Any, path: str, number: int, arena: _Arena) -> Line:
    _mapping(doc, path, f"line {number}")
    _keys(doc, {"points", "width", "colour"}, path)
    points = doc.get("points")
    if not isinstance(points, list) or not 2 <= len(points) <= MAX_LINE_POINTS:
        raise WorldError(
            f"{path}.points",
            f"line {number} needs a list of 2 to {MAX_LINE_POINTS} points, not {_kind(points)}",
        )
    parsed = []
    for index, point in enumerate(points):
        at = f"{path}.points[{index}]"
        parsed.append(_point(point, at, f"point {index + 1} of line {number}"))
        arena.check_inside(parsed[-1], at, f"point {index + 1} of line {number} is")
    width = _number(doc.get("width", 0.03), f"{path}.width", f"line {number}'s width", 0.005, 1.0)
    colour = _colour(doc.get("colour", "#000000"), f"{path}.colour", f"line {number}'s colour")
    return Line(tuple(parsed), width, colour)


def _zone(doc: Any, path: str, number: int, arena: _Arena) -> Zone:
    _mapping(doc, path, f"zone {number}")
    _keys(doc, {"name", "x", "y", "width", "height", "colour"}, path)
    what = f"zone {number}"
    colour = doc.get("colour")
    zone = Zone(
        name=_text(doc.get("name"), f"{path}.name", f"{what}'s name", 60),
        x=_number(doc.get("x"), f"{path}.x", f"{what}'s x"),
        y=_number(doc.get("y"), f"{path}.y", f"{what}'s y"),
        width=_number(doc.get("width"), f"{path}.width", f"{what}'s width", 0.01, 50.0),
        height=_number(doc.get("height"), f"{path}.height", f"{what}'s height", 0.01, 50.0),
        colour=None if colour is None else _colour(colour, f"{path}.colour", f"{what}'s colour"),
    )
    for dx in (-1, 1):
        for dy in (-1, 1):
            corner = (zone.x + dx * zone.width / 2, zone.y + dy * zone.height / 2)
            arena.check_inside(corner, path, f"{what} ({zone.name}) reaches")
    return zone


def _start(doc: Any, path: str, number: int, arena: _Arena) -> Pose:
    _mapping(doc, path, f"start pose {number}")
    _keys(doc, {"x", "y", "theta"}, path)
    what = f"start pose {number}"
    x = _number(doc.get("x"), f"{path}.x", f"{what}'s x")
    y = _number(doc.get("y"), f"{path}.y", f"{what}'s y")
    theta = _number(doc.get("theta", 0.0), f"{path}.theta", f"{what}'s theta")
    arena.check_inside((x, y), path, f"{what} is")
    return (x, y, theta)


def _robot(doc: Any) -> RobotSpec:
    _mapping(doc, "robot", "the robot")
    _keys(doc, {"radius", "range", "sonar", "floor_sensor"}, "robot")
    default = RobotSpec()
    cone = _mapping(doc.get("range", {}), "robot.range", "the range sensor")
    _keys(cone, {"cone_deg", "rays", "min", "max"}, "robot.range")
    rays = cone.get("rays", default.rays)
    if isinstance(rays, bool) or not isinstance(rays, int) or not 1 <= rays <= 31:
        raise WorldError("robot.range.rays", f"rays must be a whole number 1 to 31, not {rays!r}")
    sonar = doc.get("sonar", [])
    if not isinstance(sonar, list) or len(sonar) > 32:
        raise WorldError("robot.sonar", "sonar must be a list of at most 32 angles in degrees")
    floor = doc.get("floor_sensor", default.floor_sensor)
    if not isinstance(floor, bool):
        raise WorldError("robot.floor_sensor", f"floor_sensor must be true or false, not {floor!r}")
    spec = RobotSpec(
        radius=_number(doc.get("radius", default.radius), "robot.radius", "the robot's radius",
                       0.05, 1.0),
        cone_deg=_number(cone.get("cone_deg", default.cone_deg), "robot.range.cone_deg",
                         "the range cone's width", 0.0, 90.0),
        rays=rays,
        min_range=_number(cone.get("min", default.min_range), "robot.range.min",
                          "the range sensor's minimum", 0.0, 5.0),
        max_range=_number(cone.get("max", default.max_range), "robot.range.max",
                          "the range sensor's maximum", 0.1, 50.0),
        sonar=tuple(
            _number(angle, f"robot.sonar[{i}]", f"sonar {i + 1}'s angle", -180.0, 180.0)
            for i, angle in enumerate(sonar)
        ),
        floor_sensor=floor,
    )  # fmt: skip
    if spec.min_range >= spec.max_range:
        raise WorldError("robot.range", "the range sensor's minimum must be below its maximum")
    return spec


def _unique_zone_names(world: World) -> None:
    seen: set[str] = set()
    for index, zone in enumerate(world.zones):
        if zone.name in seen:
            raise WorldError(f"zones[{index}].name", f"two zones are called {zone.name!r}")
        seen.add(zone.name)


def _check_places(world: World) -> None:
    """Start poses clear of everything for the robot's radius; landmarks on a wall."""
    import shapely  # only to check a document: a sim running a built-in world does without

    radius = world.robot.radius
    arena = shapely.box(-world.half_width, -world.half_height, world.half_width, world.half_height)
    obstacles = [("wall", i, shapely.Polygon(w.corners())) for i, w in enumerate(world.walls)]
    obstacles += [("box", i, shapely.Polygon(b.corners())) for i, b in enumerate(world.boxes)]
    for index, (x, y, _) in enumerate(world.start):
        body = shapely.Point(x, y).buffer(radius)
        where = f"start pose {index + 1} (x {x:.2f}, y {y:.2f})"
        if not arena.buffer(1e-9).contains(body):
            raise WorldError(
                f"start[{index}]",
                f"{where} is too near the arena's wall: the robot (radius {radius:.2f} m) "
                f"needs {radius:.2f} m clear around it",
            )
        for kind, number, shape in obstacles:
            if shape.distance(shapely.Point(x, y)) < radius - 1e-9:
                raise WorldError(
                    f"start[{index}]",
                    f"{where} overlaps {kind} {number + 1}: the robot (radius {radius:.2f} m) "
                    f"needs {radius:.2f} m clear around it",
                )
    surfaces = shapely.union_all([arena.exterior] + [shape.boundary for *_, shape in obstacles])
    for index, mark in enumerate(world.landmarks):
        gap = surfaces.distance(shapely.Point(mark.x, mark.y))
        if gap > LANDMARK_REACH:
            raise WorldError(
                f"landmarks[{index}]",
                f"landmark {index + 1} ({mark.text!r}) is not on a wall: the nearest wall is "
                f"{gap:.2f} m away",
            )
        ahead = (mark.x + 0.1 * math.cos(mark.facing), mark.y + 0.1 * math.sin(mark.facing))
        if world.clearance(*ahead) <= 0:
            raise WorldError(
                f"landmarks[{index}].facing",
                f"landmark {index + 1} ({mark.text!r}) faces into its wall; "
                "facing is the direction into free space",
            )


# -- value checks --------------------------------------------------------------------------


def _kind(value: Any) -> str:
    if value is None:
        return "nothing"
    return {bool: "true/false", str: "a text", list: "a list", dict: "an object"}.get(
        type(value), "a number" if isinstance(value, int | float) else type(value).__name__
    )


def _mapping(value: Any, path: str, what: str) -> dict:
    if not isinstance(value, dict):
        raise WorldError(path, f"{what} must be an object, not {_kind(value)}")
    return value


def _keys(doc: dict, known: set[str], path: str) -> None:
    unknown = sorted(set(doc) - known)
    if unknown:
        at = f"{path}.{unknown[0]}" if path else unknown[0]
        raise WorldError(at, f"unknown key {unknown[0]!r} (known: {', '.join(sorted(known))})")


def _number(
    value: Any, path: str, what: str, low: float = -math.inf, high: float = math.inf
) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise WorldError(path, f"{what} must be a number, not {_kind(value)}")
    number = float(value)
    if not math.isfinite(number):
        raise WorldError(path, f"{what} must be a finite number")
    if not low <= number <= high:
        raise WorldError(path, f"{what} must be {low:g} to {high:g}, not {number:g}")
    return number


def _point(value: Any, path: str, what: str) -> Point:
    if not isinstance(value, list | tuple) or len(value) != 2:
        raise WorldError(path, f"{what} must be a point [x, y], not {_kind(value)}")
    return (
        _number(value[0], f"{path}[0]", f"{what}'s x"),
        _number(value[1], f"{path}[1]", f"{what}'s y"),
    )


def _text(value: Any, path: str, what: str, longest: int) -> str:
    if not isinstance(value, str):
        raise WorldError(path, f"{what} must be a text, not {_kind(value)}")
    if not value.strip():
        raise WorldError(path, f"{what} is empty")
    if len(value) > longest:
        raise WorldError(path, f"{what} is longer than {longest} characters")
    return value


def _colour(value: Any, path: str, what: str) -> str:
    if not isinstance(value, str) or not _COLOUR.match(value):
        raise WorldError(path, f"{what} must be a colour like #ff8800, not {value!r}")
    return value.lower()
