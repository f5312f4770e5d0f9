"""The agent's relays between a run's 127.0.0.1 and the host's: what one run may make them hold."""

import asyncio
import socket

from runbox.relays import TCP_CONNECTIONS_MAX, TcpRelay


async def echo(reader, writer):
    while data := await reader.read(1024):
        writer.write(data)
        await writer.drain()
    writer.close()


async def answered(reader, writer) -> bool:
    try:
        writer.write(b"ping\n")
        await writer.drain()
        return await asyncio.wait_for(reader.readline(), 5) == b"ping\n"
    except (ConnectionError, OSError):
        return False


async def test_a_tcp_relay_carries_only_so_many_connections_at_once():
    """Each costs the agent two file descriptors: past TCP_CONNECTIONS_MAX the run's next
    connections are closed, and one closed makes room again."""
    service = await asyncio.start_server(echo, "127.0.0.1", 0)
    listener = socket.socket()
    listener.bind(("127.0.0.1", 0))
    listener.listen(200)
    relay = await TcpRelay(listener, service.sockets[0].getsockname()).start()
    address = listener.getsockname()
    try:
        clients = [await asyncio.open_connection(*address) for _ in range(TCP_CONNECTIONS_MAX)]
        assert all([await answered(*client) for client in clients])
        extra = [await asyncio.open_connection(*address) for _ in range(10)]
        assert not any([await answered(*client) for client in extra])
        clients[0][1].close()
        await asyncio.sleep(0.2)
        assert await answered(*await asyncio.open_connection(*address))
        for _, writer in clients + extra:
            writer.close()
    finally:
        await relay.close()
        service.close()
