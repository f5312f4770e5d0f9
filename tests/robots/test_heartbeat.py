"""The agent's heartbeat: the database away (or a SQLite table locked) at its first beat must
not end the agent, whose robot and programs it serves (the e2e gateway test's agent died so in
make test: 'database table is locked: robots_robot')."""

import asyncio
import contextlib

import pytest
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer
from django.db import OperationalError
from django.db.models import QuerySet

from robots.agent import RobotAgent
from robots.models import Robot
from tests.waiting import until

pytestmark = pytest.mark.django_db(transaction=True)


async def test_a_first_heartbeat_that_fails_leaves_the_agent_serving(monkeypatch, settings):
    settings.AGENT_HEARTBEAT = 0.05
    update = QuerySet.update
    tries = []

    def locked_at_first(queryset, **fields):
        if queryset.model is Robot and "last_seen" in fields:
            tries.append(fields)
            if len(tries) == 1:
                raise OperationalError("database table is locked: robots_robot")
        return update(queryset, **fields)

    monkeypatch.setattr(QuerySet, "update", locked_at_first)
    await get_channel_layer().flush()
    await database_sync_to_async(Robot.objects.create)(name="sim", url="sim://")
    agent = RobotAgent("sim")
    task = asyncio.create_task(agent.serve())
    try:
        await asyncio.wait_for(agent.ready.wait(), 15)
        await until(lambda: len(tries) >= 3 or task.done())
        assert not task.done(), task.exception()
        # The beat after the failed one says who serves the robot, as the first would have
        robot = await database_sync_to_async(Robot.objects.get)(name="sim")
        assert robot.agent_host and robot.agent_started is not None
        assert (await agent.driver.sensors())["range"] > 0  # and the robot is served
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError, OperationalError):
            await task
