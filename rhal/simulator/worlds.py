"""The built-in worlds, as documents (rhal.simulator.world's format), and ``load()``.

- ``boxes`` (the default) and ``square``: the two arenas the sim has always had, 4 m x 4 m with a
  QR code on each wall (kitchen, lab, garage, home) and a zone of the same name 1 m wide and
  0.6 m deep in front of each; ``boxes`` adds two boxes in the north-east and south-west
  quarters, leaving the paths due north, east, south and west of the centre clear.
- ``maze``: 5 m x 5 m, corridors 1 m wide from the south-west corner to a goal in the north-east
  one; the robot has a ring of five sonars.
- ``line``: a black oval painted on a white floor, the robot on it with a floor sensor.
- ``rooms``: three rooms joined by doorways, with painted floors and a table.
"""

from __future__ import annotations

import copy
import math
from typing import Any

from rhal.simulator.world import World, WorldError

NORTH, EAST, SOUTH, WEST = -math.pi / 2, math.pi, math.pi / 2, 0.0  # a code's facing on each wall


def _landmarks_and_zones(half: float) -> tuple[list[dict], list[dict]]:
    """The codes of the two old arenas and the zones in front of them (1 m x 0.6 m)."""
    depth = 0.6
    places = [  # text, x, y, facing, zone colour
        ("kitchen", -0.5, half, NORTH, "#ffe08a"),
        ("lab", half, -0.8, EAST, "#bfe3ff"),
        ("garage", 0.6, -half, SOUTH, "#d9d9d9"),
        ("home", -half, 0.3, WEST, "#c9f0c0"),
    ]
    landmarks, zones = [], []
    for text, x, y, facing, colour in places:
        landmarks.append({"text": text, "x": x, "y": y, "facing": facing})
        along_x = facing in (NORTH, SOUTH)  # the zone runs along a north or south wall
        zones.append(
            {
                "name": text,
                "x": x + math.cos(facing) * depth / 2,
                "y": y + math.sin(facing) * depth / 2,
                "width": 1.0 if along_x else depth,
                "height": depth if along_x else 1.0,
                "colour": colour,
            }
        )
    for zone in zones:  # cos/sin of the facings leave 1e-17 crumbs
        zone["x"], zone["y"] = round(zone["x"], 9), round(zone["y"], 9)
    return landmarks, zones


def _arena(name: str, title: str, boxes: list[dict]) -> dict[str, Any]:
    landmarks, zones = _landmarks_and_zones(2.0)
    return {
        "format": 1,
        "name": name,
        "title": title,
        "size": {"width": 4.0, "height": 4.0},
        "boxes": boxes,
        "landmarks": landmarks,
        "zones": zones,
        "start": [{"x": 0.0, "y": 0.0, "theta": math.pi / 2}],
    }


def _maze() -> dict[str, Any]:
    # Corridors on a 1 m grid: a serpentine with stubs, the openings at alternate ends.
    walls = [
        ((-2.5, -1.5), (1.5, -1.5)),
        ((-1.5, -0.5), (2.5, -0.5)),
        ((-2.5, 0.5), (1.5, 0.5)),
        ((-1.5, 1.5), (2.5, 1.5)),
        ((0.5, -2.5), (0.5, -2.0)),
        ((-0.5, -1.0), (-0.5, -0.5)),
        ((0.5, 0.5), (0.5, 1.0)),
        ((-0.5, 2.0), (-0.5, 2.5)),
    ]
    return {
        "format": 1,
        "name": "maze",
        "title": "Maze",
        "size": {"width": 5.0, "height": 5.0},
        "walls": [{"from": list(a), "to": list(b), "thickness": 0.05} for a, b in walls],
        "landmarks": [{"text": "goal", "x": 2.5, "y": 2.0, "facing": EAST}],
        "zones": [
            {"name": "start", "x": -2.0, "y": -2.0, "width": 0.9, "height": 0.9},
            {"name": "goal", "x": 2.0, "y": 2.0, "width": 0.9, "height": 0.9, "colour": "#8fd694"},
        ],
        "start": [{"x": -2.0, "y": -2.0, "theta": 0.0}],
        "robot": {"sonar": [90, 45, 0, -45, -90], "floor_sensor": True},
    }


def _oval(half_straight: float, radius: float, arc_points: int) -> list[list[float]]:
    """A closed stadium: straights along y = -+radius, half-circles at each end (CCW)."""
    points = []
    for end, start_angle in ((half_straight, -math.pi / 2), (-half_straight, math.pi / 2)):
        for k in range(arc_points + 1):
            angle = start_angle + math.pi * k / arc_points
            points.append([round(end + radius * math.cos(angle), 6),
                           round(radius * math.sin(angle), 6)])  # fmt: skip
    points.append(points[0])
    return points


def _line() -> dict[str, Any]:
    return {
        "format": 1,
        "name": "line",
        "title": "Line track",
        "size": {"width": 4.0, "height": 3.0},
        "lines": [{"points": _oval(0.9, 0.8, 24), "width": 0.04, "colour": "#000000"}],
        "start": [{"x": 0.0, "y": -0.8, "theta": 0.0}],  # on the line, going round it CCW
        "robot": {"floor_sensor": True},
    }


def _rooms() -> dict[str, Any]:
    walls = [  # two walls across the arena, each with a doorway 0.8 m wide
        ((-1.0, -2.0), (-1.0, -0.4)),
        ((-1.0, 0.4), (-1.0, 2.0)),
        ((1.0, -2.0), (1.0, 0.9)),
        ((1.0, 1.7), (1.0, 2.0)),
    ]
    return {
        "format": 1,
        "name": "rooms",
        "title": "Rooms with doorways",
        "size": {"width": 6.0, "height": 4.0},
        "walls": [{"from": list(a), "to": list(b), "thickness": 0.05} for a, b in walls],
        "boxes": [{"x": 2.0, "y": -1.0, "width": 0.6, "height": 0.4, "angle": 0.3}],
        "landmarks": [
            {"text": "bedroom", "x": -3.0, "y": 0.0, "facing": WEST},
            {"text": "hall", "x": 0.0, "y": 2.0, "facing": NORTH},
            {"text": "kitchen", "x": 3.0, "y": 0.0, "facing": EAST},
        ],
        "zones": [
            {
                "name": "bedroom",
                "x": -2.0,
                "y": 0.0,
                "width": 1.9,
                "height": 4.0,
                "colour": "#d8c8f0",
            },
            {"name": "hall", "x": 0.0, "y": 0.0, "width": 1.9, "height": 4.0},
            {
                "name": "kitchen",
                "x": 2.0,
                "y": 0.0,
                "width": 1.9,
                "height": 4.0,
                "colour": "#ffe08a",
            },
        ],  # fmt: skip
        "start": [{"x": 0.0, "y": 0.0, "theta": math.pi / 2}, {"x": -2.0, "y": 0.0, "theta": 0.0}],
        "robot": {"floor_sensor": True},
    }


#: Built-in world documents by name.
BUILTIN: dict[str, dict[str, Any]] = {
    "boxes": _arena(
        "boxes",
        "Two boxes",
        [
            {"x": 1.05, "y": 0.75, "width": 0.5, "height": 0.5, "angle": 0.0},
            {"x": -1.2, "y": -1.0, "width": 0.6, "height": 0.6, "angle": 0.0},
        ],
    ),
    "square": _arena("square", "Empty square", []),
    "maze": _maze(),
    "line": _line(),
    "rooms": _rooms(),
}

_loaded: dict[str, World] = {}


def load(name_or_doc: str | dict[str, Any]) -> World:
    """A built-in world by name, or the world of a document (WorldError if it is not valid)."""
    if isinstance(name_or_doc, dict):
        return World.from_doc(name_or_doc)
    if name_or_doc not in BUILTIN:
        known = ", ".join(BUILTIN)
        raise WorldError("", f"there is no built-in world {name_or_doc!r}; built in: {known}")
    if name_or_doc not in _loaded:  # worlds are frozen: one per name is enough
        _loaded[name_or_doc] = World.from_doc(copy.deepcopy(BUILTIN[name_or_doc]))
    return _loaded[name_or_doc]
