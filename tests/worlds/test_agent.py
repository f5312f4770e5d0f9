"""A sim in a stored world (issue 30): the robot's agent resolves ``sim://?world=<id>`` to the
stored document and its driver runs in it; a save reopens it in the new version; a world its
owner may not see leaves it unopened, saying why on its page (the agent's link error)."""

import asyncio
import contextlib

import pytest
from asgiref.sync import sync_to_async
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer
from django.contrib.auth.models import User

from robots.agent import RobotAgent
from robots.models import Robot
from tests.waiting import until
from tests.worlds.conftest import api_of
from tests.worlds.documents import corridor
from worlds.documents import validated
from worlds.models import World

pytestmark = pytest.mark.django_db(transaction=True)


@pytest.fixture(autouse=True)
def _no_heartbeat_meanwhile(settings):
    # The in-memory SQLite fails a write meeting another (tests/robots/test_estop_race.py).
    settings.AGENT_HEARTBEAT = 3600


@database_sync_to_async
def world_of(username: str) -> tuple[User, World]:
    user = User.objects.create_user(username)
    document = validated(corridor(), "corridor")
    world = World.objects.create(owner=user, name="corridor", title=document["title"])
    world.save_document(document, user)
    return user, world


@contextlib.asynccontextmanager
async def agent_of(name: str, url: str, owner):
    await get_channel_layer().flush()
    await database_sync_to_async(Robot.objects.create)(name=name, url=url, owner=owner)
    agent = RobotAgent(name)
    task = asyncio.create_task(agent.serve())
    try:
        await asyncio.wait_for(agent.ready.wait(), 30)
        yield agent
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


async def test_sim_opens_in_its_stored_world_and_follows_saves():
    alice, world = await world_of("alice")
    async with agent_of("worldly", f"sim://?world={world.pk}", alice) as agent:
        assert agent.driver.is_open and agent.link_error is None
        assert agent.driver.world_doc() == world.document
        moved = corridor(start=[{"x": -1.5, "y": 1.0, "theta": 0.0}])
        call = await sync_to_async(api_of)(alice)
        saved = await sync_to_async(call)("PUT", f"/api/worlds/{world.pk}", moved)
        assert saved.status_code == 200
        # robot.reconfigure: the agent reopens the robot in the new version.
        await until(lambda: agent.driver.world_doc() == saved.json()["document"])
        await until(lambda: agent.driver.is_open)
        position = (await agent.driver.sensors())["position"]
        assert (round(position["x"], 6), round(position["y"], 6)) == (-1.5, 1.0)


async def test_a_world_its_owner_may_not_see_leaves_it_unopened():
    _alice, world = await world_of("alice")
    bob = await database_sync_to_async(User.objects.create_user)("bob")
    async with agent_of("nosy", f"sim://?world={world.pk}", bob) as agent:
        assert not agent.driver.is_open
        assert "no world" in agent.link_error
        state = await agent.readings()
        assert "no world" in state["error"]
