import asyncio
import contextlib

import pytest
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer

from robots.agent import RobotAgent
from robots.models import Robot


@pytest.fixture
async def sim_agent():
    """A real agent on the sim robot, in this process, on the in-memory channel layer."""
    await get_channel_layer().flush()  # nothing other tests left for an agent named sim
    await database_sync_to_async(Robot.objects.create)(name="sim", url="sim://")
    agent = RobotAgent("sim")
    task = asyncio.create_task(agent.serve())
    await asyncio.wait_for(agent.ready.wait(), 15)
    yield agent
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
