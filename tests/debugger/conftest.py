"""A real agent on the sim robot (tests/robots/conftest.py's), its debug runs, and a test that
speaks as a run's debugger over the agent's socket with the run's token (client.py)."""

import asyncio
import dataclasses
import time
from pathlib import Path

import pytest
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer

from programs.languages import LANGUAGES
from programs.models import Program, Run
from robots.bus import run_group
from robots.runs import start_run
from tests.debugger import client
from tests.robots.conftest import sim_agent  # noqa: F401 (a fixture)
from tests.waiting import DEADLINE, until

CLIENT_SOURCE = Path(client.__file__).read_text()
SLEEPER = "import time\nprint('up', flush=True)\ntime.sleep(120)\n"
# What a debug run runs instead of the real debugger (clients/python/robot_debug.py, not
# these tests' subject): the program alone, so that the test is its debugger.
PROGRAM_ALONE = (
    "import runpy, sys; sys.argv = sys.argv[1:]; runpy.run_path(sys.argv[0], run_name='__main__')"
)
NO_SPEC = {"breakpoints": [], "watches": []}


@pytest.fixture(autouse=True)
def _no_heartbeat_meanwhile(settings):
    # The in-memory SQLite fails a write meeting another ("table is locked"): see
    # tests/robots/test_estop_race.py.
    settings.AGENT_HEARTBEAT = 3600


@pytest.fixture
def test_is_the_debugger(monkeypatch):
    """Debug runs run their program alone: the test speaks as their debugger."""
    for name in ("python", "blocks"):
        language = dataclasses.replace(LANGUAGES[name], debugger=("-c", PROGRAM_ALONE))
        monkeypatch.setitem(LANGUAGES, name, language)


@database_sync_to_async
def start(user, robot, source=SLEEPER, debug=NO_SPEC, language="python") -> Run:
    name = f"p{time.monotonic_ns()}"
    program = Program.objects.create(owner=user, name=name, language=language)
    program.save_source(source, user)
    return start_run(program, robot, user, debug=debug)


async def running(agent, run: Run):
    """The run's ActiveRun, once its claim is answered and its program has printed."""
    await until(lambda: run.pk in agent.runs and agent.runs[run.pk].confirmed_now())
    await until(lambda: _printed(run))
    return agent.runs[run.pk]


def _printed(run: Run) -> bool:
    return run.log_path.exists() and b"o up" in run.log_path.read_bytes()


async def connect(agent, active) -> client.Peer:
    """A connection signed in with the run's token, as its debugger's."""
    address = f"unix:{agent.server.unix_path}"
    return await asyncio.to_thread(client.Peer, address, active.token)


async def call(peer: client.Peer, method: str, *params):
    """A call from a thread: the agent answers on this loop meanwhile."""
    return await asyncio.to_thread(peer.call, method, *params)


async def error_of(peer: client.Peer, method: str, *params):
    return await asyncio.to_thread(peer.error_of, method, *params)


def pausing(peer: client.Peer, state: dict) -> asyncio.Future:
    """debug_paused under way (its answer, when the page gives one)."""
    return asyncio.ensure_future(call(peer, "debug_paused", state))


class Events:
    """What the agent tells a run's viewers of its debugger ("run.debug" on its group)."""

    def __init__(self, run_id: int):
        self.run_id = run_id

    async def __aenter__(self):
        self.layer = get_channel_layer()
        self.channel = await self.layer.new_channel()
        await self.layer.group_add(run_group(self.run_id), self.channel)
        return self

    async def __aexit__(self, *exc):
        await self.layer.group_discard(run_group(self.run_id), self.channel)

    async def next(self, timeout=DEADLINE) -> dict:
        """The next debugger event (other events of the run skipped)."""
        while True:
            message = await asyncio.wait_for(self.layer.receive(self.channel), timeout)
            if message["type"] == "run.debug":
                assert message["run_id"] == self.run_id
                return message["event"]


async def fresh(run: Run) -> Run:
    await database_sync_to_async(run.refresh_from_db)()
    return run


async def ended(run: Run) -> Run:
    await until(lambda: _ended(run))
    return run


async def _ended(run: Run) -> bool:
    return (await fresh(run)).state not in Run.ONGOING
