"""A box made ahead of its run (no Django here).

Making a box is most of a start: bubblewrap's namespaces and mounts, the cgroup (on v1 a
move into it waits for an RCU grace period), the sockets of the run's 127.0.0.1. An agent
keeps one box ready per robot, made while nobody waits, so that a run's start is only its
own part: the program's file and command handed to the waiting box (runbox.box.Box.go).

    ahead = Ahead(make, prefix)      # make(name, key) -> RunProcess with its box, not spawned;
                                     # names (of cgroups) start with `prefix`
    ahead.soon(key)                  # a box for runs of `key` (their settings), made later
    ahead.soon(key, now=True)        # ... made at once (the robot has nothing to do)
    process = await ahead.take(key, name)   # that box if it fits, else one made now;
                                            # its cgroup is named `name` from then on
                                            # (on cgroup v1; v2 refuses renames: a box
                                            # made ahead keeps its name, `box-N`)
    await ahead.close()

A box made for other settings (`key`: limits, network, the robot's services) is not used,
and one that ended while it waited is made again at the next call.
"""

import asyncio
import contextlib
import itertools
import logging
from collections.abc import Callable, Hashable

from runbox.cgroups import CgroupError
from runbox.supervisor import RunProcess

log = logging.getLogger(__name__)


class Ahead:
    def __init__(
        self, make: Callable[[str, Hashable], RunProcess], prefix: str = "", delay: float = 0.1
    ):
        """`make(name, key)`: a RunProcess around a box for runs of `key`, whose cgroup is
        called `name`, not spawned yet; `delay`:
        how long after a start the next box is made (not while that run gets going)."""
        self.make, self.prefix, self.delay = make, prefix, delay
        self.ready: RunProcess | None = None
        self.key: Hashable = None
        self._making: asyncio.Task | None = None
        self._waiting = False  # _making has not begun yet
        self._serial = itertools.count(1)

    async def take(self, key: Hashable, name: str) -> RunProcess:
        """A prepared box for a run of `key`, its cgroup renamed prefix + `name`; made now if none
        waits (its processes then join the cgroup while the program starts)."""
        ready, self.ready = self.ready, None
        if ready is not None and self.key == key and ready.running and not ready.stop_requested:
            cgroup = ready.box.cgroup
            if cgroup is not None and cgroup.support.version == "v1":  # v2 refuses renames
                with contextlib.suppress(CgroupError):  # a name is for people: it may stay
                    cgroup.rename(self.prefix + name)
            self.soon(key)
            return ready
        if ready is not None:
            await discard(ready)
        process = self.make(self.prefix + name, key)
        await process.spawn(wait_for_cgroup=False)
        self.soon(key)
        return process

    def soon(self, key: Hashable, now: bool = False) -> None:
        """A box for runs of `key`, made after `delay` (`now`: at once, say when the robot
        has fallen idle) unless one is ready or on its way."""
        if self._making is not None and not self._making.done():
            if not (now and self._waiting):
                return
            self._making.cancel()  # it had not begun: begin at once instead
        if self.ready is not None and self.key == key:
            return
        self._making = asyncio.ensure_future(self._make(key, 0 if now else self.delay))

    async def _make(self, key: Hashable, delay: float) -> None:
        self._waiting = True
        try:
            await asyncio.sleep(delay)
        finally:
            self._waiting = False
        if self.ready is not None:
            await discard(self.ready)  # made for other settings
            self.ready = None
        process = None
        try:
            process = self.make(f"{self.prefix}box-{next(self._serial)}", key)
            await process.spawn(wait_for_cgroup=True)
        except asyncio.CancelledError:
            if process is not None:
                await discard(process)
            raise
        except Exception:
            log.exception("a box made ahead could not be spawned")
            if process is not None:
                await discard(process)
            return
        if process.stop_requested or not process.running:  # its box could not be made
            log.warning("a box made ahead could not be prepared: %s", process.outcome().reason)
            await discard(process)
            return
        self.ready, self.key = process, key
        asyncio.ensure_future(self._forget_if_it_ends(process))

    async def _forget_if_it_ends(self, process: RunProcess) -> None:
        await process.wait()
        if self.ready is process:  # it ended while it waited (killed from outside)
            self.ready = None
            await process.box.close()

    async def close(self) -> None:
        if self._making is not None:
            self._making.cancel()
            with contextlib.suppress(asyncio.CancelledError, Exception):
                await self._making
        ready, self.ready = self.ready, None
        if ready is not None:
            await discard(ready)


async def discard(process: RunProcess) -> None:
    """A box no run will use: its processes, sockets and cgroup go."""
    process.box.kill()
    if process.running:
        with contextlib.suppress(Exception):
            await asyncio.wait_for(process.wait(), 5)
    await process.box.close()
