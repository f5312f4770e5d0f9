"""The dbc profile: a base described by a DBC file, through cantools."""

from __future__ import annotations

import asyncio
import contextlib
import math
import time
from pathlib import Path
from typing import TYPE_CHECKING, Any

import can
import cantools

from rhal.canbus.profile import NOTIFIER_CYCLE, PROFILE_DIR, TICK, Link, Profile
from rhal.errors import RobotConnectionError
from rhal.kinematics import advance_pose, compass_heading
from rhal.linked import QuietClock, heard_within

if TYPE_CHECKING:
    from rhal.canbus.robot import CanRobot

EXAMPLE_DBC = PROFILE_DIR / "example_base.dbc"
SEND_TIMEOUT = 0.2  # s a send may wait for room in the interface's queue

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


class Dbc(Profile):
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
            await heard_within(link.first_feedback.wait, wait)
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

    async def _halt(self, link: _DbcLink) -> None:
        self._command = (0.0, 0.0)
        await self._send(link)

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
            link.quiet.heard()
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


class _DbcLink(Link):
    """A python-can bus with a Notifier thread handing every frame to the loop."""

    def __init__(self, profile: Dbc, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__(profile, loop)
        self.profile: Dbc = profile
        self.bus: can.BusABC | None = None
        self.first_feedback = asyncio.Event()
        self.quiet = QuietClock(profile.tick)  # since the last feedback frame, as the watch ticks

    def problem(self) -> str | None:
        reason = self.bus_problem()
        if reason:
            return reason
        if self.quiet.look() > self.profile.timeout:
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
