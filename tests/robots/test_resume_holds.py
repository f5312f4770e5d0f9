"""After an emergency stop, the runs it held do not start by themselves on resume (issue 29,
item 6): whatever made someone press it may still be there. Each waits, held, until its owner
starts it again, or the one who resumes chooses to start them all. The words on the robot's
page, its queue and a held run's page say who may resume as robots.stops decides it.

A real agent on the sim robot (its runs real processes) for the first two; the pages without
an agent for the last.
"""

import html

import pytest
from asgiref.sync import sync_to_async
from channels.db import database_sync_to_async
from django.contrib.auth.models import Group, User
from django.test import Client

from programs.models import Run
from robots import stops
from robots.bus import ask_agent
from robots.models import Robot, RobotStop
from robots.runs import request_stop
from tests.e2e.agents import run_program
from tests.waiting import until

SLEEPS = "import time\nprint('my turn', flush=True)\ntime.sleep(120)\n"
WHO = "staff, the robot's owner or whoever pressed it"


@pytest.fixture(autouse=True)
def _no_heartbeat_meanwhile(settings):
    # The in-memory SQLite fails a write meeting another ("table is locked"): see
    # tests/robots/test_estop_race.py.
    settings.AGENT_HEARTBEAT = 3600


@database_sync_to_async
def lab():
    robot = Robot.objects.get(name="sim")
    return robot, User.objects.create_user("tina"), User.objects.create_user("sam")


async def fresh(run: Run) -> Run:
    await database_sync_to_async(run.refresh_from_db)()
    return run


async def in_state(run: Run, state: str) -> Run:
    await until(lambda: _is(run, state))
    return run


async def _is(run: Run, state: str) -> bool:
    return (await fresh(run)).state == state


async def free_for_its_agent(agent) -> bool:
    """The agent's lease after it handled every message sent before this question (one
    channel, in order: the resume among them): not the emergency stop's."""
    state = await ask_agent(agent.name, "robot.state")
    return state["lease"] is None or state["lease"]["kind"] != "estop"


async def a_run_held_by_a_press(sim_agent):
    """Tina presses; Sam's run, asked for meanwhile, waits held."""
    robot, tina, sam = await lab()
    await sync_to_async(stops.press)(tina, robot, "the API")
    held = await run_program(sam, robot, SLEEPS)
    await until(lambda: _held(held))
    return robot, tina, sam, held


async def _held(run: Run) -> bool:
    run = await fresh(run)
    return run.state == "queued" and run.reason == Run.HELD


@pytest.mark.django_db(transaction=True)
async def test_a_run_asked_for_during_a_stop_waits_held_after_the_resume(sim_agent):
    robot, tina, sam, held = await a_run_held_by_a_press(sim_agent)
    assert await sync_to_async(stops.resume)(tina, robot, "the API") == 1  # she pressed it
    await until(lambda: free_for_its_agent(sim_agent))  # the agent has had the resume
    assert (await fresh(held)).reason == Run.HELD, held.reason
    # The robot serves others again (a run asked for now starts at once: the queue has looked
    # since) ...
    other = await run_program(tina, robot, SLEEPS)
    await in_state(other, "running")
    # ... but not the held run: no process was started for it.
    held = await fresh(held)
    assert (held.state, held.reason, held.pid) == ("queued", Run.HELD, None)
    assert held.pk not in sim_agent.runs

    # Its owner starts it again: it runs.
    assert await sync_to_async(stops.start_again)(sam, robot, held) == 1
    await in_state(held, "running")
    for run in (other, held):
        await database_sync_to_async(request_stop)(await fresh(run))
        await until(lambda run=run: _ended(run))


async def _ended(run: Run) -> bool:
    return (await fresh(run)).state not in Run.ONGOING


@pytest.mark.django_db(transaction=True)
async def test_the_one_who_resumes_may_start_the_held_runs_with_it(sim_agent):
    robot, tina, sam, held = await a_run_held_by_a_press(sim_agent)
    # Nobody else starts it again while the stop is in force, not even its owner.
    with pytest.raises(stops.StillPressed):
        await sync_to_async(stops.start_again)(sam, robot, held)
    await sync_to_async(stops.resume)(tina, robot, "the API", start_held=True)
    await in_state(held, "running")
    await database_sync_to_async(request_stop)(await fresh(held))
    await until(lambda: _ended(held))


@pytest.fixture
def pressed_by_sam(db):
    """The robot (olga's, class 'lab') was stopped by Sam; Eve's run waits, held."""
    users = {name: User.objects.create_user(name) for name in ("olga", "sam", "eve")}
    robot = Robot.objects.create(name="arm", url="sim://", owner=users["olga"])
    group = Group.objects.create(name="lab")
    robot.groups.add(group)
    for user in users.values():
        user.groups.add(group)
    RobotStop.objects.create(robot=robot, kind="estop", user=users["sam"], username="sam",
                             via="the API")  # fmt: skip
    from programs.models import Program

    program = Program.objects.create(owner=users["eve"], name="p", language="python")
    run = Run.create_for(program, robot, users["eve"])
    Run.enqueue(run.pk, Run.HELD)
    return users, robot, run


def page_of(user, path: str) -> str:
    client = Client()
    client.force_login(user)
    return html.unescape(client.get(path).content.decode())


def banner(page: str) -> str:
    """The robot page's stop banner."""
    return page.split('class="estopped"')[1].split('<div class="columns"')[0]


def test_who_may_resume_is_said_as_the_rule_decides(pressed_by_sam):
    users, robot, run = pressed_by_sam
    said = f"Who may resume it: {WHO}."
    # Sam pressed it (alone): his page offers Resume, and says who may.
    as_sam = banner(page_of(users["sam"], "/robots/arm/"))  # no agent here: 1 s
    assert said in as_sam and "Resume: let it move again" in as_sam
    assert stops.may_resume(users["sam"], robot, RobotStop.pressed(robot.pk))
    # Eve neither pressed it nor owns the robot: the same words, no Resume, and refused.
    as_eve = page_of(users["eve"], "/robots/arm/")
    assert said in banner(as_eve) and "Resume: let it move again" not in banner(as_eve)
    queue = page_of(users["eve"], "/robots/arm/queue")
    assert f"nothing starts until {WHO} resumes it" in queue
    client = Client()
    client.force_login(users["eve"])
    assert client.post("/robots/arm/resume").status_code == 403
    assert RobotStop.pressed(robot.pk) is not None
    # Her held run's page never names fewer people than the rule.
    run_page = page_of(users["eve"], f"/runs/{run.pk}/")
    assert "staff or the robot's owner resume it" not in run_page
    assert "held after an emergency stop" in run_page
