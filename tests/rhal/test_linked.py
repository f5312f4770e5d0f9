"""What every linked driver owes its robot through rhal.linked: when the robot goes quiet but
the link still takes bytes, the driver stops it on the wire before it lets the link go, and
says why the link was lost. Each case runs against its protocol's emulator."""

import pytest

from rhal import RobotConnectionError
from rhal.mavlink import MavlinkRobot
from rhal.pioneer import PioneerRobot
from tests.rhal.arcos_emulator import ArcosEmulator
from tests.rhal.mavlink_emulator import MavlinkEmulator
from tests.waiting import starve, until

QUIET = 3600.0  # s: an emulator told to send this seldom has gone quiet


async def test_a_pioneer_gone_quiet_is_stopped_on_the_wire():
    emulator = ArcosEmulator()
    await emulator.start_pty()
    try:
        async with PioneerRobot(f"pioneer://{emulator.path}", timeout=0.5) as robot:
            await robot.drive(0.3, 0.2)
            await until(lambda: emulator.vel == 300)
            emulator.sip_interval = QUIET  # its SIPs stop; it still listens
            await until(lambda: not robot.connected)
            # the link is marked lost before the stop is written; the emulator reads it after
            await until(lambda: (emulator.vel, emulator.rvel) == (0, 0))
            with pytest.raises(RobotConnectionError, match="no data from the robot for 0.5 s"):
                await robot.sensors()
    finally:
        await emulator.stop()


async def test_a_vehicle_gone_quiet_is_sent_a_zero_setpoint():
    emulator = MavlinkEmulator(heartbeat=0.2)
    await emulator.start()
    try:
        async with MavlinkRobot(emulator.url, arm_timeout=2, timeout=0.6) as robot:
            await robot.drive(0.5, 0.0)
            await until(lambda: emulator.commanded() == (0.5, 0.0))
            emulator.heartbeat_period = QUIET
            await until(lambda: not robot.connected)
            await until(lambda: emulator.commanded() == (0.0, 0.0))
            with pytest.raises(RobotConnectionError, match="no HEARTBEAT"):
                await robot.sensors()
    finally:
        await emulator.stop()


async def test_a_pioneer_driver_starved_of_the_cpu_keeps_its_link():
    """A busy machine can leave the driver's process asleep for longer than its timeout, the
    robot talking all along: that is not the robot gone quiet (on a loaded machine the link
    was dropped and opened again, and the robot reset its pose)."""
    emulator = ArcosEmulator()
    port = await emulator.start_tcp()
    try:
        async with PioneerRobot(f"pioneer+tcp://127.0.0.1:{port}", timeout=0.5) as robot:
            await robot.drive(0.3, 0.0)
            await until(lambda: emulator.vel == 300)
            sips = emulator.sips_sent
            starve(1.5)  # the whole process, emulator and driver alike
            await until(lambda: emulator.sips_sent > sips + 5)  # it talks again, and is heard
            assert robot.connected and emulator.names().count("OPEN") == 1
    finally:
        await emulator.stop()
