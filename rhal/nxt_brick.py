"""LEGO Mindstorms NXT bricks through nxt-python, for ``nxt://`` URLs.

    nxt://                          the first brick found on USB
    nxt://usb/MyNXT                 the brick named MyNXT on USB (or by its address:
                                    nxt://usb/00:16:53:01:02:03 or nxt://usb/001653010203)
    nxt://bt/00:16:53:01:02:03      Bluetooth, by the brick's address (needs PyBluez)
    nxt:///dev/rfcomm0              a serial device: a Bluetooth rfcomm binding

Options, also accepted in the URL query: ``left``/``right`` (motor ports, default B and C),
``reverse_left``/``reverse_right`` (a motor mounted backwards), ``wheel_diameter`` and
``track`` (m), ``ultrasonic`` (sensor port 1-4, default 4; blank, 0 or "none": not fitted),
``touch``, ``light``, ``sound`` (ports, none by default), ``floodlight`` (the light sensor's
lamp, default on), ``brake`` (stop by braking, the default, or let the motors coast),
``rate`` (Hz of polling), ``timeout`` (s to wait for a reply), ``keepalive`` (s between
KeepAlive commands), ``max_linear``, ``max_angular``.

nxt-python does the talking: its Brick encodes and decodes every telegram, and its sensor
classes run the ultrasonic sensor's I2C transactions. It is blocking, so every call goes to
one worker thread per robot: only one telegram is on the wire at a time, and the event loop
never waits. For the stream links (a device file, Bluetooth) this module subclasses
nxt-python's own sockets, keeping their framing (a 2-byte little-endian length before each
telegram) and changing how replies are read, because the stock ``recv``:

- waits forever for a brick that went quiet (here: ``timeout``, then the link counts as lost);
- takes whatever one ``read()`` returns, so a reply split across reads is cut short;
- never finds its feet again after a stray byte, which shifts every later length prefix
  (here: the stream is scanned for the header of the reply being waited for, and skipped
  bytes are counted in ``errors``);

and the stock device file is opened without O_NOCTTY, so a daemon could get the serial
device as its controlling terminal and a SIGHUP when it hangs up.

A link's life: KeepAlive (the brick answers with its sleep timeout), firmware version,
device info (name, address), both drive motors off, sensors set up, a first poll; then a
poller reads the motors, sensors and battery ``rate`` times a second and sends a KeepAlive
every ``keepalive`` s. If the link drops, callers get RobotConnectionError while the driver
reconnects with backoff. The NXT has no watchdog for direct commands: its motors keep turning
while the link is down, so each (re)connection first turns them off.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import os
import re
import select
import struct
import termios
import threading
import time
import tty
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any
from urllib.parse import unquote, urlsplit

import nxt.backend.bluetooth
import nxt.backend.devfile
import nxt.brick
import nxt.error
import nxt.locator
import nxt.motor
import nxt.sensor
import nxt.sensor.generic
import nxt.telegram
from nxt.motor import Mode, RegulationMode, RunState

from rhal.base import Robot
from rhal.errors import RobotConnectionError
from rhal.kinematics import advance_pose, compass_heading

#: The NXT motor (53787) turns at about 170 rpm without load at full power on 9 V: what
#: power 100 stands for. Under load it does less, which speed regulation makes up for
#: up to about 80 % power.
MOTOR_RPM = 170.0
WHEEL_DIAMETER = 0.056  # m, the standard 56 x 26 tyre of the NXT sets
TRACK = 0.115  # m, wheel centre to wheel centre on the Education base (TriBot-style)
ULTRASONIC_MAX = 2.54  # m; 255 cm is the sensor's "nothing in reach"
NOTHING_IN_REACH = 255  # cm
START_POSE = (0.0, 0.0, math.pi / 2)  # where the robot is when opened, facing "north"
BATTERY_EVERY = 10  # polls between battery readings: once a second at the default rate
BACKOFF_FIRST, BACKOFF_MAX = 0.2, 5.0  # s between reconnection attempts, doubling
MOTOR_PORTS = {"A": nxt.motor.Port.A, "B": nxt.motor.Port.B, "C": nxt.motor.Port.C}
MAX_TELEGRAM = 64  # bytes: the NXT's largest telegram
#: Length of each reply nxt-python waits for here (type, opcode, status, data).
REPLY_LENGTHS = {
    0x06: 25,  # GetOutputState
    0x07: 16,  # GetInputValues
    0x0B: 5,  # GetBatteryLevel
    0x0D: 7,  # KeepAlive
    0x0E: 4,  # LSGetStatus
    0x0F: 3,  # LSWrite
    0x10: 20,  # LSRead
    0x88: 7,  # GetFirmwareVersion
    0x9B: 33,  # GetDeviceInfo
}
#: Replies that are not what was asked for: a corrupted or misframed telegram. The brick
#: answering with an error status is nxt.error.DirectProtocolError, a subclass.
GARBLED = (nxt.error.ProtocolError, struct.error, ValueError, IndexError)
BT_ADDRESS = re.compile(r"^[0-9A-F]{2}(:[0-9A-F]{2}){5}$")

logger = logging.getLogger(__name__)


class NxtRobot(Robot):
    kind = "nxt"
    quick = False  # every call waits on the brick
    option_help = {
        **Robot.option_help,
        "left": "output port of the left wheel's motor",
        "right": "output port of the right wheel's motor",
        "reverse_left": "the left motor is mounted backwards",
        "reverse_right": "the right motor is mounted backwards",
        "wheel_diameter": "m: 0.056 for the standard NXT wheel",
        "track": "m between the wheels' centres",
        "ultrasonic": "sensor port (1-4) of the ultrasonic sensor; blank: none",
        "touch": "sensor port of a touch sensor (read as the bumper); blank: none",
        "light": "sensor port of a light sensor; blank: none",
        "sound": "sensor port of a sound sensor; blank: none",
        "floodlight": "light the light sensor's lamp (reflected light) or not (ambient)",
        "brake": "stop by braking the motors; off: let them coast",
        "rate": "Hz: how often the motors and sensors are read",
        "timeout": "s to wait for a reply before the link counts as lost",
        "keepalive": "s between KeepAlives, which keep the brick from switching itself off",
    }
    option_choices = {"left": tuple(MOTOR_PORTS), "right": tuple(MOTOR_PORTS)}

    def __init__(
        self,
        url: str = "nxt://",
        *,
        left: str = "B",
        right: str = "C",
        reverse_left: bool = False,
        reverse_right: bool = False,
        wheel_diameter: float = WHEEL_DIAMETER,
        track: float = TRACK,
        ultrasonic: int | None = 4,
        touch: int | None = None,
        light: int | None = None,
        sound: int | None = None,
        floodlight: bool = True,
        brake: bool = True,
        rate: float = 10.0,
        timeout: float = 1.0,
        keepalive: float = 60.0,
        max_linear: float = 0.4,
        max_angular: float = 3.0,
    ) -> None:
        super().__init__(url, max_linear=max_linear, max_angular=max_angular)
        self.link, self.target = parse_url(url)
        self.left, self.right = _motor_port("left", left), _motor_port("right", right)
        if self.left == self.right:
            raise ValueError(f"left and right are both motor port {self.left}; use two ports")
        self.reverse_left = _flag("reverse_left", reverse_left)
        self.reverse_right = _flag("reverse_right", reverse_right)
        self.wheel_diameter = _length("wheel_diameter", wheel_diameter, 0.5)
        self.track = _length("track", track, 2.0)
        ports = {"ultrasonic": ultrasonic, "touch": touch, "light": light, "sound": sound}
        #: sensor kind -> port number 1-4, for the sensors fitted
        self.sensor_ports = {
            kind: port for kind, value in ports.items() if (port := _sensor_port(kind, value))
        }
        by_port: dict[int, str] = {}
        for kind, port in self.sensor_ports.items():
            if port in by_port:
                raise ValueError(f"{by_port[port]} and {kind} are both on sensor port {port}")
            by_port[port] = kind
        self.floodlight = _flag("floodlight", floodlight)
        self.brake = _flag("brake", brake)
        self.rate = _positive("rate", rate)
        self.timeout = _positive("timeout", timeout)
        self.keepalive = _positive("keepalive", keepalive)
        #: m/s of a wheel at power 100
        self.top_speed = MOTOR_RPM / 60.0 * math.pi * self.wheel_diameter
        #: name, Bluetooth address, firmware and protocol versions the brick reported
        self.identity: dict[str, Any] = {}
        self._errors = ErrorCounter()
        self._executor: ThreadPoolExecutor | None = None
        self._session: _Session | None = None
        self._lost = "not connected yet"  # why self._session is None
        self._failure: str | None = None  # a command's write failed: the poller gives up
        self._task: asyncio.Task[None] | None = None
        self._applied = (0.0, 0.0)
        self._reset_readings()

    @property
    def errors(self) -> int:
        """Replies dropped so far: noise skipped, cut-short or garbled telegrams."""
        return self._errors.count

    @property
    def connected(self) -> bool:
        return self._session is not None

    def wheel_powers(self, linear: float, angular: float) -> tuple[int, int, float, float]:
        """(left power, right power, linear, angular) for these speeds.

        Each wheel's speed is its share of ``top_speed`` as an NXT power in -100..100. When
        a wheel would need more than power 100, both are scaled down together, keeping the
        curve, and the speeds returned are the ones the powers stand for before rounding.
        """
        half_turn = angular * self.track / 2.0
        left, right = linear - half_turn, linear + half_turn
        peak = max(abs(left), abs(right))
        if peak > self.top_speed:
            scale = self.top_speed / peak
            left, right, linear, angular = (v * scale for v in (left, right, linear, angular))
        return (
            round(100.0 * left / self.top_speed),
            round(100.0 * right / self.top_speed),
            linear,
            angular,
        )

    # -- motion: drive() returns what the motors can do, not only what the limits allow --

    async def drive(self, linear: float, angular: float) -> dict[str, float]:
        await super().drive(linear, angular)
        applied_linear, applied_angular = self._applied
        return {"linear": applied_linear, "angular": applied_angular}

    # -- hooks -----------------------------------------------------------------------------

    async def _open(self) -> None:
        self._executor = ThreadPoolExecutor(max_workers=1, thread_name_prefix="nxt")
        self._reset_readings()
        try:
            session = await self._connect()
            self._session = session
            await self._poll(session)  # a first set of readings before open() returns
        except BaseException:
            await self._drop_session()
            self._executor.shutdown(wait=False)
            self._executor = None
            raise
        self._task = asyncio.create_task(self._maintain(), name=f"nxt link {self.url}")

    async def _close(self) -> None:
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        session = self._session
        if session is not None:
            # Braked motors hold their position on battery power: leave them off.
            with contextlib.suppress(OSError, *GARBLED):
                await self._call(session.motors_off)
        await self._drop_session()
        self._lost = "closed"
        executor, self._executor = self._executor, None
        if executor is not None:
            executor.shutdown(wait=False)

    async def _drive(self, linear: float, angular: float) -> None:
        left, right, linear, angular = self.wheel_powers(linear, angular)
        if left == 0 and right == 0:
            await self._stop()
            return
        self._applied = (linear, angular)
        await self._command(lambda session: session.run(left, right))

    async def _stop(self) -> None:
        self._applied = (0.0, 0.0)
        try:
            await self._command(lambda session: session.stop(self.brake))
        except RobotConnectionError:
            # While closing, a lost link is no reason to fail; but see "Faults" in the docs:
            # the NXT keeps driving until it is reached again.
            if self.is_open:
                raise

    async def _read_sensors(self) -> dict[str, Any]:
        if self._session is None:
            raise self._lost_error()
        x, y, theta = self._pose
        readings: dict[str, Any] = {
            "position": {"x": x, "y": y, "theta": theta},
            "heading": compass_heading(theta),
            "velocity": dict(self._velocity),
            "wheels": dict(self._wheels),
            "tacho": dict(self._tacho),
        }
        if "ultrasonic" in self.sensor_ports:
            readings["range"] = self._range
        if "touch" in self.sensor_ports:
            readings["touch"] = readings["bumper"] = self._touch
        if "light" in self.sensor_ports:
            readings["light"] = self._light
        if "sound" in self.sensor_ports:
            readings["sound"] = self._sound
        readings["battery"] = self._battery
        readings["errors"] = self.errors
        return readings

    def _sensor_specs(self) -> dict[str, dict[str, Any]]:
        specs: dict[str, dict[str, Any]] = {
            "position": {"unit": {"x": "m", "y": "m", "theta": "rad"}, "source": "odometry"},
            "heading": {"unit": "deg", "source": "odometry"},
            "velocity": {"unit": {"linear": "m/s", "angular": "rad/s"}, "source": "tacho"},
            "wheels": {"unit": {"left": "m/s", "right": "m/s"}, "source": "tacho"},
            "tacho": {"unit": {"left": "deg", "right": "deg"}, "ports": [self.left, self.right]},
        }
        ports = self.sensor_ports
        if "ultrasonic" in ports:
            specs["range"] = {"unit": "m", "max": ULTRASONIC_MAX, "port": ports["ultrasonic"]}
        if "touch" in ports:
            specs["touch"] = {"unit": "bool", "port": ports["touch"]}
            specs["bumper"] = {"unit": "bool", "port": ports["touch"]}
        if "light" in ports:
            specs["light"] = {"unit": "%", "port": ports["light"], "floodlight": self.floodlight}
        if "sound" in ports:
            specs["sound"] = {"unit": "%", "port": ports["sound"], "weighting": "dBA"}
        specs["battery"] = {"unit": "V"}
        specs["errors"] = {"unit": "count"}
        return specs

    # -- the link --------------------------------------------------------------------------

    async def _call(self, function: Callable[..., Any], *args: Any) -> Any:
        """Run a blocking nxt-python call on this robot's one worker thread."""
        if self._executor is None:
            raise RobotConnectionError(f"robot {self.url!r} is closed")
        loop = asyncio.get_running_loop()
        return await loop.run_in_executor(self._executor, function, *args)

    async def _connect(self) -> _Session:
        session = _Session(self)
        try:
            identity = await self._call(session.connect)
        except TimeoutError:
            await self._call(session.close)
            raise RobotConnectionError(
                f"no NXT brick answered at {self.url!r} within {self.timeout:g} s"
            ) from None
        except GARBLED as exc:
            await self._call(session.close)
            raise RobotConnectionError(
                f"the device at {self.url!r} does not answer like an NXT brick: {exc}"
            ) from exc
        except BaseException:
            await self._call(session.close)
            raise
        self.identity = identity
        self._odometry_base = None  # counts go on from wherever they were
        return session

    async def _drop_session(self) -> None:
        session, self._session = self._session, None
        if session is not None and self._executor is not None:
            await self._call(session.close)

    async def _maintain(self) -> None:
        """Poll until the link fails, then reconnect with backoff; until cancelled."""
        while True:
            session = self._session
            assert session is not None
            reason = await self._serve(session)
            self._lost = reason
            await self._drop_session()
            self._session = await self._reconnect()

    async def _serve(self, session: _Session) -> str:
        """Poll and keep the brick awake until the link fails; return why it did."""
        period = 1.0 / self.rate
        keepalive_due = time.monotonic() + self.keepalive
        self._failure = None
        while True:
            started = time.monotonic()
            try:
                await self._poll(session)
                if started >= keepalive_due:
                    await self._guarded(session.keep_alive)
                    keepalive_due = started + self.keepalive
            except OSError as exc:
                return _reason(exc)
            except Exception as exc:  # a bug here must not leave stale readings for ever
                logger.exception("polling the NXT at %s failed", self.url)
                return f"unexpected {type(exc).__name__}: {exc}"
            if self._failure is not None:
                return self._failure
            await asyncio.sleep(max(0.0, started + period - time.monotonic()))

    async def _reconnect(self) -> _Session:
        delay = BACKOFF_FIRST
        while True:
            await asyncio.sleep(delay)
            try:
                return await self._connect()
            except (OSError, RobotConnectionError) as exc:
                self._lost = f"reconnecting failed: {_reason(exc)}"
                delay = min(2 * delay, BACKOFF_MAX)

    async def _command(self, action: Callable[[_Session], None]) -> None:
        session = self._session
        if session is None:
            raise self._lost_error()
        try:
            await self._call(action, session)
        except OSError as exc:
            self._failure = _reason(exc)
            raise RobotConnectionError(f"lost the link to {self.url!r}: {_reason(exc)}") from exc

    async def _guarded(self, function: Callable[[], Any]) -> Any:
        """A reply's value, or None when it came garbled (counted; the link goes on)."""
        try:
            return await self._call(function)
        except GARBLED:
            self._errors.add()
            return None

    def _lost_error(self) -> RobotConnectionError:
        return RobotConnectionError(
            f"no link to the nxt robot at {self.url!r} ({self._lost}); reconnecting"
        )

    # -- readings --------------------------------------------------------------------------

    def _reset_readings(self) -> None:
        self._pose = START_POSE
        self._odometry_base: tuple[int, int, float] | None = None
        self._velocity = {"linear": 0.0, "angular": 0.0}
        self._wheels = {"left": 0.0, "right": 0.0}
        self._tacho = {"left": 0, "right": 0}
        self._range: float | None = None
        self._touch: bool | None = None
        self._light: int | None = None
        self._sound: int | None = None
        self._battery: float | None = None
        self._polls = 0

    async def _poll(self, session: _Session) -> None:
        """Read everything once; one telegram (or I2C transaction) per worker job, so a
        stop() waits behind one reply at most, not a whole poll."""
        left = await self._guarded(lambda: session.rotation(self.left))
        right = await self._guarded(lambda: session.rotation(self.right))
        if left is not None and right is not None:
            self._update_odometry(left, right, time.monotonic())
        ports = self.sensor_ports
        if "ultrasonic" in ports:
            centimetres = await self._guarded(session.distance)
            if centimetres is not None:
                self._range = None if centimetres < 0 else _metres(centimetres)
        if "touch" in ports:
            value = await self._guarded(lambda: session.analog("touch"))
            if value is not None:
                self._touch = bool(value)
        for kind in ("light", "sound"):
            if kind in ports:
                value = await self._guarded(lambda kind=kind: session.analog(kind))
                if value is not None:
                    setattr(self, f"_{kind}", value)
        if self._polls % BATTERY_EVERY == 0 or self._battery is None:
            millivolts = await self._guarded(session.battery)
            if millivolts is not None:
                self._battery = millivolts / 1000.0
        self._polls += 1

    def _update_odometry(self, left: int, right: int, now: float) -> None:
        left = -left if self.reverse_left else left
        right = -right if self.reverse_right else right
        self._tacho = {"left": left, "right": right}
        base, self._odometry_base = self._odometry_base, (left, right, now)
        if base is None:
            return  # a fresh link: counts are measured from here
        metres_per_degree = math.pi * self.wheel_diameter / 360.0
        dl = (left - base[0]) * metres_per_degree
        dr = (right - base[1]) * metres_per_degree
        distance, turn = (dl + dr) / 2.0, (dr - dl) / self.track
        self._pose = advance_pose(*self._pose, distance, turn, 1.0)
        dt = now - base[2]
        if dt > 0:
            self._velocity = {"linear": distance / dt, "angular": turn / dt}
            self._wheels = {"left": dl / dt, "right": dr / dt}


class _Session:
    """One connection to a brick: every blocking nxt-python call, run on the worker thread."""

    def __init__(self, robot: NxtRobot) -> None:
        self.robot = robot
        self.brick: nxt.brick.Brick | None = None
        self.sensors: dict[str, Any] = {}

    def connect(self) -> dict[str, Any]:
        robot = self.robot
        self.brick = _open_brick(robot)
        brick = self.brick
        sleep_ms = brick.keep_alive()
        (prot_major, prot_minor), (fw_major, fw_minor) = brick.get_firmware_version()
        name, address, _, _ = brick.get_device_info()
        self.motors_off()  # the NXT keeps running what it was last told, even without us
        ports = robot.sensor_ports
        generic = nxt.sensor.generic
        if "ultrasonic" in ports:
            port = _input(ports["ultrasonic"])
            self.sensors["ultrasonic"] = generic.Ultrasonic(brick, port, check_compatible=False)
        if "touch" in ports:
            self.sensors["touch"] = generic.Touch(brick, _input(ports["touch"]))
        if "light" in ports:
            light = generic.Light(brick, _input(ports["light"]), illuminated=robot.floodlight)
            lamp = "LIGHT_ACTIVE" if robot.floodlight else "LIGHT_INACTIVE"
            # Percent (0 dark .. 100 bright) rather than nxt-python's raw 0..1023.
            light.set_input_mode(nxt.sensor.Type[lamp], nxt.sensor.Mode.PERCENT)
            self.sensors["light"] = light
        if "sound" in ports:
            sound = generic.Sound(brick, _input(ports["sound"]), adjusted=True)
            sound.set_input_mode(nxt.sensor.Type.SOUND_DBA, nxt.sensor.Mode.PERCENT)
            self.sensors["sound"] = sound
        return {
            "name": name,
            "address": address,
            "firmware": f"{fw_major}.{fw_minor}",
            "protocol": f"{prot_major}.{prot_minor}",
            "sleep_timeout_ms": sleep_ms,
        }

    def close(self) -> None:
        brick, self.brick = self.brick, None
        if brick is not None:
            with contextlib.suppress(OSError):
                brick.close()

    def _brick(self) -> nxt.brick.Brick:
        if self.brick is None:
            raise ConnectionResetError("the link is closed")
        return self.brick

    # -- motors ----------------------------------------------------------------------------

    def run(self, left: int, right: int) -> None:
        robot = self.robot
        for port, power, reverse in (
            (robot.left, left, robot.reverse_left),
            (robot.right, right, robot.reverse_right),
        ):
            self._brick().set_output_state(
                MOTOR_PORTS[port],
                -power if reverse else power,
                Mode.ON | Mode.REGULATED,
                RegulationMode.SPEED,
                0,
                RunState.RUNNING,
                nxt.motor.LIMIT_RUN_FOREVER,
            )

    def stop(self, brake: bool) -> None:
        """The stop command: power 0, motors on, braked (or floating), on both motors."""
        if brake:
            mode, regulation = Mode.ON | Mode.BRAKE | Mode.REGULATED, RegulationMode.SPEED
        else:
            mode, regulation = Mode.ON, RegulationMode.IDLE
        for port in (self.robot.left, self.robot.right):
            self._brick().set_output_state(
                MOTOR_PORTS[port], 0, mode, regulation, 0, RunState.RUNNING, 0
            )

    def motors_off(self) -> None:
        """Both drive motors off (not powered, not braked), as when the brick starts."""
        for port in (self.robot.left, self.robot.right):
            self._brick().set_output_state(
                MOTOR_PORTS[port], 0, Mode.IDLE, RegulationMode.IDLE, 0, RunState.IDLE, 0
            )

    def rotation(self, port: str) -> int:
        """The motor's rotation count: degrees since the brick started its program."""
        state = self._brick().get_output_state(MOTOR_PORTS[port])
        if state[0] != MOTOR_PORTS[port]:
            raise nxt.error.ProtocolError(f"asked for motor {port}, got {state[0].name}")
        return state[9]

    # -- sensors ---------------------------------------------------------------------------

    def distance(self) -> int:
        """Centimetres to the nearest echo; 255 when nothing is in reach; -1 on I2C errors."""
        try:
            return self.sensors["ultrasonic"].get_distance()
        except nxt.error.DirectProtocolError:  # the sensor did not answer on the I2C bus
            return -1

    def analog(self, kind: str) -> int | None:
        """The scaled value (bool, percent) of an analog sensor, None until it is valid."""
        sensor = self.sensors[kind]
        values = sensor.get_input_values()
        if values.port != sensor._port:
            raise nxt.error.ProtocolError(f"asked for sensor {sensor._port}, got {values.port}")
        return values.scaled_value if values.valid else None

    def battery(self) -> int:
        return self._brick().get_battery_level()

    def keep_alive(self) -> int:
        return self._brick().keep_alive()


# -- links: nxt-python's sockets, reading replies with a timeout and resynchronising ------


class ErrorCounter:
    """Replies dropped, counted on the worker thread and on the event loop."""

    def __init__(self) -> None:
        self.count = 0
        self._lock = threading.Lock()

    def add(self) -> None:
        with self._lock:
            self.count += 1


class ReplyScanner:
    """Cuts replies out of a stream of length-prefixed telegrams, skipping anything else.

    A reply starts with its length (3..64, little-endian, so the high byte is 0), then type
    0x02 and the opcode of the command it answers, then a status nxt-python knows; its
    length is the one that opcode's reply has (or shorter, with an error status). Bytes
    before such a header are noise: skipped, and each run of them counted once.
    """

    def __init__(self) -> None:
        self.buffer = bytearray()
        self.skipped = 0  # runs of bytes dropped

    def feed(self, data: bytes) -> None:
        self.buffer += data

    def take(self, opcode: int) -> bytes | None:
        """The next reply to ``opcode`` (without its length prefix), or None for now."""
        buffer = self.buffer
        start = _find_header(buffer, opcode)
        if start is None:
            # No whole header yet: keep only a tail that could still grow into one.
            start = len(buffer)
            for tail in range(max(0, len(buffer) - 4), len(buffer)):
                if _could_start(buffer[tail:], opcode):
                    start = tail
                    break
        if start:
            del buffer[:start]
            self.skipped += 1
        if len(buffer) < 5 or len(buffer) < 2 + buffer[0]:
            return None
        size = buffer[0]
        reply = bytes(buffer[2 : 2 + size])
        del buffer[: 2 + size]
        return reply


def _find_header(buffer: bytearray, opcode: int) -> int | None:
    for start in range(len(buffer) - 4):
        if _is_header(buffer[start : start + 5], opcode):
            return start
    return None


def _is_header(head: bytes | bytearray, opcode: int) -> bool:
    size, high, kind, code, status = head
    if high != 0 or kind != 0x02 or code != opcode or status not in nxt.telegram.CODES:
        return False
    expected = REPLY_LENGTHS.get(opcode, MAX_TELEGRAM)
    if status == 0 and opcode in REPLY_LENGTHS:
        return size == expected
    return 3 <= size <= expected


def _could_start(tail: bytes | bytearray, opcode: int) -> bool:
    """Whether ``tail`` (under 5 bytes) can still grow into a header."""
    pattern = (None, 0, 0x02, opcode)
    if tail and not 3 <= tail[0] <= MAX_TELEGRAM:
        return False
    return all(want is None or got == want for got, want in zip(tail, pattern, strict=False))


class ScanningReader:
    """``recv`` for a stream link: waits ``timeout`` at most and resynchronises on noise.

    Mixed into nxt-python's socket classes, whose ``send`` frames each telegram.
    """

    timeout: float
    errors: ErrorCounter
    _scanner: ReplyScanner
    _expect: int | None = None

    def _reader_init(self, timeout: float, errors: ErrorCounter) -> None:
        self.timeout, self.errors = timeout, errors
        self._scanner = ReplyScanner()

    def _before_sending(self, data: bytes) -> None:
        # The brick only speaks when spoken to: whatever came in since the last reply is
        # stale (a reply that came too late) or noise. Drop it, so it cannot pass for the
        # reply to this command.
        stale = bool(self._scanner.buffer)
        self._scanner.buffer.clear()
        while self._read_some(0):
            stale = True
        if stale:
            self.errors.add()
        # Telegram type bit 7 set: no reply wanted. Otherwise byte 1 is the opcode.
        self._expect = None if data[0] & 0x80 else data[1]

    def _read_some(self, timeout: float) -> bytes | None:
        """What has arrived, b"" at end of stream, None if nothing came within timeout."""
        raise NotImplementedError

    def recv(self) -> bytes:
        deadline = time.monotonic() + self.timeout
        scanner, opcode = self._scanner, self._expect
        if opcode is None:
            raise nxt.error.ProtocolError("waiting for a reply to nothing")
        while True:
            before = scanner.skipped
            reply = scanner.take(opcode)
            if scanner.skipped != before:
                self.errors.add()
            if reply is not None:
                self._expect = None
                return reply
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"no reply from the brick within {self.timeout:g} s")
            data = self._read_some(remaining)
            if data == b"":
                raise ConnectionResetError("the brick closed the link")
            if data:
                scanner.feed(data)


class DevFileLink(ScanningReader, nxt.backend.devfile.DevFileSock):
    """nxt-python's device-file socket (``/dev/rfcomm0``), opened O_NOCTTY."""

    def __init__(self, filename: str, timeout: float, errors: ErrorCounter) -> None:
        super().__init__(filename)
        self._device = None
        self._reader_init(timeout, errors)

    def connect(self) -> nxt.brick.Brick:
        fd = os.open(self._filename, os.O_RDWR | os.O_NOCTTY | os.O_CLOEXEC)
        try:
            self._device = open(fd, "r+b", buffering=0)  # noqa: SIM115 - closed by close()
        except BaseException:
            os.close(fd)
            raise
        try:
            tty.setraw(fd)
            termios.tcflush(fd, termios.TCIOFLUSH)  # nothing stale from an earlier session
        except termios.error:
            pass  # not a terminal (a FIFO, a socket file): nothing to set
        return nxt.brick.Brick(self)

    def send(self, data: bytes) -> None:
        if self._device is None:
            raise ConnectionResetError("the link is closed")
        self._before_sending(data)
        super().send(data)

    def _read_some(self, timeout: float) -> bytes | None:
        if self._device is None:
            raise ConnectionResetError("the link is closed")
        readable, _, _ = select.select([self._device], [], [], timeout)
        if not readable:
            return None
        return os.read(self._device.fileno(), 4096)


class BluetoothLink(ScanningReader, nxt.backend.bluetooth.BluetoothSock):
    """nxt-python's Bluetooth (RFCOMM) socket, through PyBluez."""

    def __init__(self, bluetooth: Any, host: str, timeout: float, errors: ErrorCounter) -> None:
        super().__init__(bluetooth, host)
        self._reader_init(timeout, errors)

    def send(self, data: bytes) -> None:
        if self._sock is None:
            raise ConnectionResetError("the link is closed")
        self._before_sending(data)
        super().send(data)

    def _read_some(self, timeout: float) -> bytes | None:
        if self._sock is None:
            raise ConnectionResetError("the link is closed")
        self._sock.settimeout(timeout)  # 0: non-blocking
        try:
            return self._sock.recv(4096)
        except (TimeoutError, BlockingIOError):  # TimeoutError is socket.timeout
            return None


def _open_brick(robot: NxtRobot) -> nxt.brick.Brick:
    """Connect the link the URL names; blocking, on the worker thread."""
    if robot.link == "dev":
        return DevFileLink(robot.target, robot.timeout, robot._errors).connect()
    if robot.link == "bt":
        try:
            import bluetooth  # PyBluez; its BluetoothError is an OSError
        except ImportError as exc:
            raise RobotConnectionError(
                "Bluetooth by address needs PyBluez (pip install pybluez), which is not "
                "installed; or bind the brick to a serial device (sudo rfcomm bind 0 "
                f"{robot.target}) and use nxt:///dev/rfcomm0"
            ) from exc
        return BluetoothLink(bluetooth, robot.target, robot.timeout, robot._errors).connect()
    filters = {"name": robot.target} if robot.target else {}
    if robot.target and BT_ADDRESS.match(robot.target):
        filters = {"host": robot.target}
    try:
        return nxt.locator.find(backends=["usb"], config=None, **filters)
    except ImportError as exc:
        raise RobotConnectionError(f"NXT over USB needs pyusb: {exc}") from exc
    except nxt.locator.BrickNotFoundError:
        which = f" matching {robot.target!r}" if robot.target else ""
        raise RobotConnectionError(f"no NXT brick{which} found on USB") from None
    except ValueError as exc:
        if type(exc).__name__ != "NoBackendError":  # pyusb's: no libusb
            raise
        raise RobotConnectionError(
            f"NXT over USB needs libusb (e.g. apt install libusb-1.0-0): {exc}"
        ) from exc


def parse_url(url: str) -> tuple[str, str | None]:
    """``("usb", name or address or None)``, ``("bt", address)`` or ``("dev", path)``."""
    parts = urlsplit(url)
    if parts.scheme.lower() != "nxt":
        raise ValueError(f"not an nxt URL: {url!r}")
    where, path = parts.netloc.lower(), unquote(parts.path)
    if not where:
        return ("dev", path) if path.strip("/") else ("usb", None)
    target = path.strip("/")
    if where == "usb":
        return "usb", _address(target) or target or None
    if where in ("bt", "bluetooth"):
        address = _address(target)
        if address is None:
            raise ValueError(
                f"nxt://bt/ needs the brick's Bluetooth address, like "
                f"nxt://bt/00:16:53:01:02:03, not {target!r}"
            )
        return "bt", address
    raise ValueError(
        f"unknown NXT link {parts.netloc!r} in {url!r}; use nxt://, nxt://usb/NAME, "
        "nxt://bt/00:16:53:01:02:03 or nxt:///dev/rfcomm0"
    )


def _address(text: str) -> str | None:
    """``00:16:53:01:02:03`` for that or ``001653010203`` (the NXT's USB serial number)."""
    digits = text.upper().replace(":", "")
    if len(digits) != 12 or not all(c in "0123456789ABCDEF" for c in digits):
        return None
    address = ":".join(digits[i : i + 2] for i in range(0, 12, 2))
    return address if BT_ADDRESS.match(text.upper()) or ":" not in text else None


def _reason(exc: BaseException) -> str:
    return str(exc) or type(exc).__name__


def _metres(centimetres: int) -> float | None:
    return None if centimetres >= NOTHING_IN_REACH else centimetres / 100.0


def _input(port: int) -> nxt.sensor.Port:
    return nxt.sensor.Port(port - 1)


def _motor_port(name: str, value: Any) -> str:
    port = value.upper() if isinstance(value, str) else value
    if port not in MOTOR_PORTS:
        raise ValueError(f"{name} must be a motor port, A, B or C; got {value!r}")
    return port


def _sensor_port(name: str, value: Any) -> int | None:
    """Port 1-4, or None for a sensor not fitted (None, blank, 0, "none", "off", false)."""
    if isinstance(value, str):
        text = value.strip().lower()
        if text in ("", "none", "off", "no"):
            return None
        value = int(text) if text.isdigit() else value
    if value is None or value is False or value == 0:
        return None
    if isinstance(value, bool) or value not in (1, 2, 3, 4):
        raise ValueError(f"{name} must be a sensor port, 1 to 4, or blank for none; got {value!r}")
    return int(value)


def _flag(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return value


def _positive(name: str, value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
        raise ValueError(f"{name} must be a number greater than 0, got {value!r}")
    if not math.isfinite(value):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return float(value)


def _length(name: str, value: Any, most: float) -> float:
    metres = _positive(name, value)
    if metres > most:
        raise ValueError(f"{name} is in metres (at most {most:g}), got {value!r}")
    return metres
