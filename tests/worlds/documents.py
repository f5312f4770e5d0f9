"""World documents the worlds tests store (in the 4 x 3 m arena, x -2..2, y -1.5..1.5)."""

import copy

CORRIDOR = {
    "format": 1,
    "name": "corridor",
    "title": "A corridor",
    "size": {"width": 4.0, "height": 3.0},
    "walls": [{"from": [-1.0, -0.5], "to": [1.0, -0.5], "thickness": 0.05}],
    "boxes": [{"x": 1.2, "y": 0.8, "width": 0.3, "height": 0.3, "angle": 0.0}],
    "landmarks": [],
    "lines": [],
    "zones": [{"name": "goal", "x": 1.5, "y": -1.0, "width": 0.5, "height": 0.5,
               "colour": "#ffe08a"}],
    "start": [{"x": 0.0, "y": 0.5, "theta": 1.5708}],
}  # fmt: skip


def corridor(**changes) -> dict:
    document = copy.deepcopy(CORRIDOR)
    document.update(changes)
    return document


def normalised(document: dict) -> dict:
    from rhal.simulator.world import World

    return World.from_doc(document).to_doc()
