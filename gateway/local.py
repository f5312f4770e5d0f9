"""An endpoint inside this process: the mavlink:// driver's link through the router.

The driver reads and writes it as it would a socket (``read``, ``send``, ``abort``, ``close``),
so the program API, ground stations and pymavlink programs share one vehicle link.
"""

from __future__ import annotations

import asyncio
import collections
from dataclasses import dataclass

from gateway.router import Endpoint, Router


@dataclass(eq=False)
class LocalEndpoint(Endpoint):
    def __post_init__(self):
        super().__post_init__()
        self.name = self.name or "robot"
        self._chunks: collections.deque[bytes] = collections.deque()
        self._queued = 0
        self._readable = asyncio.Event()
        self.closed = False
        self._why = "the router link was closed"

    async def start(self):
        pass

    async def stop(self):
        self.closed = True
        self._readable.set()

    def backlog(self) -> int:
        return self._queued

    def send(self, frames: list[bytes]) -> None:
        if self.closed:
            raise OSError("closed")
        data = b"".join(frames)
        self._chunks.append(data)
        self._queued += len(data)
        self._readable.set()

    # -- the driver's side, as its other links

    async def read(self) -> bytes:
        while not self._chunks:
            if self.closed:
                raise ConnectionResetError(self._why)
            self._readable.clear()
            await self._readable.wait()
        data = b"".join(self._chunks)
        self._chunks.clear()
        self._queued = 0
        return data

    async def send_bytes(self, data: bytes) -> None:
        if self.closed:
            raise ConnectionResetError("the router link is closed")
        self.received(data)

    def abort(self, why: str = "") -> None:
        if self.router is not None:
            self.router.detach(self)
        self.closed = True
        self._why = why or self._why
        self._readable.set()

    async def close(self) -> None:
        self.abort()


class RouterLink:
    """What the driver holds: ``send`` named as its links name it."""

    def __init__(self, endpoint: LocalEndpoint):
        self.endpoint = endpoint
        self.read = endpoint.read
        self.send = endpoint.send_bytes
        self.abort = endpoint.abort
        self.close = endpoint.close


async def open_local_link(router: Router, name: str = "robot") -> RouterLink:
    return RouterLink(await router.add(LocalEndpoint(name=name)))
