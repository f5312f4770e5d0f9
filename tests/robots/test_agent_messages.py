"""Messages to the robot agent are checked at the door (robots/messages.py): in fleet mode the
agent's channel is in Redis, which a program that reaches Redis may write to.

A real agent on the sim robot, in this process, takes forged messages from the in-memory
channel layer as it would from Redis: it refuses them with a clear reply and acts on none."""

import asyncio

import pytest
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer
from django.conf import settings
from django.contrib.auth.models import User

from programs.models import Program, Run
from robots.models import Robot, agent_channel

pytestmark = pytest.mark.django_db(transaction=True)

REPLY_TIMEOUT = 5.0


@pytest.fixture
def agent(sim_agent):
    return sim_agent


async def ask(message: dict) -> dict:
    """Send ``message`` to the sim robot's agent as anything on the layer could; its reply."""
    layer = get_channel_layer()
    reply_to = await layer.new_channel()
    await layer.send(agent_channel("sim"), {**message, "reply_to": reply_to})
    try:
        return await asyncio.wait_for(layer.receive(reply_to), REPLY_TIMEOUT)
    except TimeoutError:
        return {"error": f"no reply within {REPLY_TIMEOUT} s"}


@database_sync_to_async
def a_run_waiting_to_start() -> Run:
    """A run as the web tier makes it, before its (legitimate) start message is sent."""
    user = User.objects.create_user("mallory")
    program = Program.objects.create(owner=user, name="p", language="python")
    program.save_source("print('hello')\n", user)
    robot = Robot.objects.get(name="sim")
    return Run.create_for(program, robot, user)


def files_named(root, stem: str) -> list:
    return [p for p in root.rglob("*") if p.name.startswith(stem)]


async def test_a_run_start_with_a_path_for_a_filename_is_refused_and_writes_nothing(
    agent, tmp_path
):
    run = await a_run_waiting_to_start()
    forged = {
        "type": "run.start",
        "run_id": run.pk,
        "language": "python",
        "source": "print('escaped')\n",
        "filename": "../../escaped.py",
        "args": [],
        "user": "mallory",
    }
    reply = await ask(forged)
    assert "refused" in reply.get("error", "") and "filename" in reply["error"], reply
    await asyncio.sleep(0.5)  # what a start would have done meanwhile
    assert files_named(tmp_path, "escaped") == []
    assert files_named(settings.RUNS_DIR.parent, "escaped") == []
    await database_sync_to_async(run.refresh_from_db)()
    assert run.state == Run.State.STARTING and run.pid is None  # not acted on at all
    # The agent goes on serving.
    assert "sensors" in await ask({"type": "robot.state"})


@pytest.mark.parametrize(
    "filename", ["../x.py", "/etc/x.py", "a/b.py", ".hidden.py", "x.py\0", "-c.py", "x" * 200]
)
async def test_only_plain_file_names_are_taken(agent, filename):
    start = {"type": "run.start", "run_id": 99, "language": "python", "source": ""}
    reply = await ask({**start, "filename": filename})
    assert "refused" in reply.get("error", "") and "filename" in reply["error"], reply


async def test_launch_itself_refuses_a_path_for_a_filename(agent, tmp_path):
    message = {"language": "python", "source": "print(1)\n", "filename": "../launched.py"}
    with pytest.raises(ValueError, match="filename"):
        active = await agent._launch(4242, message)
        agent.stop_run(active.run_id, "test")  # on code without the check: not left running
    assert files_named(tmp_path, "launched") == []


async def test_unknown_fields_are_refused(agent):
    reply = await ask({"type": "robot.sensors", "also": "rm -rf /"})
    assert "refused" in reply.get("error", "") and "also" in reply["error"], reply
    reply = await ask({"type": "run.stop", "run_id": 1, "signal": 9})
    assert "refused" in reply.get("error", "") and "signal" in reply["error"], reply
    # The same message without them is answered.
    assert "sensors" in await ask({"type": "robot.sensors"})


async def test_wrong_types_are_refused_and_not_acted_on(agent):
    reply = await ask(
        {"type": "robot.teleop", "owner": "x", "user": "m", "linear": "fast", "angular": 0}
    )
    assert "refused" in reply.get("error", "") and "linear" in reply["error"], reply
    reply = await ask({"type": "run.stop", "run_id": "1; DROP TABLE"})
    assert "refused" in reply.get("error", "") and "run_id" in reply["error"], reply
    reply = await ask({"type": "robot.take_control", "owner": "x"})  # no user
    assert "refused" in reply.get("error", "") and "user" in reply["error"], reply
    assert agent.lease.holder is None  # nobody took control
    reply = await ask({"type": "no.such.thing"})
    assert "refused" in reply.get("error", "") and "no.such.thing" in reply["error"], reply
    sensors = (await ask({"type": "robot.sensors"}))["sensors"]
    assert sensors["velocity"] == {"linear": 0.0, "angular": 0.0}  # it never moved


async def test_a_bad_reply_channel_does_not_bring_the_agent_down(agent):
    layer = get_channel_layer()
    for reply_to in (5, "not a channel name!", ["x"]):
        await layer.send(agent_channel("sim"), {"type": "robot.sensors", "reply_to": reply_to})
    await layer.send(agent_channel("sim"), {"type": "robot.estop", "reply_to": {"a": 1}})
    await asyncio.sleep(0.3)
    assert "sensors" in await ask({"type": "robot.state"})  # still serving
    assert not agent.queue.held  # the forged emergency stop was not acted on


def test_what_the_web_tier_sends_passes():
    from robots.messages import check

    good = [
        {"type": "run.start", "run_id": 3, "language": "python", "source": "print(1)\n",
         "filename": "my-program.py", "args": ["a", "b"], "user": "alice"},
        {"type": "run.stop", "run_id": 3},
        {"type": "robot.estop", "reply_to": "specific.abc!def123"},
        {"type": "robot.state", "reply_to": "specific.abc!def123"},
        {"type": "robot.teleop", "owner": "specific.x!y", "user": "bob", "linear": 0.2,
         "angular": -1.0},
        {"type": "robot.teleop_stop", "owner": "specific.x!y"},
        {"type": "robot.release", "owner": "specific.x!y"},
        {"type": "robot.take_control", "owner": "specific.x!y", "user": "staff"},
        {"type": "robot.reconfigure"},
        {"type": "camera.watch", "viewer": "specific.x!y"},
        {"type": "camera.unwatch", "viewer": "specific.x!y"},
        {"type": "camera.snapshot", "reply_to": "specific.abc!d"},
        {"type": "gateway.record", "on": True, "reply_to": "specific.abc!d"},
        {"type": "bridges.reload"},
        {"type": "run.queue_changed"},
        {"type": "run.queue_resume"},
    ]  # fmt: skip
    for message in good:
        assert check(message) is None, message


async def test_every_message_the_agent_handles_has_a_schema(agent):
    """A handler added to the agent without its line in robots/messages.py would be refused."""
    from robots.messages import SCHEMAS

    assert set(agent.handlers) <= set(SCHEMAS)


@database_sync_to_async
def the_start_message_of_a_real_run() -> dict:
    run = Run.objects.get()
    return {"type": "run.start", **run.start_message()}


async def test_the_start_message_of_a_run_passes(agent):
    from robots.messages import check

    await a_run_waiting_to_start()
    assert check(await the_start_message_of_a_real_run()) is None
