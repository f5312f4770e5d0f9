"""A check run's trace (robots.check_sims.TraceRecorder) on a real sim with a clock the test
moves: it begins at the launch, and begins again when the program first signs in on the Robot
API (the agent's ActiveRun.signed_in, from robots.robot_api's auth), so that the program's
start (its box, its interpreter: real time, times the sim's speed) is neither in its times nor
in its time limit's. Lines printed before are at time 0; a program that never signs in keeps
the launch as its time 0.

On the code before this change the trace began at the launch only: there is no
``signed_in`` (AttributeError), and its times counted the start (the end-to-end test of it is
tests/classroom/test_checking.py's sign-in test)."""

import pytest

import rhal
from robots.check_sims import TraceRecorder
from tests.rhal.conftest import ManualClock

SPEED = 10.0
LIMIT = 20.0  # sim s


def line(text: str) -> list:
    return [(0, "o", text)]


@pytest.fixture
async def sim():
    clock = ManualClock()
    async with rhal.connect(f"sim://?world=boxes&speed={SPEED:g}", clock=clock) as bot:
        yield bot, clock


async def test_its_time_and_limit_begin_again_when_its_program_signs_in(sim):
    bot, clock = sim
    trace = TraceRecorder(bot, LIMIT)
    trace.start()  # the launch
    clock.advance(0.7)  # the interpreter's start: 7 s of sim time at 10x
    trace.lines(line("starting"), 0)
    assert trace.left() == pytest.approx(LIMIT - 7.0)

    trace.signed_in()
    assert trace.left() == pytest.approx(LIMIT)  # the whole limit, from now
    clock.advance(0.2)
    await bot.drive(0.3, 0.0)
    clock.advance(0.3)
    trace.lines(line("driving"), 0)
    trace.signed_in()  # a second connection: nothing begins again
    clock.advance(0.1)
    doc = trace.document("finished", 0, "exit status 0")

    assert doc["output"] == [[0.0, "starting"], [pytest.approx(5.0), "driving"]]
    assert doc["end"]["t"] == pytest.approx(6.0) and not doc["end"]["time_limit"]
    assert doc["poses"][0][0] == 0 and doc["commands"][0][0] == pytest.approx(2.0), doc


async def test_a_program_that_never_signs_in_counts_from_its_launch(sim):
    bot, clock = sim
    trace = TraceRecorder(bot, LIMIT)
    trace.start()
    clock.advance(0.5)
    trace.lines(line("only prints"), 0)
    clock.advance(1.6)
    assert trace.left() == pytest.approx(LIMIT - 21.0)  # its agent stops it: the limit is up
    trace.time_limit = True
    trace.take()
    trace.signed_in()  # too late: its trace has ended
    doc = trace.document("stopped", None, "time limit reached: 20 s of sim time")
    assert doc["output"] == [[pytest.approx(5.0), "only prints"]]
    assert doc["end"]["t"] == pytest.approx(21.0) and doc["end"]["time_limit"], doc["end"]
