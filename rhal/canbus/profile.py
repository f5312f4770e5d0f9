"""What both profiles share: a link's life (connect, watch, reconnect) and the opened bus."""

from __future__ import annotations

import asyncio
import contextlib
import math
from collections.abc import Callable
from pathlib import Path
from typing import TYPE_CHECKING, Any

import can

from rhal.errors import RobotConnectionError

if TYPE_CHECKING:
    from rhal.canbus.robot import CanRobot

#: The data files (EDS, DBC): rhal/can_profiles, beside this package.
PROFILE_DIR = Path(__file__).parent.parent / "can_profiles"
TICK = 0.05  # s between checks of the link
NOTIFIER_CYCLE = 0.05  # s a Notifier thread waits for a frame: bounds how long closing takes
BACKOFF_FIRST, BACKOFF_MAX = 0.2, 5.0  # s between reconnection attempts, doubling


class Profile:
    """A link's life: connect, watch, drop, reconnect with backoff; one blocking call at a time."""

    name = ""
    default_timeout = 1.0
    options: tuple[str, ...] = ()  # the CanRobot options this profile takes
    tick = TICK  # s between looks at the link

    def __init__(self, robot: CanRobot, timeout: float | None) -> None:
        self.robot = robot
        self.url = robot.url
        self.timeout = positive(
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


class Link:
    """One opened bus. Frames arrive in a Notifier thread and cross to the loop with ``soon``."""

    def __init__(self, profile: Profile, loop: asyncio.AbstractEventLoop) -> None:
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


def positive(kind: type, name: str, value: Any) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    result = kind(value)
    if not result > 0 or not math.isfinite(result):
        raise ValueError(f"{name} must be greater than 0, got {value!r}")
    return result
