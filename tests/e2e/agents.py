"""Helpers for end-to-end tests with a real agent (the ``robot_on`` fixture, conftest.py):
programs run through it, waited for, and their output."""

import asyncio
import time

from channels.db import database_sync_to_async

from programs.models import Program, Run
from robots.runs import start_run

# s: a deadline for an event, not how long it takes; only a failing test waits it out, and a
# busy machine (a load of 10-20 on two cores) makes a quick step take many seconds.
DEADLINE = 60.0


async def until(predicate, timeout=DEADLINE, what="condition"):
    deadline = time.monotonic() + timeout
    while not (result := predicate()):
        assert time.monotonic() < deadline, f"{what} not met within {timeout} s"
        await asyncio.sleep(0.05)
    return result


@database_sync_to_async
def run_program(user, robot, source: str, language="python") -> Run:
    program = Program.objects.create(owner=user, name=f"p{time.monotonic_ns()}", language=language)
    program.save_source(source, user)
    return start_run(program, robot, user)


async def finished(run: Run, timeout=2 * DEADLINE) -> Run:
    deadline = time.monotonic() + timeout
    while True:
        await database_sync_to_async(run.refresh_from_db)()
        if run.state not in Run.ONGOING:
            return run
        assert time.monotonic() < deadline, f"run {run.pk} still {run.state}"
        await asyncio.sleep(0.1)


def log_of(run: Run) -> str:
    """The run's whole log (output, errors and robotide's own lines), for a failure message."""
    return run.log_path.read_text() if run.log_path.exists() else "(no log)"


def output_of(run: Run) -> str:
    lines = run.log_path.read_text().splitlines()
    return "\n".join(line[2:] for line in lines if line.startswith("o "))
