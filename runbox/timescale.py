"""A run's clock at its sim's speed: a sim robot may run up to 10x faster than real time
(its driver's ``speed``), and its programs' clocks are sped up to match, so that a program's
``sleep(1)`` lasts one second of the sim's time (a tenth of a real second at 10x).

Debian's libfaketime does it: preloaded (``LD_PRELOAD``) into the run's program with
``FAKETIME="+0 x10"``, it scales what the C library tells of time (``clock_gettime`` for the
wall clock and the monotonic clock, ``gettimeofday``, ``time``) and what it waits for
(``nanosleep``, ``clock_nanosleep``, ``poll``, ``select``, ``epoll_wait``, condition
variables' and semaphores' timeouts). The first process it is loaded into makes a start time
in /dev/shm that the run's later processes share (through ``FAKETIME_SHARED``, which it puts
in their environment): a shell program's ``sleep`` and ``date`` read one clock. A box's
/dev/shm is its own, and goes with it.

The program's command is wrapped in ``env`` so that the program is the first process that
loads it: as root the box's ``setpriv`` runs before it as root, and would make that shared
start time root's alone. The library is under /usr, which every box sees (read-only).

What it does not reach: a program that reads the clock without the C library (a static
binary; the vDSO called directly) or that unsets ``LD_PRELOAD``; and the agent's side of the
Robot API (``receive``'s timeout, ``listen``'s seconds), which waits in real time.
"""

import glob
from functools import cache

from runbox.launcher import LauncherUnavailable

MAX_SPEED = 10
ENV = "/usr/bin/env"
# Debian's multiarch place (libfaketime's package); the plain library, as faketime(1) uses.
LIBRARY_GLOB = "/usr/lib/*/faketime/libfaketime.so.1"


class TimescaleUnavailable(LauncherUnavailable):
    """A sim faster than real time, and no libfaketime here: its runs are refused."""


@cache
def library() -> str | None:
    """libfaketime's path here, or None where it is not installed."""
    found = sorted(glob.glob(LIBRARY_GLOB))
    return found[0] if found else None


def speed_of(capabilities: dict) -> float:
    """A robot's speed, from its driver's capabilities(): a sim's ``sim.speed``, else 1."""
    sim = capabilities.get("sim")
    return float(sim.get("speed", 1)) if isinstance(sim, dict) else 1.0


def environment(speed: float) -> dict[str, str]:
    """What the run's processes get for `speed` (nothing at 1x)."""
    if speed == 1:
        return {}
    if not 1 < speed <= MAX_SPEED:
        raise ValueError(f"a sim's speed is 1 to {MAX_SPEED}, not {speed:g}")
    path = library()
    if path is None:
        raise TimescaleUnavailable(
            f"this sim runs at {speed:g}x real time, and its programs' clocks need libfaketime"
            " to keep up (as root: apt-get install libfaketime); or set its speed to 1"
        )
    return {"LD_PRELOAD": path, "FAKETIME": f"+0 x{speed:g}"}


def command(argv: list[str], speed: float) -> list[str]:
    """The program's command line with its clock at `speed` (as it is at 1x)."""
    env = environment(speed)
    if not env:
        return list(argv)
    return [ENV, *(f"{name}={value}" for name, value in env.items()), *argv]
