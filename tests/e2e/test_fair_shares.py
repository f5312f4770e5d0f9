"""Fair shares with real agents (in this process) on sim robots: one student's eight runs, each
holding memory, go at most two at a time, the rest queued saying why, while a classmate's run
starts at once; each end lets the next start; staff have a higher limit; a robot's
``runs_at_once`` holds whoever's runs; a run's end on one robot starts its owner's run waiting
on another (its agent woken, not its own look every few seconds).

A program here holds 16 MB and waits for a file the test puts in its run folder: the test
decides when each ends, and the count is what matters, not the size.
"""

import asyncio
import contextlib

import pytest
from channels.db import database_sync_to_async
from django.contrib.auth.models import User

from programs.models import Run
from robots import fair_shares, run_queue, stops
from robots.bus import ask_agent
from robots.models import Robot
from tests.e2e.agents import DEADLINE, run_program, until
from tests.e2e.test_run_queue import api, fresh, in_state

pytestmark = pytest.mark.django_db(transaction=True)

HOLDS = """\
import os, time
held = bytearray(16 * 1024 * 1024)  # a real allocation, kept while it runs
print('holding', len(held), flush=True)
while not os.path.exists(os.path.expanduser('~/done')):
    time.sleep(0.05)
print('done', flush=True)
"""


@pytest.fixture
def limits(settings):
    settings.RUNS_PER_USER = 2
    settings.RUNS_PER_STAFF = 3
    return settings


@database_sync_to_async
def make_user(name: str, staff: bool = False) -> User:
    return User.objects.create_user(name, is_staff=staff)


@database_sync_to_async
def states_of(runs: list[Run]) -> dict[int, str]:
    return dict(Run.objects.filter(pk__in=[r.pk for r in runs]).values_list("pk", "state"))


@database_sync_to_async
def going_of(user) -> int:
    """The user's runs that take a share now: running, or admitted and on their way."""
    return Run.objects.filter(fair_shares.going(), owner=user).count()


class Watch:
    """The most runs of one user going at once, as seen all through the test."""

    def __init__(self, user):
        self.user, self.most, self._task = user, 0, None

    async def __aenter__(self):
        self._task = asyncio.create_task(self._look())
        return self

    async def _look(self):
        while True:
            self.most = max(self.most, await going_of(self.user))
            await asyncio.sleep(0.02)

    async def __aexit__(self, *exc):
        self._task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await self._task


async def let_end(agent, run: Run) -> Run:
    """The run's program sees its file and ends by itself."""
    await until(lambda: run.pk in agent.runs and agent.runs[run.pk].process.box.folder,
                what=f"run {run.pk}'s folder")  # fmt: skip
    (agent.runs[run.pk].process.box.folder / "done").write_text("")
    return await in_state(run, "finished")


async def running(runs: list[Run]) -> list[Run]:
    states = await states_of(runs)
    return [run for run in runs if states[run.pk] == "running"]


async def test_eight_runs_of_one_student_go_two_at_a_time_and_all_finish(robot_on, limits):
    peer, agent, robot, alice = await robot_on("sim")
    bob = await make_user("bob")
    async with Watch(alice) as watch:
        runs = [await run_program(alice, robot, HOLDS) for _ in range(8)]
        for run in runs[:2]:
            await in_state(run, "running")
        for run in runs[2:]:
            await in_state(run, "queued")
        # Each says why, in the API and on the robot's line.
        status, body = await api(alice, "GET", f"/api/runs/{runs[2].pk}")
        assert status == 200 and body["state"] == "queued", body
        assert body["reason"] == "waiting: you already have 2 runs going (your limit is 2)"
        assert body["queue_position"] == 1
        # A classmate's run is not held up by alice's line.
        other = await run_program(bob, robot, HOLDS)
        await in_state(other, "running")
        assert (await going_of(alice)) == 2

        # Each end lets the next in line start, in the order asked, until all have run.
        waiting = runs[2:]
        while True:
            now = await running(runs)
            assert len(now) <= 2, [r.pk for r in now]
            if not now:
                break
            await let_end(agent, now[0])
            if waiting:
                await in_state(waiting.pop(0), "running")
                assert all(s == "queued" for s in (await states_of(waiting)).values())
        await let_end(agent, other)
    assert watch.most == 2
    assert set((await states_of(runs)).values()) == {"finished"}


async def test_staff_have_their_own_higher_limit(robot_on, limits):
    peer, agent, robot, alice = await robot_on("sim")
    teacher = await make_user("teacher", staff=True)
    runs = [await run_program(teacher, robot, HOLDS) for _ in range(4)]
    for run in runs[:3]:
        await in_state(run, "running")
    await in_state(runs[3], "queued")
    assert runs[3].reason == "waiting: you already have 3 runs going (your limit is 3)"
    status, body = await api(teacher, "GET", "/api/robots/sim")
    assert status == 200 and body["runs_per_user"] == 3 and body["runs_at_once"] is None, body
    status, body = await api(alice, "GET", "/api/robots/sim")
    assert body["runs_per_user"] == 2, body
    await let_end(agent, runs[0])
    await in_state(runs[3], "running")
    for run in runs[1:]:
        await let_end(agent, run)


async def test_a_robots_runs_at_once_holds_whoevers_runs(robot_on, limits):
    peer, agent, robot, alice = await robot_on("sim")
    bob = await make_user("bob")
    await database_sync_to_async(Robot.objects.filter(pk=robot.pk).update)(
        settings={"runs_at_once": 1}
    )
    first = await run_program(alice, robot, HOLDS)
    await in_state(first, "running")
    second = await run_program(bob, robot, HOLDS)
    await in_state(second, "queued")
    assert second.reason == "waiting: the robot runs at most 1 program at once"
    status, body = await api(bob, "GET", "/api/robots/sim")
    assert body["runs_at_once"] == 1 and body["runs_per_user"] == 2, body
    await let_end(agent, first)
    await in_state(second, "running")
    await let_end(agent, second)


async def test_an_end_on_one_robot_starts_the_owners_run_waiting_on_another(
    robot_on, limits, monkeypatch
):
    # Only the word from the other agent can start it: its own look is an hour away.
    monkeypatch.setattr(run_queue, "SHARES_LOOK", 3600.0, raising=False)
    limits.RUNS_PER_USER = 1
    peer, agent, robot, alice = await robot_on("sim")
    _, other_agent, other_robot, _ = await robot_on("sim", "sim-b")
    first = await run_program(alice, robot, HOLDS)
    await in_state(first, "running")
    waits = await run_program(alice, other_robot, HOLDS)
    await in_state(waits, "queued")
    assert waits.reason == "waiting: you already have 1 run going (your limit is 1)"
    await let_end(agent, first)
    await in_state(waits, "running")
    await let_end(other_agent, waits)


async def test_an_emergency_stop_holds_runs_waiting_for_a_share_too(robot_on, limits):
    limits.RUNS_PER_USER = 1
    peer, agent, robot, alice = await robot_on("sim")
    first = await run_program(alice, robot, HOLDS)
    await in_state(first, "running")
    waits = await run_program(alice, robot, HOLDS)
    await in_state(waits, "queued")
    assert (await ask_agent("sim", "robot.estop"))["stopped"] == 1
    await in_state(first, "stopped")
    await until_reason(waits, Run.HELD)  # its share is free, yet it waits: held
    assert (await fresh(waits)).state == "queued"
    assert (await ask_agent("sim", "robot.resume"))["resumed"] is True
    assert (await fresh(waits)).reason == Run.HELD  # until started again (issue 29)
    await database_sync_to_async(stops.start_again)(alice, robot, waits)
    await in_state(waits, "running")
    await let_end(agent, waits)


async def until_reason(run: Run, reason: str) -> None:
    async def said():
        return (await fresh(run)).reason == reason

    deadline = asyncio.get_running_loop().time() + 20
    while not await said():
        assert asyncio.get_running_loop().time() < deadline, f"run {run.pk}: {run.reason!r}"
        await asyncio.sleep(0.05)


async def test_an_emergency_stop_pressed_while_a_start_is_admitted_keeps_it_from_running(
    robot_on, limits, monkeypatch
):
    """The share's admission is a database trip between the queue's look and the launch: an
    e-stop that lands meanwhile must still keep the program from running."""
    limits.RUNS_PER_USER = 2
    peer, agent, robot, alice = await robot_on("sim")
    asked, let_go = asyncio.Event(), asyncio.Event()
    admit, loop = fair_shares.admit, asyncio.get_running_loop()

    def held_admit(run_id, box_cap=None):
        loop.call_soon_threadsafe(asked.set)
        asyncio.run_coroutine_threadsafe(let_go.wait(), loop).result(DEADLINE)
        return admit(run_id, box_cap)

    monkeypatch.setattr(fair_shares, "admit", held_admit)
    run = await run_program(alice, robot, HOLDS)
    await asyncio.wait_for(asked.wait(), DEADLINE)
    assert agent.lease.estopped is False
    await ask_agent("sim", "robot.estop")
    let_go.set()
    await in_state(run, "stopped")
    assert (await fresh(run)).reason == "emergency stop"
