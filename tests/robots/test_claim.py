"""A run's program starts while its claim (Run.claim, a database write) is on its way; the
robot is not its until the claim is answered yes, and a no ends it.

A real agent on the sim robot, in this process; the claim is held back (the real one, run
once a test lets it go: the held_claim fixture) so that the program is surely up before the
answer."""

import asyncio
import time

import pytest
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer
from django.conf import settings

from programs.models import Run
from robots.models import agent_channel
from tests.robots.test_agent_messages import a_run_waiting_to_start

pytestmark = pytest.mark.django_db(transaction=True)

PROGRAM = """\
import time
import robot
print("up", flush=True)
bot = robot.Robot()  # auth: answered once the claim is
bot.drive(0.2, 0.0)
print("drove", flush=True)
time.sleep(30)
"""


async def start(run: Run, source: str = PROGRAM) -> None:
    """The web tier's run.start for `run`."""
    message = {"type": "run.start", "run_id": run.pk, "language": "python", "source": source,
               "filename": "main.py", "args": [], "user": "mallory"}  # fmt: skip
    await get_channel_layer().send(agent_channel("sim"), message)


def log_of(run: Run) -> str:
    path = settings.RUNS_DIR / str(run.pk) / "output.log"
    return path.read_text() if path.exists() else ""


async def until(condition, timeout: float = 15.0) -> None:
    deadline = time.monotonic() + timeout
    while not condition():
        assert time.monotonic() < deadline, "timed out"
        await asyncio.sleep(0.02)


async def until_async(read, value, timeout: float = 15.0) -> None:
    deadline = time.monotonic() + timeout
    while (seen := await read()) != value:
        assert time.monotonic() < deadline, f"timed out: {seen!r}, not {value!r}"
        await asyncio.sleep(0.02)


async def state_of(run: Run) -> str:
    await database_sync_to_async(run.refresh_from_db)()
    return run.state


async def velocity(agent) -> float:
    return (await agent.driver.sensors())["velocity"]["linear"]


async def test_the_program_is_up_before_its_claim_is_answered_and_drives_after(
    sim_agent, held_claim
):
    run = await a_run_waiting_to_start()
    await start(run)
    await until(lambda: "o up" in log_of(run))  # on the old code: waits for the claim
    await asyncio.sleep(0.5)  # its auth meanwhile: unanswered
    assert "drove" not in log_of(run)
    assert sim_agent.lease.holder is None and await velocity(sim_agent) == 0
    held_claim.set()
    await until(lambda: "o drove" in log_of(run))
    assert await velocity(sim_agent) == pytest.approx(0.2)
    await until_async(lambda: state_of(run), Run.State.RUNNING)
    sim_agent.stop_run(run.pk, "test over")
    await until(lambda: run.pk not in sim_agent.runs)


async def test_a_claim_answered_no_ends_the_program_before_the_robot_is_its(sim_agent, held_claim):
    run = await a_run_waiting_to_start()
    await start(run)
    await until(lambda: "o up" in log_of(run))
    # Meanwhile the web tier failed the run (its page was told it could not start).
    await asyncio.to_thread(
        lambda: Run.objects.filter(pk=run.pk).update(state=Run.State.FAILED, reason="gone")
    )
    held_claim.set()
    await until(lambda: run.pk not in sim_agent.runs)
    assert "drove" not in log_of(run)
    assert sim_agent.lease.holder is None and await velocity(sim_agent) == 0
    await database_sync_to_async(run.refresh_from_db)()
    assert (run.state, run.reason) == (Run.State.FAILED, "gone")  # its state stays


async def test_a_program_that_ends_before_its_claim_is_recorded_as_ran_then_ended(
    sim_agent, monkeypatch
):
    """Its end waits for the claim's answer: marked running (with when), then finished. The
    claim is held before it is asked, so the database thread is free for the end: recorded
    first, the claim then found the run no longer waiting (a finished run never started)."""
    let_go, claim = asyncio.Event(), sim_agent._claim

    async def held(active):
        await let_go.wait()
        await claim(active)

    monkeypatch.setattr(sim_agent, "_claim", held)
    run = await a_run_waiting_to_start()
    await start(run, 'print("bye", flush=True)\n')
    await until(lambda: "o bye" in log_of(run))
    await asyncio.sleep(0.5)  # its end meanwhile: not recorded before the claim's answer
    assert await state_of(run) == Run.State.STARTING
    let_go.set()
    await until_async(lambda: state_of(run), Run.State.FINISHED)
    assert run.started is not None and run.exit_code == 0


async def test_a_claim_cancelled_on_its_way_is_no_answer_and_holds_nobody():
    """The start's task cancelled during the claim's trip (the agent shutting down): whoever
    waits for the answer gets a no and goes on (the run's end is still recorded)."""
    from robots.agent import ActiveRun

    active = ActiveRun(1, "token", process=None, claimed=asyncio.get_running_loop().create_future())
    waiter = asyncio.ensure_future(active.confirmed())
    await asyncio.sleep(0)
    active.claimed.cancel()
    assert await asyncio.wait_for(waiter, 2) is False
    assert not active.disowned()
