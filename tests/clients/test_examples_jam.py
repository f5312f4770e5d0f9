"""The examples that drive to a wall end on their own, in every language, from anywhere.

On the sim of old a robot that touched a wall or a box could not move forward any more, and
its range sensor, one ray straight ahead, missed what its side touched: *Wall and turn*, which
drives until the range reads under 0.5 m, drove on for ever. Here *Wall and turn* in every
language and *Stop before the wall* (Python and Blocks: it exists in no other language) each
run from the same 10 random free poses of the boxes world (seeded: the same every time), ten
sims at once at 10x with the programs' clocks to match (runbox.timescale); each must end by
itself, successfully, with the robot stopped and inside nothing.

The poses are near a wall or a box (up to 0.25 m from touching it), heading along it or into
it at a glancing angle (tests.sim_programs.grazing_poses): poses drawn anywhere with any
heading rarely meet a surface so (on the sim of old, 1 of these 100 runs from such poses
jammed); from these, each of the ten examples jammed from 4 of the 10 poses there.
"""

import asyncio
import re

import pytest

from rhal.simulator.worlds import load
from runbox import timescale
from tests.conftest import in_ci
from tests.sim_programs import (
    STOP_BEFORE_THE_WALL,
    WALL_TURN,
    example,
    grazing_poses,
    run_program,
    sims,
)

# Skipped without libfaketime here, never in CI (scripts/install-test-deps.sh installs it).
pytestmark = pytest.mark.skipif(
    timescale.library() is None and not in_ci(), reason="no libfaketime: apt-get install it"
)

POSES = 10
SEED = 30
SPEED = 10
# Some room ahead, so that each program has to drive: a pose whose range reads less is
# passed over for the generator's next.
ROOM_AHEAD = 0.7  # m
# A deadline for a program that does not end, not how long one takes: ~3 s at most here.
DEADLINE = 60.0  # s of real time

EXAMPLES = [
    *((language, filename, r"heading: -?\d+\.\d\n") for language, filename in WALL_TURN.items()),
    *((language, filename, r"Stopped \d+\.\d+ m before the wall\n")
      for language, filename in STOP_BEFORE_THE_WALL.items()),
]  # fmt: skip


async def place(agents, world) -> list[tuple[float, float, float]]:
    """Each sim at the next grazing pose with room ahead."""
    poses, placed = grazing_poses(world, SEED), []
    for agent in agents:
        for pose in poses:
            await agent.driver.reset(pose)
            if (await agent.driver.sensors())["range"] >= ROOM_AHEAD:
                placed.append(pose)
                break
    return placed


@pytest.mark.parametrize(
    "language, filename, printed", EXAMPLES, ids=[name for _, name, _ in EXAMPLES]
)
async def test_the_example_ends_on_its_own_from_ten_random_free_poses(
    language, filename, printed, tmp_path
):
    world = load("boxes")
    source = example(filename)
    async with sims(POSES, speed=SPEED, world="boxes") as agents:
        poses = await place(agents, world)
        runs = await asyncio.gather(*(
            run_program(agent, language, source, tmp_path / str(number), DEADLINE)
            for number, agent in enumerate(agents)
        ))  # fmt: skip
        ends = [await agent.driver.sensors() for agent in agents]
    radius = world.robot.radius
    wrong = []
    for pose, ran, end in zip(poses, runs, ends, strict=True):
        x, y = end["position"]["x"], end["position"]["y"]
        if ran.status is None:
            why = f"still running after {DEADLINE:g} s"
        elif ran.status != 0 or not re.fullmatch(printed, ran.out):
            why = f"exit status {ran.status}: {ran.out!r} {ran.err[-300:]!r}"
        elif end["velocity"] != {"linear": 0.0, "angular": 0.0}:
            why = f"not stopped: {end['velocity']}"
        elif world.clearance(x, y) < radius - 1e-3:
            why = f"ended inside something at ({x:.2f}, {y:.2f})"
        else:
            continue
        wrong.append("from ({:.2f}, {:.2f}) facing {:.2f} rad: ".format(*pose) + why)
    assert not wrong, f"{len(wrong)} of {POSES}:\n" + "\n".join(wrong)
