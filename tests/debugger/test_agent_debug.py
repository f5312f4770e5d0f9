"""The agent's side of the debugger (robots.debugger; PROTOCOL.md "The debugger"): a real agent
on the sim robot, real debug runs in their boxes, and the test as their debugger on the
agent's socket with the run's token (conftest: test_is_the_debugger)."""

import asyncio
import json
import time

import pytest
from channels.db import database_sync_to_async
from django.contrib.auth.models import User

from programs.consumers import RunConsumer
from robots.bus import ask_agent, send_to_agent
from robots.models import Robot
from tests.debugger.client import state
from tests.debugger.conftest import (
    Events,
    call,
    connect,
    ended,
    error_of,
    pausing,
    running,
    start,
)
from tests.programs.test_blocks import block, num, show, stack, text, workspace
from tests.programs.test_consumers import communicator
from tests.waiting import until

pytestmark = [
    pytest.mark.django_db(transaction=True),
    pytest.mark.usefixtures("test_is_the_debugger"),
]

SPEC = {"breakpoints": [{"line": 3, "condition": "x > 1"}], "watches": ["x * 2"]}


@database_sync_to_async
def lab():
    return Robot.objects.get(name="sim"), User.objects.create_user("ada")


async def debug_run(sim_agent, spec=SPEC, **kwargs):
    robot, ada = await lab()
    run = await start(ada, robot, debug=spec, **kwargs)
    active = await running(sim_agent, run)
    return ada, run, active


async def command(agent, run, command, **more):
    """The page's command, as the view sends it (robots.messages checks it on the way in)."""
    await send_to_agent(agent.name, "run.debug", run_id=run.pk, command=command, **more)


async def test_debug_start_gives_the_spec_once(sim_agent):
    _, run, active = await debug_run(sim_agent)
    peer = await connect(sim_agent, active)
    started = await call(peer, "debug_start")
    assert started == {**SPEC, "file": run.program_file, "report_line": None}
    assert await error_of(peer, "debug_start") == -32000  # once per run


async def test_a_pause_stops_the_robot_and_its_drive_until_continue(sim_agent):
    _, run, active = await debug_run(sim_agent)
    program, debugger = await connect(sim_agent, active), await connect(sim_agent, active)
    await call(program, "drive", 0.3, 0.0)
    assert (await sim_agent.driver.sensors())["velocity"]["linear"] > 0
    async with Events(run.pk) as events:
        answer = pausing(debugger, state(3))
        paused = await events.next()
        assert paused == {"state": "paused", "paused": state(3), "block": None}
        # Stopped, the lease still the run's; its drive refused while paused.
        assert (await sim_agent.driver.sensors())["velocity"] == {"linear": 0.0, "angular": 0.0}
        assert sim_agent.lease.holds(run.pk)
        with pytest.raises(Exception, match="paused in the debugger"):
            await call(program, "drive", 0.3, 0.0)
        assert (await sim_agent.driver.sensors())["velocity"]["linear"] == 0.0
        await command(sim_agent, run, "continue")
        assert await answer == {"command": "continue", **{k: SPEC[k] for k in SPEC}}
        assert await events.next() == {"state": "running"}
        # Continue gave the robot back the motion the pause stopped, before the program
        # went on (wall.py drives once, then watches its range)
        assert (await sim_agent.driver.sensors())["velocity"]["linear"] == pytest.approx(0.3)
    await call(program, "drive", 0.1, 0.0)  # it may drive again
    assert (await sim_agent.driver.sensors())["velocity"]["linear"] == pytest.approx(0.1)


async def test_steps_leave_the_robot_stopped_continue_does_not_a_stopped_run_stays_so(sim_agent):
    _, run, active = await debug_run(sim_agent)
    program, debugger = await connect(sim_agent, active), await connect(sim_agent, active)
    await call(program, "drive", 0.3, 0.0)
    answer = pausing(debugger, state(3))
    await until(lambda: active.debugger.paused)
    await command(sim_agent, run, "step_over")  # a stepped line runs with the robot still
    assert (await answer)["command"] == "step_over"
    assert (await sim_agent.driver.sensors())["velocity"]["linear"] == 0.0
    answer = pausing(debugger, state(4))  # an update's pause, then Continue: moving again
    await until(lambda: active.debugger.paused)
    await command(sim_agent, run, "update", watches=["x"])
    assert (await answer)["command"] == "update"
    answer = pausing(debugger, state(4))
    await until(lambda: active.debugger.paused)
    await command(sim_agent, run, "continue")
    assert (await answer)["command"] == "continue"
    assert (await sim_agent.driver.sensors())["velocity"]["linear"] == pytest.approx(0.3)
    await call(program, "stop")  # the program stopped it itself: Continue gives nothing back
    answer = pausing(debugger, state(4))
    await until(lambda: active.debugger.paused)
    await command(sim_agent, run, "continue")
    assert (await answer)["command"] == "continue"
    assert (await sim_agent.driver.sensors())["velocity"]["linear"] == 0.0


async def test_continue_gives_no_motion_back_to_a_run_that_lost_the_robot(sim_agent):
    _, run, active = await debug_run(sim_agent)
    program, debugger = await connect(sim_agent, active), await connect(sim_agent, active)
    await call(program, "drive", 0.3, 0.0)
    answer = pausing(debugger, state(3))
    await until(lambda: active.debugger.paused)
    await send_to_agent(sim_agent.name, "robot.take_control", owner="staff.channel", user="staff")
    await until(lambda: not sim_agent.lease.holds(run.pk))
    await command(sim_agent, run, "continue")
    assert (await answer)["command"] == "continue"
    assert (await sim_agent.driver.sensors())["velocity"]["linear"] == 0.0


async def test_the_pages_commands_answer_the_pause(sim_agent):
    _, run, active = await debug_run(sim_agent)
    debugger = await connect(sim_agent, active)
    for said in ("step_over", "step_into", "step_out"):
        answer = pausing(debugger, state(4, reason="step"))
        await until(lambda: active.debugger.paused)
        await command(sim_agent, run, said)
        assert (await answer)["command"] == said
    # update: new breakpoints and watches, answered at once (the debugger pauses again)
    answer = pausing(debugger, state(4))
    await until(lambda: active.debugger.paused)
    new = {"breakpoints": [{"line": 9, "condition": None}], "watches": ["y"]}
    await command(sim_agent, run, "update", **new)
    assert await answer == {"command": "update", **new}
    assert active.debugger.paused  # until it goes on
    # stop: answered, and the run stopped as Stop does
    answer = pausing(debugger, state(4))
    await until(lambda: active.debugger.waiter is not None)
    await command(sim_agent, run, "stop")
    assert (await answer)["command"] == "stop"
    run = await ended(run)
    assert run.state == "stopped" and run.reason == "stopped by user"


async def test_breakpoints_and_pause_reach_the_running_debugger_by_poll(sim_agent):
    _, run, active = await debug_run(sim_agent)
    poller = await connect(sim_agent, active)
    await call(poller, "debug_start")
    assert await call(poller, "debug_poll", 5, 0) is None  # nothing new
    polled = asyncio.ensure_future(call(poller, "debug_poll", 5, 5))
    await until(lambda: active.debugger.polls)
    new = [{"line": 7, "condition": None}]
    await command(sim_agent, run, "update", breakpoints=new)
    assert await polled == {"breakpoints": new, "watches": SPEC["watches"], "pause": False}
    polled = asyncio.ensure_future(call(poller, "debug_poll", 6, 5))
    await until(lambda: active.debugger.polls)
    await command(sim_agent, run, "pause")
    assert await polled == {"breakpoints": new, "watches": SPEC["watches"], "pause": True}
    assert await call(poller, "debug_poll", 6, 0) is None  # said once
    for bad in ((5, 6), (5, -1), ("5", 1), (5, True)):
        assert await error_of(poller, "debug_poll", *bad) == -32602


def blocks_program():
    """A blocks program whose blocks made lines: it says "up", then waits."""
    said, waits = show(text("up")), block("robot_wait", SECONDS=num(120))
    return workspace(stack(said, waits)), said["id"], waits["id"]


async def test_a_blocks_breakpoint_is_the_first_line_its_block_made(sim_agent):
    source, said, waits = blocks_program()
    spec = {"breakpoints": [{"block": waits, "condition": None}, {"block": "gone"}], "watches": []}
    _, run, active = await debug_run(sim_agent, spec=spec, source=source, language="blocks")
    debugger = active.debugger
    line = debugger.first_line_of(waits)
    assert debugger.source_map[line - 1] == waits and line > debugger.first_line_of(said)
    peer = await connect(sim_agent, active)
    started = await call(peer, "debug_start")
    # the block that made no line ("gone") has none
    assert started["breakpoints"] == [{"line": line, "condition": None}]
    assert started["file"].endswith(".py") and started["report_line"] == 0.1
    async with Events(run.pk) as events:
        answer = pausing(peer, state(line))
        assert (await events.next())["block"] == waits  # the block of the paused line
        await command(sim_agent, run, "continue")
        await answer
        assert await events.next() == {"state": "running"}
        at = debugger.first_line_of(said)
        await call(peer, "debug_poll", at, 0)  # where it is: the page highlights its block
        assert await events.next() == {"state": "at", "line": at, "block": said}


async def test_at_events_are_said_on_a_change_at_most_ten_times_a_second(sim_agent):
    _, run, active = await debug_run(sim_agent)
    peer = await connect(sim_agent, active)
    async with Events(run.pk) as events:
        began = time.monotonic()
        for line in [*range(1, 40), *[40] * 20]:
            await call(peer, "debug_poll", line, 0)
        said = []
        while not said or said[-1]["line"] != 40:  # the last is said, if later
            said.append(await events.next())
        elapsed = time.monotonic() - began
    lines = [event["line"] for event in said]
    assert all(event["state"] == "at" for event in said)
    assert len(lines) == len(set(lines))  # only on a change
    assert len(said) <= 1 + elapsed / 0.1  # at most 10 a second


async def test_the_emergency_stop_ends_a_paused_run_and_its_wait(sim_agent):
    _, run, active = await debug_run(sim_agent)
    program, debugger = await connect(sim_agent, active), await connect(sim_agent, active)
    await call(program, "drive", 0.3, 0.0)
    answer = pausing(debugger, state(3))
    await until(lambda: active.debugger.paused)
    poll = asyncio.ensure_future(call(program, "debug_poll", None, 5))
    await until(lambda: active.debugger.polls)
    stopped = await ask_agent(sim_agent.name, "robot.estop", by="ada")
    assert stopped["runs"] == [run.pk]
    with pytest.raises(EOFError):  # its connection closed with the run
        await answer
    with pytest.raises(EOFError):
        await poll
    run = await ended(run)
    assert run.reason == "emergency stop"
    assert active.debugger.waiter is None and not active.debugger.polls
    assert active.debugger.closed and not active.debugger.paused
    # No request of the run's is left waiting in the agent.
    await until(lambda: not handling())
    assert (await sim_agent.driver.sensors())["velocity"] == {"linear": 0.0, "angular": 0.0}


def handling() -> list:
    """Robot API requests being answered in tasks now."""
    return [
        task for task in asyncio.all_tasks()
        if not task.done() and "handle_line" in repr(task.get_coro())
    ]  # fmt: skip


async def test_a_closed_debugger_connection_ends_its_pause(sim_agent):
    _, run, active = await debug_run(sim_agent)
    program, debugger = await connect(sim_agent, active), await connect(sim_agent, active)
    answer = pausing(debugger, state(3))
    await until(lambda: active.debugger.paused)
    debugger.sock.shutdown(2)  # the debugger's process died, say
    with pytest.raises((EOFError, OSError, ValueError)):
        await answer
    await until(lambda: active.debugger.waiter is None)
    assert not active.debugger.paused
    await until(lambda: not handling())
    await call(program, "drive", 0.1, 0.0)  # not refused for a pause nobody holds


async def test_the_events_reach_the_runs_websocket_as_json(sim_agent):
    ada, run, active = await debug_run(sim_agent)
    comm = communicator(RunConsumer, f"/ws/runs/{run.pk}/", ada, run_id=run.pk)
    assert (await comm.connect())[0]
    debugger = await connect(sim_agent, active)
    answer = pausing(debugger, state(3))
    seen = await comm.receive_from()
    while not seen.startswith('{"debug"'):  # the log's and the state's HTML first
        seen = await comm.receive_from()
    assert json.loads(seen) == {"debug": {"state": "paused", "paused": state(3), "block": None}}
    await command(sim_agent, run, "continue")
    await answer
    seen = await comm.receive_from()
    while not seen.startswith('{"debug"'):
        seen = await comm.receive_from()
    assert json.loads(seen) == {"debug": {"state": "running"}}
    await comm.disconnect()


async def test_blocks_that_cannot_run_fail_as_in_a_plain_run(sim_agent):
    robot, ada = await lab()
    run = await start(ada, robot, source="{not json", debug=SPEC, language="blocks")
    run = await ended(run)
    log = run.log_path.read_text()
    assert run.exit_code == 1 and "not valid JSON" in log, log


async def test_a_continue_between_an_updates_answer_and_its_pause_is_not_lost(sim_agent):
    """The page adds a watch (update) and presses Continue before the debugger has said the
    pause again: that pause is answered Continue, not left waiting for ever."""
    _, run, active = await debug_run(sim_agent)
    debugger = await connect(sim_agent, active)
    answer = pausing(debugger, state(4))
    await until(lambda: active.debugger.waiter is not None)
    await command(sim_agent, run, "update", watches=["x"])
    assert (await answer)["command"] == "update"
    await command(sim_agent, run, "continue")  # before the debugger pauses again
    await until(lambda: active.debugger.pending == "continue")  # the agent has it
    answer = pausing(debugger, state(4))
    assert (await asyncio.wait_for(answer, 10))["command"] == "continue"
    assert not active.debugger.paused
