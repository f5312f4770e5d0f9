"""Waiting on something asynchronous (a wire, a bus, an agent) without betting on a timing."""

import asyncio
import inspect
import time


async def until(predicate, timeout=10.0):
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
