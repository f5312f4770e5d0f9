"""A Pioneer robot speaking ARCOS on the far side of a pseudo-terminal or a TCP socket.

It shares no code with the driver: framing, checksum, argument decoding and the SIP layout are
written again here from the protocol, so a mistake in ``rhal.arcos`` cannot hide by being
made on both sides. It checks every packet's checksum, answers the SYNC0-2 handshake, follows
OPEN/CLOSE/ENABLE/VEL/RVEL/PULSE as the robot's server does (motion only with the motors
enabled, and its watchdog stops the motors after 2 s without a command), integrates a pose
and sends a standard SIP every 100 ms while open.

It is one robot model at a time, from its own table (``tests/rhal/arcos_models.py``,
transcribed from ARIA's parameter files, not from our driver). The true pose is kept in mm
and radians (``x``, ``y``, ``th``; ``true_pose()`` in m), and the SIP reports it in the model's
units, as a real robot or the AMRISim simulator does:

* XPOS/YPOS = mm / DistConvFactor, in 15 bits that wrap;
* THPOS = heading in the firmware's angle steps: 4096 a turn (1024 on Pioneer 1 / PSOS),
  which ARIA's files print as AngleConvFactor 0.00153 (0.00614);
* left/right wheel velocities = mm/s / VelConvFactor, each wheel +- omega / DiffConvFactor
  from the middle (ARIA: omega = (right - left) / 2 * DiffConvFactor);
* sonar ranges = mm / RangeConvFactor; bumper bits only for the segments the model has,
  the rear ring in bits 1-7 and the front ring in bits 9-15 (ARIA's ArBumpers).

VEL is mm/s and RVEL deg/s on every model (ARIA sends them unscaled; AMRISim takes them as
such), clamped to the model's MaxVelocity and MaxRVelocity.

Every command is recorded in ``commands``; tests set the readings (``sonar``, ``battery``,
``front_bumpers``, ...) and read back what the driver said.
"""

from __future__ import annotations

import asyncio
import math
import os
import struct
import time
import tty
from dataclasses import dataclass

from tests.rhal.arcos_models import ArcosModel, get_model

COMMAND_NAMES = {0: "PULSE", 1: "OPEN", 2: "CLOSE", 4: "ENABLE", 11: "VEL", 21: "RVEL"}


@dataclass
class Command:
    name: str
    arg: int | None
    arg_type: int | None  # the type byte as sent: 0x3B positive, 0x1B negative
    raw: bytes  # the whole packet, header to checksum
    at: float  # time.monotonic() when it arrived


def arcos_checksum(body: bytes) -> int:
    """The ARCOS checksum, written apart from the driver's so they check each other."""
    even = len(body) - len(body) % 2
    words = struct.unpack(f">{even // 2}H", body[:even])
    total = sum(words) % 0x10000
    return total ^ body[-1] if len(body) % 2 else total


def arcos_packet(body: bytes) -> bytes:
    return b"\xfa\xfb" + bytes([len(body) + 2]) + body + struct.pack(">H", arcos_checksum(body))


class ArcosEmulator:
    SONAR_POLL = 0.040  # s: each array of eight discs fires one disc per 40 ms (ARCOS default)

    def __init__(
        self,
        model: str | ArcosModel = "p3dx-sh",
        *,
        name: str = "emulator",
        sip_interval: float = 0.1,
        optional_bumpers: bool = True,
    ) -> None:
        self.model = get_model(model)
        self.name = name
        self.sip_interval = sip_interval
        self.watchdog = 2.0  # s, as on a real robot
        self.commands: list[Command] = []
        self.bad_packets = 0
        self.watchdog_trips = 0
        self.sips_sent = 0
        self.state = "sync"  # -> "ready" after SYNC2 -> "open" after OPEN -> "sync" on CLOSE
        self.motors = False
        self.vel = 0  # mm/s, as commanded and clamped to the model's top speed
        self.rvel = 0  # deg/s, likewise
        self.x = self.y = 0.0  # mm, the true pose
        self.th = 0.0  # rad, counter-clockwise
        # Readings the next SIPs report; tests change them.
        self.wheels: tuple[int, int] | None = None  # mm/s; None: derived from vel and rvel
        self.battery = 12.6  # V
        self.sonar = {number: 5000 for number in range(self.model.sonar_count)}  # mm
        self.front_bumpers = 0  # one bit a segment, segment 0 in bit 0
        self.rear_bumpers = 0
        self.stall_left = self.stall_right = False
        self.compass_byte = 255  # 2-degree units; 255: no compass fitted
        # Bump rings the SIP has bits for: those the parameter file marks fitted, and with
        # optional_bumpers the rings it sizes but marks absent (an accessory on P2/P3 bases).
        model = self.model
        fitted = (model.front_bumpers, model.rear_bumpers)
        optional = (model.optional_front_bumpers, model.optional_rear_bumpers)
        self.bumper_segments = tuple(
            f or (o if optional_bumpers else 0) for f, o in zip(fitted, optional, strict=True)
        )
        self._sync_step = 0
        self._last_command = time.monotonic()
        self._sonar_next = 0
        self._buffer = bytearray()
        self._write = None
        self._master = self._slave = None
        self._server = None
        self._client = None
        self._ticker = None

    # -- what tests look at ----------------------------------------------------------------

    def names(self) -> list[str]:
        return [command.name for command in self.commands]

    def named(self, name: str) -> list[Command]:
        return [command for command in self.commands if command.name == name]

    def true_pose(self) -> tuple[float, float, float]:
        """Where the robot really is: x and y in m, heading in rad counter-clockwise."""
        return self.x / 1000.0, self.y / 1000.0, self.th

    def step(self, seconds: float, dt: float = 0.01) -> None:
        """Drive on at the current speeds for this much simulated time (no watchdog)."""
        steps = max(1, round(seconds / dt))
        for _ in range(steps):
            self._move(seconds / steps)

    def inject(self, data: bytes) -> None:
        """Put raw bytes on the wire to the driver: noise, broken packets."""
        self._send(data)

    # -- links -----------------------------------------------------------------------------

    async def start_pty(self) -> str:
        """Listen on a new pseudo-terminal; return the device path the driver opens."""
        self._master, self._slave = os.openpty()
        # Raw before the driver opens it: no echo, no CR/LF translation of binary packets.
        tty.setraw(self._slave)
        os.set_blocking(self._master, False)
        asyncio.get_running_loop().add_reader(self._master, self._on_pty_readable)
        self._write = self._write_pty
        self._start_ticker()
        self.path = os.ttyname(self._slave)
        return self.path

    async def start_tcp(self, port: int = 0) -> int:
        """Listen on 127.0.0.1; return the port."""
        self._server = await asyncio.start_server(self._on_client, "127.0.0.1", port)
        self.port = self._server.sockets[0].getsockname()[1]
        self._start_ticker()
        return self.port

    async def stop(self) -> None:
        """Pull the plug: the driver's side sees the link drop."""
        if self._ticker:
            self._ticker.cancel()
        if self._master is not None:
            asyncio.get_running_loop().remove_reader(self._master)
            os.close(self._master)
            os.close(self._slave)
            self._master = None
        if self._server is not None:
            self._server.close()
            if self._client is not None:
                self._client.close()
            await self._server.wait_closed()
            self._server = None
        self._write = None

    def _on_pty_readable(self) -> None:
        try:
            data = os.read(self._master, 4096)
        except (BlockingIOError, OSError):
            return
        self.feed(data)

    def _write_pty(self, data: bytes) -> None:
        try:
            os.write(self._master, data)
        except BlockingIOError:
            pass  # nobody reading: the bytes are lost, as on a UART

    async def _on_client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter):
        if self._client is not None:  # one client at a time, as on MobileSim
            writer.close()
            return
        self._client, self._write = writer, writer.write
        try:
            while data := await reader.read(4096):
                self.feed(data)
        except ConnectionError:
            pass
        finally:
            # A client gone is a session ended: the robot stops and waits for a new handshake.
            self._client = self._write = None
            self._close_session()
            writer.close()

    def _send(self, data: bytes) -> None:
        if self._write is not None:
            self._write(data)

    # -- receiving -------------------------------------------------------------------------

    def feed(self, data: bytes) -> None:
        buffer = self._buffer
        buffer += data
        while True:
            start = buffer.find(b"\xfa\xfb")
            if start < 0:
                del buffer[: len(buffer) - 1]
                return
            del buffer[:start]
            if len(buffer) < 3 or len(buffer) < 3 + buffer[2]:
                return
            packet = bytes(buffer[: 3 + buffer[2]])
            body, check = packet[3:-2], packet[-2:]
            if not body or arcos_checksum(body) != struct.unpack(">H", check)[0]:
                self.bad_packets += 1
                del buffer[:2]
                continue
            del buffer[: len(packet)]
            self._handle(body, packet)

    def _handle(self, body: bytes, raw: bytes) -> None:
        number, arg_type, arg = body[0], None, None
        if len(body) >= 4 and body[1] in (0x3B, 0x1B):
            arg_type = body[1]
            magnitude = int.from_bytes(body[2:4], "little")
            arg = magnitude if arg_type == 0x3B else -magnitude
        self._last_command = time.monotonic()
        if self.state == "sync" and number <= 2:
            self._record(f"SYNC{number}", arg, arg_type, raw)
            self._sync(number)
            return
        self._record(COMMAND_NAMES.get(number, f"#{number}"), arg, arg_type, raw)
        if number == 1 and self.state == "ready":
            self.state = "open"
            self.x = self.y = self.th = 0.0
        elif number == 2:
            self._close_session()
        elif self.state != "open":
            return
        elif number == 4:
            self.motors = arg == 1
            if not self.motors:
                self.vel = self.rvel = 0
        elif number == 11 and self.motors and arg is not None:
            self.vel = max(-self.model.max_vel, min(self.model.max_vel, arg))
        elif number == 21 and self.motors and arg is not None:
            self.rvel = max(-self.model.max_rvel, min(self.model.max_rvel, arg))

    def _sync(self, number: int) -> None:
        if number != 0 and number != self._sync_step:
            self._sync_step = 0  # out of order: start over, as ARCOS does
            return
        reply = bytes([number])
        if number == 2:
            for text in (self.name, self.model.robot_class, self.model.subclass):
                reply += text.encode() + b"\0"
            self.state = "ready"
        self._sync_step = number + 1
        self._send(arcos_packet(reply))

    def _record(self, name, arg, arg_type, raw) -> None:
        self.commands.append(Command(name, arg, arg_type, raw, time.monotonic()))

    def _close_session(self) -> None:
        self.state, self._sync_step = "sync", 0
        self.motors = False
        self.vel = self.rvel = 0

    # -- sending ---------------------------------------------------------------------------

    def _start_ticker(self) -> None:
        self._ticker = asyncio.get_running_loop().create_task(self._tick())

    async def _tick(self) -> None:
        last = time.monotonic()
        while True:
            await asyncio.sleep(self.sip_interval)
            now = time.monotonic()
            dt, last = now - last, now
            if self.state != "open":
                continue
            if (self.vel or self.rvel) and now - self._last_command > self.watchdog:
                self.vel = self.rvel = 0
                self.watchdog_trips += 1
            self._move(dt)
            self._send(arcos_packet(self.sip()))
            self.sips_sent += 1

    def _move(self, dt: float) -> None:
        # Straight along the mean heading: exact for a line or a spin, close on an arc.
        turn = math.radians(self.rvel) * dt
        self.x += self.vel * dt * math.cos(self.th + turn / 2)
        self.y += self.vel * dt * math.sin(self.th + turn / 2)
        self.th = math.remainder(self.th + turn, math.tau)

    def wheel_speeds(self) -> tuple[float, float]:
        """Left and right wheel speeds in mm/s: each wheel omega / DiffConvFactor off the middle."""
        if self.wheels is not None:
            return self.wheels
        spin = math.radians(self.rvel) / self.model.diff_conv
        return self.vel - spin, self.vel + spin

    def sonar_batch(self) -> list[int]:
        """The discs whose readings the next SIP carries.

        The firmware fires one disc per array of eight every 40 ms and a SIP carries the
        readings taken since the last one: 2.5 per array in 100 ms on average. The emulator
        takes two per array a SIP from the ring (the discs ``sonar`` holds a range for). Its
        order, even-numbered discs first, then odd, is its own: the firmware's is the POLLING
        sequence (each array's discs in order by default), which clients do not rely on.
        """
        discs = sorted(n for n in self.sonar if 0 <= n < self.model.sonar_count)
        if not discs:
            return []
        order = discs[::2] + discs[1::2]
        per_array = max(1, int(self.sip_interval / self.SONAR_POLL + 1e-9))
        count = min(len(order), per_array * self.model.sonar_arrays)
        start = self._sonar_next % len(order)
        self._sonar_next = start + count
        return [order[(start + i) % len(order)] for i in range(count)]

    def sip(self) -> bytes:
        """A standard SIP body for the current state, in the model's units."""
        model = self.model
        left, right = (_int16(speed / model.vel_conv) for speed in self.wheel_speeds())
        units = model.angle_units_per_turn
        heading = (round(self.th * units / math.tau) + units // 2) % units - units // 2
        front_segments, rear_segments = self.bumper_segments
        # STALL_AND_BUMPERS as ARIA reads it (ArRobot, ArBumpers): bit 0 left wheel stalled,
        # bits 1-7 the rear ring, bit 8 right wheel stalled, bits 9-15 the front ring.
        stall_bumpers = (
            self.stall_left
            | (self.rear_bumpers & ((1 << rear_segments) - 1)) << 1
            | self.stall_right << 8
            | (self.front_bumpers & ((1 << front_segments) - 1)) << 9
        )
        batch = self.sonar_batch()
        body = struct.pack(
            "<BHHhhhBHhHBB",
            0x33 if self.vel or self.rvel else 0x32,
            round(self.x / model.dist_conv) & 0x7FFF,
            round(self.y / model.dist_conv) & 0x7FFF,
            heading,
            left,
            right,
            min(255, round(self.battery * 10)),
            stall_bumpers,
            0,  # CONTROL
            int(self.motors),  # FLAGS bit 0: motors enabled
            self.compass_byte,
            len(batch),
        )
        for number in batch:
            reading = round(self.sonar[number] / model.range_conv)
            body += struct.pack("<BH", number, max(0, min(0xFFFF, reading)))
        # GRIPSTATE, ANPORT, ANALOG, DIGIN, DIGOUT, BATTERYX10, CHARGESTATE
        body += struct.pack("<5BHB", 0, 0, 0, 0, 0, round(self.battery * 10), 0)
        return body


def _int16(value: float) -> int:
    return max(-0x8000, min(0x7FFF, round(value)))
