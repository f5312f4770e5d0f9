"""The pioneer:// driver at the wire, against an ARCOS robot emulator on a pty or a socket."""

import json
import math
import os
import tty

import pytest
from hypothesis import given
from hypothesis import strategies as st

import rhal
from rhal import NotSupportedError, RobotConnectionError, arcos
from rhal.pioneer import PioneerRobot
from tests.rhal.arcos_emulator import ArcosEmulator, arcos_checksum, arcos_packet
from tests.waiting import until


@pytest.fixture
async def emulator():
    emu = ArcosEmulator()
    await emu.start_pty()
    yield emu
    await emu.stop()


@pytest.fixture
async def robot(emulator):
    bot = PioneerRobot(f"pioneer://{emulator.path}", baud=115200)
    await bot.open()
    yield bot
    await bot.close()


# -- opening and closing ---------------------------------------------------------------------


async def test_open_syncs_opens_and_enables_the_motors(robot, emulator):
    assert emulator.names()[:5] == ["SYNC0", "SYNC1", "SYNC2", "OPEN", "ENABLE"]
    assert emulator.named("ENABLE")[0].arg == 1
    assert emulator.state == "open" and emulator.motors
    assert emulator.bad_packets == 0
    assert robot.identity == {"name": "emulator", "class": "Pioneer", "subclass": "p3dx-sh"}
    assert (await robot.sensors())["motors"] is True


async def test_a_robot_left_open_is_closed_and_synced_again(emulator):
    # As after a client that died without CLOSE: the robot is still sending SIPs.
    emulator.state, emulator.motors = "open", True
    async with PioneerRobot(f"pioneer://{emulator.path}"):
        names = emulator.names()
        assert "CLOSE" in names
        assert names[-5:] == ["SYNC0", "SYNC1", "SYNC2", "OPEN", "ENABLE"]


async def test_close_stops_the_motors_then_closes_the_server(robot, emulator):
    await robot.drive(0.3, 0.0)
    await until(lambda: emulator.vel == 300)
    await robot.close()
    await until(lambda: emulator.state == "sync")
    last = motion(emulator)[-3:]
    assert [(c.name, c.arg) for c in last] == [("VEL", 0), ("RVEL", 0), ("CLOSE", None)]
    assert emulator.vel == 0 and not emulator.motors


async def test_open_fails_clearly_when_nothing_answers():
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        bot = PioneerRobot(f"pioneer://{os.ttyname(slave)}", timeout=0.3)
        with pytest.raises(RobotConnectionError, match="no ARCOS robot answered"):
            await bot.open()
        assert not bot.is_open
    finally:
        os.close(master)
        os.close(slave)


@pytest.mark.parametrize("url", ["pioneer:///dev/no-such-robot", "pioneer+tcp://127.0.0.1:1"])
async def test_open_fails_clearly_without_a_link(url):
    with pytest.raises(RobotConnectionError, match="cannot open robot"):
        await PioneerRobot(url).open()


@pytest.mark.parametrize(
    ("url", "device", "address"),
    [("pioneer+tcp://", None, ("127.0.0.1", 8101)),
     ("pioneer+tcp://robot.lab", None, ("robot.lab", 8101)),
     ("pioneer+tcp://10.0.0.5:8102", None, ("10.0.0.5", 8102)),
     ("pioneer:///dev/ttyS1", "/dev/ttyS1", None),
     ("pioneer://", "/dev/ttyUSB0", None),
     ("PIONEER://COM3", "COM3", None)],
)  # fmt: skip
def test_url_names_the_link(url, device, address):
    bot = PioneerRobot(url)
    assert (bot.device, bot.address) == (device, address)


def test_url_options_reach_the_driver(monkeypatch):
    monkeypatch.setitem(rhal.DRIVERS, "pioneer", ("rhal.pioneer", "PioneerRobot"))
    bot = rhal.connect("pioneer:///dev/ttyS0?baud=115200&compass=true&sonars=16&timeout=0.5")
    assert (bot.baud, bot.compass, len(bot.units.sonars), bot.timeout) == (115200, True, 16, 0.5)
    assert bot.capabilities()["sensors"]["sonar"]["count"] == 16
    with pytest.raises(ValueError, match="baud"):
        PioneerRobot("pioneer://", baud=0)
    with pytest.raises(ValueError, match="not a pioneer URL"):
        PioneerRobot("sim://")


# -- motion on the wire ----------------------------------------------------------------------


@pytest.mark.parametrize(
    ("linear", "angular", "vel", "rvel"),
    [(0.3, 0.5, 300, 29), (-0.25, -1.0, -250, -57), (0.1, -0.2, 100, -11), (-0.4, 1.5, -400, 86)],
)
async def test_drive_sends_vel_and_rvel_with_signs(robot, emulator, linear, angular, vel, rvel):
    await robot.drive(linear, angular)
    await until(lambda: emulator.named("RVEL"))
    (vel_command,), (rvel_command,) = emulator.named("VEL"), emulator.named("RVEL")
    assert (vel_command.arg, rvel_command.arg) == (vel, rvel)
    # The sign travels in the argument type byte, the magnitude low byte first.
    assert vel_command.raw[4] == (0x3B if vel >= 0 else 0x1B)
    assert vel_command.raw[5:7] == abs(vel).to_bytes(2, "little")
    assert rvel_command.raw[4] == (0x3B if rvel >= 0 else 0x1B)
    assert (emulator.vel, emulator.rvel) == (vel, rvel)


async def test_speeds_are_clamped_before_the_wire(emulator):
    bot = PioneerRobot(f"pioneer://{emulator.path}", max_linear=0.2, max_angular=0.5)
    async with bot:
        assert await bot.drive(1.0, -3.0) == {"linear": 0.2, "angular": -0.5}
        await until(lambda: emulator.named("RVEL"))
    assert emulator.named("VEL")[0].arg == 200
    assert emulator.named("RVEL")[0].arg == -29


async def test_stop_sends_zero_velocities(robot, emulator):
    await robot.drive(0.4, 1.0)
    await until(lambda: emulator.vel == 400)
    await robot.stop()
    await until(lambda: emulator.vel == 0 and emulator.rvel == 0)
    assert [(c.name, c.arg) for c in motion(emulator)[-2:]] == [("VEL", 0), ("RVEL", 0)]
    assert emulator.motors, "a stop is not a motor disable: the next drive() must work"


async def test_keepalive_arrives_while_idle(robot, emulator):
    emulator.commands.clear()
    await until(lambda: len(emulator.named("PULSE")) >= 2)
    assert emulator.names() == ["PULSE", "PULSE"]
    pulses = [c.at for c in emulator.named("PULSE")]
    assert pulses[1] - pulses[0] > 0.5, "about one a second, not a flood"
    assert emulator.state == "open"


async def test_velocity_is_refreshed_while_moving(robot, emulator):
    await robot.drive(0.2, 0.0)
    # Sent again and again while moving (not only once by drive()), so neither a packet lost
    # on the line nor the robot's 2 s watchdog ends the motion of a program still driving.
    await until(lambda: len([c for c in emulator.named("VEL") if c.arg == 200]) >= 4)
    assert emulator.vel == 200


# -- readings --------------------------------------------------------------------------------


async def test_sip_fields_are_parsed(emulator):
    # ARIA's p3dx-sh file marks the bump rings absent (an accessory): this one has a front one.
    robot = PioneerRobot(f"pioneer://{emulator.path}", baud=115200, front_bumpers=5)
    await robot.open()
    emulator.x, emulator.y, emulator.th = 1234.0, -500.0, math.radians(30)
    emulator.wheels = (100, -300)
    emulator.battery = 12.3
    emulator.sonar = {n: 1000 + 100 * n for n in range(8)}
    emulator.front_bumpers = 0b100
    emulator.stall_right = True

    def updated(readings):
        return readings["sonar"][:8] == pytest.approx([1.0 + 0.1 * n for n in range(8)])

    readings = await until(lambda: _when(robot, updated))
    await robot.close()
    assert len(readings["sonar"]) == 16  # the model's ring: 8 front, 8 rear discs
    assert readings["bumpers"] == {"front": [False, False, True, False, False]}
    assert readings["position"] == pytest.approx(
        {"x": 1.234, "y": -0.5, "theta": math.radians(30)}, abs=2e-3
    )
    assert readings["wheels"] == {"left": 0.1, "right": -0.3}
    # No ROTVEL from this firmware: ARIA's (right - left) / 2 * DiffConvFactor (P3-DX 0.0056).
    assert readings["velocity"] == pytest.approx({"linear": -0.1, "angular": -400 / 2 * 0.0056})
    assert readings["battery"] == pytest.approx(12.3)
    assert readings["range"] == pytest.approx(1.3)  # min of sonars 3 and 4
    assert readings["bumper"] is True and readings["stall"] is True
    assert readings["heading"] == pytest.approx(60.0, abs=0.1)  # from odometry theta
    assert readings["errors"] == 0


async def test_position_follows_the_robot_past_the_15_bit_wrap(robot, emulator):
    # Out to 20 m, past +16.384 m where 15 bits wrap to negative, and back to -4 m.
    for x in [*range(0, 20001, 2000), *range(18000, -4001, -2000)]:
        emulator.x = float(x)
        await until(lambda x=x: _when(robot, lambda r: r["position"]["x"] == x / 1000))


async def test_heading_comes_from_the_compass_when_fitted(emulator):
    emulator.compass_byte = 45  # 2-degree units
    async with PioneerRobot(f"pioneer://{emulator.path}", compass=True) as bot:
        assert (await bot.sensors())["heading"] == 90.0
        assert bot.capabilities()["sensors"]["heading"]["source"] == "compass"
        emulator.compass_byte = 255
        await until(lambda: _when(bot, lambda r: r["heading"] is None))


async def test_readings_are_json_and_match_capabilities(robot):
    readings = await robot.sensors()
    assert json.loads(json.dumps(readings)) == readings
    specs = robot.capabilities()["sensors"]
    assert set(readings) == set(specs)
    assert specs["position"]["unit"] == {"x": "m", "y": "m", "theta": "rad"}
    assert specs["heading"]["source"] == "odometry"
    with pytest.raises(NotSupportedError, match="no sensor 'gps'"):
        await robot.sensor("gps")


# -- faults ----------------------------------------------------------------------------------


async def test_noise_and_broken_packets_are_dropped_and_counted(robot, emulator):
    good = arcos_packet(emulator.sip())
    bad = bytearray(good)
    bad[-1] ^= 0xFF
    emulator.inject(b"\x13\x37line noise" + good[:9] + bytes(bad))
    await until(lambda: robot.errors >= 1)
    assert (await robot.sensors())["errors"] == robot.errors
    await robot.drive(0.1, 0.0)  # still working
    await until(lambda: emulator.vel == 100)


async def test_unplugged_pty_is_a_clear_error(robot, emulator):
    await emulator.stop()

    async def failing():
        try:
            await robot.sensors()
        except RobotConnectionError as exc:
            return exc

    error = await until(failing)
    assert "no link to the pioneer robot" in str(error)
    with pytest.raises(RobotConnectionError, match="reconnecting"):
        await robot.drive(0.2, 0.0)
    await robot.close()  # closing a robot whose link is gone still works


async def test_tcp_link_returns_and_the_driver_resyncs():
    first = ArcosEmulator()
    port = await first.start_tcp()
    async with PioneerRobot(f"pioneer+tcp://127.0.0.1:{port}") as bot:
        await bot.drive(0.2, 0.0)
        await first.stop()
        await until(lambda: not bot.connected)
        with pytest.raises(RobotConnectionError, match="no link"):
            await bot.sensors()
        with pytest.raises(RobotConnectionError, match="no link"):
            await bot.drive(0.2, 0.0)

        second = ArcosEmulator(name="second")
        await second.start_tcp(port)
        try:
            await until(lambda: bot.connected)
            assert second.names()[:5] == ["SYNC0", "SYNC1", "SYNC2", "OPEN", "ENABLE"]
            assert bot.identity["name"] == "second"
            assert second.vel == 0, "motion must not resume by itself after a reconnection"
            assert (await bot.sensors())["motors"] is True
            await bot.drive(-0.1, 0.0)
            await until(lambda: second.vel == -100)
        finally:
            await bot.close()
            await second.stop()


# -- packets ---------------------------------------------------------------------------------


def test_commands_encode_as_the_arcos_manual_shows():
    assert arcos.encode(arcos.SYNC0) == bytes.fromhex("fafb03000000")
    assert arcos.encode(arcos.SYNC2) == bytes.fromhex("fafb03020002")
    assert arcos.encode(arcos.ENABLE, 1) == bytes.fromhex("fafb06043b0100") + (
        (0x043B + 0x0100).to_bytes(2, "big")
    )
    for value in (0, 1, -1, 300, -300, 32767, -32767):
        packet = arcos.encode(arcos.VEL, value)
        assert arcos_checksum(packet[3:-2]) == int.from_bytes(packet[-2:], "big")
    with pytest.raises(ValueError):
        arcos.encode(arcos.VEL, 40000)


def test_parse_sip_reads_what_the_emulator_wrote():
    emu = ArcosEmulator()
    emu.x, emu.y, emu.th, emu.vel, emu.motors = -100.0, 250.0, -math.pi / 2, 200, True
    emu.compass_byte, emu.battery = 100, 26.1  # above 25.5 V: only BATTERYX10 holds it
    sip = arcos.parse_sip(emu.sip())
    assert sip.moving and sip.motors and sip.compass == 200
    assert (sip.left, sip.right) == (200, 200)
    assert sip.battery == pytest.approx(26.1)
    assert sip.sonar == {0: 5000, 2: 5000, 4: 5000, 6: 5000}
    odometry = arcos.Odometry()
    assert odometry.update(sip) == pytest.approx((-0.1, 0.25, -math.pi / 2))
    with pytest.raises(ValueError, match="cut short"):
        arcos.parse_sip(emu.sip()[:25])


def test_parser_recovers_after_a_truncated_packet():
    parser = arcos.PacketParser()
    good = arcos.encode(arcos.VEL, 123)
    assert parser.feed(good[:5] + good + good) == [good[3:-2], good[3:-2]]
    assert parser.errors == 1


packets = st.builds(
    lambda command, value: arcos.encode(command, value),
    st.integers(0, 255),
    st.none() | st.integers(-32767, 32767),
) | st.binary(min_size=1, max_size=200).map(arcos_packet)


@given(st.lists(st.binary(max_size=300), max_size=20))
def test_parser_survives_any_bytes(chunks):
    parser = arcos.PacketParser()
    stream = b"".join(chunks)
    for chunk in chunks:
        for body in parser.feed(chunk):
            assert arcos_packet(body) in stream, "only whole packets with good checksums"
    assert parser.errors <= len(stream)


@given(st.lists(st.tuples(st.binary(max_size=40).map(lambda b: b.replace(b"\xfa", b"")), packets)))
def test_parser_finds_every_packet_between_noise(pairs):
    parser = arcos.PacketParser()
    found = []
    for noise, packet in pairs:
        found += parser.feed(noise)
        found += parser.feed(packet)
    assert found == [packet[3:-2] for _, packet in pairs]
    assert parser.errors <= sum(1 for noise, _ in pairs if noise)


@given(st.lists(st.binary(max_size=60) | packets.map(lambda p: p[: len(p) // 2])), packets)
def test_parser_resyncs_after_any_junk(junk, packet):
    # Whatever came before, a packet after a max-length gap of filler is found: nothing in
    # the junk can claim bytes that far ahead.
    parser = arcos.PacketParser()
    found = []
    for piece in junk:
        found += parser.feed(piece)
    found += parser.feed(bytes(arcos.MAX_COUNT + 3) + packet)
    assert found[-1] == packet[3:-2]
    stream = b"".join(junk) + bytes(arcos.MAX_COUNT + 3) + packet
    assert all(arcos_packet(body) in stream for body in found)


def motion(emulator):
    """Commands other than the keep-alive, which may fall anywhere between them."""
    return [c for c in emulator.commands if c.name != "PULSE"]


async def _when(bot, condition):
    readings = await bot.sensors()
    return readings if condition(readings) else None
