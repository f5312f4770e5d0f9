"""The nxt:// driver at the wire: nxt-python's protocol against an NXT brick emulator on a pty."""

import errno
import json
import math
import os
import socket
import struct
import sys
import threading
import tty
import types

import nxt.backend.devfile
import nxt.brick
import nxt.error
import nxt.motor
import nxt.sensor
import nxt.sensor.generic
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rhal
from rhal import NotSupportedError, RobotConnectionError
from rhal.nxt_brick import DevFileLink, ErrorCounter, NxtRobot, ReplyScanner, parse_url
from tests.rhal.nxt_emulator import NxtEmulator
from tests.waiting import until

TOP_SPEED = 170 / 60 * math.pi * 0.056  # m/s of a 56 mm wheel at power 100
POWER_STEP = TOP_SPEED / 100  # m/s one unit of power stands for
ON, BRAKE, REGULATED = 0x01, 0x02, 0x04


@pytest.fixture
async def emulator():
    emu = NxtEmulator()
    await emu.start()
    yield emu
    await emu.stop()


@pytest.fixture
async def robot(emulator):
    bot = NxtRobot(emulator.url, rate=50)
    await bot.open()
    yield bot
    await bot.close()


def outputs(emulator):
    """The last SetOutputState fields for each port letter."""
    return {"ABC"[t.fields["port"]]: t.fields for t in emulator.named("SetOutputState")}


def reading(bot, name, condition):
    async def check():
        value = (await bot.sensors())[name]
        return condition(value)

    return check


# -- URLs and options ------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("url", "link"),
    [("nxt://", ("usb", None)),
     ("nxt://usb", ("usb", None)),
     ("nxt://usb/MyNXT", ("usb", "MyNXT")),
     ("nxt://usb/00:16:53:aa:bb:cc", ("usb", "00:16:53:AA:BB:CC")),
     ("nxt://usb/00165312ABCD", ("usb", "00:16:53:12:AB:CD")),  # its USB serial number
     ("nxt://usb/NXT-2", ("usb", "NXT-2")),
     ("nxt://bt/00:16:53:aa:bb:cc", ("bt", "00:16:53:AA:BB:CC")),
     ("nxt:///dev/rfcomm0", ("dev", "/dev/rfcomm0")),
     ("NXT:///dev/tty.NXT-DevB-1?rate=5", ("dev", "/dev/tty.NXT-DevB-1"))],
)  # fmt: skip
def test_url_names_the_link(url, link):
    assert parse_url(url) == link
    assert (NxtRobot(url).link, NxtRobot(url).target) == link


@pytest.mark.parametrize(
    ("url", "message"),
    [("nxt://bt", "Bluetooth address"),
     ("nxt://bt/MyNXT", "Bluetooth address"),
     ("nxt://bt/00:16:53:AA:BB", "Bluetooth address"),
     ("nxt://bt/0016:53AA:BBCC", "Bluetooth address"),
     ("nxt://wifi/robot", "unknown NXT link")],
)  # fmt: skip
def test_bad_urls_say_what_to_write(url, message):
    with pytest.raises(ValueError, match=message):
        NxtRobot(url)


@pytest.mark.parametrize(
    ("options", "message"),
    [({"left": "D"}, "motor port, A, B or C"),
     ({"left": "C"}, "both motor port C"),
     ({"ultrasonic": 5}, "sensor port, 1 to 4"),
     ({"touch": "front"}, "sensor port, 1 to 4"),
     ({"touch": 4}, "ultrasonic and touch are both on sensor port 4"),
     ({"light": 2, "sound": 2}, "light and sound are both on sensor port 2"),
     ({"wheel_diameter": 56}, "in metres"),
     ({"track": 0}, "greater than 0"),
     ({"rate": "fast"}, "rate must be a number"),
     ({"timeout": -1}, "greater than 0"),
     ({"keepalive": float("inf")}, "finite"),
     ({"reverse_left": "yes"}, "true or false"),
     ({"brake": 1}, "true or false"),
     ({"max_linear": 0}, "greater than 0")],
)  # fmt: skip
def test_bad_options_are_clear_errors(options, message):
    with pytest.raises(ValueError, match=message):
        NxtRobot("nxt://", **options)


def test_url_options_reach_the_driver():
    bot = rhal.connect(
        "nxt:///dev/rfcomm0?left=a&right=c&reverse_left=true&ultrasonic=&touch=1&track=0.12"
    )
    assert (bot.left, bot.right, bot.reverse_left, bot.track) == ("A", "C", True, 0.12)
    assert bot.sensor_ports == {"touch": 1}
    sensors = bot.capabilities()["sensors"]
    assert "range" not in sensors and sensors["bumper"] == {"unit": "bool", "port": 1}
    assert NxtRobot("nxt://", ultrasonic="none", light="3").sensor_ports == {"light": 3}
    with pytest.raises(TypeError, match="wheel"):
        rhal.connect("nxt://?wheel=3")


def test_capabilities_before_opening():
    caps = NxtRobot("nxt://").capabilities()
    assert caps["kind"] == "nxt"
    assert caps["drive"] == {"max_linear": 0.4, "max_angular": 3.0}
    assert set(caps["sensors"]) == {
        "position", "heading", "velocity", "wheels", "tacho", "range", "battery", "errors",
    }  # fmt: skip
    assert caps["sensors"]["range"]["port"] == 4


def test_speeds_map_to_powers_by_the_motor_top_speed():
    bot = NxtRobot("nxt://")
    assert bot.top_speed == pytest.approx(TOP_SPEED)
    assert bot.wheel_powers(0.2, 0.0) == (40, 40, 0.2, 0.0)  # 0.2 / 0.498 = 40.1 %
    assert bot.wheel_powers(-TOP_SPEED, 0.0)[:2] == (-100, -100)
    left, right, linear, angular = bot.wheel_powers(0.4, 3.0)
    # The outer wheel would need 0.57 m/s: both scale down, keeping the curve.
    assert right == 100 and left == 40
    assert angular / linear == pytest.approx(3.0 / 0.4)
    assert linear + angular * 0.115 / 2 == pytest.approx(TOP_SPEED)


# -- opening and closing ---------------------------------------------------------------------


async def test_open_greets_the_brick_and_sets_up_the_sensors(robot, emulator):
    assert emulator.names()[:3] == ["KeepAlive", "GetFirmwareVersion", "GetDeviceInfo"]
    off = emulator.named("SetOutputState")[:2]
    assert [(t.fields["port"], t.fields["power"], t.fields["mode"]) for t in off] == [
        (1, 0, 0),
        (2, 0, 0),
    ]
    assert (emulator.resets, emulator.stops) == (1, 0)
    modes = [tuple(t.fields.values()) for t in emulator.named("SetInputMode")]
    assert modes == [(3, 0x0B, 0x00)]  # port 4: low-speed 9 V (I2C), raw
    assert robot.identity == {
        "name": "NXT",
        "address": "00:16:53:0A:0B:0C",
        "firmware": "1.31",
        "protocol": "1.124",
        "sleep_timeout_ms": 600_000,
    }
    assert emulator.bad_frames == 0 and robot.errors == 0


async def test_close_stops_then_turns_the_motors_off(robot, emulator):
    await robot.drive(0.2, 0.0)
    await robot.close()
    await until(lambda: emulator.resets == 2)
    last = [(t.fields["port"], t.fields["mode"]) for t in emulator.named("SetOutputState")[-4:]]
    brake = ON | BRAKE | REGULATED
    assert last == [(1, brake), (2, brake), (1, 0), (2, 0)]
    assert emulator.stops == 1 and emulator.commanded() == (0.0, 0.0)
    await robot.close()  # again: nothing happens


async def test_open_fails_clearly_when_nothing_answers():
    master, slave = os.openpty()
    tty.setraw(slave)
    try:
        bot = NxtRobot(f"nxt://{os.ttyname(slave)}", timeout=0.3)
        with pytest.raises(RobotConnectionError, match="no NXT brick answered"):
            await bot.open()
        assert not bot.is_open
    finally:
        os.close(master)
        os.close(slave)


async def test_open_fails_clearly_without_the_device():
    with pytest.raises(RobotConnectionError, match="cannot open robot.*No such file"):
        await NxtRobot("nxt:///dev/no-such-rfcomm").open()


async def test_usb_without_a_brick_says_so():
    # Either no libusb here, or no brick on the bus: both name USB.
    with pytest.raises(RobotConnectionError, match="USB"):
        await NxtRobot("nxt://usb/NoSuchBrick").open()


async def test_bluetooth_without_pybluez_says_what_to_do(monkeypatch):
    monkeypatch.setitem(sys.modules, "bluetooth", None)  # import bluetooth fails
    with pytest.raises(RobotConnectionError, match="PyBluez.*nxt:///dev/rfcomm0"):
        await NxtRobot("nxt://bt/00:16:53:0A:0B:0C").open()


async def test_bluetooth_by_address_through_nxt_pythons_socket(monkeypatch, emulator):
    pybluez = FakePyBluez(emulator)
    monkeypatch.setitem(sys.modules, "bluetooth", pybluez)
    async with NxtRobot("nxt://bt/00:16:53:0a:0b:0c", rate=50) as bot:
        assert pybluez.connected_to == [("00:16:53:0A:0B:0C", 1)]  # RFCOMM channel 1
        assert bot.identity["name"] == "NXT"
        await bot.drive(0.2, 0.0)
        await until(lambda: outputs(emulator)["C"]["power"] == 40)
        emulator.distance_cm = 80
        await until(reading(bot, "range", lambda r: r == 0.8))
    await until(lambda: emulator.stops == 1)
    assert emulator.bad_frames == 0


# -- driving ---------------------------------------------------------------------------------


async def test_drive_sets_regulated_powers_on_b_and_c(robot, emulator):
    assert await robot.drive(0.2, 0.0) == {"linear": 0.2, "angular": 0.0}
    await until(lambda: outputs(emulator).get("C", {}).get("power") == 40)
    for port in "BC":
        fields = outputs(emulator)[port]
        assert fields["power"] == 40
        assert fields["mode"] == ON | REGULATED
        assert fields["regulation"] == 1  # speed
        assert fields["run_state"] == 0x20  # running
        assert (fields["turn_ratio"], fields["limit"]) == (0, 0)  # no tacho limit
    assert emulator.commanded() == pytest.approx((0.2, 0.0), abs=POWER_STEP)
    assert "A" not in outputs(emulator)


async def test_turning_sets_each_wheel(robot, emulator):
    await robot.drive(0.1, 1.0)  # wheels at 0.1 -+ 0.0575 m/s
    await until(lambda: outputs(emulator).get("C", {}).get("power") == 32)
    assert outputs(emulator)["B"]["power"] == 9
    linear, angular = emulator.commanded()
    assert linear == pytest.approx(0.1, abs=POWER_STEP)
    assert angular == pytest.approx(1.0, abs=2 * POWER_STEP / 0.115)


async def test_drive_past_what_the_motors_can_do_is_scaled_honestly(robot, emulator):
    applied = await robot.drive(1.0, 3.0)  # clamped to 0.4 m/s, then the outer wheel to 100
    await until(lambda: outputs(emulator).get("C", {}).get("power") == 100)
    assert applied["linear"] < 0.4 and applied["angular"] < 3.0
    assert applied["angular"] / applied["linear"] == pytest.approx(3.0 / 0.4)
    assert emulator.commanded() == pytest.approx(
        (applied["linear"], applied["angular"]), abs=2 * POWER_STEP / 0.115
    )


async def test_custom_ports_and_a_motor_mounted_backwards():
    emu = NxtEmulator(left="A", right="C", reverse_left=True)
    await emu.start()
    try:
        async with NxtRobot(emu.url, left="A", right="C", reverse_left=True, rate=50) as bot:
            await bot.drive(0.2, 0.0)
            await until(lambda: outputs(emu).get("C", {}).get("power") == 40)
            assert outputs(emu)["A"]["power"] == -40
            assert "B" not in outputs(emu)
            assert emu.commanded() == pytest.approx((0.2, 0.0), abs=POWER_STEP)
            # Forward for the robot although motor A counts backwards.
            await until(reading(bot, "position", lambda p: p["y"] > 0.02))
            assert (await bot.sensors())["tacho"]["left"] > 0
            await bot.stop()
            await until(lambda: emu.stops == 1)
            assert {t.fields["port"] for t in emu.named("SetOutputState")[-2:]} == {0, 2}
    finally:
        await emu.stop()


async def test_stop_brakes_both_motors_every_time(robot, emulator):
    await robot.drive(0.2, 0.0)
    for count in range(1, 4):  # stopped already: sent all the same
        await robot.stop()
        await until(lambda count=count: emulator.stops == count)
    brakes = emulator.named("SetOutputState")[-6:]
    fields = [(t.fields["port"], t.fields["power"], t.fields["mode"]) for t in brakes]
    assert fields == [(1, 0, ON | BRAKE | REGULATED), (2, 0, ON | BRAKE | REGULATED)] * 3
    assert emulator.commanded() == (0.0, 0.0)


async def test_drive_zero_is_a_stop(robot, emulator):
    await robot.drive(0.2, 0.0)
    assert await robot.drive(0.0, 0.0) == {"linear": 0.0, "angular": 0.0}
    await until(lambda: emulator.stops == 1)


async def test_coasting_stop_when_asked(emulator):
    async with NxtRobot(emulator.url, brake=False) as bot:
        await bot.drive(0.2, 0.0)
        await bot.stop()
        await until(lambda: emulator.stops == 1)
        modes = [
            (t.fields["mode"], t.fields["regulation"]) for t in emulator.named("SetOutputState")
        ]
        assert modes[-2:] == [(ON, 0), (ON, 0)]  # on, not braked, not regulated: floating


# -- odometry --------------------------------------------------------------------------------


async def test_odometry_integrates_the_rotation_counts(robot, emulator):
    start = await robot.sensors()
    assert start["position"] == {"x": 0.0, "y": 0.0, "theta": pytest.approx(math.pi / 2)}
    assert start["heading"] == 0.0
    # A whole turn of both wheels: one wheel circumference straight ahead.
    emulator.motors["B"].rotation += 360
    emulator.motors["C"].rotation += 360
    circumference = math.pi * 0.056
    await until(reading(robot, "position", lambda p: p["y"] == pytest.approx(circumference)))
    assert (await robot.sensors())["position"]["x"] == pytest.approx(0.0, abs=1e-9)
    assert (await robot.sensors())["tacho"] == {"left": 360, "right": 360}
    # Half a turn back on the left and forward on the right: a spin on the spot.
    emulator.motors["B"].rotation -= 180
    emulator.motors["C"].rotation += 180
    turn = circumference / 0.115  # rad: each wheel travels half a circumference
    await until(reading(robot, "heading", lambda h: h == pytest.approx(360 - math.degrees(turn))))
    position = (await robot.sensors())["position"]
    assert (position["x"], position["y"]) == pytest.approx((0.0, circumference), abs=1e-9)


async def test_odometry_follows_the_motors_while_driving(robot, emulator):
    await robot.drive(0.2, 0.0)
    await until(reading(robot, "velocity", lambda v: v["linear"] == pytest.approx(0.2, abs=0.03)))
    await until(reading(robot, "position", lambda p: p["y"] > 0.05))
    await robot.drive(0.0, 1.5)
    await until(reading(robot, "heading", lambda h: 30 < h < 330))
    await robot.stop()

    def agrees(readings):
        # The heading follows the counts exactly; the position is integrated one poll (0.1 s,
        # longer on a loaded machine) at a time, as one arc even when the poll spans the
        # change from driving to turning: centimetres, not millimetres, on a busy machine.
        x, y, theta = emulator.pose()
        position = readings["position"]
        return (
            position["x"] == pytest.approx(x, abs=0.03)
            and position["y"] == pytest.approx(y, abs=0.03)
            and math.remainder(position["theta"] - theta, math.tau) == pytest.approx(0, abs=0.01)
        )

    still = {"linear": 0.0, "angular": 0.0}
    readings = await until(lambda: _when(robot, lambda r: agrees(r) and r["velocity"] == still))
    assert readings["heading"] == pytest.approx(emulator.heading, abs=0.6)


# -- sensors ---------------------------------------------------------------------------------


async def test_ultrasonic_range_through_i2c(robot, emulator):
    assert (await robot.sensors())["range"] == 1.5  # the arena wall ahead
    emulator.distance_cm = 42
    await until(reading(robot, "range", lambda r: r == 0.42))
    writes = emulator.named("LSWrite")
    assert writes[-1].fields == {"port": 3, "tx_length": 2, "rx_length": 1, "data": b"\x02\x42"}
    assert "LSGetStatus" in emulator.names() and "LSRead" in emulator.names()


async def test_ultrasonic_nothing_in_reach_is_none(robot, emulator):
    emulator.distance_cm = 255
    await until(reading(robot, "range", lambda r: r is None))
    assert await robot.sensor("range") is None


async def test_ultrasonic_that_does_not_answer_reads_none(emulator):
    emulator.sensors = {}  # nothing plugged into port 4
    async with NxtRobot(emulator.url, rate=50) as bot:
        assert (await bot.sensors())["range"] is None
        assert bot.connected and bot.errors == 0


async def test_battery_in_volts(robot, emulator):
    assert (await robot.sensors())["battery"] == 8.0
    emulator.battery_mv = 7350
    await until(reading(robot, "battery", lambda v: v == 7.35))


async def test_touch_light_and_sound_when_configured():
    emu = NxtEmulator(sensors={1: "touch", 2: "sound", 3: "light", 4: "ultrasonic"})
    await emu.start()
    try:
        async with NxtRobot(emu.url, touch=1, sound=2, light=3, rate=50) as bot:
            modes = {t.fields["port"]: t.fields for t in emu.named("SetInputMode")}
            assert (modes[0]["sensor_type"], modes[0]["sensor_mode"]) == (0x01, 0x20)  # bool
            assert (modes[1]["sensor_type"], modes[1]["sensor_mode"]) == (0x08, 0x80)  # dBA %
            assert (modes[2]["sensor_type"], modes[2]["sensor_mode"]) == (0x05, 0x80)  # lamp on
            readings = await bot.sensors()
            assert (readings["touch"], readings["bumper"]) == (False, False)
            assert (readings["light"], readings["sound"]) == (50, 10)
            emu.touch_pressed, emu.light_percent, emu.sound_percent = True, 37, 64
            await until(reading(bot, "touch", lambda pressed: pressed))
            # Each sensor is its own telegram: wait for all three to have been read again.
            changed = lambda r: (r["light"], r["sound"]) == (37, 64)  # noqa: E731
            readings = await until(lambda: _when(bot, changed))
            assert readings["bumper"] is True
            assert set(readings) == set(bot.capabilities()["sensors"])
    finally:
        await emu.stop()


async def test_light_without_its_lamp(emulator):
    emulator.sensors = {2: "light"}
    async with NxtRobot(emulator.url, ultrasonic=None, light=2, floodlight=False):
        last = emulator.named("SetInputMode")[-1].fields
        assert (last["port"], last["sensor_type"]) == (1, 0x06)  # light inactive


async def test_a_sensor_not_configured_is_not_supported(emulator):
    async with NxtRobot(emulator.url, ultrasonic=None) as bot:
        readings = await bot.sensors()
        assert "range" not in readings and "touch" not in readings
        for name in ("range", "touch", "light", "sound"):
            with pytest.raises(NotSupportedError, match=f"no sensor '{name}'"):
                await bot.sensor(name)
        assert "LSWrite" not in emulator.names()


async def test_readings_are_json_and_match_capabilities(robot):
    readings = await robot.sensors()
    assert json.loads(json.dumps(readings)) == readings
    assert set(readings) == set(robot.capabilities()["sensors"])


async def test_keepalive_is_sent_periodically(emulator):
    async with NxtRobot(emulator.url, keepalive=0.05, rate=50):
        await until(lambda: emulator.keepalives >= 4)  # one on connecting, then the pulse


# -- faults ----------------------------------------------------------------------------------


async def test_unplugged_link_is_a_clear_error_then_replug_reconnects(robot, emulator):
    await robot.drive(0.2, 0.0)
    await until(lambda: emulator.commanded()[0] > 0)
    await emulator.unplug()

    async def failing():
        try:
            await robot.sensors()
        except RobotConnectionError as exc:
            return exc

    error = await until(failing)
    assert f"no link to the nxt robot at {emulator.url!r} (" in str(error)
    assert str(error).endswith("); reconnecting")
    with pytest.raises(RobotConnectionError, match="no link"):
        await robot.drive(0.1, 0.0)
    with pytest.raises(RobotConnectionError, match="no link"):
        await robot.stop()
    assert emulator.commanded()[0] > 0, "an NXT has no watchdog: it drives on"

    await emulator.replug()
    await until(lambda: robot.connected)
    assert emulator.commanded() == (0.0, 0.0), "reconnecting turns the motors off"
    assert emulator.resets == 2
    emulator.battery_mv = 7700
    await until(reading(robot, "battery", lambda v: v == 7.7))
    await robot.drive(-0.1, 0.0)
    await until(lambda: outputs(emulator)["B"]["power"] == -20)


async def test_close_while_unplugged_still_works(robot, emulator):
    await emulator.unplug()
    await until(lambda: not robot.connected)
    await robot.close()
    assert not robot.is_open


async def test_noise_between_replies_is_dropped_and_counted(robot, emulator):
    for burst in (b"\xff", bytes(range(256)), b"\x19\x00\x02\x06", b"\x00" * 70):
        before = robot.errors
        emulator.inject(burst)
        await until(lambda before=before: robot.errors > before)
    assert robot.connected
    assert (await robot.sensors())["errors"] == robot.errors
    emulator.distance_cm = 99
    await until(reading(robot, "range", lambda r: r == 0.99))
    await robot.drive(0.1, 0.0)
    await until(lambda: outputs(emulator)["C"]["power"] == 20)


async def test_a_reply_for_another_motor_is_not_taken_for_odometry(robot, emulator):
    # A well-formed GetOutputState reply for motor A, claiming a huge rotation count.
    fake = struct.pack("<BBBBbBBbBIiii", 2, 6, 0, 0, 50, 1, 1, 0, 0x20, 0, 0, 0, 99_999)
    for _ in range(5):
        before = robot.errors
        emulator.inject(struct.pack("<H", len(fake)) + fake)
        await until(lambda before=before: robot.errors > before)
    assert robot.connected
    position = (await robot.sensors())["position"]
    assert (position["x"], position["y"]) == (0.0, 0.0)


# -- the reply scanner and nxt-python's link, fed any bytes ------------------------------------

BATTERY = 0x0B


def battery_reply(millivolts: int) -> bytes:
    """A GetBatteryLevel reply with its length prefix, as LEGO's documentation lays it out."""
    return bytes([5, 0, 0x02, BATTERY, 0x00]) + struct.pack("<H", millivolts)


noise = st.binary(max_size=80).filter(lambda b: bytes([0x02, BATTERY]) not in b)


@given(noise, st.integers(0, 0xFFFF), st.data())
def test_scanner_finds_the_reply_after_any_noise(junk, millivolts, data):
    stream = junk + battery_reply(millivolts)
    cuts = sorted(data.draw(st.lists(st.integers(0, len(stream)), max_size=5)))
    scanner, found = ReplyScanner(), []
    for start, end in zip([0, *cuts], [*cuts, len(stream)], strict=True):
        scanner.feed(stream[start:end])
        if (reply := scanner.take(BATTERY)) is not None:
            found.append(reply)
    assert found == [battery_reply(millivolts)[2:]]
    assert (scanner.skipped > 0) == bool(junk)
    assert not scanner.buffer


@given(st.lists(st.binary(max_size=40), max_size=10), st.sampled_from([0x06, 0x07, 0x0B, 0x10]))
def test_scanner_only_returns_replies_to_what_was_asked(chunks, opcode):
    scanner = ReplyScanner()
    stream = b"".join(chunks)
    for chunk in chunks:
        scanner.feed(chunk)
        while (reply := scanner.take(opcode)) is not None:
            assert reply[:2] == bytes([0x02, opcode])
            assert bytes([len(reply), 0]) + reply in stream
    assert len(scanner.buffer) <= len(stream)


@settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(noise, st.integers(0, 0xFFFF))
def test_nxt_python_reads_through_noise_on_a_pty(junk, millivolts):
    # nxt-python's Brick over the driver's link; a thread here plays the brick.
    master, slave = os.openpty()
    tty.setraw(slave)
    errors = ErrorCounter()
    link = DevFileLink(os.ttyname(slave), timeout=5.0, errors=errors)
    brick = link.connect()
    requests = []

    def answer():
        requests.append(os.read(master, 100))
        os.write(master, junk + battery_reply(millivolts))

    brick_thread = threading.Thread(target=answer)
    brick_thread.start()
    try:
        assert brick.get_battery_level() == millivolts
        brick_thread.join()
        assert requests == [bytes([2, 0, 0x00, BATTERY])]  # the request, framed
        assert (errors.count > 0) == bool(junk)
    finally:
        brick_thread.join()
        brick.close()
        os.close(master)
        os.close(slave)


# -- the emulator, checked against LEGO's documentation and against nxt-python -------------------


class InMemoryDevice:
    """Stands in for nxt-python's device file, wired straight to an emulator."""

    def __init__(self, emulator: NxtEmulator) -> None:
        self.emulator, self.replies = emulator, bytearray()
        emulator._write = self.replies.extend

    def write(self, data: bytes) -> None:
        self.emulator.feed(data)

    def read(self, size: int) -> bytes:
        data = bytes(self.replies[:size])
        del self.replies[:size]
        return data

    def close(self) -> None:
        pass


def brick_on(emulator: NxtEmulator) -> nxt.brick.Brick:
    sock = nxt.backend.devfile.DevFileSock("in-memory")
    sock._device = InMemoryDevice(emulator)
    return nxt.brick.Brick(sock)


def test_emulator_decodes_telegrams_as_documented():
    emu = NxtEmulator()
    replies = bytearray()
    emu._write = replies.extend
    # SetOutputState, no reply: port B, power 75, MOTORON|REGULATED, speed regulation,
    # turn ratio 0, RUNNING, tacho limit 0 (LEGO BDK, Appendix 2).
    emu.feed(bytes.fromhex("0c00 8004 014b 0501 0020 00000000"))
    assert emu.telegrams[-1].fields == {
        "port": 1, "power": 75, "mode": 5, "regulation": 1, "turn_ratio": 0,
        "run_state": 0x20, "limit": 0,
    }  # fmt: skip
    assert not replies
    emu.feed(bytes.fromhex("0c00 8004 02b5 0501 0020 00000000"))  # port C, power -75
    assert emu.telegrams[-1].fields["power"] == -75
    assert emu.stops == 0
    assert emu.commanded() == pytest.approx((0.0, 2 * 0.75 * TOP_SPEED / -0.115))
    # GetBatteryLevel, reply wanted: 02 0B status then UWORD millivolts.
    emu.feed(bytes.fromhex("0200 000b"))
    assert bytes(replies) == bytes.fromhex("0500 020b 00 401f")  # 8000 mV
    # A stop on both: power 0, MOTORON|BRAKE|REGULATED; counted once per pair.
    emu.feed(bytes.fromhex("0c00 8004 0100 0701 0020 00000000"))
    emu.feed(bytes.fromhex("0c00 8004 0200 0701 0020 00000000"))
    assert (emu.stops, emu.commanded()) == (1, (0.0, 0.0))
    # An unknown opcode is answered as such; a frame of the wrong size is insane.
    replies.clear()
    emu.feed(bytes.fromhex("0200 0077"))
    assert bytes(replies) == bytes.fromhex("0300 0277be")
    replies.clear()
    emu.feed(bytes.fromhex("0300 000b 00"))
    assert bytes(replies) == bytes.fromhex("0500 020b bf 0000")
    assert emu.bad_frames == 1


def test_emulator_and_nxt_python_agree():
    emu = NxtEmulator(name="Robby", address="00:16:53:01:02:03")
    brick = brick_on(emu)
    assert brick.get_device_info()[:2] == ("Robby", "00:16:53:01:02:03")
    assert brick.get_firmware_version() == ((1, 124), (1, 31))
    assert brick.keep_alive() == 600_000
    emu.battery_mv = 7123
    assert brick.get_battery_level() == 7123
    port, mode = nxt.motor.Port.A, nxt.motor.Mode.ON | nxt.motor.Mode.REGULATED
    brick.set_output_state(
        port, -30, mode, nxt.motor.RegulationMode.SPEED, 5, nxt.motor.RunState.RUNNING, 720
    )
    assert emu.telegrams[-1].fields == {
        "port": 0, "power": -30, "mode": 5, "regulation": 1, "turn_ratio": 5,
        "run_state": 0x20, "limit": 720,
    }  # fmt: skip
    emu.motors["A"].rotation = -1234.4
    state = brick.get_output_state(port)
    assert state[:7] == (port, -30, mode, nxt.motor.RegulationMode.SPEED, 5,
                         nxt.motor.RunState.RUNNING, 720)  # fmt: skip
    assert state[9] == -1234
    brick.reset_motor_position(port, False)
    assert brick.get_output_state(port)[9] == 0
    # The ultrasonic sensor, through nxt-python's own I2C transactions.
    sonar = nxt.sensor.generic.Ultrasonic(brick, nxt.sensor.Port.S4)
    info = sonar.get_sensor_info()
    assert (info.version, info.product_id, info.sensor_type) == ("V1.0", "LEGO", "Sonar")
    assert sonar.get_measurement_units() == "10E-2m"
    emu.distance_cm = 123
    assert sonar.get_distance() == 123
    # Analog sensors in the modes the driver sets.
    emu.sensors = {1: "touch", 3: "light"}
    touch = nxt.sensor.generic.Touch(brick, nxt.sensor.Port.S1)
    assert touch.is_pressed() is False
    emu.touch_pressed = True
    assert touch.is_pressed() is True
    light = nxt.sensor.generic.Light(brick, nxt.sensor.Port.S3)
    light.set_input_mode(nxt.sensor.Type.LIGHT_ACTIVE, nxt.sensor.Mode.PERCENT)
    emu.light_percent = 73
    assert light.get_input_values().scaled_value == 73
    brick.play_tone(440, 100)
    assert emu.tones == [(440, 100)]
    assert emu.bad_frames == 0


def test_emulator_i2c_without_a_sensor_is_a_bus_error():
    emu = NxtEmulator(sensors={})
    brick = brick_on(emu)
    sonar = nxt.sensor.generic.Ultrasonic(brick, nxt.sensor.Port.S4, check_compatible=False)
    with pytest.raises(nxt.error.I2CError):
        sonar.get_distance()


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=80), max_size=10))
def test_emulator_survives_any_bytes(chunks):
    emu = NxtEmulator()
    replies = bytearray()
    emu._write = replies.extend
    for chunk in chunks:
        emu.feed(chunk)
    # Whatever it answered is whole length-prefixed replies.
    while replies:
        (size,) = struct.unpack_from("<H", replies)
        assert 3 <= size <= 64 and len(replies) >= 2 + size and replies[2] == 0x02
        del replies[: 2 + size]


# -- helpers ---------------------------------------------------------------------------------


class FakePyBluez(types.ModuleType):
    """The few names nxt-python's Bluetooth backend uses from PyBluez, over a socketpair."""

    RFCOMM = 3
    BluetoothError = OSError  # PyBluez's is an IOError too

    def __init__(self, emulator: NxtEmulator) -> None:
        super().__init__("bluetooth")
        self.emulator = emulator
        self.connected_to: list[tuple[str, int]] = []

    def BluetoothSocket(self, protocol):  # noqa: N802 - PyBluez's name
        assert protocol == self.RFCOMM
        return FakeRfcomm(self)


class FakeRfcomm:
    def __init__(self, pybluez: FakePyBluez) -> None:
        self.pybluez, self.sock = pybluez, None

    def connect(self, address):
        self.pybluez.connected_to.append(address)
        if address[0] != self.pybluez.emulator.address:
            raise OSError(errno.EHOSTDOWN, "Host is down")
        ours, theirs = socket.socketpair()
        self.pybluez.emulator.attach_socket(theirs)
        self.sock = ours

    def send(self, data):
        return self.sock.send(data)

    def recv(self, size):
        return self.sock.recv(size)

    def settimeout(self, seconds):
        self.sock.settimeout(seconds)

    def close(self):
        self.sock.close()


async def _when(bot, condition):
    readings = await bot.sensors()
    return readings if condition(readings) else None
