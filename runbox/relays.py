"""Relays the agent owns: a socket inside a run's namespace <-> a service on the host.

A run on `loopback` reaches a host service (a MAVLink robot's programs endpoint, a port its
robot names) at the same 127.0.0.1 port inside its own namespace; the agent carries the bytes.
"""

import asyncio
import contextlib
import socket

UDP_MAX = 65535
UDP_PEERS_MAX = 64  # distinct sockets of one run talking through one UDP relay
TCP_CONNECTIONS_MAX = 64  # connections at once through one TCP relay (two agent fds each)


class Relay:
    """Something that serves a socket until closed."""

    async def close(self) -> None:
        raise NotImplementedError


class TcpRelay(Relay):
    def __init__(self, listener: socket.socket, target: tuple[str, int]):
        self.listener, self.target = listener, target
        self.server: asyncio.base_events.Server | None = None
        self.pipes: set[asyncio.Task] = set()

    async def start(self) -> "TcpRelay":
        self.server = await asyncio.start_server(self._accepted, sock=self.listener)
        return self

    async def _accepted(self, reader, writer) -> None:
        if len(self.pipes) >= TCP_CONNECTIONS_MAX:  # the run's fds must not use up the agent's
            writer.close()
            return
        task = asyncio.current_task()
        self.pipes.add(task)
        try:
            up_reader, up_writer = await asyncio.open_connection(*self.target)
        except OSError:  # the service is down: the program sees its connection closed
            writer.close()
            self.pipes.discard(task)
            return
        try:
            await asyncio.gather(_pipe(reader, up_writer), _pipe(up_reader, writer))
        finally:
            for w in (writer, up_writer):
                w.close()
            self.pipes.discard(task)

    async def close(self) -> None:
        if self.server is not None:
            self.server.close()
        for task in list(self.pipes):
            task.cancel()
        self.listener.close()


async def _pipe(reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
    with contextlib.suppress(ConnectionError, asyncio.IncompleteReadError):
        while data := await reader.read(65536):
            writer.write(data)
            await writer.drain()  # a slow side holds the other back, nothing piles up
    with contextlib.suppress(OSError):
        writer.write_eof()


class UdpRelay(Relay):
    """Each socket of the run gets its own socket towards the service, so replies find it."""

    def __init__(self, inside: socket.socket, target: tuple[str, int]):
        self.inside, self.target = inside, target
        self.outside: dict[tuple, asyncio.DatagramTransport] = {}
        self.opening: dict[tuple, list[bytes]] = {}  # datagrams waiting for their socket
        self.transport: asyncio.DatagramTransport | None = None

    async def start(self) -> "UdpRelay":
        loop = asyncio.get_running_loop()
        self.transport, _ = await loop.create_datagram_endpoint(
            lambda: _Datagrams(self._from_run), sock=self.inside
        )
        return self

    def _from_run(self, data: bytes, peer) -> None:
        out = self.outside.get(peer)
        if out is not None:
            out.sendto(data)
        elif peer in self.opening:
            self.opening[peer].append(data)
        elif len(self.outside) + len(self.opening) < UDP_PEERS_MAX:  # else dropped, as UDP may
            self.opening[peer] = [data]
            asyncio.ensure_future(self._open(peer))

    async def _open(self, peer) -> None:
        loop = asyncio.get_running_loop()
        back = lambda data, _: self.transport.sendto(data, peer)  # noqa: E731
        try:
            transport, _ = await loop.create_datagram_endpoint(
                lambda: _Datagrams(back), remote_addr=self.target
            )
        except OSError:
            self.opening.pop(peer, None)
            return
        self.outside[peer] = transport
        for data in self.opening.pop(peer, ()):
            transport.sendto(data)

    async def close(self) -> None:
        for transport in self.outside.values():
            transport.close()
        if self.transport is not None:
            self.transport.close()
        self.inside.close()


class _Datagrams(asyncio.DatagramProtocol):
    def __init__(self, received):
        self.received = received

    def datagram_received(self, data, addr) -> None:
        self.received(data, addr)

    def error_received(self, exc) -> None:  # e.g. ECONNREFUSED from a service that is down
        pass


async def relay_to_host(service: str, inside: socket.socket) -> Relay:
    """ "tcp:PORT" / "udp:PORT": the run's socket, carried to the same port on the host's
    loopback."""
    proto, port = service.split(":")
    relay = TcpRelay if proto == "tcp" else UdpRelay
    return await relay(inside, ("127.0.0.1", int(port))).start()
