"""A real robot agent's Robot API server on a sim robot, for tests of the API and its clients.

No channel layer, database or program launch: tests admit runs by token themselves.
"""

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
