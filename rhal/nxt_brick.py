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
import struct
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from typing import Any

import nxt.error
import nxt.sensor

from rhal.base import Robot
from rhal.errors import RobotConnectionError
from rhal.kinematics import advance_pose, compass_heading
from rhal.linked import LinkKeeper
from rhal.nxt_links import BluetoothLink as BluetoothLink
from rhal.nxt_links import DevFileLink as DevFileLink
from rhal.nxt_links import ErrorCounter, parse_url
from rhal.nxt_links import ReplyScanner as ReplyScanner
from rhal.nxt_session import MOTOR_PORTS, _Session

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
#: answering with an error status is nxt.error.DirectProtocolError, a subclass.
GARBLED = (nxt.error.ProtocolError, struct.error, ValueError, IndexError)

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
        self._keeper: LinkKeeper[_Session] = LinkKeeper(
            f"the nxt robot at {url!r}",
            connect=self._connect,
            serve=self._serve,
            halt=self._halt,
            drop=self._drop_session,
            reason=_reason,
        )
        self._failure: str | None = None  # a command's write failed: the poller gives up
        self._applied = (0.0, 0.0)
        self._reset_readings()

    @property
    def errors(self) -> int:
        """Replies dropped so far: noise skipped, cut-short or garbled telegrams."""
        return self._errors.count

    @property
    def connected(self) -> bool:
        return self._keeper.connected

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
            await self._keeper.open()
        except BaseException:
            self._executor.shutdown(wait=False)
            self._executor = None
            raise

    async def _close(self) -> None:
        await self._keeper.close(goodbye=self._motors_off)
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
        self._keeper.require()
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
        session = await self._start_session()
        try:
            await self._poll(session)  # a first set of readings before the link counts as up
        except BaseException:
            await self._call(session.close)
            raise
        return session

    async def _start_session(self) -> _Session:
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

    async def _drop_session(self, session: _Session) -> None:
        if self._executor is not None:
            await self._call(session.close)

    async def _halt(self, session: _Session) -> None:
        self._applied = (0.0, 0.0)
        with contextlib.suppress(*GARBLED):
            await self._call(session.stop, self.brake)

    async def _motors_off(self, session: _Session) -> None:
        # Braked motors hold their position on battery power: leave them off.
        with contextlib.suppress(*GARBLED):
            await self._call(session.motors_off)

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

    async def _command(self, action: Callable[[_Session], None]) -> None:
        session = self._keeper.require()
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


def _reason(exc: BaseException) -> str:
    return str(exc) or type(exc).__name__


def _metres(centimetres: int) -> float | None:
    return None if centimetres >= NOTHING_IN_REACH else centimetres / 100.0


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
