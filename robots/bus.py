"""Messages between the web tier and the robot agents, over the Channels layer only.

Web -> agent: ``send_to_agent`` (fire and forget) and ``ask_agent`` (request/reply through a
fresh reply channel). Agent -> browsers: group events that consumers turn into HTML.
"""

import asyncio

from asgiref.sync import async_to_sync
from channels.layers import get_channel_layer

from robots.models import agent_channel

MANAGER_CHANNEL = "agents.manager"
RUNS_GROUP = "runs"


class AgentUnavailable(Exception):
    pass


def run_group(run_id: int) -> str:
    return f"run-{run_id}"


async def send_to_agent(robot_name: str, type: str, **data) -> None:
    await get_channel_layer().send(agent_channel(robot_name), {"type": type, **data})


async def ask_agent(robot_name: str, type: str, timeout: float = 3.0, **data) -> dict:
    layer = get_channel_layer()
    reply_to = await layer.new_channel()
    await layer.send(agent_channel(robot_name), {"type": type, "reply_to": reply_to, **data})
    try:
        reply = await asyncio.wait_for(layer.receive(reply_to), timeout)
    except TimeoutError:
        raise AgentUnavailable(
            f"The agent of robot {robot_name!r} did not answer within {timeout:g} s; is it running?"
        ) from None
    if "error" in reply:
        raise AgentUnavailable(reply["error"])
    return reply


async def announce_robot(robot_name: str) -> None:
    await get_channel_layer().send(MANAGER_CHANNEL, {"type": "robot.added", "name": robot_name})


tell_agent_sync = async_to_sync(send_to_agent)
ask_agent_sync = async_to_sync(ask_agent)
announce_robot_sync = async_to_sync(announce_robot)
