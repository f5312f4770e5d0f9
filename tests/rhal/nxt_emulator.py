"""A LEGO Mindstorms NXT brick speaking Direct Commands on the far side of a pseudo-terminal.

It shares no code with the driver or with nxt-python: the Bluetooth framing (a 2-byte
little-endian length before each telegram), the telegram layouts and the replies are written
again here with ``struct`` from LEGO's Bluetooth Developer Kit (Appendix 1, the communication
protocol; Appendix 2, the Direct Commands), so a mistake on either side shows up as a
disagreement instead of hiding by being made twice.

The brick answers KeepAlive, GetFirmwareVersion, GetDeviceInfo, SetOutputState,
GetOutputState, ResetMotorPosition, SetInputMode, GetInputValues, LSWrite, LSGetStatus,
LSRead (an ultrasonic sensor at I2C address 0x02, distance in register 0x42),
GetBatteryLevel and PlayTone; anything else gets "unknown command opcode".

Motors turn at ``power`` % of 170 rpm (the NXT motor's no-load speed at full power, the same
documented constant the driver uses) and their tacho counts integrate that over time. The
wheels on the drive ports move a simulated robot in a square walled arena, starting at
(0, 0) facing +y, and the ultrasonic sensor measures to the wall ahead unless a test sets
``distance_cm``. Like a real NXT, the brick has no watchdog: its motors keep running when
the link drops.

``url`` names a symlink in a private directory that points at the current pty's slave, so
``replug()`` can make a new pty and the driver finds it again at the same URL.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import shutil
import socket
import struct
import tempfile
import time
import tty
from dataclasses import dataclass, field

MOTOR_RPM = 170.0  # no-load speed at power 100, as documented in docs/robots/nxt.md
DEGREES_PER_SECOND_AT_FULL_POWER = MOTOR_RPM * 360.0 / 60.0
MAX_TELEGRAM = 64

# Telegram types (byte 0): bit 7 set means "no reply wanted".
DIRECT, SYSTEM, REPLY, NO_REPLY = 0x00, 0x01, 0x02, 0x80
# Output modes (bit flags) and run states.
MOTORON, BRAKE, REGULATED = 0x01, 0x02, 0x04
RUN_IDLE, RUN_RUNNING = 0x00, 0x20
# Input sensor types and modes used here.
NO_SENSOR, SWITCH, LIGHT_ACTIVE, LIGHT_INACTIVE = 0x00, 0x01, 0x05, 0x06
SOUND_DB, SOUND_DBA, LOWSPEED, LOWSPEED_9V = 0x07, 0x08, 0x0A, 0x0B
RAW, BOOLEAN, PCTFULLSCALE = 0x00, 0x20, 0x80
# Status bytes.
OK, PENDING, BUS_ERROR, NOT_CONFIGURED = 0x00, 0x20, 0xDD, 0xE0
UNKNOWN_OPCODE, INSANE_PACKET, BAD_PORT = 0xBE, 0xBF, 0xF0

ULTRASONIC_ADDRESS = 0x02  # I2C address of the LEGO ultrasonic sensor (8-bit form)
DISTANCE_REGISTER = 0x42
#: The sensor's identification strings. Reading from their first register gives the whole
#: string (they overlap: the units at 0x14 start inside the type at 0x10), as on the sensor.
ULTRASONIC_STRINGS = {0x00: b"V1.0", 0x08: b"LEGO", 0x10: b"Sonar", 0x14: b"10E-2m"}

#: opcode -> (name, struct layout of the request's fixed part, struct layout of the reply
#: after its status byte). LSWrite's data follows its fixed part.
COMMANDS: dict[int, tuple[str, str, str]] = {
    0x03: ("PlayTone", "<HH", ""),
    0x04: ("SetOutputState", "<BbBBbBI", ""),
    0x05: ("SetInputMode", "<BBB", ""),
    0x06: ("GetOutputState", "<B", "<BbBBbBIiii"),
    0x07: ("GetInputValues", "<B", "<BBBBBHHhh"),
    0x0A: ("ResetMotorPosition", "<BB", ""),
    0x0B: ("GetBatteryLevel", "<", "<H"),
    0x0D: ("KeepAlive", "<", "<I"),
    0x0E: ("LSGetStatus", "<B", "<B"),
    0x0F: ("LSWrite", "<BBB", ""),
    0x10: ("LSRead", "<B", "<B16s"),
    0x88: ("GetFirmwareVersion", "<", "<BBBB"),
    0x9B: ("GetDeviceInfo", "<", "<15s7s4BI"),
}
FIELDS = {
    "PlayTone": ("frequency", "duration_ms"),
    "SetOutputState": ("port", "power", "mode", "regulation", "turn_ratio", "run_state", "limit"),
    "SetInputMode": ("port", "sensor_type", "sensor_mode"),
    "GetOutputState": ("port",),
    "GetInputValues": ("port",),
    "ResetMotorPosition": ("port", "relative"),
    "LSGetStatus": ("port",),
    "LSWrite": ("port", "tx_length", "rx_length"),
    "LSRead": ("port",),
}


@dataclass
class Telegram:
    name: str
    opcode: int
    reply_wanted: bool
    fields: dict
    raw: bytes  # the telegram as it came, without the length prefix
    at: float  # time.monotonic() when it arrived


@dataclass
class Motor:
    power: int = 0
    mode: int = 0
    regulation: int = 0
    turn_ratio: int = 0
    run_state: int = RUN_IDLE
    limit: int = 0
    tacho: float = 0.0  # degrees, all three counted alike here
    block: float = 0.0
    rotation: float = 0.0

    def speed(self) -> float:
        """Degrees a second the motor turns under its current command."""
        if not self.mode & MOTORON or self.run_state == RUN_IDLE:
            return 0.0
        return self.power / 100.0 * DEGREES_PER_SECOND_AT_FULL_POWER


@dataclass
class InputPort:
    sensor_type: int = NO_SENSOR
    sensor_mode: int = RAW
    # I2C: the bytes a finished transaction holds, its error status, replies still pending
    i2c_result: bytes | None = None
    i2c_error: int = OK
    i2c_pending: int = 0
    registers: bytearray = field(default_factory=lambda: bytearray(256))


class NxtEmulator:
    def __init__(
        self,
        *,
        name: str = "NXT",
        address: str = "00:16:53:0A:0B:0C",
        left: str = "B",
        right: str = "C",
        reverse_left: bool = False,
        reverse_right: bool = False,
        wheel_diameter: float = 0.056,
        track: float = 0.115,
        sensors: dict[int, str] | None = None,
        arena: float = 1.5,
        i2c_pending: int = 1,
    ) -> None:
        self.name, self.address = name, address
        self.left, self.right = left, right
        self.reverse = {left: reverse_left, right: reverse_right}
        self.wheel_diameter, self.track = wheel_diameter, track
        #: sensor port 1-4 -> "ultrasonic", "touch", "light" or "sound"
        self.sensors = {4: "ultrasonic"} if sensors is None else dict(sensors)
        self.arena = arena  # m: walls at x, y = +-arena
        self.i2c_pending = i2c_pending  # "pending" answers before each I2C result is ready
        # Readings; tests change them.
        self.battery_mv = 8000
        self.distance_cm: int | None = None  # None: measured to the arena's walls
        self.touch_pressed = False
        self.light_percent = 50
        self.sound_percent = 10
        self.sleep_timeout_ms = 600_000  # what KeepAlive reports: 10 minutes
        # What the driver did.
        self.telegrams: list[Telegram] = []
        self.bad_frames = 0
        self.stops = 0  # zero power, motor on (braked or floating), on both drive motors
        self.resets = 0  # both drive motors switched off (mode IDLE)
        self.tones: list[tuple[int, int]] = []
        self.motors = {port: Motor() for port in "ABC"}
        self.inputs = [InputPort() for _ in range(4)]
        self.x, self.y, self.theta = 0.0, 0.0, math.pi / 2
        self._stopped: set[str] = set()
        self._switched_off: set[str] = set()
        self._updated = time.monotonic()
        self._buffer = bytearray()
        self._fd: int | None = None
        self._slave: int | None = None
        self._loop: asyncio.AbstractEventLoop | None = None
        self._dir: str | None = None
        self.path = self.url = ""

    # -- the interface every robot emulator offers -----------------------------------------

    async def start(self) -> None:
        self._loop = asyncio.get_running_loop()
        self._dir = tempfile.mkdtemp(prefix="nxt-emulator-")
        self.path = os.path.join(self._dir, "rfcomm0")
        self.url = f"nxt://{self.path}"
        self._plug()

    def commanded(self) -> tuple[float, float]:
        """(linear m/s, angular rad/s) the drive motors were last told, from their powers."""
        left, right = (self._wheel_speed(port) for port in (self.left, self.right))
        return (left + right) / 2.0 + 0.0, (right - left) / self.track + 0.0

    async def unplug(self) -> None:
        """Pull the cable: the pty goes, and so does the device path."""
        self._detach()
        with contextlib.suppress(FileNotFoundError):
            os.remove(self.path)

    async def replug(self) -> None:
        await self.unplug()
        self._plug()

    async def stop(self) -> None:
        await self.unplug()
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None

    # -- what tests look at ----------------------------------------------------------------

    def names(self) -> list[str]:
        return [telegram.name for telegram in self.telegrams]

    def named(self, name: str) -> list[Telegram]:
        return [telegram for telegram in self.telegrams if telegram.name == name]

    @property
    def keepalives(self) -> int:
        return len(self.named("KeepAlive"))

    @property
    def heading(self) -> float:
        """Compass degrees of the simulated robot, clockwise from +y."""
        self._advance()
        return (90.0 - math.degrees(self.theta)) % 360.0

    def pose(self) -> tuple[float, float, float]:
        self._advance()
        return self.x, self.y, self.theta

    def inject(self, data: bytes) -> None:
        """Put raw bytes on the wire to the driver: noise between replies."""
        self._write(data)

    def attach_socket(self, sock: socket.socket) -> None:
        """Serve a connected socket instead of the pty (a Bluetooth RFCOMM stand-in).

        Callable from any thread: the driver connects from its worker thread.
        """
        fd = sock.detach()
        assert self._loop is not None
        self._loop.call_soon_threadsafe(self._attach_socket, fd)

    # -- links -----------------------------------------------------------------------------

    def _plug(self) -> None:
        master, slave = os.openpty()
        tty.setraw(slave)  # before the driver opens it: binary telegrams, no echo
        os.set_blocking(master, False)
        self._attach(master)
        # Held open, so the master never sees a hang-up while the driver reopens the slave.
        self._slave = slave
        os.symlink(os.ttyname(slave), self.path)

    def _attach_socket(self, fd: int) -> None:
        self._detach()
        os.set_blocking(fd, False)
        self._attach(fd)

    def _attach(self, fd: int) -> None:
        assert self._loop is not None
        self._fd = fd
        self._buffer.clear()
        self._loop.add_reader(fd, self._on_readable)

    def _detach(self) -> None:
        if self._fd is not None:
            assert self._loop is not None
            self._loop.remove_reader(self._fd)
            os.close(self._fd)
            self._fd = None
        if self._slave is not None:
            os.close(self._slave)
            self._slave = None

    def _on_readable(self) -> None:
        try:
            data = os.read(self._fd, 4096)
        except BlockingIOError:
            return
        except OSError:
            data = b""
        if not data:  # a socket's peer went away
            self._detach()
            return
        self.feed(data)

    def _write(self, data: bytes) -> None:
        if self._fd is None:
            return
        with contextlib.suppress(BlockingIOError, OSError):
            os.write(self._fd, data)  # nobody reading: lost, as on a radio link

    # -- receiving -------------------------------------------------------------------------

    def feed(self, data: bytes) -> None:
        """Take bytes from the driver: length-prefixed telegrams."""
        buffer = self._buffer
        buffer += data
        while len(buffer) >= 2:
            (size,) = struct.unpack_from("<H", buffer)
            if not 2 <= size <= MAX_TELEGRAM:
                self.bad_frames += 1
                del buffer[:1]
                continue
            if len(buffer) < 2 + size:
                return
            telegram = bytes(buffer[2 : 2 + size])
            del buffer[: 2 + size]
            self._handle(telegram)

    def _handle(self, telegram: bytes) -> None:
        kind, opcode, body = telegram[0], telegram[1], telegram[2:]
        reply_wanted = not kind & NO_REPLY
        if kind & 0x7F not in (DIRECT, SYSTEM) or (kind & 0x7F == SYSTEM) != (opcode >= 0x80):
            self.bad_frames += 1
            return
        self._advance()
        if opcode not in COMMANDS:
            self._record(f"#{opcode:02x}", opcode, reply_wanted, {}, telegram)
            if reply_wanted:
                self._reply(opcode, UNKNOWN_OPCODE, b"")
            return
        name, request, reply = COMMANDS[opcode]
        fixed = struct.calcsize(request)
        if len(body) < fixed or (name != "LSWrite" and len(body) != fixed):
            self.bad_frames += 1
            self._record(name, opcode, reply_wanted, {"bad": True}, telegram)
            if reply_wanted:
                self._reply(opcode, INSANE_PACKET, bytes(struct.calcsize(reply)))
            return
        fields = dict(zip(FIELDS.get(name, ()), struct.unpack_from(request, body), strict=True))
        if name == "LSWrite":
            fields["data"] = bytes(body[fixed:])
        self._record(name, opcode, reply_wanted, fields, telegram)
        status, payload = getattr(self, f"_do_{name}")(**fields)
        if reply_wanted:
            if status != OK and not payload:
                payload = bytes(struct.calcsize(reply))  # the full size, zeroed
            self._reply(opcode, status, payload)

    def _record(self, name, opcode, reply_wanted, fields, raw) -> None:
        self.telegrams.append(Telegram(name, opcode, reply_wanted, fields, raw, time.monotonic()))

    def _reply(self, opcode: int, status: int, payload: bytes) -> None:
        telegram = bytes([REPLY, opcode, status]) + payload
        self._write(struct.pack("<H", len(telegram)) + telegram)

    # -- commands: each returns (status, reply payload after the status byte) -------------

    def _do_PlayTone(self, frequency, duration_ms):
        self.tones.append((frequency, duration_ms))
        return OK, b""

    def _do_SetOutputState(self, port, power, mode, regulation, turn_ratio, run_state, limit):
        ports = "ABC" if port == 0xFF else "ABC"[port] if port < 3 else None
        if ports is None or not -100 <= power <= 100:
            return BAD_PORT, b""
        for letter in ports:
            motor = self.motors[letter]
            motor.power, motor.mode, motor.regulation = power, mode, regulation
            motor.turn_ratio, motor.run_state, motor.limit = turn_ratio, run_state, limit
            self._count_stop(letter, power, mode)
        return OK, b""

    def _do_GetOutputState(self, port):
        if port > 2:
            return BAD_PORT, b""
        m = self.motors["ABC"[port]]
        counts = (round(m.tacho), round(m.block), round(m.rotation))
        return OK, struct.pack(
            "<BbBBbBIiii", port, m.power, m.mode, m.regulation, m.turn_ratio, m.run_state,
            m.limit, *counts,
        )  # fmt: skip

    def _do_ResetMotorPosition(self, port, relative):
        if port > 2:
            return BAD_PORT, b""
        motor = self.motors["ABC"[port]]
        if relative:
            motor.block = 0.0
        else:
            motor.rotation = 0.0
        return OK, b""

    def _do_SetInputMode(self, port, sensor_type, sensor_mode):
        if port > 3:
            return BAD_PORT, b""
        self.inputs[port] = InputPort(sensor_type, sensor_mode)
        return OK, b""

    def _do_GetInputValues(self, port):
        if port > 3:
            return BAD_PORT, b""
        state = self.inputs[port]
        kind = self.sensors.get(port + 1)
        if state.sensor_type in (LOWSPEED, LOWSPEED_9V):
            raw = normalized = scaled = 0
        else:
            normalized = {
                "touch": 1023 if self.touch_pressed else 0,
                "light": round(self.light_percent * 10.23),
                "sound": round(self.sound_percent * 10.23),
            }.get(kind, 0)
            raw = 1023 - normalized  # the analog sensors pull the input low
            mode = state.sensor_mode & 0xE0
            if mode == RAW:
                scaled = raw
            elif mode == BOOLEAN:
                scaled = int(normalized > 511)
            elif mode == PCTFULLSCALE:
                scaled = round(normalized * 100 / 1023)
            else:
                scaled = normalized
        return OK, struct.pack(
            "<BBBBBHHhh", port, 1, 0, state.sensor_type, state.sensor_mode, raw, normalized,
            scaled, normalized,
        )  # fmt: skip

    def _do_GetBatteryLevel(self):
        return OK, struct.pack("<H", self.battery_mv)

    def _do_KeepAlive(self):
        return OK, struct.pack("<I", self.sleep_timeout_ms)

    def _do_GetFirmwareVersion(self):
        return OK, struct.pack("<BBBB", 124, 1, 31, 1)  # protocol 1.124, firmware 1.31

    def _do_GetDeviceInfo(self):
        address = bytes(int(part, 16) for part in self.address.split(":")) + b"\0"
        name = self.name.encode("ascii")[:14]
        return OK, struct.pack("<15s7s4BI", name, address, 0, 0, 0, 0, 65536)

    def _do_LSWrite(self, port, tx_length, rx_length, data):
        if port > 3 or tx_length != len(data) or rx_length > 16:
            return BAD_PORT, b""
        state = self.inputs[port]
        if state.sensor_type not in (LOWSPEED, LOWSPEED_9V):
            return NOT_CONFIGURED, b""
        state.i2c_result, state.i2c_error, state.i2c_pending = None, OK, self.i2c_pending
        if self.sensors.get(port + 1) != "ultrasonic" or len(data) < 2:
            state.i2c_error = BUS_ERROR  # nobody acknowledges the address
            return OK, b""
        if data[0] != ULTRASONIC_ADDRESS:
            state.i2c_error = BUS_ERROR
            return OK, b""
        register, written = data[1], data[2:]
        registers = state.registers
        if not registers[0x41]:
            registers[0x41] = 0x02  # continuous measurement, the power-on mode
        for offset, value in enumerate(written[: 256 - register]):
            registers[register + offset] = value
        registers[DISTANCE_REGISTER] = self.distance()
        if register in ULTRASONIC_STRINGS:
            result = ULTRASONIC_STRINGS[register].ljust(16, b"\0")
        else:
            result = bytes(registers[register:]).ljust(16, b"\0")
        state.i2c_result = result[:rx_length]
        return OK, b""

    def _do_LSGetStatus(self, port):
        if port > 3:
            return BAD_PORT, b""
        state = self.inputs[port]
        if state.i2c_error != OK:
            return state.i2c_error, b""
        if state.i2c_pending > 0:
            state.i2c_pending -= 1
            return PENDING, b""
        return OK, struct.pack("<B", len(state.i2c_result or b""))

    def _do_LSRead(self, port):
        if port > 3:
            return BAD_PORT, b""
        state = self.inputs[port]
        if state.i2c_error != OK:
            error, state.i2c_error = state.i2c_error, OK
            return error, b""
        if state.i2c_pending > 0:
            return PENDING, b""
        result, state.i2c_result = state.i2c_result or b"", None
        return OK, struct.pack("<B16s", len(result), result)

    # -- the simulated robot ---------------------------------------------------------------

    def distance(self) -> int:
        """What the ultrasonic sensor reads, cm; 255 when nothing is in reach."""
        if self.distance_cm is not None:
            return self.distance_cm
        self._advance()
        reach = math.inf
        for position, direction in ((self.x, math.cos(self.theta)), (self.y, math.sin(self.theta))):
            if direction > 1e-12:
                reach = min(reach, (self.arena - position) / direction)
            elif direction < -1e-12:
                reach = min(reach, (-self.arena - position) / direction)
        return min(255, round(reach * 100))

    def _wheel_speed(self, port: str) -> float:
        metres_per_degree = math.pi * self.wheel_diameter / 360.0
        sign = -1.0 if self.reverse[port] else 1.0
        return sign * self.motors[port].speed() * metres_per_degree

    def _advance(self) -> None:
        """Turn the motors and move the robot from the last update to now."""
        now = time.monotonic()
        dt, self._updated = now - self._updated, now
        for motor in self.motors.values():
            degrees = motor.speed() * dt
            motor.tacho += degrees
            motor.block += degrees
            motor.rotation += degrees
        linear, angular = self.commanded()
        turn = angular * dt
        # Along the chord of the arc, which points at the mean heading.
        chord = linear * dt * (1.0 if abs(turn) < 1e-9 else math.sin(turn / 2) / (turn / 2))
        self.x += chord * math.cos(self.theta + turn / 2)
        self.y += chord * math.sin(self.theta + turn / 2)
        self.theta = math.remainder(self.theta + turn, math.tau)

    def _count_stop(self, port: str, power: int, mode: int) -> None:
        if port not in (self.left, self.right):
            return
        self._stopped.discard(port)
        self._switched_off.discard(port)
        if power == 0:
            (self._stopped if mode & MOTORON else self._switched_off).add(port)
        if len(self._stopped) == 2:
            self.stops += 1
            self._stopped.clear()
        if len(self._switched_off) == 2:
            self.resets += 1
            self._switched_off.clear()
