"""The MAVLink router: endpoints (UDP, TCP, serial) and the routing rules between them.

Routing (the MAVLink routing rules, as mavlink-router applies them):
- each endpoint remembers the (system, component) pairs it has heard from;
- a frame with a target goes only to the endpoints where that target was seen (target component
  0: any component of the system); a frame without one (or target system 0) goes to all;
- never back to the endpoint it came from;
- ``allow`` / ``block`` message-id filters apply to frames entering and leaving an endpoint;
- ``read_only``: every frame from that endpoint is dropped (heartbeats too, so a watching ground
  station cannot hold off the vehicle's GCS failsafe); it still receives everything.

Each endpoint writes through its asyncio transport; when a transport holds more than
``queue_limit`` bytes unsent (a slow TCP client, a full serial line) new frames for it are
dropped and counted, so one slow endpoint never stalls the others. Frames routed from one read
are joined per destination: one datagram or write per read, not per frame (UDP datagrams are
kept under 1472 bytes; ground stations parse datagrams as byte streams).
"""

from __future__ import annotations

import asyncio
import contextlib
import itertools
import logging
import os
import socket
import time
from dataclasses import dataclass, field

from gateway.framing import Framer

log = logging.getLogger(__name__)
UDP_MAX = 1472
QUEUE_LIMIT = 256 * 1024
# A system or a UDP peer not heard from for this long is forgotten: a ground station that
# left, a program that ended. (Ground stations and MAVSDK send a HEARTBEAT every second.)
FORGET_AFTER = 30.0


@dataclass
class Stats:
    frames_in: int = 0
    bytes_in: int = 0
    frames_out: int = 0
    bytes_out: int = 0
    drops: int = 0  # frames not sent: queue full, filtered, read-only
    parse_errors: int = 0
    refused: int = 0  # commands its guard did not let through (no control of the vehicle)

    def as_dict(self) -> dict:
        return dict(self.__dict__)


class Rates:
    """Per-second rates of a Stats, from the difference between two samples."""

    FIELDS = ("frames_in", "frames_out", "bytes_in", "bytes_out", "drops", "parse_errors")

    def __init__(self):
        self._last: tuple[float, dict] | None = None
        self.per_second: dict[str, float] = dict.fromkeys(self.FIELDS, 0.0)

    def sample(self, stats: Stats, now: float) -> None:
        current = {name: getattr(stats, name) for name in self.FIELDS}
        if self._last is not None:
            then, previous = self._last
            span = now - then
            if span > 0:
                self.per_second = {
                    name: round((current[name] - previous[name]) / span, 1) for name in self.FIELDS
                }
        self._last = (now, current)


_ids = itertools.count(1)


@dataclass(eq=False)
class Endpoint:
    """The base: what the router knows of one link. Subclasses open and write it."""

    name: str = ""
    read_only: bool = False
    allow: frozenset[int] | None = None
    block: frozenset[int] = frozenset()
    queue_limit: int = QUEUE_LIMIT
    stats: Stats = field(default_factory=Stats)
    systems: dict = field(default_factory=dict)  # (sysid, compid) -> last seen (monotonic)
    id: int = field(default_factory=lambda: next(_ids))
    # guard(frame, msgid, sender, target) -> bool: whether a frame it sent may go on; None
    # lets all through (robots/gateway.py guards programs' and ground stations' commands).
    guard: object = None

    def __post_init__(self):
        self.router: Router | None = None
        self._sysids: set[int] = set()
        self._framer = Framer()
        self._pending: list[bytes] = []
        self.rates = Rates()
        self.last_error = ""
        self.commanded_at: float | None = None  # when its guard last let a command through

    # -- the router calls these
    async def start(self) -> None:
        raise NotImplementedError

    async def stop(self) -> None:
        raise NotImplementedError

    @property
    def idle(self) -> bool:
        """Nobody to send to yet (a UDP server no peer has reached): skipped, not a drop."""
        return False

    def accepts(self, msgid: int) -> bool:
        if self.allow is not None and msgid not in self.allow:
            return False
        return msgid not in self.block

    def sees(self, tsys: int, tcomp: int) -> bool:
        if tcomp == 0:
            return tsys in self._sysids
        return (tsys, tcomp) in self.systems

    def queue(self, frame: bytes) -> None:
        self._pending.append(frame)

    def flush(self) -> None:
        frames, self._pending = self._pending, []
        if self.backlog() > self.queue_limit:
            self.stats.drops += len(frames)
            return
        try:
            self.send(frames)
        except OSError:
            self.stats.drops += len(frames)
            return
        self.stats.frames_out += len(frames)
        self.stats.bytes_out += sum(map(len, frames))

    def backlog(self) -> int:
        return 0

    def send(self, frames: list[bytes]) -> None:
        """Write the frames; drop them (counted by the caller) if the link is down."""
        raise NotImplementedError

    # -- subclasses call this with what they read
    def received(self, data: bytes) -> None:
        self.stats.bytes_in += len(data)
        framer = self._framer
        errors = framer.errors
        frames = framer.feed(data)
        self.stats.parse_errors += framer.errors - errors
        if frames and self.router is not None:
            self.router.route(self, frames)

    def learn(self, sysid: int, compid: int) -> None:
        self.systems[(sysid, compid)] = time.monotonic()
        self._sysids.add(sysid)

    def forget_older_than(self, when: float) -> None:
        stale = [key for key, seen in self.systems.items() if seen < when]
        for key in stale:
            del self.systems[key]
        if stale:
            self._sysids = {sysid for sysid, _ in self.systems}

    @property
    def status(self) -> str:
        """ "up", or "down" with ``last_error`` saying why."""
        return "up"

    def as_dict(self) -> dict:
        now = time.monotonic()
        return {
            "id": self.id,
            "name": self.name,
            "read_only": self.read_only,
            "status": self.status,
            "error": self.last_error,
            "stats": self.stats.as_dict(),
            "rates": dict(self.rates.per_second),
            "commanding": None if self.commanded_at is None else round(now - self.commanded_at, 1),
            "systems": [
                {"system": sysid, "component": compid, "seen": round(now - seen, 1)}
                for (sysid, compid), seen in sorted(self.systems.items())
            ],
        }


class Router:
    def __init__(self):
        self.endpoints: dict[int, Endpoint] = {}
        # Called as tap(frames) once per read, with the frames that passed the source's filters
        # (a .tlog recorder): only bytes, so a slow tap is the tap's own business.
        self.taps: list = []

    async def add(self, endpoint: Endpoint) -> Endpoint:
        endpoint.router = self
        self.endpoints[endpoint.id] = endpoint
        try:
            await endpoint.start()
        except BaseException:
            self.endpoints.pop(endpoint.id, None)
            raise
        return endpoint

    def attach(self, endpoint: Endpoint) -> None:
        """An endpoint made by another (a TCP server's client) joins the routing."""
        endpoint.router = self
        self.endpoints[endpoint.id] = endpoint

    def detach(self, endpoint: Endpoint) -> None:
        self.endpoints.pop(endpoint.id, None)

    async def remove(self, endpoint: Endpoint) -> None:
        self.detach(endpoint)
        await endpoint.stop()

    async def close(self) -> None:
        for endpoint in list(self.endpoints.values()):
            await self.remove(endpoint)

    def route(self, source: Endpoint, frames: list[tuple]) -> None:
        stats = source.stats
        stats.frames_in += len(frames)
        others = [e for e in self.endpoints.values() if e is not source and not e.idle]
        touched = set()
        routed = [] if self.taps else None
        seen = source.systems
        guard = source.guard
        now = time.monotonic()
        for frame, sysid, compid, msgid, tsys, tcomp in frames:
            key = (sysid, compid)
            if key not in seen:
                source.learn(sysid, compid)
            else:
                seen[key] = now
            if source.read_only or not source.accepts(msgid):
                stats.drops += 1
                continue
            if guard is not None and not guard(frame, msgid, key, (tsys, tcomp)):
                stats.refused += 1
                continue
            if routed is not None:
                routed.append(frame)
            for endpoint in others:
                if tsys and not endpoint.sees(tsys, tcomp):
                    continue
                if not endpoint.accepts(msgid):
                    continue
                endpoint.queue(frame)
                touched.add(endpoint)
        for endpoint in touched:
            endpoint.flush()
        if routed:
            for tap in self.taps:
                tap(routed)

    def stats(self) -> list[dict]:
        return [e.as_dict() for e in self.endpoints.values()]

    def tick(self) -> None:
        """Once a second or so: the rates, and forget who has been silent too long."""
        now = time.monotonic()
        for endpoint in list(self.endpoints.values()):
            endpoint.rates.sample(endpoint.stats, now)
            endpoint.forget_older_than(now - FORGET_AFTER)

    async def ticking(self, period: float = 1.0) -> None:
        while True:
            self.tick()
            await asyncio.sleep(period)


# ---------------------------------------------------------------- endpoints


class _Stream(asyncio.Protocol):
    """Glue: an asyncio protocol feeding an endpoint."""

    def __init__(self, endpoint, on_lost=None):
        self.endpoint = endpoint
        self.on_lost = on_lost
        self.transport = None

    def connection_made(self, transport):
        self.transport = transport

    def data_received(self, data):
        self.endpoint.received(data)

    def connection_lost(self, exc):
        self.transport = None
        if self.on_lost:
            self.on_lost(exc)


def _batches(frames: list[bytes], limit: int):
    batch, size = [], 0
    for frame in frames:
        if size + len(frame) > limit and batch:
            yield b"".join(batch)
            batch, size = [], 0
        batch.append(frame)
        size += len(frame)
    if batch:
        yield b"".join(batch)


def host_port(address: tuple) -> str:
    host, port = address[:2]
    return f"[{host}]:{port}" if ":" in host else f"{host}:{port}"


def split_address(address: str) -> tuple[str, int]:
    host, _, port = address.rpartition(":")
    if host.startswith("[") and host.endswith("]"):  # [::1]:14550
        host = host[1:-1]
    if not host or not port.isdigit() or int(port) > 65535:
        raise ValueError(f"not HOST:PORT (port 0 to 65535): {address!r}")
    return host, int(port)


@dataclass(eq=False)
class UdpEndpoint(Endpoint):
    """``mode="client"``: sends to ``address``. ``"server"``: listens there, answers its peers.

    Not asyncio's datagram transport: it reads one datagram per loop iteration, which loses
    packets past ~25,000/s. Here each wakeup drains the socket and routes what came as one read.
    """

    address: str = "127.0.0.1:14550"
    mode: str = "client"

    def __post_init__(self):
        super().__post_init__()
        self.name = self.name or f"udp{'in' if self.mode == 'server' else ''}:{self.address}"
        self.peers: dict[tuple, float] = {}
        self._sock = None
        self.bound: tuple | None = None

    async def start(self):
        loop = asyncio.get_running_loop()
        host, port = split_address(self.address)
        info = await loop.getaddrinfo(host, port, type=socket.SOCK_DGRAM)
        family, _, _, _, addr = info[0]
        sock = socket.socket(family, socket.SOCK_DGRAM)
        try:
            sock.setblocking(False)
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
            if self.mode == "server":
                sock.bind(addr)
            else:
                sock.connect(addr)
        except OSError:
            sock.close()
            raise
        self._sock = sock
        self.bound = sock.getsockname()[:2]
        loop.add_reader(sock.fileno(), self._readable)

    async def stop(self):
        if self._sock is not None:
            asyncio.get_running_loop().remove_reader(self._sock.fileno())
            self._sock.close()
            self._sock = None

    @property
    def status(self) -> str:
        return "up" if self._sock is not None else "down"

    @property
    def idle(self) -> bool:
        return self.mode == "server" and not self.peers

    def forget_older_than(self, when: float) -> None:
        super().forget_older_than(when)
        for peer in [peer for peer, seen in self.peers.items() if seen < when]:
            del self.peers[peer]

    def as_dict(self) -> dict:
        row = super().as_dict()
        row["bound"] = host_port(self.bound) if self.bound else None
        if self.mode == "server":
            row["peers"] = [host_port(peer) for peer in self.peers]
        return row

    def _readable(self):
        sock, chunks = self._sock, []
        server = self.mode == "server"
        for _ in range(256):
            try:
                data, addr = sock.recvfrom(65536)
            except (BlockingIOError, InterruptedError):
                break
            except OSError:  # ICMP port unreachable: the peer is not up yet
                continue
            if server:
                self.peers[addr] = time.monotonic()
            chunks.append(data)
        if chunks:
            # Datagrams hold whole frames, so they can be framed as one stream.
            self.received(b"".join(chunks))

    def send(self, frames):
        sock = self._sock
        if sock is None:
            raise OSError("closed")
        if self.mode == "server" and not self.peers:
            raise OSError("no peer yet")
        for data in _batches(frames, UDP_MAX):
            try:
                if self.mode == "server":
                    for peer in list(self.peers):
                        sock.sendto(data, peer)
                else:
                    sock.send(data)
            except (BlockingIOError, ConnectionRefusedError):
                self.stats.drops += 1  # a datagram's worth: the peer is away or behind


@dataclass(eq=False)
class BoundUdpEndpoint(UdpEndpoint):
    """A UDP server on a socket bound elsewhere: a run's 127.0.0.1 port, made inside its own
    network namespace (runbox), served here as any other endpoint."""

    sock: object = None
    mode: str = "server"

    async def start(self):
        self._sock = self.sock
        self._sock.setblocking(False)
        self.bound = self._sock.getsockname()[:2]
        asyncio.get_running_loop().add_reader(self._sock.fileno(), self._readable)


@dataclass(eq=False)
class _Reconnecting(Endpoint):
    """A link that is opened, and opened again with backoff when it drops or fails to open."""

    backoff: tuple[float, float] = (0.1, 5.0)

    def __post_init__(self):
        super().__post_init__()
        self._transport = None
        self._task = None
        self._lost = asyncio.Event()
        self.connected = asyncio.Event()
        self.last_error = ""
        self.lost_listeners: list = []  # called with the reason when an open link drops

    async def _open(self):
        raise NotImplementedError

    async def start(self):
        self._task = asyncio.create_task(self._run(), name=self.name)

    async def _run(self):
        delay = self.backoff[0]
        while True:
            try:
                self._lost.clear()
                self._transport = await self._open()
            except (OSError, ValueError, Exception) as exc:  # noqa: B014 - serial raises its own
                self.last_error = str(exc)
                await asyncio.sleep(delay)
                delay = min(delay * 2, self.backoff[1])
                continue
            delay = self.backoff[0]
            self.last_error = ""
            self.connected.set()
            await self._lost.wait()
            self.connected.clear()
            self._transport = None
            self._framer = Framer()  # a new link starts mid-frame
            await asyncio.sleep(delay)

    @property
    def status(self) -> str:
        return "up" if self._transport is not None else "connecting"

    def _on_lost(self, exc):
        if exc:
            self.last_error = str(exc)
        self._lost.set()
        for listener in list(self.lost_listeners):
            listener(self.last_error or "closed by the other end")

    async def stop(self):
        if self._task:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        if self._transport:
            self._transport.close()

    def backlog(self):
        transport = self._transport
        return transport.get_write_buffer_size() if transport else 0

    def send(self, frames):
        transport = self._transport
        if transport is None or transport.is_closing():
            raise OSError("not connected")
        transport.write(b"".join(frames))


@dataclass(eq=False)
class TcpClientEndpoint(_Reconnecting):
    address: str = "127.0.0.1:5760"

    def __post_init__(self):
        super().__post_init__()
        self.name = self.name or f"tcp:{self.address}"

    async def start(self):
        split_address(self.address)  # a malformed address is an error now, not a retry loop
        await super().start()

    async def _open(self):
        host, port = split_address(self.address)
        transport, _ = await asyncio.get_running_loop().create_connection(
            lambda: _Stream(self, self._on_lost), host, port
        )
        return transport


@dataclass(eq=False)
class SerialEndpoint(_Reconnecting):
    device: str = ""
    baud: int = 115200

    def __post_init__(self):
        super().__post_init__()
        self.name = self.name or f"{self.device}:{self.baud}"

    async def _open(self):
        import serial_asyncio

        transport, _ = await serial_asyncio.create_serial_connection(
            asyncio.get_running_loop(), lambda: _Stream(self, self._on_lost), self.device,
            baudrate=self.baud,
        )  # fmt: skip
        # serial_asyncio reads 1 KiB a wakeup; a 921600-baud burst wants bigger reads.
        transport._max_read_size = 65536
        return transport

    def send(self, frames):
        transport = self._transport
        if transport is None or transport.is_closing():
            raise OSError("not connected")
        data = b"".join(frames)
        if not transport.get_write_buffer_size():
            # serial_asyncio writes only on a later turn of the loop (add_writer, wait for
            # writable, write, remove_writer), behind whatever that turn reads first: write now
            # what the device takes, and queue only the rest.
            try:
                data = data[os.write(transport.serial.fileno(), data) :]
            except (BlockingIOError, InterruptedError):
                pass
        if data:
            transport.write(data)


@dataclass(eq=False)
class _TcpConnection(Endpoint):
    def __post_init__(self):
        super().__post_init__()
        self._transport = None

    async def start(self):
        pass

    async def stop(self):
        if self._transport:
            self._transport.close()

    def backlog(self):
        return self._transport.get_write_buffer_size() if self._transport else 0

    def send(self, frames):
        if self._transport is None or self._transport.is_closing():
            raise OSError("closed")
        self._transport.write(b"".join(frames))


@dataclass(eq=False)
class TcpServerEndpoint(Endpoint):
    """Listens on ``address``; each client becomes an endpoint of its own while connected."""

    address: str = "127.0.0.1:5760"

    def __post_init__(self):
        super().__post_init__()
        self.name = self.name or f"tcpin:{self.address}"
        self._server = None
        self.clients: list[_TcpConnection] = []

    async def start(self):
        host, port = split_address(self.address)
        self._server = await asyncio.get_running_loop().create_server(self._protocol, host, port)
        self.bound = self._server.sockets[0].getsockname()[:2]

    def as_dict(self) -> dict:
        row = super().as_dict()
        row["bound"] = host_port(self.bound) if self._server else None
        row["clients"] = [client.name for client in self.clients]
        return row

    def _protocol(self):
        client = _TcpConnection(
            read_only=self.read_only, allow=self.allow, block=self.block,
            queue_limit=self.queue_limit,
        )  # fmt: skip
        protocol = _Stream(client)

        def made(transport):
            client._transport = transport
            peer = transport.get_extra_info("peername")
            client.name = f"{self.name} {peer[0]}:{peer[1]}" if peer else self.name
            self.clients.append(client)
            if self.router:
                self.router.attach(client)

        def lost(exc):
            client._transport = None
            with contextlib.suppress(ValueError):
                self.clients.remove(client)
            if self.router:
                self.router.detach(client)

        protocol.connection_made = made
        protocol.on_lost = lost
        return protocol

    async def stop(self):
        if self._server:
            self._server.close()
        for client in list(self.clients):
            if self.router:
                self.router.detach(client)
            await client.stop()

    def send(self, frames):  # the clients are endpoints; the listener itself sends nothing
        pass


def endpoint_from_spec(spec: str, *, vehicle: bool = False, baud: int = 115200) -> Endpoint:
    """``udp:H:P`` (client), ``udpin:H:P``, ``tcp:H:P`` (client), ``tcpin:H:P``,
    ``DEVICE[:BAUD]``. ``vehicle``: a bare ``udp:`` is where the vehicle sends, a server."""
    scheme, _, rest = spec.partition(":")
    if scheme == "udp":
        return UdpEndpoint(address=rest, mode="server" if vehicle else "client")
    if scheme == "udpout":
        return UdpEndpoint(address=rest, mode="client")
    if scheme == "udpin":
        return UdpEndpoint(address=rest, mode="server")
    if scheme == "tcp":
        return TcpClientEndpoint(address=rest)
    if scheme == "tcpin":
        return TcpServerEndpoint(address=rest)
    device, _, rate = spec.rpartition(":")
    if device and rate.isdigit():
        return SerialEndpoint(device=device, baud=int(rate))
    return SerialEndpoint(device=spec, baud=baud)
