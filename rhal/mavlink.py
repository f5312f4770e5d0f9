"""MAVLink ground vehicles and boats (ArduPilot Rover, PX4 rover), for ``mavlink://`` URLs.

    mavlink:///dev/ttyACM0?baud=57600   a serial port: USB to the autopilot, or a telemetry radio
    mavlink+tcp://127.0.0.1:5760        TCP to the vehicle (ArduPilot SITL listens on 5760)
    mavlink+udp://:14550                UDP, listening on port 14550 of every interface: the
                                        vehicle (or a router such as mavlink-router) sends to us
    mavlink+udp://192.168.4.1:14550     UDP, sending to the vehicle at that address; its answers
                                        come back to our port. ``?listen=true`` listens on the
                                        given address instead (``mavlink+udp://127.0.0.1:14550?listen=true``)

Options, also accepted in the URL query: ``baud`` (serial only, default 57600), ``timeout`` (s
without a HEARTBEAT from the vehicle before the link counts as lost, default 3), ``arm`` (put
the vehicle in GUIDED/OFFBOARD and arm it on the first motion, default true), ``arm_timeout``
(s to keep retrying a refused mode switch or arming, default 10), ``setpoint_rate`` (Hz,
default 10), ``sysid`` (our MAVLink system id, default 245), ``disarm_on_close`` (default true),
``listen`` (UDP only, see above), ``max_linear``, ``max_angular``.

pymavlink does the encoding and decoding (one ``MAVLink`` object, robust parsing: bad bytes
become BAD_DATA messages that are counted, never exceptions); the I/O is asyncio's, so nothing
blocks the event loop. mavutil's connections are not used: they block.

The link's life: open the transport, send our HEARTBEAT (a GCS), wait for the vehicle's, ask
for the telemetry messages with SET_MESSAGE_INTERVAL, then a reader and a pump that sends our
HEARTBEAT each second and the velocity setpoints. drive() with a speed takes the vehicle on the
first call: the guided mode (ArduPilot GUIDED, PX4 OFFBOARD, whose setpoints must already be
streaming) and arming, retried for ``arm_timeout`` s. From then on the current setpoint (body
forward speed + yaw rate) is streamed at ``setpoint_rate``; stop() sends a zero setpoint at once
and the stream holds it. If the vehicle leaves that mode or is disarmed behind the driver's
back (RC transmitter, another GCS, a failsafe), drive() refuses until stop() is called: the
driver never takes a vehicle back from a person by itself.

Each setpoint carries in ``time_boot_ms`` the time it was commanded (ms since this robot object
was made, strictly increasing); the stream's repeats carry the same stamp. Autopilots do not
use the field for these setpoints; a peer can tell a new command from a repeat by it.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from collections import deque
from collections.abc import Awaitable, Callable
from typing import Any

import serial_asyncio
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from rhal.base import Robot
from rhal.errors import RhalError, RobotConnectionError
from rhal.kinematics import compass_heading, normalize_angle
from rhal.linked import LinkKeeper, StreamLink
from rhal.mavlink_control import VELOCITY_YAW_RATE_MASK as VELOCITY_YAW_RATE_MASK
from rhal.mavlink_control import MavlinkControl, VehicleControlError
from rhal.mavlink_links import (
    _DatagramLink,
    _flag,
    _Link,
    _new_parser,
    _parse_url,
    _positive,
)
from rhal.mavlink_telemetry import MavlinkTelemetry

COMPONENT = mavlink2.MAV_COMP_ID_MISSIONPLANNER  # 190, the usual component id of a GCS
HEARTBEAT_PERIOD = 1.0  # s: our HEARTBEAT, for the autopilot's GCS failsafe
FIRST_TELEMETRY_WAIT = 1.0  # s that opening waits for the first ATTITUDE, if it comes
TEXTS_KEPT = 5  # STATUSTEXTs kept for the "messages" reading

#: Telemetry asked for with MAV_CMD_SET_MESSAGE_INTERVAL: message id -> Hz.
TELEMETRY_RATES = {
    mavlink2.MAVLINK_MSG_ID_ATTITUDE: 10.0,
    mavlink2.MAVLINK_MSG_ID_LOCAL_POSITION_NED: 10.0,
    mavlink2.MAVLINK_MSG_ID_DISTANCE_SENSOR: 10.0,
    mavlink2.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: 5.0,
    mavlink2.MAVLINK_MSG_ID_VFR_HUD: 4.0,
    mavlink2.MAVLINK_MSG_ID_GPS_RAW_INT: 2.0,
    mavlink2.MAVLINK_MSG_ID_SYS_STATUS: 2.0,
}


class MavlinkRobot(MavlinkControl, MavlinkTelemetry, Robot):
    kind = "mavlink"
    quick = False  # every call waits on the link
    option_help = {
        **Robot.option_help,
        "baud": "serial speed, bit/s (ignored on TCP and UDP; 57600 for most telemetry radios)",
        "timeout": "s without a HEARTBEAT from the vehicle before the link counts as lost",
        "arm": "switch to GUIDED/OFFBOARD and arm on the first motion; off: a person does it",
        "arm_timeout": "s to keep retrying a refused mode switch or arming before giving up",
        "setpoint_rate": "Hz at which velocity setpoints are streamed (2 to 50)",
        "sysid": "our MAVLink system id (set ArduPilot's SYSID_MYGCS to it for the GCS failsafe)",
        "disarm_on_close": "disarm the vehicle on close, if the driver armed it",
        "listen": "UDP: listen on the URL's address (on) or send to it (off); "
        "default: listen when the host is empty",
    }

    def __init__(
        self,
        url: str = "mavlink+tcp://",
        *,
        baud: int = 57600,
        timeout: float = 3.0,
        arm: bool = True,
        arm_timeout: float = 10.0,
        setpoint_rate: float = 10.0,
        sysid: int = 245,
        disarm_on_close: bool = True,
        listen: bool | None = None,
        **limits: Any,
    ) -> None:
        super().__init__(url, **limits)
        self.device, self.address, self.listen = _parse_url(url, listen)
        self.baud = _positive(int, "baud", baud)
        self.timeout = _positive(float, "timeout", timeout)
        self.arm = _flag("arm", arm)
        self.arm_timeout = _positive(float, "arm_timeout", arm_timeout)
        self.setpoint_rate = _positive(float, "setpoint_rate", setpoint_rate)
        if not 2.0 <= self.setpoint_rate <= 50.0:
            raise ValueError(
                f"setpoint_rate must be 2 to 50 Hz (PX4 leaves OFFBOARD below 2), "
                f"got {setpoint_rate!r}"
            )
        if isinstance(sysid, bool) or not isinstance(sysid, int) or not 1 <= sysid <= 255:
            raise ValueError(f"sysid must be a MAVLink system id, 1 to 255, got {sysid!r}")
        self.sysid = sysid
        self.disarm_on_close = _flag("disarm_on_close", disarm_on_close)
        #: the vehicle the driver talks to, from its HEARTBEAT: system, component, autopilot
        #: ("ardupilot", "px4" or another MAV_AUTOPILOT name) and type (e.g. "GROUND_ROVER")
        self.vehicle: dict[str, Any] = {}
        #: set by an agent that shares the vehicle link through its MAVLink router: a
        #: coroutine function giving a link (read, send, abort, close) for each connection
        self.link_factory: Callable[[], Awaitable[Any]] | None = None
        self._mav = mavlink2.MAVLink(None, srcSystem=self.sysid, srcComponent=COMPONENT)
        self._parser = _new_parser()
        self._old_errors = 0  # bad frames counted by the parsers of earlier links
        self._keeper: LinkKeeper[_Link] = LinkKeeper(
            f"the mavlink vehicle at {url!r}",
            connect=self._connect,
            serve=self._serve,
            halt=self._halt,
            drop=_drop,
            on_lost=lambda reason: self._link_gone(self._keeper.lost_error()),
        )
        self._pending: dict[int, asyncio.Future[int]] = {}  # command id -> its ack's result
        self._engage_lock = asyncio.Lock()
        self._epoch = time.monotonic()
        self._setpoint = (0.0, 0.0, 0)  # linear m/s, angular rad/s ccw, stamp (0: never set)
        self._setpoints_sent = 0  # on this link
        self._engaged = False  # we hold the vehicle in its guided mode, armed
        self._taken_over: str | None = None  # why drive() refuses until stop()
        self._we_armed = False
        self._stops = 0  # stop() calls, so a drive() waiting to arm can tell it was stopped
        self._texts: deque[str] = deque(maxlen=TEXTS_KEPT)
        self._text_log: list[tuple[int, str]] = []  # (severity, text) since the last arming
        self._reset_readings()

    @property
    def errors(self) -> int:
        """Bad frames dropped so far: noise, bad CRCs, truncated frames, bad lengths."""
        return self._old_errors + self._parser.total_receive_errors

    @property
    def connected(self) -> bool:
        return self._keeper.connected

    # -- hooks -----------------------------------------------------------------------------

    async def _open(self) -> None:
        await self._keeper.open()

    async def _close(self) -> None:
        if self.disarm_on_close and self._we_armed and self.connected:
            # Best effort: the pump keeps streaming the zero setpoint meanwhile.
            with contextlib.suppress(RhalError, OSError):
                await self._command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 0)
            self._we_armed = False
        await self._keeper.close()
        self._link_gone(RobotConnectionError(f"robot {self.url!r} was closed"))

    async def _drive(self, linear: float, angular: float) -> None:
        self._require_link()
        if linear == 0.0 and angular == 0.0:
            await self._set_point(0.0, 0.0)
            return
        if self._taken_over is not None:
            raise VehicleControlError(self._taken_over)
        if not self._engaged:
            stops = self._stops
            await self._engage()
            if stops != self._stops:
                raise VehicleControlError(
                    f"stop() was called while the vehicle at {self.url!r} was being made "
                    f"ready; it was not driven"
                )
        await self._set_point(linear, angular)

    async def _stop(self) -> None:
        self._stops += 1
        self._taken_over = None
        try:
            self._require_link()
            await self._set_point(0.0, 0.0)
        except RobotConnectionError:
            # While closing, a lost link is no reason to fail: the autopilot's own timeouts
            # (Rover's guided timeout, PX4's offboard loss) stop the vehicle.
            if self.is_open:
                raise

    async def _read_sensors(self) -> dict[str, Any]:
        self._require_link()
        return self._snapshot()

    def _snapshot(self) -> dict[str, Any]:
        """The readings from what the vehicle last sent, converted to RHAL's frames."""
        r = self._readings
        yaw = r["yaw"]
        if yaw is None and r["hud_heading"] is not None:
            yaw = math.radians(r["hud_heading"])
        heading = None if yaw is None else compass_heading(math.pi / 2 - yaw)
        theta = None if yaw is None else normalize_angle(math.pi / 2 - yaw)
        position = velocity = None
        if r["local"] is not None and theta is not None:
            north, east, v_north, v_east = r["local"]
            position = {"x": east, "y": north, "theta": theta}
            if r["yawspeed"] is not None:
                forward = v_north * math.cos(yaw) + v_east * math.sin(yaw)
                velocity = {"linear": forward, "angular": 0.0 - r["yawspeed"]}
        return {
            "heading": heading,
            "position": position,
            "velocity": velocity,
            "range": r["range"],
            "battery": r["battery"],
            "gps": self._gps(),
            "mode": r["mode"],
            "armed": r["armed"],
            "messages": list(self._texts),
            "errors": self.errors,
        }

    def _sensor_specs(self) -> dict[str, dict[str, Any]]:
        return {
            "heading": {"unit": "deg", "source": "ATTITUDE yaw, else VFR_HUD heading"},
            "position": {
                "unit": {"x": "m", "y": "m", "theta": "rad"},
                "source": "LOCAL_POSITION_NED (x east, y north of the autopilot's origin)",
            },
            "velocity": {"unit": {"linear": "m/s", "angular": "rad/s"}},
            "range": {"unit": "m", "source": "DISTANCE_SENSOR facing forward"},
            "battery": {"unit": "V"},
            "gps": {
                "unit": {
                    "lat": "deg",
                    "lon": "deg",
                    "alt": "m",
                    "fix": "GPS_FIX_TYPE",
                    "satellites": "count",
                },
            },
            "mode": {"unit": "name"},
            "armed": {"unit": "bool"},
            "messages": {"unit": "text", "count": TEXTS_KEPT},
            "errors": {"unit": "count"},
        }

    # -- the link --------------------------------------------------------------------------

    async def _connect(self) -> _Link:
        """Open the transport, wait for the vehicle's HEARTBEAT, ask for its telemetry."""
        link = await self._open_link()
        self._old_errors += self._parser.total_receive_errors
        self._parser = _new_parser()
        self._reset_readings()
        self.vehicle = {}  # after a replug it may be another vehicle
        self._setpoints_sent = 0
        try:
            async with asyncio.timeout(self.timeout):
                while self._readings["heartbeat_at"] is None:
                    await link.send(self._heartbeat_frame())
                    with contextlib.suppress(TimeoutError):
                        async with asyncio.timeout(HEARTBEAT_PERIOD):
                            while self._readings["heartbeat_at"] is None:
                                self._receive(await link.read())
            for message_id, rate in TELEMETRY_RATES.items():
                await link.send(
                    self._encode(
                        mavlink2.MAVLink_command_long_message(
                            self.vehicle["system"],
                            self.vehicle["component"],
                            mavlink2.MAV_CMD_SET_MESSAGE_INTERVAL,
                            0,
                            message_id,
                            1e6 / rate,
                            0, 0, 0, 0, 0,
                        )
                    )
                )  # fmt: skip
        except TimeoutError:
            await link.close()
            raise RobotConnectionError(
                f"no MAVLink vehicle answered at {self.url!r} within {self.timeout:g} s "
                f"(no HEARTBEAT from an autopilot)"
            ) from None
        except BaseException:
            await link.close()
            raise
        # A program that reads the heading first thing should find one: wait a moment for
        # the first ATTITUDE, but a vehicle that sends none is no reason to fail.
        try:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(FIRST_TELEMETRY_WAIT):
                    while self._readings["yaw"] is None:
                        self._receive(await link.read())
        except BaseException:
            await link.close()
            raise
        return link

    def vehicle_link(self) -> dict:
        """The vehicle link as a gateway endpoint spec, for an agent that routes it."""
        if self.device is not None:
            return {"type": "serial", "device": self.device, "baud": self.baud}
        host, port = self.address
        if self.listen is None:
            return {"type": "tcp", "mode": "client", "address": f"{host}:{port}"}
        if self.listen:
            return {"type": "udp", "mode": "server", "address": f"{host or '0.0.0.0'}:{port}"}
        return {"type": "udp", "mode": "client", "address": f"{host}:{port}"}

    async def _open_link(self) -> _Link:
        if self.link_factory is not None:
            return await self.link_factory()
        if self.device is not None:
            reader, writer = await serial_asyncio.open_serial_connection(
                url=self.device, baudrate=self.baud
            )
            return StreamLink(reader, writer, self.timeout, "vehicle")
        host, port = self.address
        if self.listen is None:
            reader, writer = await asyncio.open_connection(host, port)
            return StreamLink(reader, writer, self.timeout, "vehicle")
        loop = asyncio.get_running_loop()
        if self.listen:
            bind = host or "0.0.0.0"
            _, protocol = await loop.create_datagram_endpoint(
                lambda: _DatagramLink(None), local_addr=(bind, port)
            )
        else:
            _, protocol = await loop.create_datagram_endpoint(
                lambda: _DatagramLink((host, port)), remote_addr=(host, port)
            )
        return protocol

    async def _serve(self, link: _Link) -> str:
        """Read until the link fails or the vehicle goes quiet; return why."""
        pump = asyncio.create_task(self._pump(link))
        try:
            while True:
                heard = self._readings["heartbeat_at"]
                wait = heard + self.timeout - time.monotonic()
                if wait <= 0:
                    return f"no HEARTBEAT from the vehicle for {self.timeout:g} s"
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(wait):
                        data = await link.read()
                    self._receive(data)
        except OSError as exc:  # EOF, reset, a vanished serial device, a failed write
            return str(exc) or type(exc).__name__
        finally:
            pump.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await pump

    async def _pump(self, link: _Link) -> None:
        """Our HEARTBEAT once a second; the setpoint at setpoint_rate while streaming."""
        period = 1.0 / self.setpoint_rate
        next_heartbeat = next_setpoint = time.monotonic()
        while True:
            now = time.monotonic()
            frames = b""
            if now >= next_heartbeat:
                frames += self._heartbeat_frame()
                next_heartbeat = now + HEARTBEAT_PERIOD
            if now >= next_setpoint:
                if self._streaming():
                    frames += self._setpoint_frame()
                next_setpoint = now + period
            if frames:
                try:
                    await link.send(frames)
                except OSError:
                    link.abort()  # the reader sees it and starts reconnecting
                    return
            await asyncio.sleep(max(0.0, min(next_heartbeat, next_setpoint) - time.monotonic()))

    async def _halt(self, link: _Link) -> None:
        """A zero setpoint, if this link was moving the vehicle; a ground station's
        guidance is not ours to interrupt."""
        if self._streaming() or self._setpoint[:2] != (0.0, 0.0):
            self._setpoint = (0.0, 0.0, self._next_stamp())
            await link.send(self._setpoint_frame())

    def _link_gone(self, error: RhalError) -> None:
        """Forget what held only for that link; motion is not resumed after a reconnection."""
        self._engaged = False
        if self._setpoint[:2] != (0.0, 0.0):
            self._setpoint = (0.0, 0.0, self._next_stamp())
        for future in self._pending.values():
            if not future.done():
                future.set_exception(error)
        self._pending.clear()

    async def _send(self, frames: bytes) -> None:
        link = self._require_link()
        try:
            await link.send(frames)
        except OSError as exc:
            link.abort()
            raise RobotConnectionError(f"lost the link to {self.url!r}: {exc}") from exc

    def _require_link(self) -> _Link:
        return self._keeper.require()


async def _drop(link: _Link) -> None:
    await link.close()
