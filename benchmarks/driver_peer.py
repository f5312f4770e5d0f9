"""A driver's peer in a process of its own, so the driver's CPU is measured alone.

    python -m benchmarks.driver_peer KIND FOLDER

Prints ``url URL`` once the peer listens, then ``cmd T LINEAR ANGULAR`` each time the command
decoded off the wire changes (T: CLOCK_MONOTONIC seconds, the same clock in every process),
until its standard input closes.
"""

import asyncio
import sys
import time
from pathlib import Path

from tests.peers import start_peer

POLL = {"dtmf": 0.005}  # s between looks at the wire; decoding a WAV costs more
DEFAULT_POLL = 0.0002


async def serve(kind: str, folder: Path) -> None:
    peer = await start_peer(kind, folder, other_process=True)
    print("url", peer.url, flush=True)
    loop = asyncio.get_running_loop()
    closed = loop.run_in_executor(None, sys.stdin.read)  # EOF: the benchmark is done
    last = peer.commanded()
    try:
        while not closed.done():
            now = peer.commanded()
            if now != last:
                print("cmd", time.monotonic(), *now, flush=True)
                last = now
            await asyncio.sleep(POLL.get(kind, DEFAULT_POLL))
    finally:
        await peer.stop()


if __name__ == "__main__":
    asyncio.run(serve(sys.argv[1], Path(sys.argv[2])))
