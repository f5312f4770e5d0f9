"""The abstract robot every driver implements.

Public methods are templates: they check state and arguments, enforce the speed limits, then
call a private hook that a driver overrides. A driver implements at least ``_drive``,
``_read_sensors`` and ``_sensor_specs``; hooks are coroutines and must never block the event
loop (use the library's async API or ``asyncio.to_thread``).
"""

from __future__ import annotations

import abc
import math
import numbers
from collections.abc import Callable
from typing import Any

from rhal.errors import NotSupportedError, RobotConnectionError


class Robot(abc.ABC):
    """One robot behind a URL such as ``sim://``. Create with :func:`rhal.connect`."""

    #: Short name of the kind of robot, shown in capabilities and error messages.
    kind = "robot"
    #: True if every method answers without waiting on anything (no I/O): its callers may
    #: then skip a task per call. A driver that talks to hardware leaves it False.
    quick = False
    #: What each option means, for forms and docs (see rhal.options).
    option_help: dict[str, str] = {
        "max_linear": "speed limit, m/s: faster drive() calls are clamped to it",
        "max_angular": "turn-rate limit, rad/s",
    }

    def __init__(self, url: str, *, max_linear: float = 0.5, max_angular: float = 2.0) -> None:
        self.url = url
        self.max_linear = _positive_limit("max_linear", max_linear)
        self.max_angular = _positive_limit("max_angular", max_angular)
        self._is_open = False
        #: called with the bytes the driver reads off its wire (a serial bridge's watchers);
        #: drivers whose bytes are theirs to read call them, others leave the list unused
        self.wire_taps: list[Callable[[bytes], None]] = []

    def __repr__(self) -> str:
        state = "open" if self._is_open else "closed"
        return f"<{type(self).__name__} {self.url!r} {state}>"

    @property
    def wire_device(self) -> str | None:
        """The serial device this robot's driver holds, if it holds one and its wire taps see
        what it reads; None otherwise."""
        return None

    def tap_wire(self, feed: Callable[[bytes], None]) -> Callable[[], None]:
        """Have ``feed`` called with what the driver reads; returns the unsubscribe."""
        self.wire_taps.append(feed)
        return lambda: self.wire_taps.remove(feed) if feed in self.wire_taps else None

    @property
    def is_open(self) -> bool:
        return self._is_open

    # -- lifecycle -------------------------------------------------------------------------

    async def open(self) -> None:
        """Connect to the robot. Opening an open robot does nothing."""
        if self._is_open:
            return
        try:
            await self._open()
        except OSError as exc:
            raise RobotConnectionError(f"cannot open robot {self.url!r}: {exc}") from exc
        self._is_open = True

    async def close(self) -> None:
        """Stop the motors and release the robot. Safe to call more than once."""
        if not self._is_open:
            return
        self._is_open = False
        try:
            await self._stop()
        finally:
            await self._close()

    async def __aenter__(self) -> Robot:
        await self.open()
        return self

    async def __aexit__(self, *exc_info: object) -> None:
        await self.close()

    # -- motion ----------------------------------------------------------------------------

    async def drive(self, linear: float, angular: float) -> dict[str, float]:
        """Drive at ``linear`` m/s forward and ``angular`` rad/s counter-clockwise.

        Speeds beyond this robot's limits are clamped; the speeds actually applied are returned.
        """
        linear = _clamp(_finite("linear", linear), self.max_linear)
        angular = _clamp(_finite("angular", angular), self.max_angular)
        self._require_open()
        await self._drive(linear, angular)
        return {"linear": linear, "angular": angular}

    async def stop(self) -> None:
        """Stop the motors. A closed robot is already stopped, so this never fails for that."""
        if self._is_open:
            await self._stop()

    # -- sensing ---------------------------------------------------------------------------

    async def sensors(self) -> dict[str, Any]:
        """All current readings as a JSON-serialisable dict keyed by sensor name."""
        self._require_open()
        return await self._read_sensors()

    async def sensor(self, name: str) -> Any:
        """One reading; :class:`NotSupportedError` if this robot has no sensor ``name``."""
        readings = await self.sensors()
        if name not in readings:
            raise NotSupportedError(
                f"the {self.kind} robot has no sensor {name!r}; "
                f"its sensors are: {', '.join(sorted(readings))}"
            )
        return readings[name]

    def capabilities(self) -> dict[str, Any]:
        """What this robot can do, as a JSON-serialisable dict.

        Each sensor's ``unit`` is a text, or for a reading made of named parts (position) a
        dict of part -> unit.
        """
        return {
            "kind": self.kind,
            "drive": {"max_linear": self.max_linear, "max_angular": self.max_angular},
            "sensors": self._sensor_specs(),
            "camera": self._camera_spec(),
        }

    async def camera_jpeg(self) -> bytes:
        """The latest camera frame as JPEG bytes."""
        self._require_open()
        return await self._camera_jpeg()

    # -- hooks for drivers -----------------------------------------------------------------

    async def _open(self) -> None:  # noqa: B027 - optional hook, not every link needs it
        """Connect; raise OSError or RobotConnectionError on failure."""

    async def _close(self) -> None:  # noqa: B027 - optional hook
        """Release the connection; the motors have already been stopped."""

    @abc.abstractmethod
    async def _drive(self, linear: float, angular: float) -> None:
        """Apply speeds already validated and clamped to the limits."""

    async def _stop(self) -> None:
        await self._drive(0.0, 0.0)

    @abc.abstractmethod
    async def _read_sensors(self) -> dict[str, Any]:
        """Return every reading; keys must match :meth:`_sensor_specs`."""

    @abc.abstractmethod
    def _sensor_specs(self) -> dict[str, dict[str, Any]]:
        """Describe each sensor: ``{"range": {"unit": "m", "max": 4.0}, ...}``."""

    def _camera_spec(self) -> dict[str, Any] | None:
        """``{"width": .., "height": .., "format": "jpeg"}``, or None without a camera."""
        return None

    async def _camera_jpeg(self) -> bytes:
        raise NotSupportedError(f"the {self.kind} robot has no camera")

    def _require_open(self) -> None:
        if not self._is_open:
            raise RobotConnectionError(f"robot {self.url!r} is not open; call open() first")


def _finite(name: str, value: object) -> float:
    # bool is an int subclass, but drive(True, 0) is a bug, not a speed.
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} speed must be a number, got {value!r}")
    result = float(value)
    if not math.isfinite(result):
        raise ValueError(f"{name} speed must be finite, got {value!r}")
    return result


def _positive_limit(name: str, value: object) -> float:
    limit = _finite(name, value)
    if limit <= 0:
        raise ValueError(f"{name} must be greater than 0, got {value!r}")
    return limit


def _clamp(value: float, limit: float) -> float:
    return max(-limit, min(limit, value))
