"""The control lease: who may move a robot now, one program or one person driving by hand.

The first to drive takes the lease; while it is held, anyone else's drive() is refused with a
message naming the holder, and other people's pages show the controls read-only. A program
holds it until it ends; a person until they release it, leave the page, or leave the controls
alone for ``IDLE_SECONDS`` (then the next one may take it). Staff may take it over at any time.
An emergency stop takes it from whoever holds it, and nobody may take it from the emergency
stop, staff included: only resuming (``end_estop``) lets the robot move again.
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass

IDLE_SECONDS = 30.0
ESTOP = "estop"  # the emergency stop's key as a holder


class LeaseHeld(Exception):
    """Someone else controls the robot."""


@dataclass(frozen=True)
class Holder:
    kind: str  # "run", "teleop", "bridge" or "estop"
    key: int | str  # the run id, the browser's channel name, "bridge HOST:PORT" or "estop"
    user: str

    def describe(self) -> str:
        if self.kind == "estop":
            return f"the emergency stop {self.user} pressed"
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
        if self.estopped:
            raise LeaseHeld(
                f"{self.holder.describe()} holds the robot: nothing moves it until staff, its"
                " owner or the one who pressed it resumes (on the robot's page)"
            )
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

    def estop(self, by: str) -> None:
        """Taken from whoever holds it, until end_estop()."""
        self.holder = Holder("estop", ESTOP, by)

    def end_estop(self) -> bool:
        """The robot may move again; True if it had been emergency-stopped."""
        if self.estopped:
            self.holder = None
            return True
        return False

    @property
    def estopped(self) -> bool:
        return self.holder is not None and self.holder.kind == "estop"

    def release(self, key: int | str) -> bool:
        """Let go if ``key`` holds the lease; True if it did (never the emergency stop's)."""
        if self.holder is not None and self.holder.key == key and not self.estopped:
            self.holder = None
            return True
        return False

    def holds(self, key: int | str) -> bool:
        return self.holder is not None and self.holder.key == key

    def _idle(self) -> bool:
        # A program holds until it ends; a person who left the controls alone lets go.
        return (
            self.holder is not None
            and self.holder.kind == "teleop"
            and self._clock() - self._active_at >= IDLE_SECONDS
        )
