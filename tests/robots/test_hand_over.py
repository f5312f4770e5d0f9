"""A new run handed to its robot's agent (robots.runs.start_run): the view does not wait for the
server's loop to do it, and a run that cannot be handed over fails at once, its viewers told."""

import asyncio
import threading

import pytest
from asgiref.sync import async_to_sync
from channels.exceptions import ChannelFull
from channels.layers import get_channel_layer
from django.contrib.auth.models import User

from programs.models import Program
from robots.bus import RUNS_GROUP
from robots.models import Robot, agent_channel
from robots.runs import start_run
from tests.appliance import wait_for

pytestmark = pytest.mark.django_db(transaction=True)


@pytest.fixture(autouse=True)
def _empty_layer():
    async_to_sync(get_channel_layer().flush)()
    yield
    async_to_sync(get_channel_layer().flush)()


@pytest.fixture
def lab():
    user = User.objects.create_user("ada")
    robot = Robot.objects.create(name="arm", url="sim://")
    program = Program.objects.create(owner=user, name="p", language="python")
    program.save_source("print(1)\n", user)
    return user, robot, program


@pytest.fixture
def server_loop(monkeypatch):
    """The web server's loop, in a thread of its own, as `robotide up` runs it."""
    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_forever, daemon=True)
    thread.start()
    monkeypatch.setattr("robots.bus._server_loop", loop)
    yield loop
    loop.call_soon_threadsafe(loop.stop)
    thread.join(5)
    loop.close()


def on(loop, coro):
    return asyncio.run_coroutine_threadsafe(coro, loop).result(5)


async def fill(channel: str) -> None:
    layer = get_channel_layer()
    while True:
        try:
            await layer.send(channel, {"type": "filler"})
        except ChannelFull:
            return


async def listen(group: str) -> str:
    layer = get_channel_layer()
    channel = await layer.new_channel()
    await layer.group_add(group, channel)
    return channel


async def events(channel: str) -> list[dict]:
    layer = get_channel_layer()
    got = []
    while layer.channels.get(channel):
        got.append(await layer.receive(channel))
    return got


def test_the_view_does_not_wait_for_a_busy_loop(lab, server_loop):
    """Fails when start_run waits for the loop: the loop is held until start_run returns (or
    for 10 s, when start_run cannot return before it is free)."""
    user, robot, program = lab
    go_on, released = threading.Event(), threading.Event()

    def busy():  # the loop busy with something else (an agent's start, say)
        go_on.wait(10)
        released.set()

    server_loop.call_soon_threadsafe(busy)
    run = start_run(program, robot, user)
    returned_while_busy = not released.is_set()
    go_on.set()
    assert returned_while_busy, "start_run waited for the server's loop"
    # Then the loop hands it over.
    layer = get_channel_layer()
    message = on(server_loop, asyncio.wait_for(layer.receive(agent_channel(robot.name)), 5))
    assert (message["type"], message["run_id"]) == ("run.start", run.pk)


def test_a_run_its_agent_does_not_take_fails_and_its_viewers_are_told(lab, server_loop):
    user, robot, program = lab
    on(server_loop, fill(agent_channel(robot.name)))  # nobody has taken its commands
    viewer = on(server_loop, listen(RUNS_GROUP))
    run = start_run(program, robot, user)
    # The run list is told once the row says so; the row is read after (this thread reading
    # while the loop's worker writes would lock the tests' shared-cache SQLite table).
    told = wait_for(lambda: on(server_loop, events(viewer)), what="the run list told")
    assert {"type": "runs.changed", "run_id": run.pk, "robot": "arm"} in told
    run.refresh_from_db()
    assert run.state == "failed" and run.ended is not None
    assert run.reason == "could not start: the agent of robot 'arm' is not taking commands"


def test_without_a_server_loop_it_is_handed_over_before_start_run_returns(lab):
    """A command or a test's client: no server loop; the hand-over is done in place."""
    user, robot, program = lab
    async_to_sync(fill)(agent_channel(robot.name))
    run = start_run(program, robot, user)
    run.refresh_from_db()
    assert run.state == "failed" and "not taking commands" in run.reason
