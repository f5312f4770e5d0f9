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
from typing import Any
from urllib.parse import urlsplit

import serial_asyncio
from pymavlink import mavutil
from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from rhal.base import Robot
from rhal.errors import RhalError, RobotConnectionError
from rhal.kinematics import compass_heading, normalize_angle

DEFAULT_DEVICE = "/dev/ttyACM0"
DEFAULT_HOST, DEFAULT_TCP_PORT = "127.0.0.1", 5760
DEFAULT_UDP_PORT = 14550
WILDCARD_HOSTS = ("", "0.0.0.0", "::")
COMPONENT = mavlink2.MAV_COMP_ID_MISSIONPLANNER  # 190, the usual component id of a GCS
HEARTBEAT_PERIOD = 1.0  # s: our HEARTBEAT, for the autopilot's GCS failsafe
FIRST_TELEMETRY_WAIT = 1.0  # s that opening waits for the first ATTITUDE, if it comes
ACK_WAIT = 1.0  # s to wait for a COMMAND_ACK before trying again
RETRY_PAUSE = 0.5  # s between refused attempts to switch mode or arm
PX4_PRESTREAM = 5  # setpoints PX4 must have had before it accepts OFFBOARD
TEXTS_KEPT = 5  # STATUSTEXTs kept for the "messages" reading
BACKOFF_FIRST, BACKOFF_MAX = 0.2, 5.0  # s between reconnection attempts, doubling

ARDUPILOT, PX4 = "ardupilot", "px4"
ROVER_GUIDED = 15  # ArduPilot Rover's custom_mode for GUIDED
PX4_MAIN_OFFBOARD = 6  # PX4's custom main mode for OFFBOARD (bits 16-23 of custom_mode)

#: SET_POSITION_TARGET_LOCAL_NED type_mask: ignore position (bits 0-2), acceleration (6-8) and
#: yaw (10); use velocity vx, vy, vz (3-5) and yaw_rate (11). 0x05C7 = 1479. ArduPilot Rover
#: reads this combination as "speed and turn rate" (set_desired_turn_rate_and_speed).
VELOCITY_YAW_RATE_MASK = (
    mavlink2.POSITION_TARGET_TYPEMASK_X_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_Y_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_Z_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_AX_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_AY_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_AZ_IGNORE
    | mavlink2.POSITION_TARGET_TYPEMASK_YAW_IGNORE
)

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


class VehicleControlError(RhalError):
    """The vehicle would not be taken under the program's control: it refused the guided mode
    or arming (the autopilot's own reason is in the message), or someone else took it over."""


class MavlinkRobot(Robot):
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
        self._mav = mavlink2.MAVLink(None, srcSystem=self.sysid, srcComponent=COMPONENT)
        self._parser = _new_parser()
        self._old_errors = 0  # bad frames counted by the parsers of earlier links
        self._link: _Link | None = None
        self._lost = "not connected yet"  # why self._link is None
        self._task: asyncio.Task[None] | None = None
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
        return self._link is not None

    # -- hooks -----------------------------------------------------------------------------

    async def _open(self) -> None:
        self._link = await self._connect()
        self._task = asyncio.create_task(self._maintain(), name=f"mavlink link {self.url}")

    async def _close(self) -> None:
        if self.disarm_on_close and self._we_armed and self._link is not None:
            # Best effort: the pump keeps streaming the zero setpoint meanwhile.
            with contextlib.suppress(RhalError, OSError):
                await self._command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 0)
            self._we_armed = False
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        link, self._link = self._link, None
        self._lost = "closed"
        self._link_gone(RobotConnectionError(f"robot {self.url!r} was closed"))
        if link is not None:
            await link.close()

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

    # -- taking the vehicle ----------------------------------------------------------------

    async def _engage(self) -> None:
        """Get the vehicle into its guided mode and armed, or raise VehicleControlError."""
        async with self._engage_lock:
            if self._engaged:
                return
            if self.vehicle.get("autopilot") not in (ARDUPILOT, PX4):
                raise VehicleControlError(
                    f"the autopilot at {self.url!r} ({self.vehicle.get('autopilot')}) is not "
                    f"one this driver can drive: ArduPilot or PX4"
                )
            if not self.arm:
                if not self._in_control():
                    raise VehicleControlError(
                        f"the vehicle at {self.url!r} is {self._state_text()}; with arm=false "
                        f"the driver does not arm it or change its mode: arm it and switch it "
                        f"to {self._guided_name()} first (RC transmitter or GCS)"
                    )
                self._engaged = True
                return
            stops, deadline = self._stops, time.monotonic() + self.arm_timeout
            self._text_log = []
            if self.vehicle["autopilot"] == PX4:
                await self._prestream(deadline)
            while not self._in_control():
                r = self._readings
                if not self._in_mode():
                    what = f"switch to {self._guided_name()}"
                    result = await self._command(mavlink2.MAV_CMD_DO_SET_MODE, *self._mode_params())
                    if result == mavlink2.MAV_RESULT_ACCEPTED:
                        # The next HEARTBEAT will say so too; the ack was sent after the switch.
                        r["base_mode"] |= mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
                        r["custom_mode"] = self._guided_custom_mode()
                        r["mode"] = self._guided_name()
                else:
                    what = "arm"
                    result = await self._command(mavlink2.MAV_CMD_COMPONENT_ARM_DISARM, 1)
                    if result == mavlink2.MAV_RESULT_ACCEPTED:
                        self._we_armed = True
                        r["armed"] = True
                if stops != self._stops:
                    return  # drive() sees it and says so
                if result == mavlink2.MAV_RESULT_ACCEPTED:
                    continue
                if result == mavlink2.MAV_RESULT_UNSUPPORTED or time.monotonic() >= deadline:
                    raise VehicleControlError(self._refused(what, result))
                await asyncio.sleep(max(0.0, min(RETRY_PAUSE, deadline - time.monotonic())))
                if stops != self._stops:
                    return
            self._engaged = True

    async def _prestream(self, deadline: float) -> None:
        """PX4 takes OFFBOARD only once setpoints stream; the pump streams from link-up."""
        while self._setpoints_sent < PX4_PRESTREAM and time.monotonic() < deadline:
            self._require_link()
            await asyncio.sleep(1.0 / self.setpoint_rate)

    def _refused(self, what: str, result: int | None) -> str:
        # The autopilot says why in a STATUSTEXT ("PreArm: GPS: No fix"); the ack only says no.
        serious = [text for severity, text in self._text_log if severity <= 4]
        texts = serious or [text for _, text in self._text_log]
        reason = texts[-1] if texts else "it gave no reason"
        answer = "no COMMAND_ACK" if result is None else f"COMMAND_ACK {_result_name(result)}"
        return (
            f"the vehicle at {self.url!r} would not {what} within {self.arm_timeout:g} s: "
            f"{reason} ({answer})"
        )

    def _in_mode(self) -> bool:
        custom = self._readings["custom_mode"]
        if custom is None:
            return False
        if self.vehicle.get("autopilot") == PX4:
            return (custom >> 16) & 0xFF == PX4_MAIN_OFFBOARD
        return custom == ROVER_GUIDED and bool(self._readings["base_mode"] & 1)

    def _in_control(self) -> bool:
        return self._in_mode() and bool(self._readings["armed"])

    def _mode_params(self) -> tuple[int, int, int]:
        """MAV_CMD_DO_SET_MODE's base mode, custom (main) mode and PX4 sub mode."""
        main = PX4_MAIN_OFFBOARD if self.vehicle.get("autopilot") == PX4 else ROVER_GUIDED
        return mavlink2.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED, main, 0

    def _guided_custom_mode(self) -> int:
        """HEARTBEAT.custom_mode in that mode: PX4 keeps its main mode in bits 16-23."""
        if self.vehicle.get("autopilot") == PX4:
            return PX4_MAIN_OFFBOARD << 16
        return ROVER_GUIDED

    def _guided_name(self) -> str:
        return "OFFBOARD" if self.vehicle.get("autopilot") == PX4 else "GUIDED"

    def _state_text(self) -> str:
        armed = "armed" if self._readings["armed"] else "disarmed"
        return f"in {self._readings['mode'] or 'an unknown mode'} and {armed}"

    # -- setpoints and commands ------------------------------------------------------------

    async def _set_point(self, linear: float, angular: float) -> None:
        self._setpoint = (linear, angular, self._next_stamp())
        await self._send(self._setpoint_frame())

    def _next_stamp(self) -> int:
        now = int((time.monotonic() - self._epoch) * 1000)
        return max(now, self._setpoint[2] + 1) % 2**32 or 1

    def _setpoint_frame(self) -> bytes:
        linear, angular, stamp = self._setpoint
        self._setpoints_sent += 1
        return self._encode(
            mavlink2.MAVLink_set_position_target_local_ned_message(
                stamp,
                self.vehicle.get("system", 1),
                self.vehicle.get("component", 1),
                mavlink2.MAV_FRAME_BODY_NED,
                VELOCITY_YAW_RATE_MASK,
                0.0, 0.0, 0.0,
                linear, 0.0, 0.0,  # body frame: x forward
                0.0, 0.0, 0.0,
                0.0,
                0.0 - angular,  # NED yaw rate is clockwise seen from above
            )
        )  # fmt: skip

    def _streaming(self) -> bool:
        # PX4 wants setpoints before it enters OFFBOARD, so they stream from link-up; an
        # ArduPilot Rover only while we hold it in GUIDED.
        return self._engaged or self.vehicle.get("autopilot") == PX4

    async def _command(self, command: int, *params: float) -> int | None:
        """Send COMMAND_LONG; the result of its COMMAND_ACK, or None if none came."""
        loop = asyncio.get_running_loop()
        future: asyncio.Future[int] = loop.create_future()
        self._pending[command] = future
        try:
            for confirmation in range(2):
                args = (list(params) + [0.0] * 7)[:7]
                await self._send(
                    self._encode(
                        mavlink2.MAVLink_command_long_message(
                            self.vehicle.get("system", 1),
                            self.vehicle.get("component", 1),
                            command,
                            confirmation,
                            *args,
                        )
                    )
                )
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(ACK_WAIT):
                        return await asyncio.shield(future)
            return None
        finally:
            if self._pending.get(command) is future:
                del self._pending[command]

    def _encode(self, message: Any) -> bytes:
        frame = message.pack(self._mav)
        self._mav.seq = (self._mav.seq + 1) % 256
        return frame

    def _heartbeat_frame(self) -> bytes:
        return self._encode(
            mavlink2.MAVLink_heartbeat_message(
                mavlink2.MAV_TYPE_GCS,
                mavlink2.MAV_AUTOPILOT_INVALID,
                0,
                0,
                mavlink2.MAV_STATE_ACTIVE,
                3,
            )
        )

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

    async def _open_link(self) -> _Link:
        if self.device is not None:
            reader, writer = await serial_asyncio.open_serial_connection(
                url=self.device, baudrate=self.baud
            )
            return _StreamLink(reader, writer, self.timeout)
        host, port = self.address
        if self.listen is None:
            reader, writer = await asyncio.open_connection(host, port)
            return _StreamLink(reader, writer, self.timeout)
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

    async def _maintain(self) -> None:
        """Serve the link until it fails, then reconnect with backoff; until cancelled."""
        link = self._link
        while link is not None:
            reason = await self._serve(link)
            self._link, self._lost = None, reason
            self._link_gone(self._lost_error())
            await link.close()
            link = await self._reconnect()
            self._link = link

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

    async def _reconnect(self) -> _Link:
        delay = BACKOFF_FIRST
        while True:
            await asyncio.sleep(delay)
            try:
                return await self._connect()
            except (OSError, RobotConnectionError) as exc:
                self._lost = f"reconnecting failed: {exc}"
                delay = min(2 * delay, BACKOFF_MAX)

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
        if self._link is None:
            raise self._lost_error()
        return self._link

    def _lost_error(self) -> RobotConnectionError:
        return RobotConnectionError(
            f"no link to the mavlink vehicle at {self.url!r} ({self._lost}); reconnecting"
        )

    # -- receiving -------------------------------------------------------------------------

    def _receive(self, data: bytes) -> None:
        """Parse bytes from the link; bad frames are only counted (robust parsing)."""
        try:
            messages = self._parser.parse_buffer(data) or []
        except mavlink2.MAVError:  # not raised with robust parsing; a safety net all the same
            self._parser.total_receive_errors += 1
            self._parser.buf, self._parser.buf_index = bytearray(), 0
            return
        for message in messages:
            handler = self._handlers.get(message.get_type())
            if handler is not None:
                handler(self, message)

    def _on_heartbeat(self, msg: Any) -> None:
        system, component = msg.get_srcSystem(), msg.get_srcComponent()
        if system == self.sysid or msg.autopilot == mavlink2.MAV_AUTOPILOT_INVALID:
            return  # a GCS, a camera, a gimbal, or our own echo: not the vehicle
        if not self.vehicle:
            self.vehicle = {
                "system": system,
                "component": component,
                "autopilot": _autopilot_name(msg.autopilot),
                "type": _enum_name("MAV_TYPE", msg.type),
            }
        if (system, component) != (self.vehicle["system"], self.vehicle["component"]):
            return
        r = self._readings
        r["heartbeat_at"] = time.monotonic()
        r["base_mode"], r["custom_mode"] = msg.base_mode, msg.custom_mode
        r["armed"] = bool(msg.base_mode & mavlink2.MAV_MODE_FLAG_SAFETY_ARMED)
        r["mode"] = mavutil.mode_string_v10(msg)
        if self._engaged and not self._in_control():
            self._engaged = False
            self._taken_over = (
                f"the vehicle at {self.url!r} is now {self._state_text()}: an RC transmitter, "
                f"another GCS or a failsafe took it over; the driver does not take it back "
                f"until stop() is called"
            )
            if self._setpoint[:2] != (0.0, 0.0):
                self._setpoint = (0.0, 0.0, self._next_stamp())

    def _from_vehicle(self, msg: Any) -> bool:
        return bool(self.vehicle) and msg.get_srcSystem() == self.vehicle["system"]

    def _on_attitude(self, msg: Any) -> None:
        if self._from_vehicle(msg):
            self._readings["yaw"] = _finite(msg.yaw)
            self._readings["yawspeed"] = _finite(msg.yawspeed)

    def _on_vfr_hud(self, msg: Any) -> None:
        if self._from_vehicle(msg):
            self._readings["hud_heading"] = float(msg.heading % 360)

    def _on_local_position(self, msg: Any) -> None:
        values = [_finite(v) for v in (msg.x, msg.y, msg.vx, msg.vy)]
        if self._from_vehicle(msg) and None not in values:
            self._readings["local"] = tuple(values)

    def _on_global_position(self, msg: Any) -> None:
        if self._from_vehicle(msg):
            self._readings["global"] = (msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1000.0)

    def _on_gps_raw(self, msg: Any) -> None:
        if self._from_vehicle(msg):
            satellites = None if msg.satellites_visible == 255 else msg.satellites_visible
            position = (msg.lat / 1e7, msg.lon / 1e7, msg.alt / 1000.0)
            self._readings["gps_raw"] = (msg.fix_type, satellites, position)

    def _on_sys_status(self, msg: Any) -> None:
        if self._from_vehicle(msg) and msg.voltage_battery != 0xFFFF:
            self._readings["battery"] = msg.voltage_battery / 1000.0

    def _on_distance_sensor(self, msg: Any) -> None:
        if self._from_vehicle(msg) and msg.orientation == mavlink2.MAV_SENSOR_ROTATION_NONE:
            beyond = msg.max_distance and msg.current_distance >= msg.max_distance
            self._readings["range"] = None if beyond else msg.current_distance / 100.0

    def _on_statustext(self, msg: Any) -> None:
        if self._from_vehicle(msg):
            text = msg.text.strip()
            self._texts.append(text)
            self._text_log.append((msg.severity, text))
            del self._text_log[:-50]

    def _on_command_ack(self, msg: Any) -> None:
        if not self._from_vehicle(msg) or msg.target_system not in (0, self.sysid):
            return  # an answer to another GCS
        future = self._pending.get(msg.command)
        if future is not None and not future.done():
            if msg.result != mavlink2.MAV_RESULT_IN_PROGRESS:  # the final answer follows
                future.set_result(msg.result)

    _handlers = {
        "HEARTBEAT": _on_heartbeat,
        "ATTITUDE": _on_attitude,
        "VFR_HUD": _on_vfr_hud,
        "LOCAL_POSITION_NED": _on_local_position,
        "GLOBAL_POSITION_INT": _on_global_position,
        "GPS_RAW_INT": _on_gps_raw,
        "SYS_STATUS": _on_sys_status,
        "DISTANCE_SENSOR": _on_distance_sensor,
        "STATUSTEXT": _on_statustext,
        "COMMAND_ACK": _on_command_ack,
    }

    # -- readings --------------------------------------------------------------------------

    def _reset_readings(self) -> None:
        self._readings: dict[str, Any] = {
            "heartbeat_at": None,
            "base_mode": 0,
            "custom_mode": None,
            "armed": None,
            "mode": None,
            "yaw": None,
            "yawspeed": None,
            "hud_heading": None,
            "local": None,  # north, east, v_north, v_east
            "global": None,  # lat, lon, alt
            "gps_raw": None,  # fix, satellites, (lat, lon, alt)
            "battery": None,
            "range": None,
        }

    def _gps(self) -> dict[str, Any] | None:
        fused, raw = self._readings["global"], self._readings["gps_raw"]
        if fused is None and raw is None:
            return None
        lat, lon, alt = fused if fused is not None else raw[2]
        fix, satellites = (raw[0], raw[1]) if raw is not None else (None, None)
        return {"lat": lat, "lon": lon, "alt": alt, "fix": fix, "satellites": satellites}


class _StreamLink:
    """TCP or serial: one StreamReader/StreamWriter pair."""

    def __init__(
        self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter, timeout: float
    ) -> None:
        self._reader, self._writer, self._timeout = reader, writer, timeout

    async def read(self) -> bytes:
        data = await self._reader.read(4096)
        if not data:
            raise ConnectionResetError("the vehicle closed the link")
        return data

    async def send(self, data: bytes) -> None:
        if self._writer.is_closing():
            raise ConnectionResetError("the link is closed")
        self._writer.write(data)
        # Bounded: a peer that stopped reading must not hang the pump or a drive().
        async with asyncio.timeout(self._timeout):
            await self._writer.drain()

    def abort(self) -> None:
        self._writer.transport.abort()

    async def close(self) -> None:
        self._writer.close()
        with contextlib.suppress(OSError):
            await self._writer.wait_closed()


class _DatagramLink(asyncio.DatagramProtocol):
    """UDP: to a fixed vehicle address, or (listening) back to whoever sent to us last."""

    def __init__(self, remote: tuple[str, int] | None) -> None:
        self._remote = remote
        self._peer = remote
        self._queue: asyncio.Queue[bytes | None] = asyncio.Queue()
        self._transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        if self._remote is None:
            self._peer = addr
        self._queue.put_nowait(data)

    def error_received(self, exc: Exception) -> None:
        pass  # e.g. ICMP port unreachable while the vehicle is down: the silence tells

    def connection_lost(self, exc: Exception | None) -> None:
        self._queue.put_nowait(None)

    async def read(self) -> bytes:
        data = await self._queue.get()
        if data is None:
            self._queue.put_nowait(None)
            raise ConnectionResetError("the UDP socket was closed")
        return data

    async def send(self, data: bytes) -> None:
        if self._transport is None or self._transport.is_closing():
            raise ConnectionResetError("the UDP socket is closed")
        if self._peer is None:
            return  # listening, and no vehicle has sent to us yet
        self._transport.sendto(data, None if self._remote else self._peer)

    def abort(self) -> None:
        if self._transport is not None:
            self._transport.abort()

    async def close(self) -> None:
        if self._transport is not None:
            self._transport.close()


_Link = _StreamLink | _DatagramLink


def _new_parser() -> Any:
    parser = mavlink2.MAVLink(None)
    parser.robust_parsing = True  # bad bytes become BAD_DATA messages, never exceptions
    return parser


def _parse_url(
    url: str, listen: bool | None
) -> tuple[str | None, tuple[str, int] | None, bool | None]:
    """``(serial device, None, None)`` or ``(None, (host, port), listen)``; listen is None
    for TCP, True or False for UDP."""
    parts = urlsplit(url)
    scheme = parts.scheme.lower()
    if listen is not None and scheme != "mavlink+udp":
        raise ValueError(f"the listen option is for mavlink+udp:// URLs only, not {url!r}")
    if scheme == "mavlink":
        # mavlink://COM3 names a Windows port in the host part.
        return (parts.netloc + parts.path) or DEFAULT_DEVICE, None, None
    try:
        port = parts.port
    except ValueError:
        raise ValueError(f"bad port in {url!r}") from None
    if scheme == "mavlink+tcp":
        return None, (parts.hostname or DEFAULT_HOST, port or DEFAULT_TCP_PORT), None
    if scheme == "mavlink+udp":
        host = parts.hostname or ""
        if listen is None:
            listen = host in WILDCARD_HOSTS
        else:
            listen = _flag("listen", listen)
        if not listen and host in WILDCARD_HOSTS:
            raise ValueError(f"listen=false needs the vehicle's address in {url!r}")
        return None, (host, port or DEFAULT_UDP_PORT), listen
    raise ValueError(
        f"not a mavlink URL: {url!r}; use mavlink:///dev/..., mavlink+tcp:// or mavlink+udp://"
    )


def _positive(kind: type, name: str, value: Any) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    result = kind(value)
    if not (result > 0 and math.isfinite(result)):
        raise ValueError(f"{name} must be greater than 0, got {value!r}")
    return result


def _flag(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return value


def _finite(value: float) -> float | None:
    return float(value) if math.isfinite(value) else None


def _enum_name(enum: str, value: int) -> str:
    entry = mavlink2.enums.get(enum, {}).get(value)
    prefix = enum + "_"
    return entry.name.removeprefix(prefix) if entry is not None else str(value)


def _autopilot_name(value: int) -> str:
    if value == mavlink2.MAV_AUTOPILOT_ARDUPILOTMEGA:
        return ARDUPILOT
    if value == mavlink2.MAV_AUTOPILOT_PX4:
        return PX4
    return _enum_name("MAV_AUTOPILOT", value)


def _result_name(result: int | None) -> str:
    return "no answer" if result is None else _enum_name("MAV_RESULT", result)
