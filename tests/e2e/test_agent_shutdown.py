"""An agent that stops while a program runs leaves nothing running after it."""

import pytest

from tests.e2e.agents import run_program, until

pytestmark = pytest.mark.django_db(transaction=True)
SLEEPS = "import time\ntime.sleep(60)\n"


async def test_an_agent_stopped_during_a_run_makes_no_box_after_it(robot_on):
    # The run it stops ends after the agent closed its boxes; a box made ahead then was left to
    # the event loop's end, which cancelled its creation half-way: asyncio then waited forever.
    peer, agent, robot, user = await robot_on("sim")
    run = await run_program(user, robot, SLEEPS)  # as the tests beside it call it
    await until(lambda: run.pk in agent.runs and agent.runs[run.pk].process.started, what="run")
    await agent.shutdown()  # as when its server stops: the run is stopped
    assert not agent.runs
    making = agent.boxes._making
    assert making is None or making.done(), "a box is being made for an agent that has stopped"
    assert agent.boxes.ready is None
