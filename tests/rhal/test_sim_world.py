"""rhal.simulator.world: the world document, checked with plain-words errors, and its geometry."""

import copy
import json
import math

import numpy as np
import pytest

from rhal.simulator.world import World, WorldError
from rhal.simulator.worlds import BUILTIN, load


def boxes_doc() -> dict:
    return copy.deepcopy(BUILTIN["boxes"])


def refused(doc) -> WorldError:
    with pytest.raises(WorldError) as caught:
        World.from_doc(doc)
    return caught.value


@pytest.mark.parametrize("name", sorted(BUILTIN))
def test_every_built_in_world_is_valid_and_round_trips(name):
    world = load(name)
    doc = world.to_doc()
    assert json.loads(json.dumps(doc)) == doc
    assert World.from_doc(doc) == world
    assert World.from_doc(doc).to_doc() == doc
    assert world.clearance(*world.start_pose[:2]) >= world.robot.radius


def test_the_boxes_world_is_the_old_arena():
    world = load("boxes")
    assert (world.width, world.height, world.start_pose) == (4.0, 4.0, (0.0, 0.0, math.pi / 2))
    edges = [edge for b in world.boxes for edge in (b.west, b.south, b.east, b.north)]
    assert edges == pytest.approx([0.8, 0.5, 1.3, 1.0, -1.5, -1.3, -0.9, -0.7])
    places = {m.text: (m.x, m.y) for m in world.landmarks}
    assert places == {"kitchen": (-0.5, 2.0), "lab": (2.0, -0.8), "garage": (0.6, -2.0),
                      "home": (-2.0, 0.3)}  # fmt: skip
    assert load("square").boxes == () and load("square").landmarks == world.landmarks


@pytest.mark.parametrize(
    ("name", "inside", "outside"),
    [("kitchen", (-0.5, 1.5), (-0.5, 1.3)), ("lab", (1.5, -0.4), (1.5, 0.0)),
     ("garage", (1.05, -1.5), (1.2, -1.5)), ("home", (-1.45, 0.3), (-1.35, 0.3))],
)  # fmt: skip
def test_each_zone_is_1_m_wide_and_60_cm_deep_in_front_of_its_landmark(name, inside, outside):
    for world in (load("boxes"), load("square")):
        assert world.zone_at(*inside) == name
        assert world.zone_at(*outside) is None


def test_segments_include_the_arena_walls_and_thick_walls_and_turned_boxes():
    doc = {
        "size": {"width": 4, "height": 3},
        "walls": [{"from": [0, -1], "to": [0, 1], "thickness": 0.1}],
        "boxes": [{"x": 1, "y": 0.5, "width": 0.4, "height": 0.2, "angle": math.pi / 4}],
        "start": [{"x": -1, "y": 0, "theta": 0}],
    }
    world = World.from_doc(doc)
    assert world.segments.shape == (12, 4)
    assert world.clearance(-1.0, 0.0) == pytest.approx(1.0 - 0.05)  # to the wall's west face
    assert world.clearance(0.0, 1.1) == pytest.approx(0.05)  # beyond its square cap
    assert world.clearance(0.0, 0.0) < 0  # inside the wall
    assert world.clearance(1.0, 0.5) < 0  # inside the turned box
    corners = np.array(world.boxes[0].corners())
    assert np.hypot(*(corners - (1.0, 0.5)).T) == pytest.approx([math.hypot(0.2, 0.1)] * 4)
    assert world.ray_distance(-1.0, 0.0, 0.0, 4.0) == pytest.approx(0.95)


def test_floor_is_lines_over_zones_over_white():
    doc = {
        "size": {"width": 4, "height": 4},
        "zones": [{"name": "pad", "x": 0, "y": 1, "width": 1, "height": 1, "colour": "#ff0000"},
                  {"name": "bare", "x": 0, "y": -1, "width": 1, "height": 1}],
        "lines": [{"points": [[-1, 1], [1, 1]], "width": 0.04, "colour": "#000000"}],
    }  # fmt: skip
    world = World.from_doc(doc)
    assert world.floor_at(0.0, 1.01) == ("black", "#000000", 6)
    assert world.floor_at(0.0, 1.3)[:2] == ("red", "#ff0000")
    assert world.floor_at(0.0, -1.0) == ("white", "#ffffff", 94)  # an unpainted zone
    assert world.zone_at(0.0, -1.0) == "bare" and world.zone_at(1.5, 1.5) is None


@pytest.mark.parametrize(
    ("change", "path", "words"),
    [
        (lambda d: d.update(walls=[{"from": [0, 0], "to": [2.4, 0]}]), "walls[0].to",
         "wall 1 ends outside the arena (x 2.40 m, the arena's east wall is at x 2.00 m)"),
        (lambda d: d["boxes"].append({"x": 0, "y": -1.9, "width": 0.5, "height": 0.5}),
         "boxes[2]", "box 3 reaches outside the arena"),
        (lambda d: d.update(start=[{"x": 1.0, "y": 0.5, "theta": 0}]), "start[0]",
         "start pose 1 (x 1.00, y 0.50) overlaps box 1"),
        (lambda d: d.update(start=[{"x": 1.9, "y": 0, "theta": 0}]), "start[0]",
         "too near the arena's wall"),
        (lambda d: d.update(start=[]), "start", "at least one start pose"),
        (lambda d: d["size"].update(width="4"), "size.width",
         "the arena's width must be a number, not a text"),
        (lambda d: d["size"].update(height=80), "size.height", "must be 1 to 50, not 80"),
        (lambda d: d.update(size=None), "size", "the arena's size must be an object"),
        (lambda d: d["boxes"][1].update(width=True), "boxes[1].width",
         "box 2's width must be a number, not true/false"),
        (lambda d: d["boxes"][0].update(colour="red"), "boxes[0].colour", "unknown key 'colour'"),
        (lambda d: d.update(walls={}), "walls", "walls must be a list"),
        (lambda d: d.update(walls=[{"from": [0, 0], "to": [1]}]), "walls[0].to",
         "wall 1's end must be a point [x, y]"),
        (lambda d: d["zones"].append(dict(d["zones"][0])), "zones[4].name",
         "two zones are called 'kitchen'"),
        (lambda d: d["zones"][0].update(colour="yellow"), "zones[0].colour",
         "must be a colour like #ff8800"),
        (lambda d: d["landmarks"][0].update(y=1.0), "landmarks[0]", "is not on a wall"),
        (lambda d: d["landmarks"][0].update(facing=math.pi / 2), "landmarks[0].facing",
         "faces into its wall"),
        (lambda d: d.update(lines=[{"points": [[0, 0]]}]), "lines[0].points", "2 to 500 points"),
        (lambda d: d.update(boxes=[{"x": 0, "y": 0, "width": 0.1, "height": 0.1}] * 201),
         "boxes", "at most 200 boxes"),
        (lambda d: d.update(robot={"sonar": [0, 200]}), "robot.sonar[1]", "-180 to 180"),
        (lambda d: d.update(robot={"range": {"min": 2, "max": 1}}), "robot.range",
         "minimum must be below its maximum"),
        (lambda d: d.update(format=2), "format", "only format 1"),
    ],
)  # fmt: skip
def test_a_bad_document_says_where_and_what(change, path, words):
    doc = boxes_doc()
    change(doc)
    error = refused(doc)
    assert error.path == path
    assert words in str(error)


def test_a_document_that_is_not_an_object_is_refused():
    assert "must be an object" in str(refused([1, 2]))


def test_the_defaults_are_filled_in():
    world = World.from_doc({"size": {"width": 2, "height": 2}})
    doc = world.to_doc()
    assert doc["start"] == [{"x": 0.0, "y": 0.0, "theta": math.pi / 2}]
    assert doc["robot"] == {"radius": 0.15, "range": {"cone_deg": 15.0, "rays": 5, "min": 0.03,
                            "max": 4.0}, "sonar": [], "floor_sensor": False}  # fmt: skip
    assert doc["walls"] == doc["boxes"] == doc["lines"] == doc["zones"] == []
