"""A link's life, for every driver that keeps one: open, serve, stop, reconnect.

A driver that talks to its robot over a link (serial, TCP, UDP, USB, a CAN bus) gives a
``LinkKeeper`` four steps: how to connect (handshake included), how to serve a link until it
fails (returning why), how to stop the robot on that link, and how to drop it. The keeper
runs them: it serves the link in a task; when the link fails it stops the robot on the wire
if the link still takes bytes (a robot that went quiet may still be listening), drops the
link, says why it was lost, and reconnects with a doubling backoff until closed. Closing
comes after ``Robot.close`` has stopped the robot through the driver: the keeper then says
the driver's goodbye on the link, if it has one, and drops it.

While there is no link, callers get ``RobotConnectionError`` naming the reason, so a program
learns that it lost the robot. Motion is never resumed after a reconnection.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Awaitable, Callable
from typing import Generic, TypeVar

from rhal.errors import RhalError, RobotConnectionError

logger = logging.getLogger(__name__)

L = TypeVar("L")
T = TypeVar("T")

BACKOFF_FIRST, BACKOFF_MAX = 0.2, 5.0  # s between reconnection attempts, doubling
HALT_WAIT = 0.5  # s a stop on a failing link may take before it is given up
QUIET_SLICES = 10  # a silence is heard out in this many slices of its length


class LinkKeeper(Generic[L]):
    """Keeps one link up; ``link`` is None while there is none, and ``lost`` says why."""

    def __init__(
        self,
        label: str,
        *,
        connect: Callable[[], Awaitable[L]],
        serve: Callable[[L], Awaitable[str]],
        halt: Callable[[L], Awaitable[None]],
        drop: Callable[[L], Awaitable[None]],
        on_lost: Callable[[str], None] | None = None,
        reason: Callable[[BaseException], str] = str,
    ) -> None:
        self.label = label  # "the pioneer robot at 'pioneer+tcp://...'"
        self.link: L | None = None
        self.lost = "not connected yet"
        self._connect, self._serve, self._halt, self._drop = connect, serve, halt, drop
        self._on_lost = on_lost
        self._reason = reason
        self._task: asyncio.Task[None] | None = None

    @property
    def connected(self) -> bool:
        return self.link is not None

    async def open(self) -> L:
        """Connect once (errors go to the caller), then keep the link in a task."""
        self.link = await self._connect()
        self._task = asyncio.create_task(self._keep(), name=f"link to {self.label}")
        return self.link

    async def close(self, goodbye: Callable[[L], Awaitable[None]] | None = None) -> None:
        """Stop keeping the link; say ``goodbye`` on it (best effort, bounded), drop it."""
        task, self._task = self._task, None
        if task is not None:
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
        link, self.link = self.link, None
        self.lost = "closed"
        if link is None:
            return
        try:
            if goodbye is not None:
                with contextlib.suppress(OSError, RhalError):
                    await _bounded(goodbye(link))
        finally:
            await self._drop(link)

    def require(self) -> L:
        """The link, or RobotConnectionError saying why there is none."""
        if self.link is None:
            raise self.lost_error()
        return self.link

    def lost_error(self) -> RobotConnectionError:
        return RobotConnectionError(f"no link to {self.label} ({self.lost}); reconnecting")

    async def _keep(self) -> None:
        link = self.link
        while link is not None:
            reason = await self._serve_until_lost(link)
            self.link, self.lost = None, reason
            try:
                await self._stop_on(link)
            finally:
                if self._on_lost is not None:
                    self._on_lost(reason)
                await self._drop(link)
            link = await self._reconnect()
            self.link = link

    async def _serve_until_lost(self, link: L) -> str:
        try:
            return await self._serve(link)
        except (OSError, RhalError) as exc:
            return self._reason(exc) or type(exc).__name__
        except Exception as exc:  # a bug here must not leave a dead link looking alive
            logger.exception("serving the link to %s failed", self.label)
            return f"unexpected {type(exc).__name__}: {exc}"

    async def _stop_on(self, link: L) -> None:
        """Best effort: a link that no longer takes bytes is no reason to fail."""
        with contextlib.suppress(OSError, RhalError):
            await _bounded(self._halt(link))

    async def _reconnect(self) -> L:
        delay = BACKOFF_FIRST
        while True:
            await asyncio.sleep(delay)
            try:
                return await self._connect()
            except (OSError, RobotConnectionError) as exc:
                self.lost = f"reconnecting failed: {self._reason(exc)}"
                delay = min(2 * delay, BACKOFF_MAX)


# -- silence, as the robot made it --------------------------------------------------------------
# A process starved of the CPU (a busy machine; a program hogging the robot's computer) wakes
# to its timers before it reads what the robot sent meanwhile: its own sleep is not the
# robot's silence. Silence is therefore counted in slices, each at most its own length,
# however late the process got to it: as quick as before when the process runs on time.


async def heard_within(receive: Callable[[], Awaitable[T]], timeout: float | None) -> T:
    """``await receive()`` (cancel-safe: a stream read), or TimeoutError once the robot has
    been silent for ``timeout`` s of this process's waking time."""
    if timeout is None:
        return await receive()
    for _ in range(QUIET_SLICES):
        with contextlib.suppress(TimeoutError):
            async with asyncio.timeout(timeout / QUIET_SLICES):
                return await receive()
    raise TimeoutError


class QuietClock:
    """How long a peer has been silent, for a watcher that looks every ``step`` s: a look
    counts at most ``step`` since the one before, so a starved process's sleep counts once."""

    def __init__(self, step: float) -> None:
        self.step = step
        self.heard()

    def heard(self) -> None:
        self._quiet, self._looked = 0.0, time.monotonic()

    def look(self) -> float:
        """Seconds of silence so far."""
        now = time.monotonic()
        self._quiet += min(now - self._looked, self.step)
        self._looked = now
        return self._quiet


async def _bounded(step: Awaitable[None]) -> None:
    """A step on a link that may have stopped reading must not hang: TimeoutError after
    HALT_WAIT (an OSError, so callers suppressing link errors suppress it too)."""
    async with asyncio.timeout(HALT_WAIT):
        await step


class StreamLink:
    """A TCP or serial link: one StreamReader/StreamWriter pair."""

    def __init__(
        self,
        reader: asyncio.StreamReader,
        writer: asyncio.StreamWriter,
        timeout: float,
        peer: str = "robot",
    ) -> None:
        self._reader, self._writer, self._timeout, self._peer = reader, writer, timeout, peer

    async def read(self) -> bytes:
        data = await self._reader.read(4096)
        if not data:
            raise ConnectionResetError(f"the {self._peer} closed the link")
        return data

    async def send(self, data: bytes) -> None:
        if self._writer.is_closing():
            raise ConnectionResetError("the link is closed")
        self._writer.write(data)
        # Bounded: a peer that stopped reading must not hang a keep-alive or a drive().
        async with asyncio.timeout(self._timeout):
            await self._writer.drain()

    def abort(self) -> None:
        self._writer.transport.abort()

    async def close(self) -> None:
        self._writer.close()
        with contextlib.suppress(OSError):
            await self._writer.wait_closed()
