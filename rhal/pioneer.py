"""Pioneer P3-DX/P3-AT and other ARCOS/P2OS robots, for ``pioneer://`` URLs.

    pioneer:///dev/ttyUSB0?baud=9600    a serial port, 8N1 (default device /dev/ttyUSB0)
    pioneer+tcp://127.0.0.1:8101        TCP, where MobileSim and AMRISim listen (the default)

Options, also accepted in the URL query: ``baud`` (serial only, default 9600, the ARCOS
default), ``timeout`` (s without a packet from the robot before the link counts as lost,
default 2), ``pulse`` (s between keep-alives, default 1), ``compass`` (true if a compass is
fitted: heading then comes from it instead of odometry), ``max_linear``, ``max_angular``.

Units differ by model: a classic P3-AT counts position in 0.465 mm units, a Pioneer 1 turns
in 1024 heading units. The model the robot names in its SYNC2 reply picks its factors from
ARIA's parameter files (rhal.pioneer_models); ``model`` names another, and ``dist_conv``,
``angle_conv``, ``vel_conv``, ``range_conv``, ``track``, ``sonars``, ``front_bumpers`` and
``rear_bumpers`` override one value each (rhal.pioneer_units). Speeds are also held under the
model's top speeds. Commands are mm/s and deg/s on every model, as ARIA sends them.

Serial goes through pyserial-asyncio's streams and TCP through asyncio's, so after connecting
both are one StreamReader/StreamWriter pair and nothing blocks the event loop.

A link's life: SYNC0-2 handshake, OPEN, ENABLE motors, then a reader that parses SIPs and a
keep-alive. If the link drops or the robot goes quiet, callers get RobotConnectionError while
the driver reconnects with backoff and handshakes again. Motion is not resumed after a
reconnection: the program must ask again, knowing it lost the robot for a while.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections import deque
from typing import Any
from urllib.parse import urlsplit

import serial_asyncio

from rhal import arcos
from rhal.base import Robot
from rhal.errors import RobotConnectionError
from rhal.kinematics import compass_heading
from rhal.linked import LinkKeeper, StreamLink, heard_within
from rhal.pioneer_models import MODELS
from rhal.pioneer_units import Units, fit

DEFAULT_DEVICE = "/dev/ttyUSB0"
DEFAULT_HOST, DEFAULT_TCP_PORT = "127.0.0.1", 8101
SONAR_MAX = 5.0  # m, the Pioneer sonar's reach
VELOCITY_REFRESH = 0.5  # s: while moving, re-send the speeds this often, so one packet lost
# on a noisy line cannot leave the robot on an old speed
KEEPALIVE_TICK = 0.1  # s
SYNC_WAIT = 0.5  # s to wait for each handshake reply before starting over


class PioneerRobot(Robot):
    kind = "pioneer"
    quick = False  # every call waits on the link
    option_help = {
        **Robot.option_help,
        "baud": "serial speed, bit/s (ignored on TCP)",
        "timeout": "s without a packet before the link counts as lost",
        "pulse": "s between keep-alive PULSEs for the robot's watchdog",
        "compass": "a compass is fitted: heading comes from it instead of odometry",
        "model": "ARIA model whose units to use; blank: the one the robot names",
        "dist_conv": "mm per position unit; blank: the model's DistConvFactor",
        "angle_conv": "rad per heading unit; blank: the model's AngleConvFactor",
        "vel_conv": "mm/s per wheel-speed unit; blank: the model's VelConvFactor",
        "range_conv": "mm per sonar unit; blank: the model's RangeConvFactor",
        "track": "m, effective wheel track; blank: 2 / the model's DiffConvFactor",
        "sonars": "sonar discs reported; blank: the model's ring",
        "front_bumpers": "front bump-ring segments; blank: the model's (0: none fitted)",
        "rear_bumpers": "rear bump-ring segments; blank: the model's (0: none fitted)",
    }
    option_choices = {"model": ("", *sorted(MODELS))}

    def __init__(
        self,
        url: str = "pioneer+tcp://",
        *,
        baud: int = 9600,
        timeout: float = 2.0,
        pulse: float = 1.0,
        compass: bool = False,
        model: str | None = None,
        dist_conv: float | None = None,
        angle_conv: float | None = None,
        vel_conv: float | None = None,
        range_conv: float | None = None,
        track: float | None = None,
        sonars: int | None = None,
        front_bumpers: int | None = None,
        rear_bumpers: int | None = None,
        **limits: Any,
    ) -> None:
        super().__init__(url, **limits)
        self.device, self.address = _parse_url(url)
        self.baud = _positive(int, "baud", baud)
        self.timeout = _positive(float, "timeout", timeout)
        self.pulse = _positive(float, "pulse", pulse)
        self.compass = bool(compass)
        self._unit_options = {
            "model": model or None,
            **{
                name: None if value is None else _positive(float, name, value)
                for name, value in (
                    ("dist_conv", dist_conv),
                    ("angle_conv", angle_conv),
                    ("vel_conv", vel_conv),
                    ("range_conv", range_conv),
                    ("track", track),
                )
            },
            **{
                name: None if value is None else _count(name, value)
                for name, value in (
                    ("sonars", sonars),
                    ("front_bumpers", front_bumpers),
                    ("rear_bumpers", rear_bumpers),
                )
            },
        }
        #: what this robot's units are worth: its model's, once it has named it
        self.units: Units = fit(None, self._unit_options)
        #: name, class and subclass the robot gave in its SYNC2 reply
        self.identity: dict[str, str] = {}
        self._parser = arcos.PacketParser()
        self._bad_sips = 0
        self._keeper: LinkKeeper[_Link] = LinkKeeper(
            f"the pioneer robot at {url!r}",
            connect=self._connect,
            serve=self._serve,
            halt=self._halt,
            drop=_Link.close,
            on_lost=self._forget_command,
        )
        self._command = (0, 0)  # mm/s, deg/s: what the robot was last told
        self._velocity_sent = self._pulse_sent = 0.0
        self._reset_readings()

    @property
    def errors(self) -> int:
        """Packets dropped so far: noise, bad checksums, truncated packets, short SIPs."""
        return self._parser.errors + self._bad_sips

    def capabilities(self) -> dict[str, Any]:
        found = super().capabilities()
        model = self.units.describe()
        drive = found["drive"]
        drive["max_linear"] = min(drive["max_linear"], model["max_velocity"])
        drive["max_angular"] = min(drive["max_angular"], model["max_rvelocity"])
        return {**found, "model": model}

    @property
    def connected(self) -> bool:
        return self._keeper.connected

    @property
    def wire_device(self) -> str | None:
        return self.device

    # -- hooks -----------------------------------------------------------------------------

    async def _open(self) -> None:
        await self._keeper.open()

    async def _close(self) -> None:
        await self._keeper.close(goodbye=_say_close)

    async def _drive(self, linear: float, angular: float) -> None:
        top = self.units.model
        linear = _clamp(linear * 1000.0, top.max_velocity)
        angular = _clamp(math.degrees(angular), top.max_rvelocity)
        # Set before sending: the keep-alive re-sends self._command and must never re-send an
        # older speed after this one.
        self._command = (round(linear), round(angular))
        self._velocity_sent = time.monotonic()
        await self._send(self._velocity_packets())

    async def _stop(self) -> None:
        try:
            await self._drive(0.0, 0.0)
        except RobotConnectionError:
            # While closing, a lost link is no reason to fail: the robot's watchdog stops it.
            if self.is_open:
                raise

    async def _read_sensors(self) -> dict[str, Any]:
        sip = self._sip
        if sip is None or not self.connected:
            raise self._keeper.lost_error()
        units = self.units
        x, y, theta = self._pose
        if self.compass:
            heading = None if sip.compass is None else float(sip.compass)
        else:
            heading = compass_heading(theta)
        front = [self._sonar[i] for i in units.front_sonars]
        front = [reading for reading in front if reading is not None]
        left, right = (wheel * units.mm_s_per_unit / 1000.0 for wheel in (sip.left, sip.right))
        if sip.rotvel is not None:  # the firmware's own turn rate
            turning = math.radians(sip.rotvel)
        else:
            turning = (right - left) / units.track
        bumpers = {
            ring: _bits(bits, count)
            for ring, bits, count in (
                ("front", sip.front_bumpers, units.front_bumpers),
                ("rear", sip.rear_bumpers, units.rear_bumpers),
            )
            if count
        }
        readings = {
            "position": {"x": x, "y": y, "theta": theta},
            "velocity": {"linear": (left + right) / 2.0, "angular": turning},
            "wheels": {"left": left, "right": right},
            "heading": heading,
            "range": min(front) if front else None,
            "sonar": list(self._sonar),
            "bumper": any(any(ring) for ring in bumpers.values()),
            "bumpers": bumpers,
            "stall": sip.stall_left or sip.stall_right,
            "battery": sip.battery,
            "motors": sip.motors,
            "errors": self.errors,
        }
        if not bumpers:
            del readings["bumpers"]  # a model without bump rings
        return readings

    def _sensor_specs(self) -> dict[str, dict[str, Any]]:
        rings = {"front": self.units.front_bumpers, "rear": self.units.rear_bumpers}
        rings = {ring: count for ring, count in rings.items() if count}
        specs = {
            "position": {"unit": {"x": "m", "y": "m", "theta": "rad"}, "source": "odometry"},
            "velocity": {"unit": {"linear": "m/s", "angular": "rad/s"}, "source": "wheels"},
            "wheels": {"unit": {"left": "m/s", "right": "m/s"}},
            "heading": {"unit": "deg", "source": "compass" if self.compass else "odometry"},
            "range": {"unit": "m", "max": SONAR_MAX, "sonars": list(self.units.front_sonars)},
            "sonar": {
                "unit": "m",
                "max": SONAR_MAX,
                "count": len(self.units.sonars),
                # where each disc sits: m forward and left of the centre, degrees to the left
                "discs": [
                    {"x": disc.x / 1000.0, "y": disc.y / 1000.0, "heading": disc.heading}
                    for disc in self.units.sonars
                ],
            },
            "bumper": {"unit": "bool"},
            # Each ring's segments in ARIA's order: the front ring from its left end, the rear
            # ring from its right end.
            "bumpers": {"unit": {ring: "bool" for ring in rings}, "segments": rings},
            "stall": {"unit": "bool"},
            "battery": {"unit": "V"},
            "motors": {"unit": "bool"},
            "errors": {"unit": "count"},
        }
        if not rings:
            del specs["bumpers"]
        return specs

    # -- the link --------------------------------------------------------------------------

    async def _connect(self) -> _Link:
        """Open the link, handshake, open the server, enable the motors, read a first SIP."""
        if self.address is not None:
            reader, writer = await asyncio.open_connection(*self.address)
        else:
            reader, writer = await serial_asyncio.open_serial_connection(
                url=self.device, baudrate=self.baud
            )
        link = _Link(reader, writer, self.timeout, self._parser, self.wire_taps)
        deadline = 3 * self.timeout
        try:
            async with asyncio.timeout(deadline):
                await self._handshake(link)
                await link.send(arcos.encode(arcos.OPEN) + arcos.encode(arcos.ENABLE, 1))
                self._reset_readings()
                while self._sip is None:
                    self._take(await link.packet())
        except TimeoutError:
            await link.close()
            raise RobotConnectionError(
                f"no ARCOS robot answered at {self.url!r} within {deadline:g} s"
            ) from None
        except BaseException:
            await link.close()
            raise
        self._command = (0, 0)
        self._pulse_sent = time.monotonic()
        return link

    async def _handshake(self, link: _Link) -> None:
        step = arcos.SYNC0
        while step <= arcos.SYNC2:
            await link.send(arcos.encode(step))
            reply = await _sync_reply(link, step)
            if reply is None:
                step = arcos.SYNC0  # a reply was lost or out of order: ARCOS starts over too
                continue
            if step == arcos.SYNC2:
                parts = reply[1:].split(b"\0") + [b"", b"", b""]
                names = [part.decode("latin-1") for part in parts[:3]]
                self.identity = dict(zip(("name", "class", "subclass"), names, strict=True))
                self.units = fit(self.identity["subclass"], self._unit_options)
            step += 1

    async def _serve(self, link: _Link) -> str:
        """Read packets until the link fails; return why it did."""
        keepalive = asyncio.create_task(self._keep_alive(link))
        try:
            while True:
                self._take(await link.packet(self.timeout))
        except TimeoutError:
            return f"no data from the robot for {self.timeout:g} s"
        except OSError as exc:  # EOF, reset, a vanished serial device, a failed write
            return str(exc) or type(exc).__name__
        finally:
            keepalive.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await keepalive

    async def _halt(self, link: _Link) -> None:
        self._command = (0, 0)
        await link.send(self._velocity_packets())

    def _forget_command(self, reason: str) -> None:
        self._command = (0, 0)

    async def _keep_alive(self, link: _Link) -> None:
        """PULSE for the robot's watchdog, which stops the motors after ~2 s of silence."""
        while True:
            await asyncio.sleep(KEEPALIVE_TICK)
            now = time.monotonic()
            packets = b""
            if self._command != (0, 0) and now - self._velocity_sent >= VELOCITY_REFRESH:
                packets += self._velocity_packets()
                self._velocity_sent = now
            if now - self._pulse_sent >= self.pulse:
                packets += arcos.encode(arcos.PULSE)
                self._pulse_sent = now
            if packets:
                try:
                    await link.send(packets)
                except OSError:
                    link.abort()  # the reader sees it and starts reconnecting
                    return

    async def _send(self, packets: bytes) -> None:
        link = self._keeper.require()
        try:
            await link.send(packets)
        except OSError as exc:
            link.abort()
            raise RobotConnectionError(f"lost the link to {self.url!r}: {exc}") from exc

    def _velocity_packets(self) -> bytes:
        linear, angular = self._command
        return arcos.encode(arcos.VEL, linear) + arcos.encode(arcos.RVEL, angular)

    # -- readings --------------------------------------------------------------------------

    def _reset_readings(self) -> None:
        self._sip: arcos.Sip | None = None
        self._odometry = arcos.Odometry(self.units.mm_per_unit, self.units.rad_per_unit)
        self._pose = (0.0, 0.0, 0.0)
        self._sonar: list[float | None] = [None] * len(self.units.sonars)

    def _take(self, body: bytes) -> None:
        if not arcos.is_sip(body):
            return  # configuration, encoder and I/O packets: nothing here asks for them
        try:
            sip = arcos.parse_sip(body)
        except ValueError:
            self._bad_sips += 1
            return
        self._pose = self._odometry.update(sip)
        metres = self.units.mm_per_range_unit / 1000.0
        for number, reading in sip.sonar.items():
            if number < len(self._sonar):  # ARIA too drops discs its model does not have
                self._sonar[number] = reading * metres
        self._sip = sip


class _Link(StreamLink):
    """One connection's streams, cut into packets."""

    def __init__(
        self,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        timeout: float,
        parser: arcos.PacketParser,
        taps: list,
    ) -> None:
        super().__init__(reader, writer, timeout)
        self._parser, self._taps = parser, taps
        self._pending: deque[bytes] = deque()
        parser.reset()

    async def packet(self, timeout: float | None = None) -> bytes:
        """The next valid packet body; TimeoutError, or OSError when the link is gone."""
        while not self._pending:
            data = await heard_within(self.read, timeout)
            for tap in self._taps:
                tap(data)
            self._pending.extend(self._parser.feed(data))
        return self._pending.popleft()


async def _say_close(link: _Link) -> None:
    await link.send(arcos.encode(arcos.CLOSE))


async def _sync_reply(link: _Link, step: int) -> bytes | None:
    """The robot's echo of SYNC ``step``, or None if it did not come in time."""
    with contextlib.suppress(TimeoutError):
        while True:
            body = await link.packet(SYNC_WAIT)
            if body[0] == step:
                return body
            if arcos.is_sip(body):
                # Still open for an earlier client (this one, before a crash): close it.
                await link.send(arcos.encode(arcos.CLOSE))
                return None
            # Anything else is a stale echo of an earlier try: skip it.
    return None


def _parse_url(url: str) -> tuple[str | None, tuple[str, int] | None]:
    """``(serial device, None)`` or ``(None, (host, port))``."""
    parts = urlsplit(url)
    scheme = parts.scheme.lower()
    if scheme == "pioneer+tcp":
        return None, (parts.hostname or DEFAULT_HOST, parts.port or DEFAULT_TCP_PORT)
    if scheme == "pioneer":
        # pioneer://COM3 names a Windows port in the host part.
        return (parts.netloc + parts.path) or DEFAULT_DEVICE, None
    raise ValueError(f"not a pioneer URL: {url!r}; use pioneer:///dev/... or pioneer+tcp://")


def _clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))


def _bits(value: int, count: int) -> list[bool]:
    return [bool(value >> i & 1) for i in range(count)]


def _count(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(f"{name} must be a whole number, 0 or more, got {value!r}")
    return value


def _positive(kind: type, name: str, value: Any) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    result = kind(value)
    if not result > 0:
        raise ValueError(f"{name} must be greater than 0, got {value!r}")
    return result
