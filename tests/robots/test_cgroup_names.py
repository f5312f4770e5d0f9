"""An agent coming up sweeps the run cgroups its robot's dead agent left, and nobody else's.
Robot "sim"'s cgroup names were a prefix of robot "sim-2"'s (`…-sim-` of `…-sim-2-run-5`), so
the start of sim's agent killed every program that ran on sim-2.

Real agents in this process, on the in-memory channel layer, with the machine's cgroups."""

import pytest
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer
from django.contrib.auth.models import User

from programs.models import Program, Run
from robots.models import Robot, agent_channel
from tests.robots.test_one_start import ended, send_start, serving
from tests.waiting import until

pytestmark = pytest.mark.django_db(transaction=True)

TICKING = "import time\nwhile True:\n    print('tick', flush=True)\n    time.sleep(0.05)\n"


@database_sync_to_async
def a_run_on(robot_name: str) -> Run:
    user = User.objects.create_user(f"student-{robot_name}")
    program = Program.objects.create(owner=user, name="ticks", language="python")
    program.save_source(TICKING, user)
    return Run.create_for(program, Robot.objects.get(name=robot_name), user)


def ticks(run: Run) -> int:
    path = Run.log_path_of(run.pk)
    return path.read_text().count("o tick") if path.exists() else 0


async def test_an_agent_coming_up_leaves_the_runs_of_a_robot_named_like_it_alone():
    await get_channel_layer().flush()
    for name in ("sim-2", "sim"):
        await database_sync_to_async(Robot.objects.create)(name=name, url="sim://")
    async with serving("sim-2") as other:
        if not other.cgroups.available:
            pytest.skip(f"no cgroups here: {other.cgroups.why}")
        run = await a_run_on("sim-2")
        await send_start(run, TICKING, robot="sim-2")
        await until(lambda: ticks(run) > 0, timeout=30)
        async with serving("sim"):  # its start sweeps its robot's leftovers
            seen = ticks(run)
            await until(lambda: ticks(run) > seen, timeout=15)  # alive after the sweep
        message = {"type": "run.stop", "run_id": run.pk}
        await get_channel_layer().send(agent_channel("sim-2"), message)
        await ended(run)
    assert (run.state, run.reason) == ("stopped", "stopped by user")
