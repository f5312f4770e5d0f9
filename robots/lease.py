"""The control lease: who may move a robot now, one program or one person driving by hand.

The first to drive takes the lease; while it is held, anyone else's drive() is refused with a
message naming the holder, and other people's pages show the controls read-only. A program
holds it until it ends; a person until they release it, leave the page, or leave the controls
alone for ``IDLE_SECONDS`` (then the next one may take it). Staff may take it over at any time.
An emergency stop clears it.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

IDLE_SECONDS = 30.0


class LeaseHeld(Exception):
    """Someone else controls the robot."""


@dataclass(frozen=True)
class Holder:
    kind: str  # "run", "teleop" or "bridge"
    key: int | str  # the run id, the browser's channel name, or "bridge HOST:PORT"
    user: str

    def describe(self) -> str:
        if self.kind == "run":
            return f"{self.user}'s program (run #{self.key})"
        if self.kind == "bridge":
            return f"a serial bridge client at {self.user}"
        return f"{self.user}, driving by hand"

    def as_dict(self) -> dict:
        return {"kind": self.kind, "key": self.key, "user": self.user, "text": self.describe()}


class ControlLease:
    def __init__(self, clock: Callable[[], float] = time.monotonic) -> None:
        self.holder: Holder | None = None
        self._clock = clock
        self._active_at = 0.0

    def acquire(self, holder: Holder, *, take_over: bool = False) -> bool:
        """Hold the lease (again); LeaseHeld if another holds it. True if it changed hands."""
        if self.holder == holder:
            self._active_at = self._clock()
            return False
        if self.holder is not None and not take_over and not self._idle():
            raise LeaseHeld(
                f"the robot is controlled by {self.holder.describe()}; "
                "wait until it is released, or ask staff to take over"
            )
        self.holder, self._active_at = holder, self._clock()
        return True

    def release(self, key: int | str) -> bool:
        """Let go if ``key`` holds the lease; True if it did."""
        if self.holder is not None and self.holder.key == key:
            self.holder = None
            return True
        return False

    def clear(self) -> bool:
        held, self.holder = self.holder is not None, None
        return held

    def holds(self, key: int | str) -> bool:
        return self.holder is not None and self.holder.key == key

    def _idle(self) -> bool:
        # A program holds until it ends; a person who left the controls alone lets go.
        return (
            self.holder is not None
            and self.holder.kind == "teleop"
            and self._clock() - self._active_at >= IDLE_SECONDS
        )
