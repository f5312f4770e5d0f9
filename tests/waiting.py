"""Waiting on something asynchronous (a wire, a bus, an agent) without betting on a timing."""

import asyncio
import inspect
import os
import signal
import subprocess
import sys
import time

# s: a deadline for an event, not how long it takes. Only a failing test waits it out, and a
# busy machine (a load of 10-20 on two cores) can take many seconds for what takes 0.1 s.
DEADLINE = 60.0


async def until(predicate, timeout=DEADLINE):
    """Wait for ``predicate`` (plain or async) to hold and return its value; the timeout only
    decides how long a failing test takes to say so."""
    deadline = time.monotonic() + timeout
    while True:
        result = predicate()
        if inspect.isawaitable(result):
            result = await result
        if result:
            return result
        assert time.monotonic() < deadline, "condition not met in time"
        await asyncio.sleep(0.01)


# Another process wakes this one: it waits until this one is stopped, so its sleep cannot
# begin (and the wake-up come) before the stop, however slowly either gets the CPU.
_WAKER = """
import os, signal, sys, time
pid, seconds = int(sys.argv[1]), float(sys.argv[2])
def state():
    with open(f"/proc/{pid}/stat") as stat:
        return stat.read().rpartition(")")[2].split()[0]
while state() != "T":
    time.sleep(0.005)
time.sleep(seconds)
os.kill(pid, signal.SIGCONT)
"""


def starve(seconds: float) -> None:
    """Freeze this whole process, every thread of it, for ``seconds`` (and however long the
    waker takes to come back): what a busy machine does to a process that gets no CPU. Its
    timers are all late when it wakes, and a peer in this process said nothing meanwhile."""
    waker = subprocess.Popen([sys.executable, "-c", _WAKER, str(os.getpid()), str(seconds)])
    os.kill(os.getpid(), signal.SIGSTOP)
    waker.wait()
