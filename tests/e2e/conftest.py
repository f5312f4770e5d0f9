"""``robot_on(kind)``: a real robot agent in this process, on the in-memory channel layer, on
the robot of that kind behind its peer (tests/peers.py); all torn down after the test."""

import asyncio
import contextlib

import pytest
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer
from django.contrib.auth.models import User

from robots.agent import RobotAgent
from robots.models import Robot
from tests.e2e.agents import DEADLINE, until
from tests.peers import start_peer


@pytest.fixture
async def robot_on(tmp_path):
    """``await robot_on(kind)`` -> (peer, agent, robot row, user), all torn down after.
    ``await robot_on.restart(kind)`` -> a new agent for that robot, the old one stopped.
    ``await robot_on.retire(name)``: that robot's agent and peer stopped now (a test of many
    robots keeps only those it still drives)."""
    peers = {}
    agents = {}

    # Messages other tests left on the in-memory layer (a run.start for "run 1" of another
    # database) must not reach this test's agent.
    await get_channel_layer().flush()

    async def start(kind, name=None, **peer_options):
        """``name``: the robot's, if not its kind (several of one kind in a test)."""
        name = name or kind
        peer = peers[name] = await start_peer(kind, tmp_path, **peer_options)
        robot = await database_sync_to_async(Robot.objects.create)(name=name, url=peer.url)
        agent = await serve(name)
        user = await database_sync_to_async(User.objects.create_user)(f"student-{name}")
        return peer, agent, robot, user

    async def serve(kind):
        agent = RobotAgent(kind)
        agents[kind] = (agent, asyncio.create_task(agent.serve()))
        await asyncio.wait_for(agent.ready.wait(), DEADLINE)
        await until(lambda: agent.driver.is_open, what=f"{kind} robot open")
        return agent

    async def restart(kind):
        await stop(agents.pop(kind)[1])
        return await serve(kind)

    async def retire(name):
        await stop(agents.pop(name)[1])
        await peers.pop(name).stop()

    async def stop(task):
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task

    start.restart = restart
    start.retire = retire
    yield start
    # Copies: a test's task still starting a robot (one that failed first) may add to them.
    for _, task in list(agents.values()):
        await stop(task)
    for peer in list(peers.values()):
        await peer.stop()
