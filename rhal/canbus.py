"""CAN-bus robot bases, for ``can://`` URLs, through python-can, canopen and cantools.

    can://                                             socketcan/can0, two CiA 402 drives (default)
    can://socketcan/can0?profile=cia402&left=1&right=2
    can://slcan/dev/ttyACM0?bitrate=500000             a serial-line (SLCAN) USB adapter
    can://virtual/robot0                               python-can's in-process bus (tests)
    can://socketcan/can0?profile=dbc&dbc=/etc/robot/base.dbc&speed=BaseCommand.LinearSpeed

The URL's host is python-can's interface name and the rest of the path its channel; the
channel of a serial adapter keeps its leading slash when it is a path (``/dev/ttyACM0``).

Profiles:

``cia402``
    Two CiA 402 servo drives, one per wheel (node ids ``left`` and ``right``), driven in profile
    velocity mode through canopen's :class:`~canopen.BaseNode402`. At start-up the driver puts
    both in PRE-OPERATIONAL, checks they are CiA 402 devices, sets their heartbeat, maps its PDOs
    (RPDO1: controlword + target velocity; TPDO1: statusword + mode display; TPDO2: position
    actual + velocity actual, sent on every SYNC the driver produces), selects mode 3, starts
    them (NMT OPERATIONAL) and walks the 402 state machine to OPERATION ENABLED. A drive whose
    heartbeat stops or that leaves OPERATIONAL is a lost link: the driver starts over with
    backoff. A drive in FAULT is reported and refuses motion until the robot is opened again.

``dbc``
    A base described by a DBC file: a command message whose speed and turn-rate signals the
    driver encodes with cantools, and feedback messages it decodes. Commands are repeated at
    ``rate`` Hz while the base should move, for bases with a command timeout.

Threads: python-can reads the bus in a Notifier thread (canopen's Network runs its own); every
frame crosses into the event loop with ``loop.call_soon_threadsafe`` and the driver's state is
changed only there. Blocking calls (SDO transfers, NMT, sends, opening and shutting the bus) run
through ``asyncio.to_thread``, one at a time per robot.
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import inspect
import math
import time
from collections.abc import Callable
from functools import partial
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlsplit

import can
import canopen
import cantools
from canopen.emcy import EmcyError
from canopen.network import MessageListener
from canopen.nmt import NMT_STATES
from canopen.profiles.p402 import State402

from rhal.base import Robot
from rhal.errors import RobotConnectionError
from rhal.kinematics import advance_pose, compass_heading

PROFILE_DIR = Path(__file__).with_name("can_profiles")
CIA402_EDS = PROFILE_DIR / "cia402_drive.eds"
EXAMPLE_DBC = PROFILE_DIR / "example_base.dbc"

DEFAULT_INTERFACE, DEFAULT_CHANNEL = "socketcan", "can0"
#: Interfaces whose channel is a serial port: their channel may be an absolute path.
SERIAL_INTERFACES = frozenset({"slcan", "serial", "robotell", "seeedstudio"})
TICK = 0.05  # s between checks of the link
NOTIFIER_CYCLE = 0.05  # s a Notifier thread waits for a frame: bounds how long closing takes
SEND_TIMEOUT = 0.2  # s a send may wait for room in the interface's queue
BACKOFF_FIRST, BACKOFF_MAX = 0.2, 5.0  # s between reconnection attempts, doubling

SIDES = ("left", "right")
PROFILED_VELOCITY = 3  # 0x6060 modes of operation
CW_ENABLE = 0x000F  # controlword: enable operation
CW_HALT = 0x0100  # controlword bit 8: halt
CW_SHUTDOWN = 0x0006  # controlword: shutdown, to READY TO SWITCH ON (power stage off)
NMT_OPERATIONAL = 5
INT32 = 1 << 32
#: Objects the cia402 profile reads or writes; its EDS must have all of them.
CIA402_OBJECTS = {
    0x1000: "device type",
    0x1017: "producer heartbeat time",
    0x1400: "RPDO1 communication",
    0x1600: "RPDO1 mapping",
    0x1800: "TPDO1 communication",
    0x1801: "TPDO2 communication",
    0x1A00: "TPDO1 mapping",
    0x1A01: "TPDO2 mapping",
    0x603F: "error code",
    0x6040: "controlword",
    0x6041: "statusword",
    0x6060: "modes of operation",
    0x6061: "modes of operation display",
    0x6064: "position actual value",
    0x606C: "velocity actual value",
    0x60FF: "target velocity",
}
#: The PDOs the driver maps: (TPDO or RPDO, number) -> objects. TPDOs go on every SYNC, the
#: RPDO at once; the drives' other predefined PDOs are switched off.
PDO_LAYOUT = {
    ("rpdo", 1): (0x6040, 0x60FF),
    ("tpdo", 1): (0x6041, 0x6061),
    ("tpdo", 2): (0x6064, 0x606C),
}

#: Units the dbc profile understands for each mapped signal -> factor to its reading's unit.
#: An empty unit means the reading's own unit.
UNITS: dict[str, dict[str, float]] = {
    "speed": {"": 1.0, "m/s": 1.0, "cm/s": 0.01, "mm/s": 0.001, "km/h": 1 / 3.6},
    "turn": {"": 1.0, "rad/s": 1.0, "mrad/s": 0.001, "deg/s": math.pi / 180, "°/s": math.pi / 180},
    "heading": {"": 1.0, "deg": 1.0, "°": 1.0, "rad": 180 / math.pi},
    "battery": {"": 1.0, "V": 1.0, "mV": 0.001},
    "range": {"": 1.0, "m": 1.0, "cm": 0.01, "mm": 0.001},
}
UNITS["feedback_speed"], UNITS["feedback_turn"] = UNITS["speed"], UNITS["turn"]


class CanRobot(Robot):
    kind = "can"
    quick = False  # every call waits on the bus
    option_help = {
        **Robot.option_help,
        "profile": "cia402: two CiA 402 wheel drives; dbc: a base described by a DBC file",
        "bitrate": "bit/s, for interfaces that set it (slcan, pcan...); socketcan's is set "
        "with ip link",
        "timeout": "s of silence (no heartbeat / no feedback frame) before the link counts as "
        "lost; blank: 0.5 for cia402, 1 for dbc",
        "left": "cia402: node id of the left wheel's drive",
        "right": "cia402: node id of the right wheel's drive",
        "eds": "cia402: the drives' EDS file (blank: the generic CiA 402 one shipped)",
        "track": "cia402: m between the wheels' contact points",
        "wheel_diameter": "cia402: m",
        "counts_per_rev": "cia402: position counts (0x6064) per wheel turn, gearbox included",
        "counts_per_metre": "cia402: position counts per metre of travel (blank: from "
        "counts_per_rev and wheel_diameter)",
        "velocity_per_mps": "cia402: units of 0x60FF/0x606C per m/s (blank: counts_per_metre, "
        "for drives whose velocity is in counts/s)",
        "invert_left": "cia402: the left drive turns the wheel backwards for a positive speed",
        "invert_right": "cia402: the right drive turns the wheel backwards for a positive speed "
        "(usual: it is mounted mirrored)",
        "heartbeat": "cia402: s between the drives' heartbeats (0x1017)",
        "sync": "cia402: s between the SYNCs the driver sends; the drives answer each with "
        "their TPDOs",
        "dbc": "dbc: the base's DBC file (blank: the example base shipped)",
        "command": "dbc: the message the driver sends",
        "speed": "dbc: Message.Signal for the forward speed the driver sends",
        "turn": "dbc: Message.Signal for the turn rate (counter-clockwise) the driver sends",
        "feedback_speed": "dbc: Message.Signal of the measured forward speed",
        "feedback_turn": "dbc: Message.Signal of the measured turn rate",
        "heading": "dbc: Message.Signal of a compass heading, degrees (blank: none)",
        "battery": "dbc: Message.Signal of the battery voltage (blank: none)",
        "range": "dbc: Message.Signal of the distance ahead (blank: none)",
        "rate": "dbc: Hz at which a command is repeated while moving (0: sent once)",
    }
    option_choices = {"profile": ("cia402", "dbc")}

    def __init__(
        self,
        url: str = "can://",
        *,
        profile: str = "cia402",
        bitrate: int | None = 500000,
        timeout: float | None = None,
        # cia402
        left: int = 1,
        right: int = 2,
        eds: str | None = None,
        track: float = 0.4,
        wheel_diameter: float = 0.2,
        counts_per_rev: float = 4096,
        counts_per_metre: float | None = None,
        velocity_per_mps: float | None = None,
        invert_left: bool = False,
        invert_right: bool = True,
        heartbeat: float = 0.1,
        sync: float = 0.05,
        # dbc
        dbc: str | None = None,
        command: str = "BaseCommand",
        speed: str = "BaseCommand.LinearSpeed",
        turn: str = "BaseCommand.TurnRate",
        feedback_speed: str = "BaseFeedback.Speed",
        feedback_turn: str = "BaseFeedback.TurnRate",
        heading: str = "",
        battery: str = "",
        range: str = "",  # the option's documented name, though a builtin's
        rate: float = 20.0,
        max_linear: float = 0.5,
        max_angular: float = 2.0,
    ) -> None:
        super().__init__(url, max_linear=max_linear, max_angular=max_angular)
        self.interface, self.channel = parse_url(url)
        if bitrate is not None:
            bitrate = _positive(int, "bitrate", bitrate)
        self.bitrate = bitrate
        given = dict(locals())
        profiles: dict[str, type[_Profile]] = {"cia402": _Cia402, "dbc": _Dbc}
        if profile not in profiles:
            raise ValueError(f"unknown CAN profile {profile!r}; use one of: {', '.join(profiles)}")
        self.profile = profile
        defaults = {
            name: parameter.default
            for name, parameter in inspect.signature(CanRobot.__init__).parameters.items()
        }
        mine = profiles[profile].options
        for other, cls in profiles.items():
            for name in cls.options:
                value = given[name]
                if other != profile and name not in mine and value not in (None, defaults[name]):
                    raise ValueError(
                        f"{name} is an option of the {other} profile; this robot's profile "
                        f"is {profile}"
                    )
        self._profile: _Profile = profiles[profile](
            self, timeout=timeout, **{name: given[name] for name in mine}
        )

    @property
    def errors(self) -> int:
        """Frames dropped so far: error frames, wrong lengths, frames that did not decode."""
        return self._profile.errors

    @property
    def connected(self) -> bool:
        return self._profile.link is not None

    @property
    def timeout(self) -> float:
        return self._profile.timeout

    # -- hooks -----------------------------------------------------------------------------

    async def _open(self) -> None:
        await self._profile.open()

    async def _close(self) -> None:
        await self._profile.close()

    async def _drive(self, linear: float, angular: float) -> None:
        await self._profile.drive(linear, angular)

    async def _stop(self) -> None:
        try:
            await self._profile.stop()
        except RobotConnectionError:
            # While closing, a lost link is no reason to fail: the drives' own watchdogs act.
            if self.is_open:
                raise

    async def _read_sensors(self) -> dict[str, Any]:
        return self._profile.readings()

    def _sensor_specs(self) -> dict[str, dict[str, Any]]:
        return self._profile.sensor_specs()

    def make_bus(self) -> can.BusABC:
        """Open the bus (blocking: called in a worker thread)."""
        config: dict[str, Any] = {"interface": self.interface, "channel": self.channel}
        if self.bitrate is not None:
            config["bitrate"] = self.bitrate
        try:
            return can.Bus(**config)
        except (can.CanError, OSError, ValueError) as exc:
            raise RobotConnectionError(
                f"cannot open the CAN bus {self.interface}:{self.channel}: {exc}"
            ) from exc


def parse_url(url: str) -> tuple[str, str | None]:
    """``can://<interface>/<channel>`` -> (python-can interface, channel)."""
    parts = urlsplit(url)
    if parts.scheme.lower() != "can":
        raise ValueError(f"not a CAN URL: {url!r}; use can://<interface>/<channel>")
    interface = parts.netloc.lower() or DEFAULT_INTERFACE
    if interface not in can.VALID_INTERFACES:
        known = ", ".join(sorted(can.VALID_INTERFACES))
        raise ValueError(f"unknown python-can interface {interface!r} in {url!r}; known: {known}")
    path = unquote(parts.path)
    channel = path[1:]
    if interface in SERIAL_INTERFACES and "/" in channel:
        channel = path  # can://slcan/dev/ttyACM0 -> /dev/ttyACM0; can://slcan/COM3 -> COM3
    if not channel:
        return interface, DEFAULT_CHANNEL if interface == DEFAULT_INTERFACE else None
    return interface, channel


# -- what both profiles share ------------------------------------------------------------------


class _Profile:
    """A link's life: connect, watch, drop, reconnect with backoff; one blocking call at a time."""

    name = ""
    default_timeout = 1.0
    options: tuple[str, ...] = ()  # the CanRobot options this profile takes
    tick = TICK  # s between looks at the link

    def __init__(self, robot: CanRobot, timeout: float | None) -> None:
        self.robot = robot
        self.url = robot.url
        self.timeout = _positive(
            float, "timeout", self.default_timeout if timeout is None else timeout
        )
        self.errors = 0
        self.link: Any = None
        self._pending: Any = None  # the link being brought up, so close() can abort it
        self._lost = "not connected yet"  # why self.link is None
        self._task: asyncio.Task[None] | None = None
        self._io = asyncio.Lock()

    async def call(self, function: Callable[..., Any], *args: Any) -> Any:
        """Run a blocking library call in a worker thread, one at a time."""
        async with self._io:
            work = asyncio.ensure_future(asyncio.to_thread(function, *args))
            try:
                return await asyncio.shield(work)
            except asyncio.CancelledError:
                # A thread cannot be stopped: let it finish before the next call starts.
                await asyncio.wait({work})
                raise

    async def open(self) -> None:
        self._io = asyncio.Lock()  # in this event loop
        self._reset()
        self.link = await self._connect()
        self._task = asyncio.create_task(self._maintain(), name=f"CAN link {self.url}")

    async def close(self) -> None:
        if self._pending is not None:
            self._pending.aborted = True
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        link, self.link = self.link, None
        self._lost = "closed"
        if link is not None:
            await self.call(link.goodbye)

    def require_link(self) -> Any:
        if self.link is None:
            raise self.lost_error()
        return self.link

    def lost_error(self) -> RobotConnectionError:
        return RobotConnectionError(
            f"no link to the CAN base at {self.url!r} ({self._lost}); reconnecting"
        )

    async def _connect(self) -> Any:
        link = self._new_link(asyncio.get_running_loop())
        self._pending = link
        try:
            await self.call(link.bring_up)
            await self._after_bring_up(link)
        except BaseException as exc:
            await self.call(link.drop)
            if isinstance(exc, Exception) and not isinstance(exc, RobotConnectionError):
                # Whatever a library raised on the way (a CanError, an odd answer...).
                raise RobotConnectionError(
                    f"cannot bring up the CAN base at {self.url!r}: {exc}"
                ) from exc
            raise
        finally:
            self._pending = None
        return link

    async def _maintain(self) -> None:
        """Watch the link until it fails, then reconnect with backoff; until cancelled."""
        link = self.link
        while link is not None:
            reason = await self._watch(link)
            self.link, self._lost = None, reason
            self._on_lost()
            await self.call(link.drop)
            link = await self._reconnect()
            self.link = link

    async def _reconnect(self) -> Any:
        delay = BACKOFF_FIRST
        while True:
            await asyncio.sleep(delay)
            try:
                return await self._connect()
            except (OSError, RobotConnectionError) as exc:
                self._lost = f"reconnecting failed: {exc}"
                delay = min(2 * delay, BACKOFF_MAX)

    async def _watch(self, link: Any) -> str:
        """Return why the link failed, once it does."""
        while True:
            await asyncio.sleep(self.tick)
            reason = link.problem()
            if reason:
                return reason
            try:
                await self._tend(link)
            except RobotConnectionError as exc:
                return str(exc)

    # -- hooks -----------------------------------------------------------------------------

    def _reset(self) -> None:
        """Forget the readings of an earlier session (on open, not on a reconnection)."""

    def _new_link(self, loop: asyncio.AbstractEventLoop) -> Any:
        raise NotImplementedError

    async def _after_bring_up(self, link: Any) -> None:
        """Async steps of connecting, after the blocking ones."""

    async def _tend(self, link: Any) -> None:
        """Periodic work while the link is up."""

    def _on_lost(self) -> None:
        """The link has just been declared lost."""

    async def drive(self, linear: float, angular: float) -> None:
        raise NotImplementedError

    async def stop(self) -> None:
        raise NotImplementedError

    def readings(self) -> dict[str, Any]:
        raise NotImplementedError

    def sensor_specs(self) -> dict[str, dict[str, Any]]:
        raise NotImplementedError


class _Link:
    """One opened bus. Frames arrive in a Notifier thread and cross to the loop with ``soon``."""

    def __init__(self, profile: _Profile, loop: asyncio.AbstractEventLoop) -> None:
        self.profile = profile
        self.loop = loop
        self.aborted = False
        self.dropped = False
        self.notifier: can.Notifier | None = None

    def soon(self, function: Callable[..., Any], *args: Any) -> None:
        """Call ``function`` in the event loop's thread (from a Notifier thread)."""
        if self.dropped:
            return
        with contextlib.suppress(RuntimeError):  # the loop has closed
            self.loop.call_soon_threadsafe(function, *args)

    def count_error(self) -> None:
        self.profile.errors += 1

    def bus_problem(self) -> str | None:
        notifier = self.notifier
        if notifier is not None and notifier.exception is not None:
            return f"the CAN bus failed: {notifier.exception}"
        return None

    def check_aborted(self) -> None:
        if self.aborted:
            raise RobotConnectionError("closed while connecting")


# -- cia402: two CiA 402 drives through canopen -------------------------------------------------


class _Cia402(_Profile):
    name = "cia402"
    default_timeout = 0.5
    options = (
        "left", "right", "eds", "track", "wheel_diameter", "counts_per_rev", "counts_per_metre",
        "velocity_per_mps", "invert_left", "invert_right", "heartbeat", "sync",
    )  # fmt: skip

    def __init__(
        self,
        robot: CanRobot,
        *,
        timeout: float | None,
        left: int,
        right: int,
        eds: str | None,
        track: float,
        wheel_diameter: float,
        counts_per_rev: float,
        counts_per_metre: float | None,
        velocity_per_mps: float | None,
        invert_left: bool,
        invert_right: bool,
        heartbeat: float,
        sync: float,
    ) -> None:
        super().__init__(robot, timeout)
        self.nodes = {"left": _node_id("left", left), "right": _node_id("right", right)}
        if left == right:
            raise ValueError(f"left and right must be different node ids, both are {left}")
        self.eds = str(eds or CIA402_EDS)
        _check_eds(self.eds)
        self.track = _positive(float, "track", track)
        self.wheel_diameter = _positive(float, "wheel_diameter", wheel_diameter)
        self.counts_per_rev = _positive(float, "counts_per_rev", counts_per_rev)
        if counts_per_metre is None:
            counts_per_metre = self.counts_per_rev / (math.pi * self.wheel_diameter)
        self.counts_per_metre = _positive(float, "counts_per_metre", counts_per_metre)
        if velocity_per_mps is None:
            velocity_per_mps = self.counts_per_metre  # the drive counts velocity in counts/s
        self.velocity_per_mps = _positive(float, "velocity_per_mps", velocity_per_mps)
        self.signs = {"left": -1 if _flag("invert_left", invert_left) else 1,
                      "right": -1 if _flag("invert_right", invert_right) else 1}  # fmt: skip
        self.heartbeat = _positive(float, "heartbeat", heartbeat)
        if not 0.001 <= self.heartbeat <= 65.535:
            raise ValueError(f"heartbeat must be 0.001 to 65.535 s, got {heartbeat!r}")
        if self.timeout <= self.heartbeat:
            raise ValueError(
                f"timeout ({self.timeout:g} s) must be longer than the heartbeat period "
                f"({self.heartbeat:g} s)"
            )
        self.sync = _positive(float, "sync", sync)
        self._pose = (0.0, 0.0, 0.0)
        self._counts: dict[str, int] | None = None  # positions odometry last took

    def describe(self, side: str) -> str:
        return f"the {side} drive (node {self.nodes[side]})"

    def _reset(self) -> None:
        self._pose = (0.0, 0.0, 0.0)

    def _new_link(self, loop: asyncio.AbstractEventLoop) -> _Cia402Link:
        self._counts = None  # the drives may have restarted: take new reference positions
        return _Cia402Link(self, loop)

    async def _watch(self, link: _Cia402Link) -> str:
        reason = await super()._watch(link)
        # A drive that can still hear must not go on with the last speeds.
        with contextlib.suppress(RobotConnectionError):
            await self.call(link.command, dict.fromkeys(SIDES, 0), CW_ENABLE | CW_HALT)
        return reason

    async def _tend(self, link: _Cia402Link) -> None:
        for side in SIDES:
            if link.state(side) == "FAULT" and link.fault[side] is None:
                link.fault[side] = await self.call(link.read_fault, side)
            elif link.state(side) != "FAULT":
                link.fault[side] = None

    # -- motion ----------------------------------------------------------------------------

    async def drive(self, linear: float, angular: float) -> None:
        link = self.require_link()
        for side in SIDES:
            state = link.state(side)
            if state != "OPERATION ENABLED":
                fault = f" ({link.fault[side]})" if link.fault[side] else ""
                raise RobotConnectionError(
                    f"{self.describe(side)} of the CAN base at {self.url!r} is in {state}{fault}, "
                    "not OPERATION ENABLED; close and open the robot to enable it again"
                )
        half = angular * self.track / 2.0
        speeds = {"left": linear - half, "right": linear + half}
        targets = {side: self._target(side, speed) for side, speed in speeds.items()}
        await self.call(link.command, targets, CW_ENABLE)

    async def stop(self) -> None:
        # Whatever state the drives are in: a stop is always sent, halt bit and zero target.
        link = self.require_link()
        await self.call(link.command, {"left": 0, "right": 0}, CW_ENABLE | CW_HALT)

    def _target(self, side: str, speed: float) -> int:
        value = round(speed * self.velocity_per_mps) * self.signs[side]
        return max(-(1 << 31), min((1 << 31) - 1, value))

    # -- readings --------------------------------------------------------------------------

    def take_position(self, link: _Cia402Link) -> None:
        """Odometry from both wheels' position actual values (in the loop's thread).

        Called once both drives have sent a new position since the last call: the pair from
        one SYNC, so one wheel's move is never taken without the other's.
        """
        if link is not self.link and link is not self._pending:
            return
        counts = dict(link.position)
        last, self._counts = self._counts, counts
        if last is None:
            return
        moved = {
            side: _wrap32(counts[side] - last[side]) * self.signs[side] / self.counts_per_metre
            for side in SIDES
        }
        distance = (moved["left"] + moved["right"]) / 2.0
        turn = (moved["right"] - moved["left"]) / self.track
        self._pose = advance_pose(*self._pose, distance, turn, 1.0)

    def readings(self) -> dict[str, Any]:
        link = self.require_link()
        wheels = {
            side: link.velocity[side] * self.signs[side] / self.velocity_per_mps for side in SIDES
        }
        x, y, theta = self._pose
        return {
            "position": {"x": x, "y": y, "theta": theta},
            "velocity": {
                "linear": (wheels["left"] + wheels["right"]) / 2.0,
                "angular": (wheels["right"] - wheels["left"]) / self.track,
            },
            "heading": compass_heading(theta),
            "wheels": wheels,
            "drives": {
                side: {
                    "node": self.nodes[side],
                    "state": link.state(side),
                    "mode": link.mode[side],
                    "fault": link.fault[side],
                }
                for side in SIDES
            },
            "errors": self.errors,
        }

    def sensor_specs(self) -> dict[str, dict[str, Any]]:
        return {
            "position": {"unit": {"x": "m", "y": "m", "theta": "rad"}, "source": "odometry"},
            "velocity": {"unit": {"linear": "m/s", "angular": "rad/s"}},
            "heading": {"unit": "deg", "source": "odometry"},
            "wheels": {"unit": {"left": "m/s", "right": "m/s"}},
            "drives": {
                "unit": {"node": "id", "state": "CiA 402 state", "mode": "0x6061", "fault": "text"}
            },
            "errors": {"unit": "count"},
        }


class _Cia402Link(_Link):
    """One canopen Network with the two drives as BaseNode402 nodes."""

    def __init__(self, profile: _Cia402, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__(profile, loop)
        self.profile: _Cia402 = profile
        self.network: canopen.Network | None = None
        self.nodes: dict[str, canopen.BaseNode402] = {}
        self.sizes: dict[int, int] = {}  # COB-ID -> the only length its frames may have
        now = time.monotonic()
        self.heard = dict.fromkeys(SIDES, now)  # when each drive's last heartbeat came
        self.nmt: dict[str, int | None] = dict.fromkeys(SIDES)  # NMT state it said
        self.nmt_seen: dict[str, int | None] = dict.fromkeys(SIDES)  # the same, thread side
        self.status: dict[str, int | None] = dict.fromkeys(SIDES)
        self.mode: dict[str, int | None] = dict.fromkeys(SIDES)
        self.position: dict[str, int | None] = dict.fromkeys(SIDES)
        self.fresh: set[str] = set()  # wheels with a position odometry has not taken yet
        self.velocity: dict[str, int] = dict.fromkeys(SIDES, 0)
        self.fault: dict[str, str | None] = dict.fromkeys(SIDES)

    # -- in the loop's thread --------------------------------------------------------------

    def state(self, side: str) -> str:
        status = self.status[side]
        if status is None:
            return "UNKNOWN"
        for name, (mask, bits) in State402.SW_MASK.items():
            if status & mask == bits:
                return name
        return "UNKNOWN"

    def problem(self) -> str | None:
        reason = self.bus_problem()
        if reason:
            return reason
        now = time.monotonic()
        for side in SIDES:
            what = self.profile.describe(side)
            if now - self.heard[side] > self.profile.timeout:
                return f"no heartbeat from {what} for {self.profile.timeout:g} s"
            state = self.nmt[side]
            if state == 0:
                return f"{what} restarted (boot-up message)"
            if state is not None and state != NMT_OPERATIONAL:
                return f"{what} left OPERATIONAL: its heartbeat says {NMT_STATES.get(state, state)}"
        return None

    def _heartbeat(self, side: str, state: int) -> None:
        self.heard[side] = time.monotonic()
        self.nmt[side] = state

    def _tpdo(self, side: str, values: dict[int, int]) -> None:
        if 0x6041 in values:
            self.status[side] = values[0x6041]
        if 0x6061 in values:
            self.mode[side] = values[0x6061]
        if 0x606C in values:
            self.velocity[side] = values[0x606C]
        if 0x6064 in values:
            self.position[side] = values[0x6064]
            self.fresh.add(side)
            if len(self.fresh) == len(SIDES):
                self.fresh.clear()
                self.profile.take_position(self)

    # -- in the Notifier thread ------------------------------------------------------------

    def _on_tpdo(self, side: str, pdo_map: canopen.pdo.PdoMap) -> None:
        values = {variable.index: variable.raw for variable in pdo_map}
        self.soon(self._tpdo, side, values)

    def _on_heartbeat(self, side: str, state: int) -> None:
        self.nmt_seen[side] = state  # for bring_up, which runs in a worker thread
        self.soon(self._heartbeat, side, state)

    # -- in a worker thread ----------------------------------------------------------------

    def bring_up(self) -> None:
        profile = self.profile
        bus = profile.robot.make_bus()
        network = canopen.Network(bus)
        network.NOTIFIER_CYCLE = NOTIFIER_CYCLE
        network.listeners = [_CheckedListener(network, self)]
        self.network = network
        for side in SIDES:
            node_id = profile.nodes[side]
            node = canopen.BaseNode402(node_id, profile.eds)
            # canopen's waits, stretched to a few SYNC periods so a slow bus still makes it.
            node.TIMEOUT_CHECK_TPDO = max(0.2, 4 * profile.sync)
            node.TIMEOUT_SWITCH_STATE_SINGLE = max(0.4, 8 * profile.sync)
            node.TIMEOUT_SWITCH_STATE_FINAL = max(0.8, 16 * profile.sync)
            network.add_node(node)
            node.nmt.add_heartbeat_callback(partial(self._on_heartbeat, side))
            self.nodes[side] = node
            self.sizes.update({0x700 + node_id: 1, 0x580 + node_id: 8, 0x80 + node_id: 8})
        network.connect()
        self.notifier = network.notifier
        for node in self.nodes.values():
            node.nmt.state = "PRE-OPERATIONAL"
        for side, node in self.nodes.items():
            self._sdo(side, self._configure, side, node)
        self.check_aborted()
        network.sync.start(profile.sync)
        for node in self.nodes.values():
            node.nmt.state = "OPERATIONAL"
        # Both drives walk their state machines at once: each step waits for a SYNC.
        with concurrent.futures.ThreadPoolExecutor(len(SIDES), "rhal-can-402") as pool:
            walks = [pool.submit(self._sdo, side, self._enable, side, node)
                     for side, node in self.nodes.items()]  # fmt: skip
        for walk in walks:
            walk.result()
        for side in SIDES:
            self._await_operational(side)
        # A drive that was already enabled keeps its last target: motion must not resume.
        self.command(dict.fromkeys(SIDES, 0), CW_ENABLE)
        self.check_aborted()

    def _sdo(self, side: str, step: Callable[..., None], *args: Any) -> None:
        what = self.profile.describe(side)
        try:
            step(*args)
        except canopen.SdoCommunicationError as exc:
            raise RobotConnectionError(f"no answer from {what}: {exc}") from None
        except canopen.SdoAbortedError as exc:
            raise RobotConnectionError(f"{what} refused a setting: {exc}") from None
        except can.CanError as exc:
            raise RobotConnectionError(f"cannot send to {what}: {exc}") from None

    def _configure(self, side: str, node: canopen.BaseNode402) -> None:
        self.check_aborted()
        what = self.profile.describe(side)
        device_type = node.sdo[0x1000].raw
        if device_type & 0xFFFF != 402:
            raise RobotConnectionError(
                f"{what} is not a CiA 402 drive: its device type is 0x{device_type:08X}"
            )
        node.sdo[0x1017].raw = round(self.profile.heartbeat * 1000)
        maps = {"tpdo": node.tpdo, "rpdo": node.rpdo}
        for kind, pdos in maps.items():
            for number, pdo_map in pdos.map.items():
                if pdo_map.predefined_cob_id is None:
                    continue  # beyond the predefined four: left as the drive has it
                objects = PDO_LAYOUT.get((kind, number))
                pdo_map.cob_id = pdo_map.predefined_cob_id
                pdo_map.clear()
                pdo_map.enabled = objects is not None
                for index in objects or ():
                    pdo_map.add_variable(index)
                if objects is not None:
                    pdo_map.trans_type = 1 if kind == "tpdo" else 255  # every SYNC / at once
                pdo_map.save()
                if objects is not None and kind == "tpdo":
                    self.sizes[pdo_map.cob_id] = (pdo_map.length + 7) // 8
        node.sdo[0x6060].raw = PROFILED_VELOCITY  # by SDO: no PDO carries it
        node.setup_pdos(upload=False)  # BaseNode402 learns the mapping just saved
        for rpdo in node.rpdo.map.values():
            # canopen listens on our own RPDOs too: a bus that echoes what it sends
            # (udp_multicast) would put an old frame back into the one about to go out.
            with contextlib.suppress(KeyError, ValueError):
                self.network.unsubscribe(rpdo.cob_id, rpdo.on_message)
        for number in (1, 2):
            node.tpdo[number].add_callback(partial(self._on_tpdo, side))

    def _enable(self, side: str, node: canopen.BaseNode402) -> None:
        self.check_aborted()
        what = self.profile.describe(side)
        wait = max(0.5, 10 * self.profile.sync)
        for number in (1, 2):
            tpdo = node.tpdo[number]
            if tpdo.timestamp is None and tpdo.wait_for_reception(wait) is None:
                raise RobotConnectionError(f"no TPDO{number} from {what} {wait:g} s after SYNC")
        mode = node.tpdo_values.get(0x6061)
        if mode != PROFILED_VELOCITY:
            raise RobotConnectionError(
                f"{what} did not take profile velocity mode (0x6060 = 3): it reports mode {mode}"
            )
        node.rpdo_pointers[0x60FF].raw = 0
        try:
            node.state = "OPERATION ENABLED"
        except (RuntimeError, ValueError) as exc:
            state = node.state
            fault = f" ({self.read_fault(side)})" if state == "FAULT" else ""
            raise RobotConnectionError(
                f"{what} did not reach OPERATION ENABLED: it stays in {state}{fault} ({exc})"
            ) from None

    def _await_operational(self, side: str) -> None:
        # Its heartbeat must say OPERATIONAL before the link is watched: one sent before the
        # NMT start would otherwise read as the drive leaving OPERATIONAL.
        deadline = time.monotonic() + max(0.5, 3 * self.profile.heartbeat)
        while self.nmt_seen[side] != NMT_OPERATIONAL:
            if time.monotonic() > deadline:
                state = self.nmt_seen[side]
                raise RobotConnectionError(
                    f"{self.profile.describe(side)} did not start: its heartbeat says "
                    f"{NMT_STATES.get(state, state) if state is not None else 'nothing'}"
                )
            time.sleep(0.005)

    def read_fault(self, side: str) -> str:
        try:
            code = self.nodes[side].sdo[0x603F].raw
        except Exception as exc:  # noqa: BLE001 - a garbled answer must not end the watch
            return f"error code unreadable: {exc}"
        return str(EmcyError(code, 0, b"", 0))

    def command(self, targets: dict[str, int], controlword: int) -> None:
        """Target velocity and controlword to both drives, one RPDO each."""
        if self.dropped:  # a call queued behind the one that dropped the link
            raise RobotConnectionError(f"no link to the CAN base at {self.profile.url!r}")
        try:
            for side, node in self.nodes.items():
                node.rpdo_pointers[0x60FF].raw = targets[side]
                node.rpdo_pointers[0x6040].raw = controlword
                node.rpdo_pointers[0x6040].pdo_parent.transmit()
        except (can.CanError, RuntimeError) as exc:
            raise RobotConnectionError(f"lost the CAN bus at {self.profile.url!r}: {exc}") from exc

    def goodbye(self) -> None:
        """An orderly end: power stages off, PDOs stopped, then the bus closed."""
        with contextlib.suppress(can.CanError, RobotConnectionError, RuntimeError):
            self.command({"left": 0, "right": 0}, CW_SHUTDOWN)
            for node in self.nodes.values():
                node.nmt.state = "PRE-OPERATIONAL"
        self.drop()

    def drop(self) -> None:
        self.dropped = True
        network, self.network = self.network, None
        if network is not None:
            # disconnect() re-raises an error the Notifier thread died of: it is known already.
            with contextlib.suppress(Exception):
                network.disconnect()


class _CheckedListener(MessageListener):
    """canopen's listener, after dropping (and counting) frames no drive can have sent."""

    def __init__(self, network: canopen.Network, link: _Cia402Link) -> None:
        super().__init__(network)
        self.link = link

    def on_message_received(self, msg: can.Message) -> None:
        if msg.is_error_frame:
            self.link.count_error()
            return
        if msg.is_extended_id:
            return  # CANopen speaks 11-bit identifiers: a 29-bit frame is someone else's
        size = self.link.sizes.get(msg.arbitration_id)
        if size is not None and not msg.is_remote_frame and len(msg.data) != size:
            self.link.count_error()
            return
        super().on_message_received(msg)


# -- dbc: a base described by a DBC file -------------------------------------------------------


class _Dbc(_Profile):
    name = "dbc"
    default_timeout = 1.0
    options = (
        "dbc", "command", "speed", "turn", "feedback_speed", "feedback_turn", "heading",
        "battery", "range", "rate",
    )  # fmt: skip

    def __init__(
        self,
        robot: CanRobot,
        *,
        timeout: float | None,
        dbc: str | None,
        command: str,
        speed: str,
        turn: str,
        feedback_speed: str,
        feedback_turn: str,
        heading: str,
        battery: str,
        range: str,  # the option's documented name, though a builtin's
        rate: float,
    ) -> None:
        super().__init__(robot, timeout)
        self.path = Path(dbc) if dbc else EXAMPLE_DBC
        try:
            self.db = cantools.database.load_file(str(self.path), database_format="dbc")
        except (OSError, cantools.database.Error, ValueError) as exc:
            raise ValueError(f"cannot load the DBC file {str(self.path)!r}: {exc}") from exc
        if isinstance(rate, bool) or not isinstance(rate, (int, float)) or rate < 0:
            raise ValueError(f"rate must be a number of Hz, 0 or more, got {rate!r}")
        self.rate = float(rate)
        if self.rate:
            self.tick = min(TICK, 1.0 / self.rate)
        self.command = self._message(command, "command")
        if self.command.is_container or any(s.multiplexer_ids for s in self.command.signals):
            raise ValueError(f"the command message {command!r} is multiplexed: not supported")
        #: option -> (message, signal, factor to the reading's unit); optional ones when given
        self.signals: dict[str, tuple[Any, Any, float]] = {}
        mapping = {"speed": speed, "turn": turn, "feedback_speed": feedback_speed,
                   "feedback_turn": feedback_turn, "heading": heading, "battery": battery,
                   "range": range}  # fmt: skip
        for option, reference in mapping.items():
            if reference in ("", None) and option in ("heading", "battery", "range"):
                continue  # not on this base
            self.signals[option] = self._signal(option, reference)
        for option in ("speed", "turn"):
            message = self.signals[option][0]
            if message is not self.command:
                raise ValueError(
                    f"{option}={mapping[option]} must be a signal of the command message "
                    f"{self.command.name!r} (command=)"
                )
        self.feedback = self.signals["feedback_speed"][0]
        self._defaults = {signal.name: _start_value(signal) for signal in self.command.signals}
        self._command = (0.0, 0.0)  # m/s, rad/s: what the base was last told
        self._sent = 0.0  # time.monotonic() of the last command frame
        self._reset()

    def _message(self, name: Any, option: str) -> Any:
        try:
            return self.db.get_message_by_name(str(name))
        except KeyError:
            known = ", ".join(message.name for message in self.db.messages) or "none"
            raise ValueError(
                f"the DBC file {str(self.path)!r} has no message {name!r} ({option}=); "
                f"its messages are: {known}"
            ) from None

    def _signal(self, option: str, reference: Any) -> tuple[Any, Any, float]:
        text = str(reference)
        if text.count(".") != 1 or text.startswith(".") or text.endswith("."):
            raise ValueError(f"{option} must name a signal as Message.Signal, got {reference!r}")
        message_name, signal_name = text.split(".")
        message = self._message(message_name, option)
        try:
            signal = message.get_signal_by_name(signal_name)
        except KeyError:
            known = ", ".join(signal.name for signal in message.signals)
            raise ValueError(
                f"message {message.name!r} in {str(self.path)!r} has no signal {signal_name!r} "
                f"({option}=); its signals are: {known}"
            ) from None
        units = UNITS[option]
        unit = signal.unit or ""
        if unit not in units:
            raise ValueError(
                f"{option}={text} is in {unit!r}; {option} signals must be in one of: "
                f"{', '.join(repr(u) for u in units if u)}"
            )
        return message, signal, units[unit]

    def _reset(self) -> None:
        self._values: dict[str, float | int] = {}  # "Message.Signal" -> latest value
        self._pose = (0.0, 0.0, 0.0)
        self._stamp: float | None = None  # bus timestamp of the last feedback frame

    def _new_link(self, loop: asyncio.AbstractEventLoop) -> _DbcLink:
        return _DbcLink(self, loop)

    async def _after_bring_up(self, link: _DbcLink) -> None:
        wait = 3 * self.timeout
        try:
            async with asyncio.timeout(wait):
                await link.first_feedback.wait()
        except TimeoutError:
            raise RobotConnectionError(
                f"no {self.feedback.name} frame from the base on {self.url!r} within {wait:g} s"
            ) from None
        self._command = (0.0, 0.0)

    def _on_lost(self) -> None:
        self._command = (0.0, 0.0)

    async def _tend(self, link: _DbcLink) -> None:
        if self.rate and self._command != (0.0, 0.0):
            if time.monotonic() - self._sent >= 1.0 / self.rate:
                await self._send(link)

    async def _watch(self, link: _DbcLink) -> str:
        reason = await super()._watch(link)
        # The bus may still carry a frame: the base should not go on with the last speeds.
        with contextlib.suppress(RobotConnectionError):
            await self.call(link.send, self._frame(0.0, 0.0))
        return reason

    # -- motion ----------------------------------------------------------------------------

    async def drive(self, linear: float, angular: float) -> None:
        link = self.require_link()
        self._command = (linear, angular)
        await self._send(link)

    async def stop(self) -> None:
        self._command = (0.0, 0.0)
        await self._send(self.require_link())

    async def _send(self, link: _DbcLink) -> None:
        await self.call(self._send_latest, link)

    def _send_latest(self, link: _DbcLink) -> None:
        # In the worker, so the frame is made from the command as it is when its turn comes:
        # a repeat queued before a stop can never reach the wire after it.
        self._sent = time.monotonic()
        link.send(self._frame(*self._command))

    def _frame(self, linear: float, angular: float) -> can.Message:
        data = dict(self._defaults)
        for option, value in (("speed", linear), ("turn", angular)):
            _, signal, factor = self.signals[option]
            data[signal.name] = _clamp_to(signal, value / factor)
        payload = self.command.encode(data)
        return can.Message(
            arbitration_id=self.command.frame_id,
            data=payload,
            is_extended_id=self.command.is_extended_frame,
        )

    # -- readings (in the loop's thread) ---------------------------------------------------

    def take(self, link: _DbcLink, msg: can.Message) -> None:
        if link is not self.link and link is not self._pending:
            return
        if msg.is_error_frame:
            self.errors += 1
            return
        if msg.is_remote_frame:
            return
        try:
            message = self.db.get_message_by_frame_id(
                msg.arbitration_id, force_extended_id=msg.is_extended_id
            )
        except KeyError:
            return  # not in the DBC: another node's frame
        if message is self.command:
            return  # our own command, from a bus that echoes what it sends (udp_multicast)
        try:
            values = message.decode(bytes(msg.data), decode_choices=False)
        except Exception:  # noqa: BLE001 - whatever the decoder makes of garbage, it is dropped
            self.errors += 1
            return
        if not all(isinstance(v, (int, float)) and math.isfinite(v) for v in values.values()):
            self.errors += 1
            return
        for name, value in values.items():
            self._values[f"{message.name}.{name}"] = value
        if message is self.feedback:
            self._odometry(msg.timestamp)
            link.heard = time.monotonic()
            link.first_feedback.set()

    def _odometry(self, stamp: float) -> None:
        last, self._stamp = self._stamp, stamp
        velocity = self._velocity()
        if last is None or velocity is None or not 0.0 < stamp - last <= 1.0:
            return  # the first frame, or after a gap: nothing to integrate over
        self._pose = advance_pose(*self._pose, *velocity, stamp - last)

    def _reading(self, option: str) -> float | None:
        message, signal, factor = self.signals[option]
        value = self._values.get(f"{message.name}.{signal.name}")
        return None if value is None else value * factor

    def _velocity(self) -> tuple[float, float] | None:
        linear, angular = self._reading("feedback_speed"), self._reading("feedback_turn")
        if linear is None or angular is None:
            return None
        return linear, angular

    def readings(self) -> dict[str, Any]:
        self.require_link()
        x, y, theta = self._pose
        velocity = self._velocity()
        readings: dict[str, Any] = {
            "position": {"x": x, "y": y, "theta": theta},
            "velocity": None
            if velocity is None
            else {"linear": velocity[0], "angular": velocity[1]},
            "heading": compass_heading(theta),
        }
        if "heading" in self.signals:
            heading = self._reading("heading")
            readings["heading"] = None if heading is None else heading % 360.0
        if "battery" in self.signals:
            readings["battery"] = self._reading("battery")
        if "range" in self.signals:
            distance = self._reading("range")
            _, signal, factor = self.signals["range"]
            if distance is not None and signal.maximum is not None:
                if distance >= signal.maximum * factor:
                    distance = None  # the sensor's "nothing in reach"
            readings["range"] = distance
        readings["signals"] = dict(self._values)
        readings["errors"] = self.errors
        return readings

    def sensor_specs(self) -> dict[str, dict[str, Any]]:
        specs: dict[str, dict[str, Any]] = {
            "position": {"unit": {"x": "m", "y": "m", "theta": "rad"}, "source": "odometry"},
            "velocity": {"unit": {"linear": "m/s", "angular": "rad/s"}},
            "heading": {"unit": "deg", "source": "odometry"},
        }
        if "heading" in self.signals:
            specs["heading"] = {"unit": "deg", "source": self._name("heading")}
        if "battery" in self.signals:
            specs["battery"] = {"unit": "V", "source": self._name("battery")}
        if "range" in self.signals:
            _, signal, factor = self.signals["range"]
            maximum = None if signal.maximum is None else signal.maximum * factor
            specs["range"] = {"unit": "m", "max": maximum, "source": self._name("range")}
        specs["signals"] = {
            "unit": {
                f"{message.name}.{signal.name}": signal.unit or ""
                for message in self.db.messages
                if message is not self.command
                for signal in message.signals
            }
        }
        specs["errors"] = {"unit": "count"}
        return specs

    def _name(self, option: str) -> str:
        message, signal, _ = self.signals[option]
        return f"{message.name}.{signal.name}"


class _DbcLink(_Link):
    """A python-can bus with a Notifier thread handing every frame to the loop."""

    def __init__(self, profile: _Dbc, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__(profile, loop)
        self.profile: _Dbc = profile
        self.bus: can.BusABC | None = None
        self.first_feedback = asyncio.Event()
        self.heard = time.monotonic()

    def problem(self) -> str | None:
        reason = self.bus_problem()
        if reason:
            return reason
        if time.monotonic() - self.heard > self.profile.timeout:
            name = self.profile.feedback.name
            return f"no {name} frame from the base for {self.profile.timeout:g} s"
        return None

    def on_message_received(self, msg: can.Message) -> None:  # in the Notifier thread
        self.soon(self.profile.take, self, msg)

    def bring_up(self) -> None:
        self.bus = self.profile.robot.make_bus()
        self.notifier = can.Notifier(self.bus, [self.on_message_received], NOTIFIER_CYCLE)
        self.check_aborted()

    def send(self, frame: can.Message) -> None:
        bus = self.bus
        if bus is None or self.dropped:
            raise RobotConnectionError(f"no link to the CAN base at {self.profile.url!r}")
        try:
            bus.send(frame, timeout=SEND_TIMEOUT)
        except can.CanError as exc:
            raise RobotConnectionError(f"lost the CAN bus at {self.profile.url!r}: {exc}") from exc

    def goodbye(self) -> None:
        self.drop()

    def drop(self) -> None:
        self.dropped = True
        notifier, bus, self.bus = self.notifier, self.bus, None
        if notifier is not None:
            notifier.stop(NOTIFIER_CYCLE * 5)
        if bus is not None:
            bus.shutdown()


# -- helpers -----------------------------------------------------------------------------------


def _check_eds(path: str) -> None:
    try:
        od = canopen.import_od(path, 1)
    except Exception as exc:  # noqa: BLE001 - OSError, configparser's errors...: a bad file
        raise ValueError(f"cannot read the EDS file {path!r}: {exc}") from exc
    missing = [f"0x{index:04X} {name}" for index, name in CIA402_OBJECTS.items() if index not in od]
    if missing:
        needed = ", ".join(missing)
        raise ValueError(f"the EDS file {path!r} lacks objects the cia402 profile needs: {needed}")


def _start_value(signal: Any) -> float | int:
    """A signal's start value (GenSigStartValue), else 0, inside its range."""
    if signal.raw_initial is not None:
        value = signal.conversion.raw_to_scaled(signal.raw_initial, decode_choices=False)
    else:
        value = 0
    return _clamp_to(signal, value)


def _clamp_to(signal: Any, value: float) -> float:
    if signal.minimum is not None:
        value = max(signal.minimum, value)
    if signal.maximum is not None:
        value = min(signal.maximum, value)
    return value


def _wrap32(delta: int) -> int:
    """A difference of two 32-bit counters, across their wrap."""
    return (delta + (1 << 31)) % INT32 - (1 << 31)


def _node_id(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 127:
        raise ValueError(f"{name} must be a CANopen node id from 1 to 127, got {value!r}")
    return value


def _flag(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return value


def _positive(kind: type, name: str, value: Any) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    result = kind(value)
    if not result > 0 or not math.isfinite(result):
        raise ValueError(f"{name} must be greater than 0, got {value!r}")
    return result
