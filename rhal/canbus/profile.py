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
from rhal.linked import LinkKeeper

if TYPE_CHECKING:
    from rhal.canbus.robot import CanRobot

#: The data files (EDS, DBC): rhal/can_profiles, beside this package.
PROFILE_DIR = Path(__file__).parent.parent / "can_profiles"
TICK = 0.05  # s between checks of the link
NOTIFIER_CYCLE = 0.05  # s a Notifier thread waits for a frame: bounds how long closing takes


class Profile:
    """A CAN link's steps for its LinkKeeper; one blocking library call at a time."""

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
        self._pending: Any = None  # the link being brought up, so close() can abort it
        self._keeper: LinkKeeper[Any] = LinkKeeper(
            f"the CAN base at {self.url!r}",
            connect=self._connect,
            serve=self._watch,
            halt=self._halt,
            drop=self._drop,
            on_lost=lambda reason: self._on_lost(),
        )
        self._io = asyncio.Lock()

    @property
    def link(self) -> Any:
        return self._keeper.link

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
        await self._keeper.open()

    async def close(self) -> None:
        if self._pending is not None:
            self._pending.aborted = True
        await self._keeper.close(goodbye=self._goodbye)

    def require_link(self) -> Any:
        return self._keeper.require()

    async def stop(self) -> None:
        await self._halt(self.require_link())

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

    async def _goodbye(self, link: Any) -> None:
        await self.call(link.goodbye)

    async def _drop(self, link: Any) -> None:
        await self.call(link.drop)

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

    async def _halt(self, link: Any) -> None:
        """Stop the wheels through this link."""
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
