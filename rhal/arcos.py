"""ARCOS/P2OS packets: framing, checksum, commands and server information packets (SIPs).

No I/O here, so the same code serves a serial port, a socket, and the tests. A packet, in
either direction::

    0xFA 0xFB | count | body ... | checksum, 2 bytes, high byte first

``count`` is the number of bytes after it (body + checksum). The body's first byte is the
command number (client to robot) or the packet type (robot to client). The checksum adds the
body as big-endian 16-bit words, keeping 16 bits, and XORs an odd last byte into the low byte.
A command's integer argument is a type byte giving the sign (0x3B positive, 0x1B negative)
followed by the magnitude, 2 bytes little-endian: ARCOS integers are low byte first, only the
checksum is not.
"""

from __future__ import annotations

import math
import struct
from dataclasses import dataclass, field

from rhal.kinematics import normalize_angle

HEADER = b"\xfa\xfb"
MIN_COUNT = 3  # a one-byte body and the checksum
MAX_COUNT = 249  # no ARCOS packet is longer: a larger count is noise, not a packet

# Client commands. SYNC0-2 share numbers with PULSE, OPEN and CLOSE: the robot tells them
# apart by whether the handshake is done.
SYNC0, SYNC1, SYNC2 = 0, 1, 2
PULSE, OPEN, CLOSE, ENABLE, VEL, RVEL = 0, 1, 2, 4, 11, 21

ARG_POSITIVE, ARG_NEGATIVE = 0x3B, 0x1B
MAX_ARG = 0x7FFF

SIP_TYPES = (0x32, 0x33)  # standard SIP: 0x32 while stopped, 0x33 while moving
NO_COMPASS = 255  # the COMPASS byte of a robot without one

# Standard SIP, in order: type, XPOS, YPOS, THPOS, L VEL, R VEL, BATTERY (0.1 V), STALL AND
# BUMPERS, CONTROL, FLAGS, COMPASS (2-degree units), SONAR_COUNT; then SONAR_COUNT readings.
_SIP_HEAD = struct.Struct("<BHHhhhBHhHBB")
_SONAR_READING = struct.Struct("<BH")  # sonar number, range in mm
# After the sonar: GRIPSTATE, ANPORT, ANALOG, DIGIN, DIGOUT, BATTERYX10; then CHARGESTATE and
# ROTVEL (0.1 deg/s). Older firmware stops earlier, so each part is optional.
_SIP_TAIL = struct.Struct("<5BH")
_SIP_ROTVEL = struct.Struct("<Bh")


def checksum(body: bytes) -> int:
    total = 0
    for i in range(0, len(body) - 1, 2):
        total = (total + (body[i] << 8 | body[i + 1])) & 0xFFFF
    if len(body) % 2:
        total ^= body[-1]
    return total


def frame(body: bytes) -> bytes:
    """Wrap a body in header, byte count and checksum."""
    if not MIN_COUNT <= len(body) + 2 <= MAX_COUNT:
        raise ValueError(f"an ARCOS packet body is 1 to {MAX_COUNT - 2} bytes, not {len(body)}")
    return HEADER + bytes([len(body) + 2]) + body + checksum(body).to_bytes(2, "big")


def encode(command: int, value: int | None = None) -> bytes:
    """One command packet, with an optional signed integer argument."""
    body = bytes([command])
    if value is not None:
        if abs(value) > MAX_ARG:
            raise ValueError(f"ARCOS integer arguments are at most {MAX_ARG} in size: {value}")
        kind = ARG_POSITIVE if value >= 0 else ARG_NEGATIVE
        body += bytes([kind]) + abs(value).to_bytes(2, "little")
    return frame(body)


class PacketParser:
    """Cut a byte stream into packet bodies; drop and count whatever is not a valid packet.

    ``errors`` counts the times the stream lost sync: stray bytes, an impossible byte count,
    a bad checksum, a packet cut short by the next one. Losing sync again before a good
    packet has come through is the same episode, so one burst of noise counts once.
    """

    def __init__(self) -> None:
        self._buffer = bytearray()
        self._in_sync = True
        self.errors = 0

    def reset(self) -> None:
        """Forget a partial packet (a new link starts clean); keep the error count."""
        self._buffer.clear()
        self._in_sync = True

    def feed(self, data: bytes) -> list[bytes]:
        buffer = self._buffer
        buffer += data
        bodies = []
        while True:
            start = buffer.find(HEADER)
            if start < 0:
                # A trailing 0xFA may be the first half of the next header.
                keep = 1 if buffer.endswith(HEADER[:1]) else 0
                self._drop(len(buffer) - keep)
                return bodies
            self._drop(start)
            if len(buffer) < 3:
                return bodies
            count = buffer[2]
            if not MIN_COUNT <= count <= MAX_COUNT:
                self._drop(1)
                continue
            if len(buffer) < 3 + count:
                return bodies  # the rest has not arrived yet
            body = bytes(buffer[3 : 1 + count])
            if int.from_bytes(buffer[1 + count : 3 + count], "big") != checksum(body):
                # Skip only the first header byte: a good packet may start inside this one
                # (a truncated packet swallows the start of the next).
                self._drop(1)
                continue
            del buffer[: 3 + count]
            self._in_sync = True
            bodies.append(body)

    def _drop(self, count: int) -> None:
        if count <= 0:
            return
        del self._buffer[:count]
        if self._in_sync:
            self.errors += 1
            self._in_sync = False


@dataclass(frozen=True)
class Sip:
    """A standard server information packet, in the robot's own units: what a unit is worth
    depends on the model (rhal.pioneer_models), so nothing here is converted."""

    moving: bool
    xpos: int  # position units (DistConvFactor mm each), 15 bits that wrap: see Odometry
    ypos: int
    thpos: int  # heading units (AngleConvFactor rad each), counter-clockwise
    left: int  # wheel speeds, velocity units (VelConvFactor mm/s each)
    right: int
    battery: float  # V
    stall_left: bool
    stall_right: bool
    # The manual: bits 1-7 of STALL AND BUMPERS are the first bumper input, the rear ring;
    # bits 9-15 the second, the front ring. Bumper i is bit i here.
    front_bumpers: int
    rear_bumpers: int
    motors: bool  # motors enabled
    compass: int | None  # degrees clockwise from north, None without a compass
    sonar: dict[int, int] = field(default_factory=dict)  # sonar number -> range units
    rotvel: float | None = None  # deg/s, from firmware that sends ROTVEL


def is_sip(body: bytes) -> bool:
    return bool(body) and body[0] in SIP_TYPES


def parse_sip(body: bytes) -> Sip:
    """Decode a standard SIP body; ValueError if it is not one or is cut short."""
    if not is_sip(body):
        raise ValueError("not a standard SIP")
    try:
        (kind, xpos, ypos, thpos, left, right, battery, stall_bumpers, _control, flags,
         compass, sonar_count) = _SIP_HEAD.unpack_from(body)  # fmt: skip
        offset = _SIP_HEAD.size
        sonar = {}
        for _ in range(sonar_count):
            number, millimetres = _SONAR_READING.unpack_from(body, offset)
            sonar[number] = millimetres
            offset += _SONAR_READING.size
    except struct.error as exc:
        raise ValueError(f"SIP cut short: {exc}") from None
    volts, rotvel = battery / 10.0, None
    if len(body) >= offset + _SIP_TAIL.size:
        # BATTERYX10 also reads right above 25.5 V, where the one-byte field overflows.
        volts = _SIP_TAIL.unpack_from(body, offset)[-1] / 10.0 or volts
        offset += _SIP_TAIL.size
        if len(body) >= offset + _SIP_ROTVEL.size:
            rotvel = _SIP_ROTVEL.unpack_from(body, offset)[1] / 10.0
    return Sip(
        moving=kind == 0x33,
        xpos=xpos & 0x7FFF,
        ypos=ypos & 0x7FFF,
        thpos=thpos,
        left=left,
        right=right,
        battery=volts,
        stall_left=bool(stall_bumpers & 0x0001),
        stall_right=bool(stall_bumpers & 0x0100),
        front_bumpers=(stall_bumpers >> 9) & 0x7F,
        rear_bumpers=(stall_bumpers >> 1) & 0x7F,
        motors=bool(flags & 0x0001),
        compass=None if compass > 180 else 2 * compass,
        sonar=sonar,
        rotvel=rotvel,
    )


class Odometry:
    """Turn successive SIP positions into a continuous pose in metres and radians.

    XPOS and YPOS are 15-bit counters that wrap (MobileSim and AMRISim send 16 bits that wrap,
    the same modulo 2**15), so positions are followed by the change between packets: right as
    long as the robot moves less than 2**14 units between two SIPs (7.6 m on a P3-AT).
    ``mm_per_unit`` is the model's DistConvFactor; ``rad_per_unit`` its AngleConvFactor.
    """

    def __init__(self, mm_per_unit: float = 1.0, rad_per_unit: float = math.tau / 4096) -> None:
        self.mm_per_unit, self.rad_per_unit = mm_per_unit, rad_per_unit
        self._raw: tuple[int, int] | None = None
        self._x = self._y = 0  # position units

    def update(self, sip: Sip) -> tuple[float, float, float]:
        if self._raw is None:
            self._x, self._y = _wrap15(sip.xpos), _wrap15(sip.ypos)
        else:
            self._x += _wrap15(sip.xpos - self._raw[0])
            self._y += _wrap15(sip.ypos - self._raw[1])
        self._raw = (sip.xpos, sip.ypos)
        metres = self.mm_per_unit / 1000.0
        theta = normalize_angle(sip.thpos * self.rad_per_unit)
        return self._x * metres, self._y * metres, theta


def _wrap15(value: int) -> int:
    """A 15-bit difference or position as a signed number."""
    return ((value + 0x4000) & 0x7FFF) - 0x4000
