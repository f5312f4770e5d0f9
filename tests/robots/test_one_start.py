"""One start per run, whatever order its starts come in: the untaken scan of an agent coming up
and the run's run.start both, a run.start delivered twice, one arriving while the first start
is under way or after the run ended. A second start made a second box, and on cgroup v1 that
box's cgroup took the first one's name and removed it as a leftover: the program that had
started was killed, and the second one ran until its claim said no.

A real agent on the sim robot, in this process, on the in-memory channel layer; each program
says "started" once in its log, so a second start shows there."""

import asyncio
import contextlib

import pytest
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer

from programs.models import Run
from robots.agent import RobotAgent
from robots.bus import ask_agent
from robots.models import Robot, agent_channel
from tests.robots.test_agent_messages import a_run_waiting_to_start
from tests.waiting import until

pytestmark = pytest.mark.django_db(transaction=True)

# Long enough that a second box made meanwhile would find it running.
PROGRAM = "import time\nprint('started', flush=True)\ntime.sleep(0.5)\nprint('ended')\n"


async def asked(source: str = PROGRAM) -> Run:
    run = await a_run_waiting_to_start()
    await database_sync_to_async(Run.objects.filter(pk=run.pk).update)(source=source)
    return run


async def send_start(run: Run, source: str = PROGRAM, robot: str = "sim") -> None:
    """The web tier's run.start for `run` (as robots.runs makes it)."""
    message = {"type": "run.start", "run_id": run.pk, "language": "python", "source": source,
               "filename": "main.py", "args": [], "user": "mallory"}  # fmt: skip
    await get_channel_layer().send(agent_channel(robot), message)


async def handled(agent: RobotAgent) -> None:
    """Everything sent to the agent so far has been taken and every start it began is over:
    its answer to a question sent last comes after the starts were dispatched."""
    await ask_agent("sim", "robot.state", timeout=15)
    await until(lambda: not agent._starting, timeout=30)


async def ended(run: Run) -> Run:
    async def done():
        await database_sync_to_async(run.refresh_from_db)()
        return run.state not in Run.ONGOING

    await until(done, timeout=30)
    return run


def starts_in_log(run: Run) -> int:
    path = Run.log_path_of(run.pk)
    lines = path.read_text().splitlines() if path.exists() else []
    return lines.count("o started")


@contextlib.asynccontextmanager
async def serving(robot: str = "sim"):
    agent = RobotAgent(robot)
    task = asyncio.create_task(agent.serve())
    try:
        await asyncio.wait_for(agent.ready.wait(), 15)
        yield agent
    finally:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task


@pytest.fixture
async def sim_robot():
    await get_channel_layer().flush()  # nothing other tests left for an agent named sim
    await database_sync_to_async(Robot.objects.create)(name="sim", url="sim://")


def assert_ran_once(run: Run) -> None:
    assert (run.state, run.exit_code) == ("finished", 0), (run.state, run.reason)
    assert starts_in_log(run) == 1, Run.log_path_of(run.pk).read_text()


async def test_a_run_start_delivered_twice_starts_it_once(sim_robot):
    async with serving() as agent:
        run = await asked()
        await send_start(run)
        await send_start(run)  # the second while the first is under way
        await handled(agent)
        assert_ran_once(await ended(run))
        log = Run.log_path_of(run.pk).read_bytes()
        await send_start(run)  # once more, after it ended
        await handled(agent)
        await database_sync_to_async(run.refresh_from_db)()
        assert_ran_once(run)
        assert Run.log_path_of(run.pk).read_bytes() == log


async def test_the_untaken_scan_and_the_run_start_start_it_once(sim_robot):
    """A run asked while the robot's agent was not listening yet: its run.start waits on the
    channel, and the agent's start finds it in the database too."""
    run = await asked()
    await send_start(run)
    async with serving() as agent:
        # The agent's scan of the database was asked before anything of this test's: once
        # this test's own database calls are answered, its starts are under way.
        await ended(run)
        await handled(agent)
        assert_ran_once(run)
