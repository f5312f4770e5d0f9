"""The mavlink:// driver at the wire, against a MAVLink vehicle emulator that keeps the rules."""

import asyncio
import json
import math
import re

import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink.dialects.v20 import ardupilotmega as mavlink

import rhal
from rhal import NotSupportedError, RobotConnectionError
from rhal.mavlink import VELOCITY_YAW_RATE_MASK, MavlinkRobot, VehicleControlError
from tests.rhal.mavlink_emulator import MavlinkEmulator
from tests.waiting import until

REQUESTED = {
    mavlink.MAVLINK_MSG_ID_ATTITUDE,
    mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED,
    mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT,
    mavlink.MAVLINK_MSG_ID_GPS_RAW_INT,
    mavlink.MAVLINK_MSG_ID_SYS_STATUS,
    mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR,
    mavlink.MAVLINK_MSG_ID_VFR_HUD,
}
ACCEPTED = mavlink.MAV_RESULT_ACCEPTED


@pytest.fixture
async def emulator():
    emu = MavlinkEmulator(heartbeat=0.2)
    await emu.start()
    yield emu
    await emu.stop()


@pytest.fixture
async def robot(emulator):
    bot = MavlinkRobot(emulator.url, arm_timeout=2)
    await bot.open()
    yield bot
    await bot.close()


@pytest.fixture
async def px4():
    emu = MavlinkEmulator(autopilot="px4", heartbeat=0.2)
    await emu.start()
    yield emu
    await emu.stop()


def control_commands(emulator):
    """Mode and arming commands, leaving out the telemetry requests."""
    return [c for c in emulator.commands if c.name != "SET_MESSAGE_INTERVAL"]


async def _when(bot, condition):
    readings = await bot.sensors()
    return readings if condition(readings) else None


# -- opening ---------------------------------------------------------------------------------


async def test_open_meets_the_vehicle_as_a_ground_station(robot, emulator):
    (system, component, mav_type), *_ = await until(lambda: emulator.gcs_heartbeats[-1:])
    assert (system, component, mav_type) == (245, 190, mavlink.MAV_TYPE_GCS)
    assert robot.vehicle == {
        "system": 1, "component": 1, "autopilot": "ardupilot", "type": "GROUND_ROVER",
    }  # fmt: skip
    await until(lambda: set(emulator.intervals) == REQUESTED)
    assert emulator.intervals[mavlink.MAVLINK_MSG_ID_ATTITUDE] == pytest.approx(0.1)
    readings = await robot.sensors()
    assert (readings["mode"], readings["armed"]) == ("MANUAL", False)
    assert emulator.setpoints == [], "nothing streams to an ArduPilot the program has not taken"
    assert emulator.bad_frames == 0


async def test_our_system_id_is_an_option(emulator):
    async with MavlinkRobot(emulator.url, sysid=42):
        await until(lambda: any(beat[0] == 42 for beat in emulator.gcs_heartbeats))
    assert {c.source for c in emulator.commands} == {(42, 190)}


async def test_open_fails_clearly_when_nothing_answers():
    silent = await asyncio.start_server(lambda r, w: None, "127.0.0.1", 0)
    port = silent.sockets[0].getsockname()[1]
    try:
        bot = MavlinkRobot(f"mavlink+tcp://127.0.0.1:{port}", timeout=0.3)
        with pytest.raises(RobotConnectionError, match="no MAVLink vehicle answered"):
            await bot.open()
        assert not bot.is_open
    finally:
        silent.close()
        await silent.wait_closed()


@pytest.mark.parametrize("url", ["mavlink:///dev/no-such-autopilot", "mavlink+tcp://127.0.0.1:1"])
async def test_open_fails_clearly_without_a_link(url):
    with pytest.raises(RobotConnectionError, match="cannot open robot"):
        await MavlinkRobot(url).open()


@pytest.mark.parametrize(
    ("url", "device", "address", "listen"),
    [("mavlink://", "/dev/ttyACM0", None, None),
     ("mavlink:///dev/ttyUSB1?baud=57600", "/dev/ttyUSB1", None, None),
     ("MAVLINK://COM4", "COM4", None, None),
     ("mavlink+tcp://", None, ("127.0.0.1", 5760), None),
     ("mavlink+tcp://127.0.0.1:5762", None, ("127.0.0.1", 5762), None),
     ("mavlink+udp://", None, ("", 14550), True),
     ("mavlink+udp://:14551", None, ("", 14551), True),
     ("mavlink+udp://127.0.0.1:14550", None, ("127.0.0.1", 14550), False),
     ("mavlink+udp://127.0.0.1:14550?listen=true", None, ("127.0.0.1", 14550), True)],
)  # fmt: skip
def test_url_names_the_link(url, device, address, listen):
    bot = rhal.connect(url)
    assert (bot.device, bot.address, bot.listen) == (device, address, listen)


def test_options_are_checked():
    bot = rhal.connect(
        "mavlink+tcp://?arm=false&arm_timeout=0.5&setpoint_rate=20&sysid=200&timeout=1.5"
        "&disarm_on_close=false&baud=115200"
    )
    assert (bot.arm, bot.arm_timeout, bot.setpoint_rate, bot.sysid) == (False, 0.5, 20.0, 200)
    assert (bot.timeout, bot.disarm_on_close, bot.baud) == (1.5, False, 115200)
    for options, word in [
        ({"sysid": 0}, "sysid"),
        ({"sysid": 256}, "sysid"),
        ({"setpoint_rate": 1}, "setpoint_rate"),
        ({"arm_timeout": 0}, "arm_timeout"),
        ({"arm": "yes"}, "arm"),
        ({"listen": True}, "listen"),  # a TCP URL
    ]:
        with pytest.raises(ValueError, match=word):
            MavlinkRobot("mavlink+tcp://", **options)
    with pytest.raises(ValueError, match="listen=false"):
        MavlinkRobot("mavlink+udp://:14550", listen=False)
    with pytest.raises(ValueError, match="not a mavlink URL"):
        MavlinkRobot("sim://")


def test_capabilities_before_open():
    specs = MavlinkRobot().capabilities()["sensors"]
    assert {"heading", "position", "range", "battery", "gps", "mode", "armed"} <= set(specs)
    assert specs["position"]["unit"] == {"x": "m", "y": "m", "theta": "rad"}


# -- taking the vehicle ----------------------------------------------------------------------


async def test_first_drive_switches_to_guided_then_arms(robot, emulator):
    assert await robot.drive(0.3, 0.5) == {"linear": 0.3, "angular": 0.5}
    mode, arm = control_commands(emulator)
    assert (mode.name, mode.params[:2], mode.result) == ("DO_SET_MODE", (1.0, 15.0), ACCEPTED)
    assert (arm.name, arm.params[0], arm.result) == ("ARM_DISARM", 1.0, ACCEPTED)
    assert mode.source == arm.source == (245, 190)
    assert emulator.mode == "GUIDED" and emulator.armed
    await until(lambda: emulator.setpoints)
    first = emulator.setpoints[0]
    assert first.frame == mavlink.MAV_FRAME_BODY_NED
    assert first.type_mask == VELOCITY_YAW_RATE_MASK == 0x05C7
    assert first.applied
    assert emulator.commanded() == pytest.approx((0.3, 0.5))
    assert first.yaw_rate == pytest.approx(-0.5), "NED yaw rate is clockwise"
    await until(lambda: emulator.north > 0.02)  # it moves
    await until(lambda: _when(robot, lambda r: (r["mode"], r["armed"]) == ("GUIDED", True)))
    await robot.drive(-0.2, 0.0)
    await until(lambda: emulator.commanded() == pytest.approx((-0.2, 0.0)))
    assert len(control_commands(emulator)) == 2, "taken once, then only setpoints"


async def test_px4_streams_setpoints_then_switches_to_offboard_then_arms(px4):
    async with MavlinkRobot(px4.url, arm_timeout=3) as bot:
        assert bot.vehicle["autopilot"] == "px4"
        await bot.drive(0.2, -0.4)
        mode, arm = control_commands(px4)
        assert mode.name == "DO_SET_MODE" and mode.params[:3] == (1.0, 6.0, 0.0)
        assert mode.setpoints_before >= 3, "OFFBOARD needs setpoints streaming before"
        assert arm.name == "ARM_DISARM" and arm.result == ACCEPTED
        assert px4.mode == "OFFBOARD" and px4.armed
        await until(lambda: px4.commanded() == pytest.approx((0.2, -0.4)))
        assert px4.stops == 0, "the idle stream before any command is not a stop"
        readings = await until(lambda: _when(bot, lambda r: r["mode"] == "OFFBOARD"))
        assert readings["armed"] is True
        # Held past PX4's 0.5 s offboard timeout: still in OFFBOARD.
        held = len(px4.setpoints)
        await until(lambda: len(px4.setpoints) >= held + 8)
        assert px4.failsafes == 0 and px4.mode == "OFFBOARD"
        assert px4.speed == pytest.approx(0.2)
        await bot.stop()
        await until(lambda: px4.stops == 1 and px4.speed == 0.0)


async def test_px4_refuses_offboard_without_a_stream(px4):
    # The rule the driver's prestream satisfies, met by a bare client that skips it.
    port = int(px4.url.rsplit(":", 1)[1])
    reader, writer = await asyncio.open_connection("127.0.0.1", port)
    client = mavlink.MAVLink(None, srcSystem=255, srcComponent=190)
    client.robust_parsing = True
    writer.write(
        mavlink.MAVLink_command_long_message(1, 1, 176, 0, 1, 6, 0, 0, 0, 0, 0).pack(client)
    )
    received = []
    try:
        while not any(m.get_type() == "COMMAND_ACK" for m in received):
            received += client.parse_buffer(await asyncio.wait_for(reader.read(4096), 3)) or []
    finally:
        writer.close()
    (ack,) = [m for m in received if m.get_type() == "COMMAND_ACK"]
    assert ack.result == mavlink.MAV_RESULT_TEMPORARILY_REJECTED
    assert "Offboard is currently not available" in px4.texts_sent[-1]
    assert px4.mode == "MANUAL"


async def test_a_held_speed_keeps_streaming(robot, emulator):
    await robot.drive(0.2, 0.1)
    start = len(emulator.setpoints)
    await until(lambda: len(emulator.setpoints) >= start + 10)
    held = emulator.setpoints[start:]
    assert {(s.vx, s.yaw_rate, s.stamp) for s in held} == {
        (held[0].vx, held[0].yaw_rate, held[0].stamp)
    }, "repeats of the one command, with its stamp"
    assert held[0].vx == pytest.approx(0.2)
    assert emulator.timeouts == 0 and emulator.speed == pytest.approx(0.2)


async def test_stop_sends_a_zero_setpoint_every_time(robot, emulator):
    await robot.drive(0.4, 1.0)
    await until(lambda: emulator.speed > 0)
    await robot.stop()
    await until(lambda: emulator.commanded() == (0.0, 0.0) and emulator.speed == 0.0)
    assert emulator.stops == 1
    await robot.stop()  # already stopped: sent all the same
    await until(lambda: emulator.stops == 2)
    streamed = len(emulator.setpoints)
    await until(lambda: len(emulator.setpoints) >= streamed + 5)  # zeros hold it
    assert emulator.stops == 2, "the stream's repeats are not new stops"
    assert all(s.vx == 0 and s.yaw_rate == 0 for s in emulator.setpoints[streamed:])
    assert emulator.mode == "GUIDED" and emulator.armed, "a stop holds, it does not disarm"
    await robot.drive(0.1, 0.0)  # and the next drive needs no new mode or arming
    await until(lambda: emulator.speed > 0)
    assert len(control_commands(emulator)) == 2


async def test_stop_is_sent_even_before_the_vehicle_was_taken(robot, emulator):
    await robot.stop()
    await until(lambda: emulator.stops == 1)
    assert emulator.commanded() == (0.0, 0.0)
    assert not emulator.setpoints[-1].applied  # ignored in MANUAL, as ArduPilot does
    assert control_commands(emulator) == [], "a stop never arms"


async def test_refused_arming_is_a_clear_error_with_the_autopilot_reason(emulator):
    emulator.gps_fix = False
    async with MavlinkRobot(emulator.url, arm_timeout=0.3) as bot:
        with pytest.raises(VehicleControlError, match="PreArm: GPS: No fix") as caught:
            await bot.drive(0.3, 0.0)
        assert "would not arm within 0.3 s" in str(caught.value)
        assert "COMMAND_ACK DENIED" in str(caught.value)
        assert not emulator.armed
        assert all(s.vx == 0 for s in emulator.setpoints), "no speed before arming"
        readings = await bot.sensors()  # still usable
        assert "PreArm: GPS: No fix" in readings["messages"]
        await bot.stop()


async def test_arming_is_retried_until_the_autopilot_agrees(emulator):
    emulator.gps_fix = False
    async with MavlinkRobot(emulator.url, arm_timeout=20) as bot:
        driving = asyncio.create_task(bot.drive(0.2, 0.0))
        await until(lambda: emulator.named("ARM_DISARM"))
        assert emulator.named("ARM_DISARM")[0].result == mavlink.MAV_RESULT_DENIED
        emulator.gps_fix = True  # the GPS gets its fix
        await asyncio.wait_for(driving, 10)
        assert emulator.armed and emulator.named("ARM_DISARM")[-1].result == ACCEPTED
        await until(lambda: emulator.commanded() == pytest.approx((0.2, 0.0)))


async def test_stop_while_arming_abandons_the_drive(emulator):
    emulator.gps_fix = False
    async with MavlinkRobot(emulator.url, arm_timeout=20) as bot:
        driving = asyncio.create_task(bot.drive(0.2, 0.0))
        await until(lambda: emulator.named("ARM_DISARM"))
        await bot.stop()
        with pytest.raises(VehicleControlError, match=r"stop\(\) was called"):
            await asyncio.wait_for(driving, 10)
        assert not emulator.armed
        assert all(s.vx == 0 for s in emulator.setpoints)


async def test_a_refused_mode_is_a_clear_error_with_the_autopilot_reason(emulator):
    emulator.position = False  # Rover's GUIDED needs a position estimate
    async with MavlinkRobot(emulator.url, arm_timeout=0.3) as bot:
        with pytest.raises(VehicleControlError, match="would not switch to GUIDED") as caught:
            await bot.drive(0.3, 0.0)
        assert "requires position (COMMAND_ACK FAILED)" in str(caught.value)
    assert emulator.named("ARM_DISARM") == [], "no arming in the wrong mode"


async def test_with_arm_false_the_driver_never_arms(emulator):
    async with MavlinkRobot(emulator.url, arm=False) as bot:
        with pytest.raises(VehicleControlError, match="arm=false") as caught:
            await bot.drive(0.3, 0.0)
        assert "MANUAL and disarmed" in str(caught.value)
        assert control_commands(emulator) == []
        emulator.set_mode("GUIDED")  # the operator, from the transmitter
        emulator.armed = True
        await until(lambda: _when(bot, lambda r: r["armed"] and r["mode"] == "GUIDED"))
        await bot.drive(0.3, 0.0)
        await until(lambda: emulator.speed == pytest.approx(0.3))
        assert control_commands(emulator) == []
    assert emulator.armed, "it did not arm the vehicle, so it does not disarm it"


async def test_a_take_over_is_honoured_until_stop(robot, emulator):
    await robot.drive(0.3, 0.0)
    emulator.set_mode("HOLD")  # someone flips the mode switch
    await until(lambda: _when(robot, lambda r: r["mode"] == "HOLD"))
    with pytest.raises(VehicleControlError, match="took it over"):
        await robot.drive(0.3, 0.0)
    assert len(control_commands(emulator)) == 2, "the driver did not take it back"
    await robot.stop()
    await robot.drive(0.2, 0.0)
    assert emulator.mode == "GUIDED"
    await until(lambda: emulator.speed == pytest.approx(0.2))


async def test_close_stops_then_disarms_what_it_armed(emulator):
    async with MavlinkRobot(emulator.url) as bot:
        await bot.drive(0.3, 0.0)
        await until(lambda: emulator.speed > 0)
    assert emulator.stops == 1 and emulator.commanded() == (0.0, 0.0)
    last = control_commands(emulator)[-1]
    assert (last.name, last.params[0], last.result) == ("ARM_DISARM", 0.0, ACCEPTED)
    assert not emulator.armed and emulator.speed == 0.0


async def test_disarm_on_close_false_leaves_it_armed_and_stopped(emulator):
    async with MavlinkRobot(emulator.url, disarm_on_close=False) as bot:
        await bot.drive(0.3, 0.0)
    assert emulator.armed and emulator.mode == "GUIDED"
    assert emulator.commanded() == (0.0, 0.0) and emulator.stops == 1


@pytest.mark.parametrize(
    ("linear", "angular"), [(0.3, 0.5), (-0.25, -1.0), (0.1, -0.2), (-0.4, 1.5)]
)
async def test_setpoints_carry_speeds_with_ned_signs(robot, emulator, linear, angular):
    await robot.drive(linear, angular)
    await until(lambda: emulator.commanded() == pytest.approx((linear, angular)))
    assert emulator.setpoints[-1].yaw_rate == pytest.approx(-angular)


async def test_speeds_are_clamped_before_the_wire(emulator):
    async with MavlinkRobot(emulator.url, max_linear=0.2, max_angular=0.5) as bot:
        assert await bot.drive(1.0, -3.0) == {"linear": 0.2, "angular": -0.5}
        await until(lambda: emulator.commanded() == pytest.approx((0.2, -0.5)))


# -- readings --------------------------------------------------------------------------------


async def test_telemetry_is_converted_to_rhal_frames(robot, emulator):
    emulator.north, emulator.east, emulator.yaw = 3.0, 4.0, math.radians(30)  # NED
    emulator.battery = 11.1

    def updated(r):
        return r["battery"] == pytest.approx(11.1) and r["position"] and r["gps"]

    readings = await until(lambda: _when(robot, updated))
    assert readings["heading"] == pytest.approx(30.0, abs=1e-3)  # compass: clockwise
    assert readings["position"] == pytest.approx(
        {"x": 4.0, "y": 3.0, "theta": math.radians(60)}, abs=1e-4
    )  # x east, y north, theta counter-clockwise from east
    assert readings["velocity"] == {"linear": 0.0, "angular": 0.0}
    gps = readings["gps"]
    assert gps["lat"] == pytest.approx(47.397742 + math.degrees(3.0 / 6378137.0), abs=1e-7)
    assert gps["lon"] > 8.545594 and gps["alt"] == pytest.approx(488.0)
    assert (gps["fix"], gps["satellites"]) == (mavlink.GPS_FIX_TYPE_3D_FIX, 10)
    assert readings["range"] == pytest.approx(2.0)  # the east wall at 5 m, 30 deg off
    assert (readings["mode"], readings["armed"], readings["errors"]) == ("MANUAL", False, 0)


async def test_measured_velocity_is_forward_speed_and_ccw_turn(robot, emulator):
    emulator.yaw = math.radians(-120)
    await robot.drive(0.25, 0.4)

    def moving(r):
        return r["velocity"] and r["velocity"]["linear"] > 0.2

    readings = await until(lambda: _when(robot, moving))
    assert readings["velocity"] == pytest.approx({"linear": 0.25, "angular": 0.4}, abs=1e-3)


async def test_reversing_keeps_the_telemetry_coming(robot, emulator):
    await robot.drive(-0.2, 0.0)

    def reversing(r):
        return r["velocity"] and r["velocity"]["linear"] < -0.1

    await until(lambda: _when(robot, reversing))
    # The vehicle lives on, sending GPS_RAW_INT (its ground speed is unsigned) as it backs up.
    backing_from = emulator.north
    await until(lambda: emulator.north < backing_from - 0.2)  # 1 s: two GPS reports at least


async def test_range_is_none_beyond_the_sensors_reach(robot, emulator):
    emulator.north = -4.0  # 9 m from the north wall; the sensor reaches 8
    await until(lambda: _when(robot, lambda r: r["range"] is None))
    emulator.range_override = 0.75
    await until(lambda: _when(robot, lambda r: r["range"] == 0.75))


async def test_status_texts_keep_the_last_few(robot, emulator):
    for number in range(7):
        emulator.say(f"message {number}")
    await until(lambda: _when(robot, lambda r: r["messages"][-1:] == ["message 6"]))
    assert (await robot.sensor("messages")) == [f"message {n}" for n in range(2, 7)]


async def test_readings_are_json_and_match_capabilities(robot):
    readings = await robot.sensors()
    assert json.loads(json.dumps(readings)) == readings
    assert set(readings) == set(robot.capabilities()["sensors"])
    with pytest.raises(NotSupportedError, match="no sensor 'bumper'"):
        await robot.sensor("bumper")


# -- links and faults ------------------------------------------------------------------------


async def failing(call):
    try:
        await call()
    except RobotConnectionError as exc:
        return exc


async def test_tcp_link_lost_then_back(emulator):
    async with MavlinkRobot(emulator.url, timeout=1) as bot:
        await bot.drive(0.2, 0.0)
        await emulator.unplug()
        error = await until(lambda: failing(bot.sensors))
        assert "no link to the mavlink vehicle" in str(error)
        assert re.search(r"\(.*(reset|closed).*\); reconnecting$", str(error))
        with pytest.raises(RobotConnectionError, match="no link"):
            await bot.drive(0.2, 0.0)
        with pytest.raises(RobotConnectionError, match="no link"):
            await bot.stop()
        await emulator.replug()
        await until(lambda: bot.connected)
        streamed = len(emulator.setpoints)
        await until(lambda: _when(bot, lambda r: r["armed"]))
        assert all(s.vx == 0 for s in emulator.setpoints[streamed:]), "motion not resumed"
        await bot.drive(-0.1, 0.0)  # still GUIDED and armed: taken without new commands
        await until(lambda: emulator.speed == pytest.approx(-0.1))
        assert [c.name for c in control_commands(emulator)] == ["DO_SET_MODE", "ARM_DISARM"]


async def test_serial_link_on_a_pty_and_its_replug():
    emu = MavlinkEmulator(link="pty", heartbeat=0.2)
    await emu.start()
    try:
        assert emu.url.startswith("mavlink:///") and "baud=115200" in emu.url
        async with rhal.connect(emu.url, timeout=1) as bot:
            await bot.drive(0.2, 0.3)
            await until(lambda: emu.commanded() == pytest.approx((0.2, 0.3)))
            await emu.unplug()
            await until(lambda: not bot.connected)
            error = await failing(bot.sensors)
            assert "no link to the mavlink vehicle" in str(error)
            await emu.replug()
            await until(lambda: bot.connected)
            await bot.drive(0.1, 0.0)
            await until(lambda: emu.commanded() == pytest.approx((0.1, 0.0)))
    finally:
        await emu.stop()


async def test_udp_to_a_vehicle_and_its_silence():
    emu = MavlinkEmulator(link="udp", heartbeat=0.2)
    await emu.start()
    try:
        async with rhal.connect(emu.url, timeout=1) as bot:
            assert bot.listen is False
            await bot.drive(0.2, 0.0)
            await until(lambda: emu.speed == pytest.approx(0.2))
            await emu.unplug()  # UDP has no hang-up: the silence tells
            error = await until(lambda: failing(bot.sensors))
            assert "no HEARTBEAT from the vehicle for 1 s" in str(error)
            await emu.replug()
            await until(lambda: bot.connected)
            await bot.drive(0.1, 0.0)
            await until(lambda: emu.speed == pytest.approx(0.1))
    finally:
        await emu.stop()


async def test_udp_listening_for_the_vehicle():
    emu = MavlinkEmulator(link="udpout", heartbeat=0.2)
    await emu.start()
    try:
        async with rhal.connect(emu.url) as bot:
            assert bot.listen is True
            await bot.drive(0.2, 0.0)
            await until(lambda: emu.speed == pytest.approx(0.2))
            assert emu.gcs_heartbeats[0][:2] == (245, 190)
    finally:
        await emu.stop()


async def test_noise_on_the_wire_is_dropped_and_counted(robot, emulator):
    good = emulator.frame(mavlink.MAVLink_statustext_message(6, b"after the noise"))
    bad = bytearray(emulator.frame(mavlink.MAVLink_statustext_message(6, b"bad crc")))
    bad[-1] ^= 0xFF
    emulator.inject(b"\x13\x37line noise" + good[:7] + bytes(300) + bytes(bad) + good)
    await until(lambda: robot.errors >= 2)
    await until(lambda: _when(robot, lambda r: r["messages"][-1:] == ["after the noise"]))
    assert (await robot.sensors())["errors"] == robot.errors
    assert "bad crc" not in (await robot.sensors())["messages"]
    await robot.drive(0.1, 0.0)  # still working
    await until(lambda: emulator.speed == pytest.approx(0.1))


# -- frames, without a link ------------------------------------------------------------------


def frame(message, system=1):
    return message.pack(mavlink.MAVLink(None, srcSystem=system, srcComponent=1))


HEARTBEAT = frame(mavlink.MAVLink_heartbeat_message(10, 3, 1, 0, 3, 3))


def fresh_robot():
    bot = MavlinkRobot("mavlink+tcp://")
    bot._receive(HEARTBEAT)
    return bot


def statustext(text):
    return frame(mavlink.MAVLink_statustext_message(6, text.encode()))


floats = st.floats(width=32)
messages = st.one_of(
    st.builds(mavlink.MAVLink_heartbeat_message, st.integers(0, 255), st.integers(0, 255),
              st.integers(0, 255), st.integers(0, 2**32 - 1), st.integers(0, 255),
              st.integers(0, 255)),
    st.builds(mavlink.MAVLink_attitude_message, st.integers(0, 2**32 - 1), floats, floats,
              floats, floats, floats, floats),
    st.builds(mavlink.MAVLink_local_position_ned_message, st.integers(0, 2**32 - 1), floats,
              floats, floats, floats, floats, floats),
    st.builds(mavlink.MAVLink_global_position_int_message, st.integers(0, 2**32 - 1),
              st.integers(-(2**31), 2**31 - 1), st.integers(-(2**31), 2**31 - 1),
              st.integers(-(2**31), 2**31 - 1), st.integers(-(2**31), 2**31 - 1),
              st.integers(-(2**15), 2**15 - 1), st.integers(-(2**15), 2**15 - 1),
              st.integers(-(2**15), 2**15 - 1), st.integers(0, 65535)),
    st.builds(mavlink.MAVLink_distance_sensor_message, st.integers(0, 2**32 - 1),
              st.integers(0, 65535), st.integers(0, 65535), st.integers(0, 65535),
              st.integers(0, 255), st.integers(0, 255), st.integers(0, 255), st.integers(0, 255)),
    st.builds(mavlink.MAVLink_vfr_hud_message, floats, floats, st.integers(-(2**15), 2**15 - 1),
              st.integers(0, 65535), floats, floats),
    st.builds(mavlink.MAVLink_sys_status_message, *[st.integers(0, 2**32 - 1)] * 3,
              *[st.integers(0, 65535)] * 2, st.integers(-(2**15), 2**15 - 1),
              st.integers(-128, 127), *[st.integers(0, 65535)] * 6),
    st.builds(mavlink.MAVLink_statustext_message, st.integers(0, 255), st.binary(max_size=50)),
    st.builds(mavlink.MAVLink_command_ack_message, st.integers(0, 65535), st.integers(0, 255)),
)  # fmt: skip


@settings(max_examples=60, deadline=None)
@given(st.lists(st.binary(max_size=300), max_size=15))
def test_any_bytes_are_survived_and_counted(chunks):
    bot = fresh_robot()
    for chunk in chunks:
        bot._receive(chunk)
    assert bot.errors <= sum(len(chunk) for chunk in chunks)
    json.dumps(bot._snapshot(), allow_nan=False)


@settings(max_examples=60, deadline=None)
@given(st.lists(messages, max_size=12))
def test_any_field_values_give_json_readings(vehicle_messages):
    bot = fresh_robot()
    for message in vehicle_messages:
        bot._receive(frame(message))
    readings = bot._snapshot()
    json.dumps(readings, allow_nan=False)  # no NaN or infinity reaches a program
    if readings["heading"] is not None:
        assert 0.0 <= readings["heading"] < 360.0
    assert bot.errors == 0


@settings(max_examples=60, deadline=None)
@given(st.lists(st.tuples(st.binary(max_size=40), st.text(min_size=1, max_size=40)), max_size=20))
def test_every_frame_between_noise_is_found(pairs):
    # Noise without the frame markers (0xFD, 0xFE) cannot swallow the frame that follows it.
    bot = fresh_robot()
    noises = [noise.replace(b"\xfd", b"").replace(b"\xfe", b"") for noise, _ in pairs]
    for noise, (_, text) in zip(noises, pairs, strict=True):
        bot._receive(noise)
        bot._receive(statustext(text))
    # As STATUSTEXT carries them: 50 bytes, up to the first NUL, ASCII.
    texts = [t.encode()[:50].split(b"\0")[0] for _, t in pairs]
    expected = [t.decode("ascii", errors="replace").strip() for t in texts]
    assert [text for _, text in bot._text_log] == expected
    assert bot.errors == sum(1 for noise in noises if noise)


@settings(max_examples=60, deadline=None)
@given(st.lists(st.binary(max_size=60) | messages.map(lambda m: frame(m)[:9]), max_size=10))
def test_a_frame_after_a_gap_is_found_whatever_came_before(junk):
    # The longest frame is 280 bytes: after that many zeros no junk can still claim bytes.
    bot = fresh_robot()
    for piece in junk:
        bot._receive(piece)
    bot._receive(bytes(300) + statustext("in sync"))
    assert bot._text_log[-1:] == [(6, "in sync")]


@settings(max_examples=60, deadline=None)
@given(
    st.floats(-0.5, 0.5, allow_subnormal=False),
    st.floats(-2.0, 2.0, allow_subnormal=False),
)
def test_setpoint_frames_decode_to_body_speed_and_clockwise_rate(linear, angular):
    bot = fresh_robot()
    bot._setpoint = (linear, angular, 7)
    parser = mavlink.MAVLink(None)
    (message,) = parser.parse_buffer(bot._setpoint_frame())
    assert message.get_type() == "SET_POSITION_TARGET_LOCAL_NED"
    assert (message.target_system, message.target_component) == (1, 1)
    assert (message.get_srcSystem(), message.get_srcComponent()) == (245, 190)
    assert message.coordinate_frame == mavlink.MAV_FRAME_BODY_NED
    assert message.type_mask == VELOCITY_YAW_RATE_MASK and message.time_boot_ms == 7
    assert message.vx == pytest.approx(linear, rel=1e-6, abs=1e-30)
    assert message.yaw_rate == pytest.approx(-angular, rel=1e-6, abs=1e-30)
    assert (message.vy, message.vz) == (0.0, 0.0)


def test_telemetry_from_another_system_is_ignored():
    bot = fresh_robot()
    bot._receive(frame(mavlink.MAVLink_sys_status_message(0, 0, 0, 0, 9000, 0, 0, 0, 0, 0, 0, 0, 0),
                       system=7))  # fmt: skip
    bot._receive(frame(mavlink.MAVLink_heartbeat_message(6, 8, 0, 0, 4, 3), system=255))
    assert bot._snapshot()["battery"] is None
    assert bot.vehicle["system"] == 1


def test_heading_falls_back_to_vfr_hud():
    bot = fresh_robot()
    bot._receive(frame(mavlink.MAVLink_vfr_hud_message(0, 0, 275, 0, 0, 0)))
    assert bot._snapshot()["heading"] == pytest.approx(275.0)
    bot._receive(frame(mavlink.MAVLink_attitude_message(0, 0, 0, math.radians(-10), 0, 0, 0)))
    assert bot._snapshot()["heading"] == pytest.approx(350.0)
