"""A run on a sim faster than real time, through the agent's own launch (its box and all):
the program's clock runs at the sim's speed (runbox.timescale), or, where libfaketime is
missing, the run is refused saying what to install."""

import pytest
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer
from django.utils import translation

from programs.models import Run
from robots.models import Robot
from runbox import timescale
from runlogs.system_words import translated
from tests.robots.test_one_start import asked, ended, send_start, serving

pytestmark = pytest.mark.django_db(transaction=True)

SLEEP_A_SECOND = """\
import time
import robot
bot = robot.Robot()
before = bot.sensors()["time"]
time.sleep(1)
print("sim seconds", bot.sensors()["time"] - before)
"""


@pytest.fixture
async def sim_at_10x():
    await get_channel_layer().flush()  # nothing other tests left for an agent named sim
    await database_sync_to_async(Robot.objects.create)(name="sim", url="sim://?speed=10")


def printed(run: Run) -> list[str]:
    lines = Run.log_path_of(run.pk).read_text().splitlines()
    return [line[2:] for line in lines if line.startswith("o ")]


async def test_a_runs_second_is_a_second_of_the_sims_time(sim_at_10x):
    assert timescale.library(), "libfaketime (scripts/install-test-deps.sh installs it)"
    async with serving():
        run = await asked(SLEEP_A_SECOND)
        await send_start(run, SLEEP_A_SECOND)
        run = await ended(run)
    assert (run.state, run.exit_code) == ("finished", 0), (run.state, run.reason)
    (line,) = printed(run)
    # Its sleep of 1 s and the calls around it; 10 s if its clock were the real one.
    assert 1.0 <= float(line.split()[-1]) < 2.0, line


async def test_without_libfaketime_the_run_is_refused_saying_what_to_install(
    sim_at_10x, monkeypatch
):
    monkeypatch.setattr(timescale, "library", lambda: None)
    async with serving():
        run = await asked(SLEEP_A_SECOND)
        await send_start(run, SLEEP_A_SECOND)
        run = await ended(run)
    assert run.state == "failed", run.reason
    assert run.reason == (
        "could not start: this sim runs at 10x real time, and its programs' clocks need"
        " libfaketime to keep up (as root: apt-get install libfaketime); or set its speed to 1"
    )
    with translation.override("pt-br"):  # in the reader's language where shown
        assert "apt-get install libfaketime" in translated(run.reason)
        assert translated(run.reason).startswith("não pôde começar: este simulador roda a 10x")
