"""Programs in every language against sims of their own, faster than real time.

Each sim has a real agent's Robot API server (as tests/robot_api_server.py); each program is
run by its language's interpreter with the command line and environment a run gets
(programs.languages, runbox.launcher.environment) and its clock at the sim's speed
(runbox.timescale), unboxed: the box is tests/runbox/test_timescale.py's.
"""

import asyncio
import contextlib
import math
import os
import random
import shutil
import signal
import time
from dataclasses import dataclass
from pathlib import Path

import rhal
from programs.languages import CLIENTS_DIR, get_language
from robots.agent import RobotAgent
from runbox import launcher, timescale
from tests.robot_api_server import admit

EXAMPLES = CLIENTS_DIR.parent / "examples"
# Each language's Wall and turn example (Blocks: its workspace, compiled as a run does).
WALL_TURN = {
    "python": "wall_turn.py", "shell": "wall_turn.sh", "perl": "wall_turn.pl",
    "ruby": "wall_turn.rb", "lua": "wall_turn.lua", "javascript": "wall_turn.js",
    "tcl": "wall_turn.tcl", "blocks": "wall_turn.json",
}  # fmt: skip
# Stop before the wall exists in Python and Blocks only.
STOP_BEFORE_THE_WALL = {"python": "wall.py", "blocks": "wall.json"}
LANGUAGES = list(WALL_TURN)


@dataclass
class Ran:
    status: int | None  # None: still running at its deadline (then killed)
    out: str
    err: str
    seconds: float  # real time from its start to its end


@contextlib.asynccontextmanager
async def sims(count: int, speed: float = 1, **options):
    """`count` sim robots at `speed`, each with an agent serving the Robot API to one run."""
    agents: list[RobotAgent] = []
    try:
        for number in range(count):
            agent = RobotAgent(f"sim-{number}")
            agents.append(agent)
            agent.driver = rhal.connect("sim://", speed=speed, **options)
            await agent.driver.open()
            agent.api_address = await agent.server.start()
            admit(agent)
        yield agents
    finally:
        for agent in agents:
            with contextlib.suppress(Exception):
                await agent.server.close()
            if agent.driver is not None:
                await agent.driver.close()
            shutil.rmtree(agent.socket_dir, ignore_errors=True)


async def run_program(
    agent: RobotAgent, language: str, source: str, folder: Path, deadline: float = 60.0
) -> Ran:
    """`source` in `language` against `agent`'s sim, its clock at the sim's speed."""
    lang = get_language(language)
    filename, text = lang.program_file(f"program{lang.extension}", source)
    folder.mkdir(parents=True, exist_ok=True)
    (folder / filename).write_text(text)
    speed = timescale.speed_of(agent.driver.capabilities())
    argv = timescale.command(lang.command(str(folder / filename)), speed)
    extra = {
        "ROBOT_API": f"unix:{agent.server.unix_path}", "ROBOT_API_TCP": agent.api_address,
        "ROBOT_TOKEN": "good-token",
    }  # fmt: skip
    env = launcher.environment(lang, folder, extra, clients_dir=CLIENTS_DIR)
    started = time.monotonic()
    process = await asyncio.create_subprocess_exec(
        *argv, env=env, cwd=folder, stdin=asyncio.subprocess.DEVNULL,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
        start_new_session=True,  # its children end with it (a shell's `sleep`, `robot`)
    )  # fmt: skip
    try:
        out, err = await asyncio.wait_for(process.communicate(), deadline)
    except TimeoutError:
        os.killpg(process.pid, signal.SIGKILL)
        out, err = await process.communicate()
    finally:
        forget_shared_clock(process.pid)
    status = None if process.returncode == -9 else process.returncode
    return Ran(status, out.decode(), err.decode(), time.monotonic() - started)


def example(filename: str) -> str:
    return (EXAMPLES / filename).read_text()


def forget_shared_clock(pid: int) -> None:
    """libfaketime's shared start time, made by the program's first process: a run's box
    takes its /dev/shm with it, this machine's keeps it (a later process of that pid would
    find it and fail)."""
    for name in (f"faketime_shm_{pid}", f"sem.faketime_sem_{pid}"):
        Path("/dev/shm", name).unlink(missing_ok=True)


def free_poses(world, seed: int, margin: float = 0.05, near: float = math.inf):
    """Poses where the robot touches nothing (`margin` m clear at least) and, with `near`,
    is at most that far from touching a wall or a box; any heading. From a seeded generator:
    the same ones every time."""
    rng = random.Random(seed)
    radius = world.robot.radius
    while True:
        x = rng.uniform(-world.half_width + radius, world.half_width - radius)
        y = rng.uniform(-world.half_height + radius, world.half_height - radius)
        theta = rng.uniform(-math.pi, math.pi)
        if radius + margin <= world.clearance(x, y) <= radius + near:
            yield (x, y, theta)


def grazing_poses(world, seed: int, near: float = 0.25, glance_deg: float = 15.0):
    """Free poses at most `near` m from touching a wall or a box, heading along it or into
    it at up to `glance_deg` degrees: where the sim of old jammed (its one ray, straight
    ahead, read the far wall while the robot's side pressed on the near one)."""
    rng = random.Random(seed)
    for x, y, _ in free_poses(world, seed, near=near):
        # The nearest surface's normal (out of it): where the clearance grows fastest.
        step = 1e-4
        dx = world.clearance(x + step, y) - world.clearance(x - step, y)
        dy = world.clearance(x, y + step) - world.clearance(x, y - step)
        side = rng.choice((-1.0, 1.0))  # along it one way or the other, turned into it
        glance = math.radians(rng.uniform(0.0, glance_deg))
        theta = math.atan2(dy, dx) + side * (math.pi / 2 + glance)
        yield (x, y, math.atan2(math.sin(theta), math.cos(theta)))
