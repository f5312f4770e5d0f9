"""A MAVLink ground vehicle (ArduPilot Rover, or PX4) on a TCP socket, a pty or UDP.

It decodes and encodes with its own pymavlink ``MAVLink`` object and shares no code with the
driver: modes, frames and conversions are written again here from the MAVLink and autopilot
documentation, so a mistake in ``rhal.mavlink`` cannot hide by being made on both sides.

It enforces the rules a real autopilot does:

- GUIDED is refused without a position estimate (``position=False``), with ArduPilot's text;
- arming is refused unless the mode allows it and the pre-arm checks pass (``gps_fix=False``:
  a STATUSTEXT "PreArm: GPS: No fix" (PX4: "Preflight Fail: ...") then COMMAND_ACK DENIED);
- setpoints move the vehicle only when it is armed and in GUIDED (PX4: OFFBOARD), in a body
  frame with the velocity + yaw-rate type_mask; anything else is recorded and ignored;
- PX4 refuses OFFBOARD unless setpoints arrived in the last ``setpoint_timeout`` s, and falls
  back to HOLD when they stop for that long in OFFBOARD (a failsafe);
- ArduPilot's guided timeout: no setpoint for ``setpoint_timeout`` (3 s) stops the vehicle,
  which stays in GUIDED;
- telemetry is sent only as asked with MAV_CMD_SET_MESSAGE_INTERVAL; HEARTBEAT always.

It integrates the commanded speeds into a pose (north, east, yaw clockwise from north), in a
square arena of walls ``arena`` m from the start, which its forward range finder sees.

The interface every driver's emulator offers:
    ``await emu.start()``, ``emu.url``, ``emu.commanded()`` (the last setpoint received as
    (linear m/s, angular rad/s counter-clockwise)), ``emu.stops``, ``await emu.unplug()``,
    ``await emu.replug()``, ``await emu.stop()``.

``stops`` counts stop commands: zero-velocity setpoints whose ``time_boot_ms`` differs from the
setpoint received before. The driver stamps each setpoint with the time it was commanded and
its periodic stream repeats that stamp, so every stop() (and drive(0, 0)) counts once, however
long the stream of zeros that holds it. Stamp 0 marks the idle zeros a driver streams to PX4
before any command; they are not stops.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import os
import shutil
import socket
import tempfile
import time
import tty
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import ardupilotmega as mavlink

ARDUPILOT_MODES = {"MANUAL": 0, "ACRO": 1, "STEERING": 3, "HOLD": 4, "LOITER": 5, "AUTO": 10,
                   "RTL": 11, "SMART_RTL": 12, "GUIDED": 15}  # fmt: skip
ARDUPILOT_ARMABLE = {"MANUAL", "ACRO", "STEERING", "HOLD", "LOITER", "GUIDED"}
PX4_MODES = {
    "MANUAL": (1, 0),
    "POSCTL": (3, 0),
    "HOLD": (4, 3),
    "MISSION": (4, 4),
    "RTL": (4, 5),
    "OFFBOARD": (6, 0),
}  # fmt: skip  (main mode, sub mode)
COMMAND_NAMES = {176: "DO_SET_MODE", 400: "ARM_DISARM", 511: "SET_MESSAGE_INTERVAL"}
# type_mask bits: velocity x/y/z are bits 3-5, yaw rate bit 11.
VELOCITY_BITS, YAW_RATE_BIT = 0b111 << 3, 1 << 11
BODY_FRAMES = (mavlink.MAV_FRAME_BODY_NED, mavlink.MAV_FRAME_BODY_OFFSET_NED)
EARTH_RADIUS = 6378137.0  # m
ORIGIN = (47.397742, 8.545594, 488.0)  # lat, lon, alt of the start: PX4's SITL home
RANGE_MIN, RANGE_MAX = 20, 800  # cm, the range finder's reach


@dataclass
class Setpoint:
    vx: float  # m/s forward (body frame)
    yaw_rate: float  # rad/s, clockwise seen from above (NED)
    frame: int
    type_mask: int
    stamp: int  # time_boot_ms
    source: tuple[int, int]  # system, component
    applied: bool  # the vehicle acted on it
    at: float  # time.monotonic()


@dataclass
class Command:
    name: str
    params: tuple[float, ...]
    result: int
    source: tuple[int, int]
    confirmation: int
    setpoints_before: int  # setpoints received before it


class MavlinkEmulator:
    def __init__(
        self,
        *,
        autopilot: str = "ardupilot",
        link: str = "tcp",
        vehicle: str = "rover",
        gps_fix: bool = True,
        position: bool = True,
        heartbeat: float = 1.0,
        tick: float = 0.05,
        setpoint_timeout: float | None = None,
        system: int = 1,
        component: int = 1,
        arena: float = 5.0,
    ) -> None:
        if autopilot not in ("ardupilot", "px4") or link not in ("tcp", "pty", "udp", "udpout"):
            raise ValueError(f"unknown autopilot {autopilot!r} or link {link!r}")
        self.autopilot, self.link = autopilot, link
        self.mav_type = (
            mavlink.MAV_TYPE_SURFACE_BOAT if vehicle == "boat" else mavlink.MAV_TYPE_GROUND_ROVER
        )
        self.gps_fix = gps_fix
        self.position = position  # a position estimate, which ArduPilot's GUIDED needs
        self.heartbeat_period, self.tick = heartbeat, tick
        default_timeout = 0.5 if autopilot == "px4" else 3.0
        self.setpoint_timeout = (
            setpoint_timeout if setpoint_timeout is not None else default_timeout
        )
        self.system, self.component = system, component
        self.arena = arena
        # The vehicle: it outlives any link to it.
        self.mode = "MANUAL"
        self.armed = False
        self.north = self.east = 0.0  # m from the start
        self.yaw = 0.0  # rad clockwise from north, (-pi, pi]
        self.speed = 0.0  # m/s forward, as applied
        self.turn = 0.0  # rad/s clockwise, as applied
        self.battery = 12.6  # V
        self.satellites = 10
        self.range_override: float | None = None  # m; None: the arena's walls
        # What the ground station did, for tests.
        self.setpoints: list[Setpoint] = []
        self.commands: list[Command] = []
        self.gcs_heartbeats: list[tuple[int, int, int]] = []  # system, component, MAV_TYPE
        self.intervals: dict[int, float] = {}  # message id -> s, as asked
        self.bad_frames = 0
        self.timeouts = 0  # guided timeouts that stopped the vehicle (ArduPilot)
        self.failsafes = 0  # offboard losses (PX4)
        self.stops = 0
        self.texts_sent: list[str] = []
        self.url = ""
        self._commanded = (0.0, 0.0)
        self._last_stamp: int | None = None
        self._setpoint_at = -math.inf  # time the last setpoint in a usable form arrived
        self._applied_at = -math.inf
        self._due: dict[int, float] = {}
        self._boot = time.monotonic()
        self._mav = mavlink.MAVLink(None, srcSystem=system, srcComponent=component)
        self._parser = self._new_parser()
        self._write = None
        self._ticker: asyncio.Task | None = None
        self._server: asyncio.Server | None = None
        self._client: asyncio.StreamWriter | None = None
        self._master = self._slave = None
        self._dir: str | None = None  # holds the pty's symlink
        self._path = ""
        self._udp: asyncio.DatagramTransport | None = None
        self._udp_peer: tuple[str, int] | None = None
        self._port: int | None = None

    # -- the interface ---------------------------------------------------------------------

    async def start(self) -> None:
        await self._plug()
        self._ticker = asyncio.get_running_loop().create_task(self._tick())

    def commanded(self) -> tuple[float, float]:
        """(linear m/s, angular rad/s counter-clockwise) of the last setpoint received."""
        return self._commanded

    async def unplug(self) -> None:
        """Drop the link as if a cable were pulled; the vehicle itself carries on."""
        if self._server is not None:
            self._server.close()
            if self._client is not None:
                self._client.transport.abort()
            await self._server.wait_closed()
            self._server = self._client = None
        if self._master is not None:
            asyncio.get_running_loop().remove_reader(self._master)
            os.close(self._master)
            os.close(self._slave)
            os.unlink(self._path)
            self._master = self._slave = None
        if self._udp is not None:
            self._udp.close()
            self._udp = None
        self._write = None

    async def replug(self) -> None:
        """The link back, at the same URL."""
        await self._plug()

    async def stop(self) -> None:
        await self.unplug()
        if self._ticker is not None:
            self._ticker.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._ticker
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)

    # -- for tests -------------------------------------------------------------------------

    def inject(self, data: bytes) -> None:
        """Put raw bytes on the wire to the driver: noise, broken frames."""
        if self._write is not None:
            self._write(data)

    def say(self, text: str, severity: int = mavlink.MAV_SEVERITY_WARNING) -> None:
        self.texts_sent.append(text)
        self._send(mavlink.MAVLink_statustext_message(severity, text.encode()))

    def set_mode(self, name: str) -> None:
        """As from the RC transmitter: no rules checked."""
        self.mode = name
        if not self._moving_mode():
            self.speed = self.turn = 0.0

    def named(self, name: str) -> list[Command]:
        return [command for command in self.commands if command.name == name]

    def heading(self) -> float:
        """Degrees clockwise from north, [0, 360)."""
        return math.degrees(self.yaw) % 360.0

    def frame(self, message: Any) -> bytes:
        """``message`` as this vehicle would send it, with a good CRC."""
        data = message.pack(self._mav)
        self._mav.seq = (self._mav.seq + 1) % 256
        return data

    # -- links -----------------------------------------------------------------------------

    async def _plug(self) -> None:
        loop = asyncio.get_running_loop()
        if self.link == "tcp":
            self._server = await asyncio.start_server(self._on_client, "127.0.0.1", self._port or 0)
            self._port = self._server.sockets[0].getsockname()[1]
            self.url = f"mavlink+tcp://127.0.0.1:{self._port}"
        elif self.link == "pty":
            self._master, self._slave = os.openpty()
            tty.setraw(self._slave)  # raw before the driver opens it: binary frames
            os.set_blocking(self._master, False)
            loop.add_reader(self._master, self._on_pty_readable)
            # The pty's name changes with each replug: the URL names a link that follows it.
            self._dir = self._dir or tempfile.mkdtemp(prefix="mavlink-emu-")
            self._path = os.path.join(self._dir, "ttyMAV0")
            os.symlink(os.ttyname(self._slave), self._path)
            self._write = self._write_pty
            self._parser = self._new_parser()
            self.url = f"mavlink://{self._path}?baud=115200"
        elif self.link == "udp":  # we listen; the driver sends to us first
            self._udp, _ = await loop.create_datagram_endpoint(
                lambda: _Datagrams(self), local_addr=("127.0.0.1", self._port or 0)
            )
            self._port = self._udp.get_extra_info("sockname")[1]
            self._udp_peer = None
            self._write = self._write_udp
            self.url = f"mavlink+udp://127.0.0.1:{self._port}"
        else:  # "udpout": we send to a port the driver listens on, as a vehicle to a GCS
            if self._port is None:
                with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
                    probe.bind(("127.0.0.1", 0))
                    self._port = probe.getsockname()[1]
            self._udp, _ = await loop.create_datagram_endpoint(
                lambda: _Datagrams(self), remote_addr=("127.0.0.1", self._port)
            )
            self._udp_peer = None
            self._write = self._write_udp
            self.url = f"mavlink+udp://127.0.0.1:{self._port}?listen=true"

    async def _on_client(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter):
        if self._client is not None:  # one ground station at a time, as on SITL's port
            writer.close()
            return
        self._client, self._write = writer, writer.write
        self._parser = self._new_parser()
        self._send_heartbeat()
        try:
            while data := await reader.read(4096):
                self.feed(data)
        except ConnectionError:
            pass
        finally:
            if self._client is writer:
                self._client = self._write = None
            writer.close()

    def _on_pty_readable(self) -> None:
        try:
            data = os.read(self._master, 4096)
        except (BlockingIOError, OSError):
            return
        self.feed(data)

    def _write_pty(self, data: bytes) -> None:
        with contextlib.suppress(BlockingIOError, OSError):
            os.write(self._master, data)  # nobody reading: the bytes are lost, as on a UART

    def _write_udp(self, data: bytes) -> None:
        if self._udp is None:
            return
        if self.link == "udpout":
            self._udp.sendto(data)
        elif self._udp_peer is not None:
            self._udp.sendto(data, self._udp_peer)

    def _send(self, message: Any) -> None:
        if self._write is not None:
            self._write(self.frame(message))

    @staticmethod
    def _new_parser():
        parser = mavlink.MAVLink(None)
        parser.robust_parsing = True
        return parser

    # -- receiving -------------------------------------------------------------------------

    def feed(self, data: bytes) -> None:
        for message in self._parser.parse_buffer(data) or []:
            kind = message.get_type()
            if kind == "BAD_DATA":
                self.bad_frames += 1
            elif kind == "HEARTBEAT":
                self.gcs_heartbeats.append(
                    (message.get_srcSystem(), message.get_srcComponent(), message.type)
                )
            elif kind == "SET_POSITION_TARGET_LOCAL_NED":
                if message.target_system == self.system:
                    self._on_setpoint(message)
            elif kind == "COMMAND_LONG":
                if message.target_system == self.system:
                    self._on_command(message)

    def _on_setpoint(self, msg: Any) -> None:
        now = time.monotonic()
        usable = (
            msg.type_mask & VELOCITY_BITS == 0
            and msg.type_mask & YAW_RATE_BIT == 0
            and msg.coordinate_frame in BODY_FRAMES
        )
        applied = usable and self.armed and self._moving_mode()
        if usable:
            self._setpoint_at = now
        if applied:
            self.speed, self.turn = msg.vx, msg.yaw_rate
            self._applied_at = now
        self.setpoints.append(
            Setpoint(
                msg.vx, msg.yaw_rate, msg.coordinate_frame, msg.type_mask, msg.time_boot_ms,
                (msg.get_srcSystem(), msg.get_srcComponent()), applied, now,
            )
        )  # fmt: skip
        if msg.vx == 0 and msg.yaw_rate == 0 and msg.time_boot_ms not in (0, self._last_stamp):
            self.stops += 1
        self._last_stamp = msg.time_boot_ms
        # NED yaw rate is clockwise; ours counter-clockwise. "+ 0.0" turns -0.0 into 0.0.
        self._commanded = (msg.vx + 0.0, -msg.yaw_rate + 0.0)

    def _on_command(self, msg: Any) -> None:
        params = (msg.param1, msg.param2, msg.param3, msg.param4, msg.param5, msg.param6,
                  msg.param7)  # fmt: skip
        source = (msg.get_srcSystem(), msg.get_srcComponent())
        if msg.command == mavlink.MAV_CMD_DO_SET_MODE:
            result = self._set_mode_command(params)
        elif msg.command == mavlink.MAV_CMD_COMPONENT_ARM_DISARM:
            result = self._arm_command(params[0])
        elif msg.command == mavlink.MAV_CMD_SET_MESSAGE_INTERVAL:
            result = self._interval_command(int(params[0]), params[1])
        else:
            result = mavlink.MAV_RESULT_UNSUPPORTED
        name = COMMAND_NAMES.get(msg.command, str(msg.command))
        self.commands.append(
            Command(name, params, result, source, msg.confirmation, len(self.setpoints))
        )
        self._send(mavlink.MAVLink_command_ack_message(msg.command, result, 0, 0, *source))

    def _set_mode_command(self, params: tuple[float, ...]) -> int:
        if not int(params[0]) & mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED:
            return mavlink.MAV_RESULT_DENIED
        if self.autopilot == "ardupilot":
            names = {number: name for name, number in ARDUPILOT_MODES.items()}
            name = names.get(int(params[1]))
        else:
            names = {numbers: name for name, numbers in PX4_MODES.items()}
            name = names.get((int(params[1]), int(params[2])))
            if name == "OFFBOARD" and not self._offboard_signal():
                self.say("Switching to Offboard is currently not available",
                         mavlink.MAV_SEVERITY_CRITICAL)  # fmt: skip
                return mavlink.MAV_RESULT_TEMPORARILY_REJECTED
        if name is None:
            return mavlink.MAV_RESULT_DENIED
        if name == "GUIDED" and not self.position:
            self.say("Mode change to GUIDED failed: requires position",
                     mavlink.MAV_SEVERITY_WARNING)  # fmt: skip
            return mavlink.MAV_RESULT_FAILED
        self.set_mode(name)
        return mavlink.MAV_RESULT_ACCEPTED

    def _arm_command(self, arm: float) -> int:
        if arm == 0:
            self.armed = False
            self.speed = self.turn = 0.0
            return mavlink.MAV_RESULT_ACCEPTED
        if self.armed:
            return mavlink.MAV_RESULT_ACCEPTED
        px4 = self.autopilot == "px4"
        if not px4 and self.mode not in ARDUPILOT_ARMABLE:
            self.say("Arm: Mode not armable", mavlink.MAV_SEVERITY_CRITICAL)
            return mavlink.MAV_RESULT_FAILED
        if px4 and self.mode == "OFFBOARD" and not self._offboard_signal():
            self.say("Arming denied: no offboard signal", mavlink.MAV_SEVERITY_CRITICAL)
            return mavlink.MAV_RESULT_DENIED
        if not self.gps_fix:
            text = "Preflight Fail: GPS fix too low" if px4 else "PreArm: GPS: No fix"
            self.say(text, mavlink.MAV_SEVERITY_CRITICAL)
            return mavlink.MAV_RESULT_DENIED
        self.armed = True
        return mavlink.MAV_RESULT_ACCEPTED

    def _interval_command(self, message_id: int, interval_us: float) -> int:
        if message_id not in self._senders:
            return mavlink.MAV_RESULT_DENIED
        if interval_us < 0:
            self.intervals.pop(message_id, None)
        else:
            self.intervals[message_id] = interval_us / 1e6 if interval_us > 0 else 1.0
            self._due[message_id] = time.monotonic()
        return mavlink.MAV_RESULT_ACCEPTED

    def _offboard_signal(self) -> bool:
        return time.monotonic() - self._setpoint_at <= self.setpoint_timeout

    def _moving_mode(self) -> bool:
        return self.mode == ("OFFBOARD" if self.autopilot == "px4" else "GUIDED")

    # -- the vehicle -----------------------------------------------------------------------

    async def _tick(self) -> None:
        last = next_heartbeat = time.monotonic()
        while True:
            await asyncio.sleep(self.tick)
            now = time.monotonic()
            dt, last = now - last, now
            # A tick this late means the whole process stalled (a loaded CI machine): the
            # ground station could not have sent either, so no timeout is blamed on it.
            if dt < self.setpoint_timeout / 2:
                self._enforce(now)
            # Along the chord of the arc: exact for constant speeds over the tick.
            half = self.turn * dt / 2
            chord = self.speed * dt * (math.sin(half) / half if half else 1.0)
            self.north += chord * math.cos(self.yaw + half)
            self.east += chord * math.sin(self.yaw + half)
            self.yaw = math.remainder(self.yaw + 2 * half, math.tau)
            if now >= next_heartbeat:
                self._send_heartbeat()
                next_heartbeat = now + self.heartbeat_period
            for message_id, interval in list(self.intervals.items()):
                if now >= self._due.get(message_id, now):
                    self._send(self._senders[message_id](self))
                    self._due[message_id] = now + interval

    def _enforce(self, now: float) -> None:
        if self.autopilot == "px4" and self.mode == "OFFBOARD" and not self._offboard_signal():
            self.set_mode("HOLD")
            self.failsafes += 1
            self.say("Failsafe activated: no offboard signal", mavlink.MAV_SEVERITY_CRITICAL)
        elif (self.speed or self.turn) and now - self._applied_at > self.setpoint_timeout:
            self.speed = self.turn = 0.0
            self.timeouts += 1
        if not self.armed or not self._moving_mode():
            self.speed = self.turn = 0.0

    def _send_heartbeat(self) -> None:
        base = mavlink.MAV_MODE_FLAG_CUSTOM_MODE_ENABLED
        if self.armed:
            base |= mavlink.MAV_MODE_FLAG_SAFETY_ARMED
        if self.autopilot == "ardupilot":
            autopilot, custom = mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA, ARDUPILOT_MODES[self.mode]
        else:
            main, sub = PX4_MODES[self.mode]
            autopilot, custom = mavlink.MAV_AUTOPILOT_PX4, main << 16 | sub << 24
        state = mavlink.MAV_STATE_ACTIVE if self.armed else mavlink.MAV_STATE_STANDBY
        self._send(mavlink.MAVLink_heartbeat_message(self.mav_type, autopilot, base, custom,
                                                     state, 3))  # fmt: skip

    def range_m(self) -> float | None:
        """Distance ahead to the arena's walls, None beyond the range finder's reach."""
        if self.range_override is not None:
            return self.range_override
        distances = []
        for position, direction in ((self.north, math.cos(self.yaw)),
                                    (self.east, math.sin(self.yaw))):  # fmt: skip
            if direction > 1e-9:
                distances.append((self.arena - position) / direction)
            elif direction < -1e-9:
                distances.append((-self.arena - position) / direction)
        distance = min(distances)
        return distance if distance * 100 < RANGE_MAX else None

    def _boot_ms(self) -> int:
        return int((time.monotonic() - self._boot) * 1000) % 2**32

    def _attitude(self):
        return mavlink.MAVLink_attitude_message(self._boot_ms(), 0.0, 0.0, self.yaw, 0.0, 0.0,
                                                self.turn)  # fmt: skip

    def _velocity_ne(self) -> tuple[float, float]:
        return self.speed * math.cos(self.yaw), self.speed * math.sin(self.yaw)

    def _local_position(self):
        v_north, v_east = self._velocity_ne()
        return mavlink.MAVLink_local_position_ned_message(
            self._boot_ms(), self.north, self.east, 0.0, v_north, v_east, 0.0
        )

    def _lat_lon(self) -> tuple[int, int]:
        lat = ORIGIN[0] + math.degrees(self.north / EARTH_RADIUS)
        lon = ORIGIN[1] + math.degrees(
            self.east / (EARTH_RADIUS * math.cos(math.radians(ORIGIN[0])))
        )
        return round(lat * 1e7), round(lon * 1e7)

    def _global_position(self):
        lat, lon = self._lat_lon()
        v_north, v_east = self._velocity_ne()
        return mavlink.MAVLink_global_position_int_message(
            self._boot_ms(), lat, lon, round(ORIGIN[2] * 1000), 0,
            round(v_north * 100), round(v_east * 100), 0, round(self.heading() * 100) % 36000,
        )  # fmt: skip

    def _gps_raw(self):
        lat, lon = self._lat_lon()
        fix = mavlink.GPS_FIX_TYPE_3D_FIX if self.gps_fix else mavlink.GPS_FIX_TYPE_NO_FIX
        return mavlink.MAVLink_gps_raw_int_message(
            self._boot_ms() * 1000, fix, lat, lon, round(ORIGIN[2] * 1000), 100, 100,
            round(abs(self.speed) * 100), 65535, self.satellites if self.gps_fix else 3,
        )  # fmt: skip

    def _sys_status(self):
        return mavlink.MAVLink_sys_status_message(
            0, 0, 0, 100, round(self.battery * 1000), -1, -1, 0, 0, 0, 0, 0, 0
        )

    def _distance_sensor(self):
        distance = self.range_m()
        centimetres = RANGE_MAX if distance is None else max(RANGE_MIN, round(distance * 100))
        return mavlink.MAVLink_distance_sensor_message(
            self._boot_ms(), RANGE_MIN, RANGE_MAX, centimetres,
            mavlink.MAV_DISTANCE_SENSOR_LASER, 0, mavlink.MAV_SENSOR_ROTATION_NONE, 255,
        )  # fmt: skip

    def _vfr_hud(self):
        return mavlink.MAVLink_vfr_hud_message(0.0, abs(self.speed), round(self.heading()) % 360,
                                               0, 0.0, 0.0)  # fmt: skip

    _senders = {
        mavlink.MAVLINK_MSG_ID_ATTITUDE: _attitude,
        mavlink.MAVLINK_MSG_ID_LOCAL_POSITION_NED: _local_position,
        mavlink.MAVLINK_MSG_ID_GLOBAL_POSITION_INT: _global_position,
        mavlink.MAVLINK_MSG_ID_GPS_RAW_INT: _gps_raw,
        mavlink.MAVLINK_MSG_ID_SYS_STATUS: _sys_status,
        mavlink.MAVLINK_MSG_ID_DISTANCE_SENSOR: _distance_sensor,
        mavlink.MAVLINK_MSG_ID_VFR_HUD: _vfr_hud,
    }


class _Datagrams(asyncio.DatagramProtocol):
    def __init__(self, emulator: MavlinkEmulator) -> None:
        self.emulator = emulator

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        if self.emulator.link == "udp":
            new = self.emulator._udp_peer != addr
            self.emulator._udp_peer = addr  # answer whoever sent to us last, as SITL does
            if new:
                self.emulator._send_heartbeat()
        self.emulator.feed(data)

    def error_received(self, exc: Exception) -> None:
        pass  # nobody listening yet on the driver's side
