"""Walls, box obstacles and landmarks of the simulated robot's arena.

The arena is a rectangle centred on the world origin (x east, y north, metres) with walls on
all four sides; boxes are axis-aligned rectangles inside it. Landmarks are square codes (QR
codes, as in "Using barcodes for robotic landmarks", the paper's reference 17) printed on the
walls, for the robot's front camera to read. Geometry is plain float arithmetic: it runs on
every sensor read.
"""

from __future__ import annotations

import math
from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class Box:
    """An axis-aligned obstacle: west, south, east and north edges in metres."""

    west: float
    south: float
    east: float
    north: float


@dataclass(frozen=True, slots=True)
class Landmark:
    """A square QR code on a wall, seen from the side its normal points to.

    ``x``, ``y`` is the centre of the printed square (quiet zone included) on the wall,
    ``facing`` the direction in radians (world frame) of its normal, into the arena, ``size``
    its side and ``height`` the height of its centre above the floor, in metres.
    """

    text: str
    x: float
    y: float
    facing: float
    size: float = 0.4
    height: float = 0.3


#: Wall name -> (the direction a code on it faces, into the arena).
WALL_FACING = {"north": -math.pi / 2, "east": math.pi, "south": math.pi / 2, "west": 0.0}


@dataclass(frozen=True, slots=True)
class Arena:
    """Walls at x = +-half_width and y = +-half_height, some boxes and landmarks inside."""

    half_width: float
    half_height: float
    boxes: tuple[Box, ...] = ()
    landmarks: tuple[Landmark, ...] = ()

    def on_wall(self, wall: str, along: float, text: str, **options: float) -> Landmark:
        """A landmark on ``wall`` ("north", "east", "south" or "west"), centred ``along``
        metres from the wall's middle (east or north of it is positive)."""
        facing = WALL_FACING[wall]
        if wall in ("north", "south"):
            y = self.half_height if wall == "north" else -self.half_height
            return Landmark(text, along, y, facing, **options)
        x = self.half_width if wall == "east" else -self.half_width
        return Landmark(text, x, along, facing, **options)

    def clearance(self, x: float, y: float) -> float:
        """Distance from a point to the nearest wall or box surface; 0 or less inside one."""
        nearest = min(self.half_width - abs(x), self.half_height - abs(y))
        for box in self.boxes:
            dx = box.west - x if x < box.west else (x - box.east if x > box.east else 0.0)
            dy = box.south - y if y < box.south else (y - box.north if y > box.north else 0.0)
            # Skipping boxes that cannot be nearer keeps this cheap: it runs on every read.
            if dx < nearest and dy < nearest:
                nearest = min(nearest, math.hypot(dx, dy))
        return nearest

    def ray_distance(self, x: float, y: float, theta: float, max_range: float) -> float:
        """Distance from a point inside the arena along ``theta`` to the first surface."""
        dx, dy = math.cos(theta), math.sin(theta)
        nearest = max_range
        # From inside, the ray leaves through the wall it is heading towards on each axis.
        if dx:
            nearest = min(nearest, ((self.half_width if dx > 0 else -self.half_width) - x) / dx)
        if dy:
            nearest = min(nearest, ((self.half_height if dy > 0 else -self.half_height) - y) / dy)
        for box in self.boxes:
            hit = _ray_box_entry(x, y, dx, dy, box)
            if hit is not None and hit < nearest:
                nearest = hit
        return max(nearest, 0.0)


def _ray_box_entry(x: float, y: float, dx: float, dy: float, box: Box) -> float | None:
    """Slab test: distance along the ray to where it enters ``box``, or None if it misses."""
    near, far = -math.inf, math.inf
    if dx:
        near, far = _ordered((box.west - x) / dx, (box.east - x) / dx)
    elif not box.west <= x <= box.east:
        return None
    if dy:
        low, high = _ordered((box.south - y) / dy, (box.north - y) / dy)
        near, far = (low if low > near else near), (high if high < far else far)
    elif not box.south <= y <= box.north:
        return None
    if near > far or far < 0.0:
        return None
    return near if near > 0.0 else 0.0


def _ordered(a: float, b: float) -> tuple[float, float]:
    return (a, b) if a <= b else (b, a)


def _with_landmarks(arena: Arena, *places: tuple[str, float, str]) -> Arena:
    landmarks = tuple(arena.on_wall(wall, along, text) for wall, along, text in places)
    return Arena(arena.half_width, arena.half_height, arena.boxes, landmarks)


#: The codes on the walls of both arenas: (wall, metres along it, text). "home" is the one the
#: paper's "I'm home" example looks for.
LANDMARKS = (
    ("north", -0.5, "kitchen"),
    ("east", -0.8, "lab"),
    ("south", 0.6, "garage"),
    ("west", 0.3, "home"),
)

#: Named arenas for the ``arena`` option. Both are 4 m x 4 m; "boxes" adds two obstacles in the
#: north-east and south-west quarters and leaves the paths due north, east, south and west of
#: the centre clear, so from the start the range ahead is the 2 m to the wall.
ARENAS: dict[str, Arena] = {
    "boxes": _with_landmarks(
        Arena(2.0, 2.0, (Box(0.8, 0.5, 1.3, 1.0), Box(-1.5, -1.3, -0.9, -0.7))), *LANDMARKS
    ),
    "square": _with_landmarks(Arena(2.0, 2.0), *LANDMARKS),
}
