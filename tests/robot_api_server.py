"""A real robot agent's Robot API server on a sim robot, for tests of the API and its clients.

No channel layer, database or program launch: tests admit runs by token themselves.
"""

import math
import re
import shutil

import pytest

import rhal
from robots.agent import ActiveRun, RobotAgent


@pytest.fixture
async def agent():
    agent = RobotAgent("sim")
    agent.driver = rhal.connect("sim://", max_linear=0.5)
    await agent.driver.open()
    agent.api_address = await agent.server.start()
    yield agent
    await agent.server.close()
    await agent.driver.close()
    shutil.rmtree(agent.socket_dir)


def admit(agent, token="good-token", run_id=7) -> ActiveRun:
    """A run the agent serves, as if it had launched it."""
    active = ActiveRun(run_id, token, process=None)
    agent.tokens[token] = active
    agent.runs[run_id] = active
    return active


async def check_wall_turn(agent, status: int, out: str, err: str) -> None:
    """What the wall-and-turn example must leave behind on the sim robot, in any language."""
    assert status == 0, err
    match = re.fullmatch(r"heading: (-?\d+\.\d)\n", out)
    assert match, out
    printed = float(match.group(1))
    shown = agent.shows["heading"]["value"]
    assert type(shown) in (int, float) and shown == printed  # a number, not a text
    after = await agent.driver.sensors()
    assert after["velocity"] == {"linear": 0.0, "angular": 0.0}  # stopped
    assert abs(after["heading"] - printed) <= 0.05 + 1e-9
    assert after["position"]["y"] > 1.0 and not after["bumper"]  # drove ahead, hit nothing
    turned = (after["position"]["theta"] - math.pi / 2) % math.tau
    assert 1.0 < turned < math.pi  # about 1.5 rad to the left
