"""A command on its way to the motors when its sender loses the robot: the robot must not
follow it. On a serial robot a drive() takes its time on the wire; a program that sends one
and exits ends its run (the lease freed, nothing yet to stop) before the command lands."""

import asyncio
import json

from robots.agent import ActiveRun
from runbox.supervisor import Outcome


class EndsWhenTold:
    """A run's process, as the agent watches it: it exits when the test says."""

    stop_requested = False

    def __init__(self):
        self.exited = asyncio.get_running_loop().create_future()
        self.box = self

    async def wait(self):
        await self.exited
        return Outcome("finished", 0, "exit status 0")

    async def close(self):  # its box
        pass


def on_a_slow_wire(driver, seconds=0.05):
    """Each command takes `seconds` to reach the motors, one at a time, as on a serial link."""
    lock, send = asyncio.Lock(), driver._drive

    async def _drive(linear, angular):
        async with lock:
            await asyncio.sleep(seconds)
            await send(linear, angular)

    driver._drive, driver.quick = _drive, False


def line(id_, method, *params) -> bytes:
    request = {"jsonrpc": "2.0", "id": id_, "method": method, "params": list(params)}
    return json.dumps(request).encode() + b"\n"


async def test_a_drive_that_lands_after_its_run_ended_is_stopped(agent, monkeypatch):
    on_a_slow_wire(agent.driver)
    agent.isolation = None  # no box to make ahead after the run

    async def ended(*_):  # the run's row: not this test's business
        pass

    monkeypatch.setattr(agent, "_end_run", ended)
    process = EndsWhenTold()
    active = ActiveRun(7, "run-token", process, user="mallory")
    agent.tokens[active.token], agent.runs[7] = active, active
    active.watcher = asyncio.create_task(agent._watch(active))
    host, port = agent.api_address.rsplit(":", 1)
    reader, writer = await asyncio.open_connection(host, int(port))
    writer.write(line(1, "auth", "run-token"))
    assert "result" in json.loads(await reader.readline())
    writer.write(line(2, "drive", 0.4, 0.0))  # and the program exits at once
    await writer.drain()
    writer.close()
    await asyncio.sleep(0.01)
    process.exited.set_result(None)
    await active.watcher
    await asyncio.sleep(0.3)  # the command, and whatever follows it, has landed
    assert (await agent.driver.sensors())["velocity"]["linear"] == 0.0
    assert agent.lease.holder is None and agent.motion_owner is None


async def test_connections_a_run_signed_in_end_with_it(agent, monkeypatch):
    """Another program may hold connections signed in with a run's token (handed over through
    the shared memory, say): they close when that run ends, and what they held goes with them
    (subscriptions count against the robot's caps). A connection signs in once."""
    agent.isolation = None

    async def ended(*_):
        pass

    monkeypatch.setattr(agent, "_end_run", ended)
    process = EndsWhenTold()
    short = ActiveRun(8, "short-token", process, user="mallory")
    agent.tokens[short.token], agent.runs[8] = short, short
    short.watcher = asyncio.create_task(agent._watch(short))
    host, port = agent.api_address.rsplit(":", 1)
    reader, writer = await asyncio.open_connection(host, int(port))
    writer.write(line(1, "auth", "short-token") + line(2, "subscribe", "loot"))
    assert "result" in json.loads(await reader.readline())
    assert "result" in json.loads(await reader.readline())
    writer.write(line(3, "auth", "short-token"))
    assert json.loads(await reader.readline())["error"]["code"] == -32600
    assert agent.api.subscriptions == 1
    process.exited.set_result(None)
    await short.watcher
    assert await asyncio.wait_for(reader.read(), 5) == b""  # closed by the agent
    await asyncio.sleep(0.05)
    assert agent.api.subscriptions == 0
    writer.close()
