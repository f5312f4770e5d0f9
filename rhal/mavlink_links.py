"""The transports under the mavlink:// driver: a stream (TCP, serial) or a UDP socket, and
the URL that names one."""

from __future__ import annotations

import asyncio
import math
from typing import Any
from urllib.parse import urlsplit

from pymavlink.dialects.v20 import ardupilotmega as mavlink2

from rhal.linked import StreamLink

DEFAULT_DEVICE = "/dev/ttyACM0"
DEFAULT_HOST, DEFAULT_TCP_PORT = "127.0.0.1", 5760
DEFAULT_UDP_PORT = 14550
WILDCARD_HOSTS = ("", "0.0.0.0", "::")


class _DatagramLink(asyncio.DatagramProtocol):
    """UDP: to a fixed vehicle address, or (listening) back to whoever sent to us last."""

    def __init__(self, remote: tuple[str, int] | None) -> None:
        self._remote = remote
        self._peer = remote
        self._queue: asyncio.Queue[bytes | None] = asyncio.Queue()
        self._transport: asyncio.DatagramTransport | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        self._transport = transport  # type: ignore[assignment]

    def datagram_received(self, data: bytes, addr: tuple[str, int]) -> None:
        if self._remote is None:
            self._peer = addr
        self._queue.put_nowait(data)

    def error_received(self, exc: Exception) -> None:
        pass  # e.g. ICMP port unreachable while the vehicle is down: the silence tells

    def connection_lost(self, exc: Exception | None) -> None:
        self._queue.put_nowait(None)

    async def read(self) -> bytes:
        data = await self._queue.get()
        if data is None:
            self._queue.put_nowait(None)
            raise ConnectionResetError("the UDP socket was closed")
        return data

    async def send(self, data: bytes) -> None:
        if self._transport is None or self._transport.is_closing():
            raise ConnectionResetError("the UDP socket is closed")
        if self._peer is None:
            return  # listening, and no vehicle has sent to us yet
        self._transport.sendto(data, None if self._remote else self._peer)

    def abort(self) -> None:
        if self._transport is not None:
            self._transport.abort()

    async def close(self) -> None:
        if self._transport is not None:
            self._transport.close()


_Link = StreamLink | _DatagramLink


def _new_parser() -> Any:
    parser = mavlink2.MAVLink(None)
    parser.robust_parsing = True  # bad bytes become BAD_DATA messages, never exceptions
    return parser


def _parse_url(
    url: str, listen: bool | None
) -> tuple[str | None, tuple[str, int] | None, bool | None]:
    """``(serial device, None, None)`` or ``(None, (host, port), listen)``; listen is None
    for TCP, True or False for UDP."""
    parts = urlsplit(url)
    scheme = parts.scheme.lower()
    if listen is not None and scheme != "mavlink+udp":
        raise ValueError(f"the listen option is for mavlink+udp:// URLs only, not {url!r}")
    if scheme == "mavlink":
        # mavlink://COM3 names a Windows port in the host part.
        return (parts.netloc + parts.path) or DEFAULT_DEVICE, None, None
    try:
        port = parts.port
    except ValueError:
        raise ValueError(f"bad port in {url!r}") from None
    if scheme == "mavlink+tcp":
        return None, (parts.hostname or DEFAULT_HOST, port or DEFAULT_TCP_PORT), None
    if scheme == "mavlink+udp":
        host = parts.hostname or ""
        if listen is None:
            listen = host in WILDCARD_HOSTS
        else:
            listen = _flag("listen", listen)
        if not listen and host in WILDCARD_HOSTS:
            raise ValueError(f"listen=false needs the vehicle's address in {url!r}")
        return None, (host, port or DEFAULT_UDP_PORT), listen
    raise ValueError(
        f"not a mavlink URL: {url!r}; use mavlink:///dev/..., mavlink+tcp:// or mavlink+udp://"
    )


def _positive(kind: type, name: str, value: Any) -> Any:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name} must be a number, got {value!r}")
    result = kind(value)
    if not (result > 0 and math.isfinite(result)):
        raise ValueError(f"{name} must be greater than 0, got {value!r}")
    return result


def _flag(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return value
