"""A Pioneer's serial port shared over TCP by its agent, under the control lease: a remote
client (as a Pioneer client library would) takes the robot while nobody drives, programs are
refused meanwhile, and the driver has the port back when the client leaves; a client that
comes while a program drives only watches, or is refused."""

import asyncio
import contextlib
import json

import pytest
from channels.db import database_sync_to_async
from django.contrib.auth.models import User

from rhal import arcos
from robots.agent import RobotAgent
from robots.bus import ask_agent
from robots.models import Robot, SerialBridge
from tests.e2e.agents import finished, output_of, run_program, until
from tests.rhal.arcos_emulator import ArcosEmulator

pytestmark = pytest.mark.django_db(transaction=True)

DRIVE = "import robot, time\nbot = robot.Robot()\nbot.drive(0.2, 0.0)\ntime.sleep(60)\n"
TRY_DRIVE = """
import robot
try:
    robot.Robot().drive(0.2, 0.0)
except robot.RobotError as exc:
    print("refused:", exc)
"""


@pytest.fixture
async def pioneer_on_a_pty():
    emulator = ArcosEmulator()
    path = await emulator.start_pty()
    robot = await database_sync_to_async(Robot.objects.create)(name="p3", url=f"pioneer://{path}")
    bridge = await database_sync_to_async(SerialBridge.objects.create)(
        robot=robot, address="127.0.0.1:0", when_busy="read_only"
    )
    agent = RobotAgent("p3")
    task = asyncio.create_task(agent.serve())
    await asyncio.wait_for(agent.ready.wait(), 15)
    await until(lambda: agent.driver.is_open, what="the Pioneer open")
    user = await database_sync_to_async(User.objects.create_user)("student")
    yield emulator, agent, robot, bridge, user
    task.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await task
    await emulator.stop()


def bridge_port(agent, bridge) -> int:
    return int(agent.bridges.stats()["bridges"][bridge.pk]["address"].rpartition(":")[2])


async def test_a_bridge_client_takes_the_robot_and_gives_it_back(pioneer_on_a_pty):
    emulator, agent, robot, bridge, user = pioneer_on_a_pty
    reader, writer = await asyncio.open_connection("127.0.0.1", bridge_port(agent, bridge))
    await until(lambda: not agent.driver.is_open, what="the driver letting go of the port")
    assert agent.lease.holder.kind == "bridge"
    syncs = len(emulator.named("SYNC0"))
    writer.write(arcos.encode(arcos.SYNC0))  # a client library's handshake, on the wire
    await writer.drain()
    await until(lambda: len(emulator.named("SYNC0")) > syncs, what="SYNC0 through the bridge")
    echo = await asyncio.wait_for(reader.read(64), 5)
    assert arcos.frame(bytes([arcos.SYNC0])) in echo
    # Meanwhile a program may not drive, and is told who has the robot.
    run = await finished(await run_program(user, robot, TRY_DRIVE))
    assert "refused:" in output_of(run) and "serial bridge client" in output_of(run)
    writer.close()
    await until(lambda: agent.driver.is_open, what="the driver back on the port")
    assert agent.lease.holder is None


@pytest.mark.parametrize("when_busy", ["read_only", "refuse"])
async def test_while_a_program_drives_a_client_watches_or_is_refused(pioneer_on_a_pty, when_busy):
    emulator, agent, robot, bridge, user = pioneer_on_a_pty
    if when_busy == "refuse":
        await database_sync_to_async(SerialBridge.objects.filter(pk=bridge.pk).update)(
            when_busy="refuse"
        )
        await agent.bridges.reload()
    run = await run_program(user, robot, DRIVE)
    await until(lambda: emulator.vel > 0, what="the program driving")
    reader, writer = await asyncio.open_connection("127.0.0.1", bridge_port(agent, bridge))
    if when_busy == "refuse":
        assert await asyncio.wait_for(reader.read(), 5) == b""  # closed at once
        assert agent.bridges.stats()["bridges"][bridge.pk]["refused"] == 1
    else:
        sips = await asyncio.wait_for(reader.read(4096), 5)  # what the driver reads: SIPs
        assert any(arcos.is_sip(body) for body in arcos.PacketParser().feed(sips))
        vels = len(emulator.named("VEL"))
        writer.write(arcos.encode(arcos.VEL, 0))  # a watcher's command never reaches the robot
        await writer.drain()
        await asyncio.sleep(0.5)
        assert all(c.arg != 0 for c in emulator.named("VEL")[vels:])
        stats = agent.bridges.stats()["bridges"][bridge.pk]
        assert stats["clients"][0]["mode"] == "read_only", json.dumps(stats)
    assert agent.driver.is_open and emulator.vel > 0
    writer.close()
    agent.stop_run(run.pk, "test over")
    await finished(run)


async def test_an_emergency_stop_sends_the_bridge_client_away_and_stops_the_robot(
    pioneer_on_a_pty,
):
    """A client driving through the bridge holds the robot's device; the e-stop takes it back,
    the driver's stop goes on the wire, and the client cannot come back to drive."""
    emulator, agent, robot, bridge, user = pioneer_on_a_pty
    port = bridge_port(agent, bridge)
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    await until(lambda: not agent.driver.is_open, what="the driver letting go of the port")
    # The client connects to the robot and drives, as a client library would.
    for command in (arcos.SYNC0, arcos.SYNC1, arcos.SYNC2):
        writer.write(arcos.encode(command))
        await writer.drain()
        await asyncio.sleep(0.1)
    for packet in (arcos.encode(arcos.OPEN), arcos.encode(arcos.ENABLE, 1),
                   arcos.encode(arcos.VEL, 300)):  # fmt: skip
        writer.write(packet)
        await writer.drain()
        await asyncio.sleep(0.1)
    await until(lambda: emulator.vel == 300, what="VEL 300 through the bridge")
    reply = await asyncio.wait_for(ask_agent("p3", "robot.estop", by=user.username), 10)
    assert reply["stopped"] == 0
    with contextlib.suppress(ConnectionResetError):  # the client was sent away: its end
        await asyncio.wait_for(reader.read(), 5)  # of the stream comes (no TimeoutError)
    assert agent.driver.is_open and agent.lease.estopped
    assert emulator.vel == 0  # the driver's stop, on the wire
    # Back again, it may watch (when_busy: read_only) but not take the robot.
    again_reader, again_writer = await asyncio.open_connection("127.0.0.1", port)
    await asyncio.sleep(0.5)
    assert agent.driver.is_open and agent.lease.estopped
    again_writer.close()
