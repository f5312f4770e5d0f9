"""The agent with the real debugger in the box (clients/python/robot_debug.py, bdb): a Python
run pauses at a conditional breakpoint with the robot stopped, and runs to its end on continue;
a blocks run pauses on a block breakpoint and says its running block."""

import pytest
from channels.db import database_sync_to_async
from django.contrib.auth.models import User

from robots.bus import send_to_agent
from robots.models import Robot
from tests.debugger.conftest import Events, call, connect, ended, start
from tests.programs.test_blocks import block, show, stack, text, workspace

pytestmark = pytest.mark.django_db(transaction=True)

LOOP = """\
import robot
bot = robot.Robot()
x = 0
for i in range(3):
    bot.drive(0.2, 0.0)
    x = x + 10
bot.stop()
print("done", x, flush=True)
"""


@database_sync_to_async
def lab():
    return Robot.objects.get(name="sim"), User.objects.create_user("ada")


def named(variables: list, name: str) -> str:
    return next(v["value"] for v in variables if v["name"] == name)


async def test_a_python_run_pauses_at_its_breakpoint_and_goes_on(sim_agent):
    robot, ada = await lab()
    spec = {"breakpoints": [{"line": 6, "condition": "i == 1"}], "watches": ["x * 2"]}
    run = await start(ada, robot, source=LOOP, debug=spec)
    async with Events(run.pk) as events:
        paused = await events.next()
        assert paused["state"] == "paused" and paused["block"] is None, paused
        state = paused["paused"]
        assert (state["reason"], state["line"]) == ("breakpoint", 6), state
        assert named(state["globals"], "i") == "1" and named(state["globals"], "x") == "10"
        assert state["watches"] == [{"expression": "x * 2", "value": state["watches"][0]["value"]}]
        assert state["watches"][0]["value"]["value"] == "20"
        # A pause is a motion stop: the drive of the line before is undone.
        velocity = (await sim_agent.driver.sensors())["velocity"]
        assert velocity == {"linear": 0.0, "angular": 0.0}
        assert sim_agent.lease.holds(run.pk)
        await send_to_agent(robot.name, "run.debug", run_id=run.pk, command="continue")
        assert await events.next() == {"state": "running"}
    run = await ended(run)
    assert run.state == "finished", run.log_path.read_text()
    assert "o done 30" in run.log_path.read_text()


async def test_a_blocks_run_pauses_on_a_block_and_says_its_running_block(sim_agent):
    robot, ada = await lab()
    waits = show(block("robot_receive", {"TOPIC": "go"}))  # print(bot.receive("go", None))
    last = show(text("end"))
    source = workspace(stack(show(text("up")), waits, last))
    spec = {"breakpoints": [{"block": last["id"], "condition": None}], "watches": []}
    run = await start(ada, robot, source=source, language="blocks", debug=spec)
    async with Events(run.pk) as events:
        event = await events.next()
        while (event["state"], event.get("block")) != ("at", waits["id"]):
            event = await events.next()  # its running block: where it waits for "go"
        peer = await connect(sim_agent, sim_agent.runs[run.pk])
        assert await call(peer, "publish", "go", 1) == 1
        event = await events.next()
        while event["state"] == "at":
            event = await events.next()
        assert event["state"] == "paused" and event["block"] == last["id"], event
        await send_to_agent(robot.name, "run.debug", run_id=run.pk, command="continue")
    run = await ended(run)
    assert "o end" in run.log_path.read_text(), run.log_path.read_text()
