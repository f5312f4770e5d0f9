"""What programs show (bot.show) on a robot's page (issue 29, item 11): a viewer sees the values
of runs still running there and of the ended runs they may see (their own; their students'),
never another student's stale numbers; a value leaves the page, and the agent's memory, a
while (settings.SHOWS_KEEP_SECONDS) after its run ended."""

import asyncio
import time
from types import SimpleNamespace

import pytest
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer
from django.contrib.auth.models import Group, User
from django.test import Client

from programs.models import Program, Run
from robotide.models import ClassTeacher
from robots.consumers import RobotConsumer
from robots.models import Robot
from tests.programs.test_consumers import communicator
from tests.waiting import DEADLINE, until

pytestmark = pytest.mark.django_db(transaction=True)


def make_lab():
    """Two students' runs on one robot: alice's ended, bob's one ended and one running; a
    teacher of bob's class."""
    alice, bob = User.objects.create_user("alice"), User.objects.create_user("bob")
    robot = Robot.objects.get_or_create(name="sim", url="sim://")[0]

    def run(owner, state):
        program = Program.objects.create(owner=owner, name=f"p-{owner}-{state}", language="python")
        made = Run.create_for(program, robot, owner)
        Run.objects.filter(pk=made.pk).update(state=state)
        return made.pk

    runs = {
        "alice_ended": run(alice, "finished"),
        "bob_ended": run(bob, "finished"),
        "bob_running": run(bob, "running"),
    }
    group = Group.objects.create(name="class-b")
    bob.groups.add(group)
    teacher = User.objects.create_user("teacher", is_staff=True)
    ClassTeacher.objects.create(group=group, user=teacher)
    shows = {
        # Values no run number can spell (the card names runs "#111"...).
        "mine": {"value": 0.111, "run": runs["alice_ended"], "time": 1.0, "ended": 5.0},
        "stale": {"value": 0.222, "run": runs["bob_ended"], "time": 1.0, "ended": 5.0},
        "now": {"value": 0.333, "run": runs["bob_running"], "time": 2.0},
    }
    return {"alice": alice, "bob": bob, "teacher": teacher}, shows


async def shown_to(user, shows) -> str:
    """The "Shown by programs" card a viewer's websocket renders from the agent's snapshot."""
    comm = communicator(RobotConsumer, "/ws/robots/sim/", user, name="sim")
    assert (await comm.connect())[0]
    await comm.receive_from()  # what runs there now
    event = {"type": "robot.telemetry", "robot": "sim", "sensors": {}, "units": {},
             "shows": shows, "all_shows": True}  # fmt: skip
    await get_channel_layer().group_send("robot-sim", event)
    html = await comm.receive_from()
    while 'id="shows"' not in html:
        html = await comm.receive_from()
    await comm.disconnect()
    return html[html.index('id="shows"') :]


async def test_a_student_sees_a_running_run_and_their_own_never_anothers_ended_one():
    users, shows = await database_sync_to_async(make_lab)()
    card = await shown_to(users["alice"], shows)
    assert "0.333" in card and "0.111" in card
    assert "0.222" not in card  # bob's run ended: his numbers are his
    card = await shown_to(users["teacher"], shows)  # bob's teacher sees bob's runs
    assert "0.222" in card and "0.333" in card and "0.111" not in card


def test_the_robot_page_shows_a_student_the_same(monkeypatch):
    users, shows = make_lab()
    state = {"sensors": {}, "units": {}, "camera": False, "drive": None, "lease": None,
             "shows": shows}  # fmt: skip
    monkeypatch.setattr("robots.views.ask_agent_sync", lambda *args, **kwargs: state)
    client = Client()
    client.force_login(users["alice"])
    page = client.get("/robots/sim/").content.decode()
    card = page[page.index('id="shows"') :]
    assert "0.333" in card and "0.111" in card and "0.222" not in card


async def test_a_value_leaves_a_while_after_its_run_ended(sim_agent, settings):
    """The agent marks an ended run's values, then forgets them (and what they cost)."""
    settings.SHOWS_KEEP_SECONDS = 0.2
    layer = get_channel_layer()
    channel = await layer.new_channel()
    await layer.group_add("robot-sim", channel)
    sim_agent.runs[7] = SimpleNamespace(run_id=7, watcher=None)  # run 7 is running
    try:
        for name, run in (("going", 7), ("gone", 8)):
            sim_agent.shows[name] = {"value": run, "run": run, "time": time.time()}
            sim_agent.api.show_costs[name] = (run, 100)

        async def snapshot(check):
            async def first():
                while True:
                    event = await layer.receive(channel)
                    if event["type"] == "robot.telemetry" and event["all_shows"] and check(event):
                        return event["shows"]

            return await asyncio.wait_for(first(), DEADLINE)  # only a failing test waits it

        marked = await snapshot(lambda e: "ended" in e["shows"].get("gone", {}))
        assert "ended" not in marked["going"]  # a running run's value is not aged
        await snapshot(lambda e: "gone" not in e["shows"])
        assert "gone" not in sim_agent.shows and "gone" not in sim_agent.api.show_costs
        assert "ended" not in sim_agent.shows["going"]
    finally:
        del sim_agent.runs[7]  # it ends
    await until(lambda: "going" not in sim_agent.shows)
    assert "going" not in sim_agent.api.show_costs
