"""A Pioneer robot speaking ARCOS on the far side of a pseudo-terminal or a TCP socket.

It shares no code with the driver: framing, checksum, argument decoding and the SIP layout are
written again here from the protocol, so a mistake in ``rhal.arcos`` cannot hide by being
made on both sides. It checks every packet's checksum, answers the SYNC0-2 handshake, follows
OPEN/CLOSE/ENABLE/VEL/RVEL/PULSE as the robot's server does (motion only with the motors
enabled, and its watchdog stops the motors after 2 s without a command), integrates a pose
and sends a standard SIP every 100 ms while open.

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
    def __init__(self, *, name: str = "emulator", sip_interval: float = 0.1) -> None:
        self.name = name
        self.sip_interval = sip_interval
        self.watchdog = 2.0  # s, as on a real robot
        self.commands: list[Command] = []
        self.bad_packets = 0
        self.watchdog_trips = 0
        self.sips_sent = 0
        self.state = "sync"  # -> "ready" after SYNC2 -> "open" after OPEN -> "sync" on CLOSE
        self.motors = False
        self.vel = 0  # mm/s, as commanded
        self.rvel = 0  # deg/s
        self.x = self.y = 0.0  # mm
        self.th = 0.0  # rad, counter-clockwise
        # Readings the next SIPs report; tests change them.
        self.wheels: tuple[int, int] | None = None  # mm/s; None: derived from vel and rvel
        self.battery = 12.6  # V
        self.sonar = {number: 5000 for number in range(8)}  # mm
        self.front_bumpers = 0  # bits 0-6
        self.stall_left = self.stall_right = False
        self.compass_byte = 255  # 2-degree units; 255: no compass fitted
        self._sync_step = 0
        self._last_command = time.monotonic()
        self._sonar_half = 0
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
        elif number == 11 and self.motors:
            self.vel = arg
        elif number == 21 and self.motors:
            self.rvel = arg

    def _sync(self, number: int) -> None:
        if number != 0 and number != self._sync_step:
            self._sync_step = 0  # out of order: start over, as ARCOS does
            return
        reply = bytes([number])
        if number == 2:
            reply += self.name.encode() + b"\0Pioneer\0p3dx-sh\0"
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
            # Straight along the mean heading: exact enough at 10 Hz.
            turn = math.radians(self.rvel) * dt
            self.x += self.vel * dt * math.cos(self.th + turn / 2)
            self.y += self.vel * dt * math.sin(self.th + turn / 2)
            self.th = math.remainder(self.th + turn, math.tau)
            self._send(arcos_packet(self.sip()))
            self.sips_sent += 1

    def sip(self) -> bytes:
        """A standard SIP body for the current state; half the sonar ring in each."""
        if self.wheels is not None:
            left, right = self.wheels
        else:
            spin = math.radians(self.rvel) * 165  # mm/s at each wheel, half a 330 mm track
            left, right = round(self.vel - spin), round(self.vel + spin)
        numbers = sorted(self.sonar)
        half = numbers[self._sonar_half :: 2]
        self._sonar_half ^= 1
        stall_bumpers = self.stall_left | self.front_bumpers << 1 | self.stall_right << 8
        body = struct.pack(
            "<BHHhhhBHhHBB",
            0x33 if self.vel or self.rvel else 0x32,
            round(self.x) & 0x7FFF,
            round(self.y) & 0x7FFF,
            round(self.th * 4096 / math.tau),
            left,
            right,
            min(255, round(self.battery * 10)),
            stall_bumpers,
            0,  # CONTROL
            int(self.motors),  # FLAGS bit 0: motors enabled
            self.compass_byte,
            len(half),
        )
        for number in half:
            body += struct.pack("<BH", number, self.sonar[number])
        # GRIPSTATE, ANPORT, ANALOG, DIGIN, DIGOUT, BATTERYX10, CHARGESTATE
        body += struct.pack("<5BHB", 0, 0, 0, 0, 0, round(self.battery * 10), 0)
        return body
