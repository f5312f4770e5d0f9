"""A shared robot's run queue with a real agent (in this process) on the sim robot.

Alice's program drives and holds the robot; Bob's and Carol's runs wait in line, their pages
told their places live; staff move Carol to the front; Alice's run ends and Carol's starts,
holding the robot's control lease before her program does anything; Bob cancels; a short turn
setting stops the run holding the robot while another waits; an emergency stop holds the
queue until it is resumed; queued runs outlive their agent's restart.
"""

import asyncio
import json
import re

import pytest
from channels.db import database_sync_to_async
from channels.testing import WebsocketCommunicator
from django.contrib.auth.models import User
from django.test import Client

from programs.consumers import RunConsumer
from programs.models import Run
from robotide.models import ApiToken
from robots.bus import ask_agent, send_to_agent
from robots.consumers import RobotConsumer
from robots.lease import Holder
from robots.models import Robot
from robots.runs import request_stop
from tests.e2e.agents import run_program, until

pytestmark = pytest.mark.django_db(transaction=True)

DRIVES = (
    "import robot, time\nbot = robot.Robot()\nbot.drive(0.1, 0.0)\n"
    "print('driving', flush=True)\ntime.sleep(120)\n"
)
SLEEPS = "import time\nprint('my turn', flush=True)\ntime.sleep(120)\n"


@database_sync_to_async
def make_user(name: str, staff: bool = False) -> User:
    return User.objects.create_user(name, is_staff=staff)


@database_sync_to_async
def api(user, method: str, path: str, body=None) -> tuple[int, dict]:
    _, token = ApiToken.issue(user)
    client = Client(HTTP_AUTHORIZATION=f"Bearer {token}")
    response = getattr(client, method.lower())(path, body, content_type="application/json")
    return response.status_code, response.json()


async def fresh(run: Run) -> Run:
    await database_sync_to_async(run.refresh_from_db)()
    return run


async def in_state(run: Run, *states: str, timeout: float = 20.0) -> Run:
    async def check():
        return (await fresh(run)).state in states

    deadline = asyncio.get_running_loop().time() + timeout
    while not await check():
        assert asyncio.get_running_loop().time() < deadline, (
            f"run {run.pk} still {run.state} ({run.reason}), not {states}"
        )
        await asyncio.sleep(0.05)
    return run


async def positions(user, *runs: Run) -> list:
    found = []
    for run in runs:
        status, body = await api(user, "GET", f"/api/runs/{run.pk}")
        assert status == 200, body
        found.append(body["queue_position"])
    return found


async def status_text(page: WebsocketCommunicator, wanted: str, timeout: float = 10.0) -> str:
    """Frames from a run page's websocket until its status bar says ``wanted``."""
    deadline = asyncio.get_running_loop().time() + timeout
    while True:
        left = deadline - asyncio.get_running_loop().time()
        assert left > 0, f"the run page was never told {wanted!r}"
        frame = await page.receive_from(timeout=left)
        if 'id="run-status"' in frame:
            text = re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", frame))
            if wanted in text:
                return text


def run_page(user, run: Run) -> WebsocketCommunicator:
    page = WebsocketCommunicator(RunConsumer.as_asgi(), f"/ws/runs/{run.pk}/")
    page.scope["user"] = user
    page.scope["url_route"] = {"kwargs": {"run_id": run.pk}}
    return page


async def holder_of(agent) -> Holder | None:
    return agent.lease.holder


async def test_three_users_share_one_robot_through_its_queue(robot_on):
    peer, agent, robot, alice = await robot_on("sim")
    bob, carol = await make_user("bob"), await make_user("carol")
    staff = await make_user("teacher", staff=True)

    first = await run_program(alice, robot, DRIVES)
    await in_state(first, "running")
    await until(lambda: agent.lease.holds(first.pk), what="alice's program holding the robot")

    # Alice's own second program is not held back by her first: it runs beside it.
    beside = await run_program(alice, robot, SLEEPS)
    await in_state(beside, "running")
    await database_sync_to_async(request_stop)(beside)

    # The robot is busy: bob's and carol's runs wait, in the order asked.
    second = await run_program(bob, robot, SLEEPS)
    await in_state(second, "queued")
    third = await run_program(carol, robot, SLEEPS)
    await in_state(third, "queued")
    assert await positions(alice, first) == [None]
    # Staff see the runs queued on a robot, whoever's they are: they decide the order.
    assert await positions(staff, second, third) == [1, 2]
    assert second.pid is None and second.started is None  # nothing of theirs runs
    assert agent.lease.holds(first.pk)

    # Carol's page says where she is, and hears when that changes.
    page = run_page(carol, third)
    assert (await page.connect())[0]
    assert "queued — 2nd in line" in await status_text(page, "queued")

    # Only staff (or the robot's owner) reorder: not carol herself; bob does not even see it.
    status, body = await api(carol, "POST", f"/api/runs/{third.pk}/queue", {"position": 1})
    assert status == 403, body
    status, body = await api(bob, "POST", f"/api/runs/{third.pk}/queue", {"position": 1})
    assert status == 404, body
    # Staff move carol to the front; her page is told at once.
    status, body = await api(staff, "POST", f"/api/runs/{third.pk}/queue", {"position": 1})
    assert status == 200 and body["queue_position"] == 1, body
    await status_text(page, "queued — 1st in line")
    assert await positions(bob, second) == [2]

    # Alice's run ends: carol's starts at once, holding the lease before it even runs.
    await database_sync_to_async(request_stop)(first)
    await in_state(first, "stopped")
    await in_state(third, "starting", "running")
    assert agent.lease.holder == Holder("run", third.pk, "carol")
    await in_state(third, "running")
    await status_text(page, "running")
    await page.disconnect()
    assert await positions(bob, second) == [1]
    # Nobody slips in: a hand drive is refused while carol's program holds the robot.
    robot_page = WebsocketCommunicator(RobotConsumer.as_asgi(), "/ws/robots/sim/")
    robot_page.scope["user"] = alice
    robot_page.scope["url_route"] = {"kwargs": {"name": "sim"}}
    assert (await robot_page.connect())[0]
    await robot_page.send_to(json.dumps({"drive": [0.2, 0.0]}))
    refused = await robot_page.receive_from(timeout=5)
    while "teleop-status" not in refused:
        refused = await robot_page.receive_from(timeout=5)
    assert "carol&#x27;s program (run #" in refused
    await robot_page.disconnect()

    # Bob changes his mind: the stop action on a queued run cancels it; it never ran.
    status, body = await api(bob, "POST", f"/api/runs/{second.pk}/stop")
    assert status == 200 and body["state"] == "stopped", body
    assert body["reason"] == "cancelled while queued" and body["started"] is None
    assert body["queue_position"] is None

    # A short turn: carol's run is stopped once someone waits for longer than it.
    await database_sync_to_async(Robot.objects.filter(pk=robot.pk).update)(
        settings={"queue_turn_seconds": 1.5}
    )
    await asyncio.sleep(2)  # nobody waited: her turn was not counting
    assert (await fresh(third)).state == "running"
    fourth = await run_program(bob, robot, SLEEPS)
    await in_state(fourth, "queued")
    await in_state(third, "stopped", timeout=10)
    assert third.reason == "its turn on the shared robot ended (1.5 s)", third.reason
    await in_state(fourth, "running")
    await until(lambda: agent.lease.holds(fourth.pk), what="bob's run holding the robot")
    await database_sync_to_async(request_stop)(fourth)
    await in_state(fourth, "stopped")


async def test_an_emergency_stop_holds_the_queue_until_it_is_resumed(robot_on):
    peer, agent, robot, alice = await robot_on("sim")
    bob, staff = await make_user("bob"), await make_user("teacher", staff=True)
    first = await run_program(alice, robot, DRIVES)
    await until(lambda: agent.lease.holds(first.pk), what="alice driving")
    second = await run_program(bob, robot, SLEEPS)
    await in_state(second, "queued")

    assert (await ask_agent("sim", "robot.estop"))["stopped"] == 1
    await in_state(first, "stopped")
    assert agent.lease.estopped
    await asyncio.sleep(1)  # its program is gone, yet nothing starts on its own
    assert (await fresh(second)).state == "queued" and second.reason == Run.HELD
    # Another run asked for meanwhile waits behind it, held too.
    third = await run_program(alice, robot, SLEEPS)
    await in_state(third, "queued")
    assert third.reason == Run.HELD

    status, body = await api(bob, "POST", "/api/runs/queue/resume", {"robot": "sim"})
    assert status == 403, body
    status, body = await api(staff, "POST", "/api/runs/queue/resume", {"robot": "sim"})
    assert status == 200 and body == {"robot": "sim", "waiting": 2}, body
    await in_state(second, "running")
    assert agent.lease.holds(second.pk) and second.reason == ""
    assert (await fresh(third)).state == "queued" and third.reason == ""
    for run in (second, third):
        await database_sync_to_async(request_stop)(await fresh(run))


async def test_queued_runs_outlive_their_agent_and_are_served_when_it_is_back(robot_on):
    peer, agent, robot, alice = await robot_on("sim")
    bob = await make_user("bob")
    first = await run_program(alice, robot, DRIVES)
    await until(lambda: agent.lease.holds(first.pk), what="alice driving")
    second = await run_program(bob, robot, SLEEPS)
    await in_state(second, "queued")

    agent = await robot_on.restart("sim")  # the old one stops its programs as it goes
    await in_state(first, "stopped", "lost")
    await in_state(second, "running")
    assert agent.lease.holds(second.pk)
    await database_sync_to_async(request_stop)(second)
    await in_state(second, "stopped")


async def test_a_person_who_leaves_the_controls_idle_makes_way_for_the_queue(robot_on, monkeypatch):
    monkeypatch.setattr("robots.lease.IDLE_SECONDS", 1.0)
    peer, agent, robot, alice = await robot_on("sim")
    bob = await make_user("bob")
    page = WebsocketCommunicator(RobotConsumer.as_asgi(), "/ws/robots/sim/")
    page.scope["user"] = alice
    page.scope["url_route"] = {"kwargs": {"name": "sim"}}
    assert (await page.connect())[0]
    await page.send_to(json.dumps({"drive": [0.2, 0.0]}))
    await until(lambda: agent.lease.holder is not None, what="alice driving by hand")
    run = await run_program(bob, robot, SLEEPS)
    await in_state(run, "queued")
    # Alice stays on the page but leaves the controls alone: bob's turn comes.
    await in_state(run, "running", timeout=10)
    assert agent.lease.holder == Holder("run", run.pk, "bob")
    await page.disconnect()  # her leaving now lets go of nothing: bob keeps the robot
    await asyncio.sleep(0.3)
    assert agent.lease.holds(run.pk)
    await database_sync_to_async(request_stop)(run)
    await in_state(run, "stopped")


async def test_a_stop_that_reaches_the_agent_cancels_a_queued_run(robot_on):
    # The page saw the run "starting" and asked its agent, which had queued it meanwhile.
    peer, agent, robot, alice = await robot_on("sim")
    bob = await make_user("bob")
    first = await run_program(alice, robot, DRIVES)
    await until(lambda: agent.lease.holds(first.pk), what="alice driving")
    second = await run_program(bob, robot, SLEEPS)
    await in_state(second, "queued")
    await send_to_agent("sim", "run.stop", run_id=second.pk)
    await in_state(second, "stopped")
    assert second.reason == "cancelled while queued" and second.started is None
    assert (await fresh(first)).state == "running" and agent.queue.waiting == 0
    await database_sync_to_async(request_stop)(first)
    await in_state(first, "stopped")


async def test_a_queued_run_that_cannot_start_fails_and_the_next_one_starts(robot_on):
    peer, agent, robot, alice = await robot_on("sim")
    bob, carol = await make_user("bob"), await make_user("carol")
    first = await run_program(alice, robot, DRIVES)
    await until(lambda: agent.lease.holds(first.pk), what="alice driving")
    broken = await run_program(bob, robot, SLEEPS)
    await in_state(broken, "queued")
    after = await run_program(carol, robot, SLEEPS)
    await in_state(after, "queued")
    # Its language went away while it waited (an interpreter uninstalled, a row edited).
    await database_sync_to_async(Run.objects.filter(pk=broken.pk).update)(language="cobol")
    await database_sync_to_async(request_stop)(first)
    await in_state(broken, "failed")
    assert broken.reason.startswith("could not start: Unknown language 'cobol'")
    await in_state(after, "running")
    assert agent.lease.holds(after.pk)
    await database_sync_to_async(request_stop)(after)
    await in_state(after, "stopped")
