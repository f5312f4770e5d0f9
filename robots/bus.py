"""Messages between the web tier and the robot agents, over the Channels layer only.

Web -> agent: ``send_to_agent`` (fire and forget) and ``ask_agent`` (request/reply through a
fresh reply channel). Agent -> browsers: group events that consumers turn into HTML.
"""

import asyncio
import logging
import threading

from asgiref.sync import async_to_sync
from channels.layers import get_channel_layer
from django.utils.translation import gettext as _

from robots.models import agent_channel, manager_channel, robot_group

log = logging.getLogger(__name__)
RUNS_GROUP = "runs"


class AgentUnavailable(Exception):
    pass


def console_group(program_id: int, user_id: int) -> str:
    """A user's workbench consoles on one program (robotide's consumers.ConsoleConsumer)."""
    return f"console.{program_id}.{user_id}"


def run_group(run_id: int) -> str:
    return f"run-{run_id}"


async def send_to_agent(robot_name: str, type: str, **data) -> None:
    await get_channel_layer().send(agent_channel(robot_name), {"type": type, **data})


async def hand_over_run(robot_name: str, message: dict, consoles: str) -> None:
    """A new run to its robot's agent, then to its owner's open workbench consoles (which
    join its group before reading its log, so they miss no line): one trip to the loop."""
    try:
        await send_to_agent(robot_name, "run.start", **message)
    finally:
        try:
            await get_channel_layer().group_send(
                consoles, {"type": "console.attach", "run_id": message["run_id"]}
            )
        except Exception:  # the channel layer away: the agent's turn says so
            log.warning("run %s: could not tell the consoles", message["run_id"], exc_info=True)


async def tell_run_changed(run_id: int, robot_name: str) -> None:
    """A run's state changed outside its agent (it failed to start, or was lost): its page,
    the run lists and its robot's page hear of it."""
    layer = get_channel_layer()
    await layer.group_send(run_group(run_id), {"type": "run.state", "run_id": run_id})
    changed = {"type": "runs.changed", "run_id": run_id, "robot": robot_name}
    await layer.group_send(RUNS_GROUP, changed)
    await layer.group_send(robot_group(robot_name), {"type": "robot.runs", "robot": robot_name})


async def ask_agent(robot_name: str, type: str, timeout: float = 3.0, **data) -> dict:
    reply_to = await request_agent(robot_name, type, **data)
    return await agent_reply(robot_name, reply_to, timeout)


async def request_agent(robot_name: str, type: str, **data) -> str:
    """The first half of ``ask_agent``: the message sent; the channel its reply comes to. Apart
    so that a caller may send while it holds a lock and wait for the reply after letting go
    (robots.stops: presses reach the agent in the order they are recorded)."""
    layer = get_channel_layer()
    reply_to = await layer.new_channel()
    await layer.send(agent_channel(robot_name), {"type": type, "reply_to": reply_to, **data})
    return reply_to


async def agent_reply(robot_name: str, reply_to: str, timeout: float = 3.0) -> dict:
    """The second half of ``ask_agent``: AgentUnavailable if no reply comes in time."""
    layer = get_channel_layer()
    try:
        reply = await asyncio.wait_for(layer.receive(reply_to), timeout)
    except TimeoutError:
        raise AgentUnavailable(
            _("The agent of robot %(robot)s did not answer within %(seconds)s s; is it running?")
            % {"robot": repr(robot_name), "seconds": f"{timeout:g}"}
        ) from None
    if "error" in reply:
        raise AgentUnavailable(reply["error"])
    return reply


async def announce_robot(robot_name: str) -> None:
    await get_channel_layer().send(manager_channel(), {"type": "robot.added", "name": robot_name})


async def reconfigure(robot_name: str) -> None:
    """The robot's row changed: its agent reopens the robot with the new URL and settings."""
    await send_to_agent(robot_name, "robot.reconfigure")


# -- from sync code (views in the web server's worker threads) -------------------------------

_server_loop: asyncio.AbstractEventLoop | None = None


def serve_on(loop: asyncio.AbstractEventLoop) -> None:
    """Tell the bus which loop the web server runs: the in-memory layer lives on it."""
    global _server_loop
    _server_loop = loop


def blocking(coro_fn):
    """``coro_fn`` callable from sync code (a view's worker thread), on the server's loop."""

    def call(*args, **kwargs):
        loop = _server_loop
        if loop is None or not loop.is_running():
            return async_to_sync(coro_fn)(*args, **kwargs)
        if threading.get_ident() == getattr(loop, "_thread_id", None):
            raise RuntimeError("blocking bus call from the event loop's own thread")
        return asyncio.run_coroutine_threadsafe(coro_fn(*args, **kwargs), loop).result()

    return call


def begin_soon(coro_fn, *args) -> None:
    """``coro_fn(*args)`` begun on the server's loop from a view's thread and not waited for:
    the thread goes on to its response while the loop does it (it must catch and log its own
    errors: nobody reads its result). Where no server loop runs (a command, a test's client),
    done before this returns."""
    loop = _server_loop
    if loop is None or not loop.is_running():
        async_to_sync(coro_fn)(*args)
    elif threading.get_ident() == getattr(loop, "_thread_id", None):
        raise RuntimeError("begin_soon from the event loop's own thread")
    else:
        asyncio.run_coroutine_threadsafe(coro_fn(*args), loop)


tell_agent_sync = blocking(send_to_agent)
ask_agent_sync = blocking(ask_agent)
request_agent_sync = blocking(request_agent)
agent_reply_sync = blocking(agent_reply)
announce_robot_sync = blocking(announce_robot)
reconfigure_sync = blocking(reconfigure)
