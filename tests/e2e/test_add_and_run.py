"""A robot added and a run asked of it at once, before its agent is up: the run waits for the
agent, runs once and ends well. Ten robots in embedded mode, ten in fleet mode (Redis and
PostgreSQL, the agents in a process of their own that the robot computer starts after).

Each robot is a Pioneer (the ARCOS emulator) behind a link that answers its agent only 0.1-1 s
after it connects, as a robot, or its simulator, still coming up: its agent's start waits that
long. Before, the agent's start took the run from the database and its run.start as well; the
second start's box took the first one's cgroup name and removed it as a leftover, killing the
program (`failed`, SIGKILL). In fleet mode a run asked of a robot whose agent was not up
within the offline period was marked `lost`, which is for runs whose agent died. Here that
period is 2 s (a heartbeat every 0.25 s), shorter than an agent process takes to come up, as
7 s is on a loaded machine."""

import asyncio
import contextlib
import threading

import pytest

from tests.appliance import Appliance
from tests.rhal.arcos_emulator import ArcosEmulator

LATE = [0.1 * (i + 1) for i in range(10)]  # s each robot keeps its agent waiting
PROGRAM = "print('started', flush=True)\n"  # in the log once per start


class LateLink:
    """A TCP front to a robot that answers only `delay` s after a client connects: what the
    client sends waits in the socket meanwhile, then bytes flow both ways."""

    def __init__(self, robot_port: int, delay: float):
        self.robot_port, self.delay = robot_port, delay

    async def start(self) -> str:
        self.server = await asyncio.start_server(self._connected, "127.0.0.1", 0)
        return f"pioneer+tcp://127.0.0.1:{self.server.sockets[0].getsockname()[1]}"

    async def _connected(self, reader, writer) -> None:
        await asyncio.sleep(self.delay)
        try:
            robot_reader, robot_writer = await asyncio.open_connection("127.0.0.1", self.robot_port)
        except OSError:
            writer.close()
            return
        await asyncio.gather(_pipe(reader, robot_writer), _pipe(robot_reader, writer))

    async def stop(self) -> None:
        self.server.close()


async def _pipe(reader, writer) -> None:
    try:
        while data := await reader.read(4096):
            writer.write(data)
            await writer.drain()
    except ConnectionError:
        pass
    finally:
        writer.close()


class LateRobots:
    """Pioneers behind late links, served from an event loop of their own in a thread (the
    test's own thread waits on HTTP)."""

    def __init__(self, delays):
        self.loop = asyncio.new_event_loop()
        self.thread = threading.Thread(target=self.loop.run_forever, daemon=True)
        self.thread.start()
        self.parts = []
        self.urls = [self._call(self._start(delay)) for delay in delays]

    def _call(self, coro):
        return asyncio.run_coroutine_threadsafe(coro, self.loop).result(timeout=15)

    async def _start(self, delay: float) -> str:
        emulator = ArcosEmulator("p3dx-sh")
        link = LateLink(await emulator.start_tcp(), delay)
        self.parts += [emulator, link]
        return await link.start()

    def stop(self) -> None:
        for part in self.parts:
            with contextlib.suppress(Exception):
                self._call(part.stop())
        self._call(_end_the_rest())
        self.loop.call_soon_threadsafe(self.loop.stop)
        self.thread.join(timeout=5)


async def _end_the_rest() -> None:
    """The links' connections still piping (their agents keep them open): ended."""
    rest = [task for task in asyncio.all_tasks() if task is not asyncio.current_task()]
    for task in rest:
        task.cancel()
    await asyncio.gather(*rest, return_exceptions=True)


@pytest.fixture(scope="module", params=["embedded", "split"])
def app(request, tmp_path_factory):
    beats = {"ROBOTIDE_AGENT_HEARTBEAT": "0.25", "ROBOTIDE_AGENT_OFFLINE_AFTER": "2"}
    mode = request.param
    appliance = Appliance(tmp_path_factory.mktemp(mode), mode=mode, extra_env=beats).start()
    yield appliance
    appliance.stop()


@pytest.fixture
def late_robots():
    robots = LateRobots(LATE)
    yield robots.urls
    robots.stop()


def test_a_run_asked_of_a_robot_just_added_runs_once(app, late_robots):
    program = app.create_program("at once", PROGRAM)
    names, runs = [], []
    for i, url in enumerate(late_robots):
        name = f"late-{app.mode}-{i}"
        response = app.api("POST", "/api/robots", {"name": name, "url": url})
        assert response.status_code == 201, response.text
        runs.append(app.run_program(program["id"], robot=name)["id"])  # at once
        names.append(name)
    if app.mode == "split":  # fleet mode: the robot computer starts its agents after
        app._spawn("agent", *names)
    for i, run_id in enumerate(runs):
        run = app.wait_run(run_id, timeout=120)
        log = app.api("GET", f"/api/runs/{run_id}/log").text
        assert (run["state"], run["exit_code"]) == ("finished", 0), (i, run, log)
        assert log.splitlines().count("started") == 1, (i, log)
