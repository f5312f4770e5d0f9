"""Attacks on the debugger's ways in (robots.debugger, programs.views_debug): a program without
the debugger, another run's program, a classmate or a teacher, bad specs and states, and bad
messages on the agent's channel. Real agent and boxes where a program acts."""

import asyncio
import json

import pytest
from asgiref.sync import sync_to_async
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer
from django.contrib.auth.models import Group, User
from django.test import Client
from django.urls import reverse

from programs.models import Program, Run
from robotide.models import ClassTeacher
from robots import messages
from robots.bus import ask_agent, send_to_agent
from robots.debugger import MAX_STATE_BYTES
from robots.models import Robot, agent_channel
from tests.debugger.client import state
from tests.debugger.conftest import (
    CLIENT_SOURCE,
    Events,
    call,
    connect,
    ended,
    error_of,
    pausing,
    running,
    start,
)
from tests.waiting import until

pytestmark = pytest.mark.django_db(transaction=True)

SPEC_A = {"breakpoints": [{"line": 1, "condition": None}], "watches": ["a"]}
SPEC_B = {"breakpoints": [{"line": 2, "condition": None}], "watches": ["b"]}

# A plain run's program that tries the debugger's methods on its own token.
TRIES = (
    CLIENT_SOURCE
    + """
peer = Peer()
codes = [
    peer.error_of("debug_start"),
    peer.error_of("debug_poll", None, 0),
    peer.error_of("debug_paused", state(1)),
]
print("codes", *codes, flush=True)
"""
)


@database_sync_to_async
def lab():
    robot = Robot.objects.get(name="sim")
    return robot, User.objects.create_user("ada"), User.objects.create_user("bo")


async def test_a_plain_runs_program_may_not_use_the_debuggers_methods(sim_agent):
    robot, ada, _ = await lab()
    run = await start(ada, robot, source=TRIES, debug=None)
    run = await ended(run)
    log = run.log_path.read_text()
    assert "o codes -32000 -32000 -32000" in log, log


@pytest.mark.usefixtures("test_is_the_debugger")
async def test_one_runs_program_cannot_reach_another_runs_debugger(sim_agent):
    robot, ada, bo = await lab()
    run_a = await start(ada, robot, debug=SPEC_A)
    run_b = await start(bo, robot, debug=SPEC_B)
    active_a, active_b = await running(sim_agent, run_a), await running(sim_agent, run_b)
    peer_a, peer_b = await connect(sim_agent, active_a), await connect(sim_agent, active_b)
    # Each token reaches its own run's debugger: A's sees A's spec, never B's.
    assert (await call(peer_a, "debug_start"))["watches"] == ["a"]
    # No parameter names a run: one that tries is refused.
    assert await error_of(peer_a, "debug_paused", state(1), run_b.pk) == -32602
    assert await error_of(peer_a, "debug_poll", None, 0, run_b.pk) == -32602
    named = {"state": state(1), "run": run_b.pk}
    assert await asyncio.to_thread(_named_error, peer_a, "debug_paused", named) == -32602
    async with Events(run_b.pk) as seen_by_b:
        waits_b = pausing(peer_b, state(2))
        assert (await seen_by_b.next())["paused"] == state(2)
        waits_a = pausing(peer_a, state(1))
        await until(lambda: active_a.debugger.paused)
        # A's commands answer A's pause, not B's ...
        await send_to_agent(sim_agent.name, "run.debug", run_id=run_a.pk, command="continue")
        assert (await waits_a)["watches"] == ["a"]
        await send_to_agent(sim_agent.name, "run.debug", run_id=run_a.pk, command="stop")
        await ended(run_a)
        await ask_agent(sim_agent.name, "robot.state")  # the agent has had them all
        assert not waits_b.done() and active_b.debugger.paused
        # ... and B's viewers heard nothing of A's pause or its end.
        with pytest.raises(TimeoutError):
            await seen_by_b.next(timeout=0.2)
        await send_to_agent(sim_agent.name, "run.debug", run_id=run_b.pk, command="continue")
        assert await waits_b == {"command": "continue", **SPEC_B}


def _named_error(peer, method, params):
    """A call with named params (the client sends positional ones)."""
    peer.ids += 1
    request = {"jsonrpc": "2.0", "id": peer.ids, "method": method, "params": params}
    peer.file.write(json.dumps(request).encode() + b"\n")
    peer.file.flush()
    return json.loads(peer.file.readline())["error"]["code"]


@pytest.mark.usefixtures("test_is_the_debugger")
async def test_an_oversize_state_is_refused(sim_agent):
    robot, ada, _ = await lab()
    run = await start(ada, robot)
    active = await running(sim_agent, run)
    peer = await connect(sim_agent, active)
    too_big = state(1, exception="x" * MAX_STATE_BYTES)
    assert await error_of(peer, "debug_paused", too_big) == -32602
    assert await error_of(peer, "debug_paused", "not a state") == -32602
    assert not active.debugger.paused and active.debugger.waiter is None
    await call(peer, "drive", 0.1, 0.0)  # not paused


@pytest.mark.usefixtures("test_is_the_debugger")
async def test_a_bad_run_debug_message_is_refused_at_the_agents_door(sim_agent):
    robot, ada, _ = await lab()
    run = await start(ada, robot)
    active = await running(sim_agent, run)
    peer = await connect(sim_agent, active)
    waits = pausing(peer, state(1))
    await until(lambda: active.debugger.paused)
    good = {"type": "run.debug", "run_id": run.pk, "command": "continue"}
    for bad in (
        {**good, "command": "jump"},
        {**good, "run_id": str(run.pk)},
        {**good, "breakpoints": [{"line": 0}]},
        {**good, "watches": ["x" * 501]},
        {**good, "breakpoints": [{"line": 1, "block": "b"}]},
        {**good, "also": 1},
    ):
        assert messages.check(bad) is not None, bad
        await get_channel_layer().send(agent_channel(sim_agent.name), bad)
    await ask_agent(sim_agent.name, "robot.state")  # the agent has had them all
    assert not waits.done() and active.debugger.paused
    await get_channel_layer().send(agent_channel(sim_agent.name), good)
    assert (await waits)["command"] == "continue"


# -- the page's commands: POST /runs/ID/debug -----------------------------------------------------


def classroom():
    """Ada's debug run on the sim; Bo, her classmate; Tess, their teacher; Root, an admin."""
    ada, bo = User.objects.create_user("ada"), User.objects.create_user("bo")
    group = Group.objects.create(name="class-a")
    ada.groups.add(group)
    bo.groups.add(group)
    tess = User.objects.create_user("tess", is_staff=True)
    ClassTeacher.objects.create(group=group, user=tess)
    root = User.objects.create_superuser("root")
    robot = Robot.objects.create(name="sim", url="sim://")
    program = Program.objects.create(owner=ada, name="p", language="python")
    run = Run.create_for(program, robot, ada, debug=SPEC_A)
    Run.objects.filter(pk=run.pk).update(state=Run.State.RUNNING)
    return {"ada": ada, "bo": bo, "tess": tess, "root": root}, run


def poster(user, csrf=False) -> Client:
    client = Client(enforce_csrf_checks=csrf)
    client.force_login(user)
    return client


def post(client: Client, run: Run, body, **headers):
    text = body if isinstance(body, str) else json.dumps(body)
    url = reverse("run-debug", args=[run.pk])
    return client.post(url, text, content_type="application/json", **headers)


@sync_to_async
def post_as(user, run: Run, body, csrf=False):
    return post(poster(user, csrf), run, body)


async def sent_to_agent() -> dict:
    return await asyncio.wait_for(get_channel_layer().receive(agent_channel("sim")), 10)


async def test_the_owner_sends_a_command_to_the_runs_agent():
    await get_channel_layer().flush()
    users, run = await database_sync_to_async(classroom)()
    body = {"command": "update", "breakpoints": [{"block": "b1", "condition": "x > 1"}]}
    answer = await post_as(users["ada"], run, body)
    assert answer.status_code == 202 and answer.json() == {"sent": True}
    assert await sent_to_agent() == {"type": "run.debug", "run_id": run.pk, **body}


async def test_nobody_but_the_owner_commands_a_debug_run():
    await get_channel_layer().flush()
    users, run = await database_sync_to_async(classroom)()
    go = {"command": "continue"}
    # Bo may not see Ada's run: as if there were none.
    assert (await post_as(users["bo"], run, go)).status_code == 404
    # Her teacher and an admin see it, and may stop it, but not debug it.
    for who in ("tess", "root"):
        assert (await post_as(users[who], run, go)).status_code == 403
    # Without the CSRF token, not even Ada.
    assert (await post_as(users["ada"], run, go, csrf=True)).status_code == 403
    assert (await sync_to_async(post)(Client(), run, go)).status_code == 302  # to sign in
    get = await sync_to_async(lambda: poster(users["ada"]).get(f"/runs/{run.pk}/debug"))()
    assert get.status_code == 405
    with pytest.raises(TimeoutError):  # nothing reached the agent
        await asyncio.wait_for(get_channel_layer().receive(agent_channel("sim")), 0.2)


@pytest.mark.parametrize(
    "body",
    [
        "not json",
        "[]",
        {},
        {"command": "jump"},
        {"command": "continue", "run_id": 3},
        {"command": "update", "breakpoints": [{"line": 0}]},
        {"command": "update", "breakpoints": [{"line": 1, "block": "b"}]},
        {"command": "update", "breakpoints": [{"line": 1}] * 201},
        {"command": "update", "watches": ["x" * 501]},
        {"command": "update", "watches": "x"},
    ],
)
def test_a_bad_command_is_refused_saying_why(body):
    users, run = classroom()
    answer = post(poster(users["ada"]), run, body)
    assert answer.status_code == 400 and answer.json()["error"], answer.content


def test_a_run_not_under_the_debugger_or_ended_is_a_conflict():
    users, run = classroom()
    Run.objects.filter(pk=run.pk).update(debug=None)
    assert post(poster(users["ada"]), run, {"command": "continue"}).status_code == 409
    Run.objects.filter(pk=run.pk).update(debug=SPEC_A, state=Run.State.FINISHED)
    assert post(poster(users["ada"]), run, {"command": "continue"}).status_code == 409


# -- Debug on the workbench ------------------------------------------------------------------------


@pytest.mark.parametrize(
    "spec",
    [
        "{not json",
        json.dumps([]),
        json.dumps({"breakpoints": [{"line": "3"}], "watches": []}),
        json.dumps({"breakpoints": [], "watches": [], "run": 1}),
    ],
)
def test_debug_with_bad_breakpoints_is_refused_and_starts_nothing(spec):
    users, run = classroom()
    program = run.program
    answer = poster(users["ada"]).post(
        reverse("program-start", args=[program.pk]),
        {"source": "print(1)\n", "language": "python", "robot": "sim", "action": "debug",
         "debug": spec},
    )  # fmt: skip
    assert answer.status_code == 400 and answer.json()["error"], answer.content
    assert Run.objects.count() == 1 and program.revisions.count() == 0  # nothing saved


def test_debug_on_the_workbench_starts_a_run_under_the_debugger():
    users, run = classroom()
    program = run.program
    pages = poster(users["ada"])
    url = reverse("program-start", args=[program.pk])
    fields = {"source": "print(1)\n", "language": "python", "robot": "sim"}
    spec = {"breakpoints": [{"line": 1, "condition": None}], "watches": ["1 + 1"]}
    debug = pages.post(url, {**fields, "action": "debug", "debug": json.dumps(spec)})
    assert debug.status_code == 200, debug.content
    assert Run.objects.get(pk=debug["X-Run"]).debug == spec
    bare = pages.post(url, {**fields, "action": "debug"})
    assert Run.objects.get(pk=bare["X-Run"]).debug == {"breakpoints": [], "watches": []}
    plain = pages.post(url, {**fields, "action": "run"})
    assert Run.objects.get(pk=plain["X-Run"]).debug is None
