"""The router on real links: UDP, TCP, a pty that is unplugged and plugged again, and two
pymavlink clients commanding one emulated vehicle at once. Only 127.0.0.1."""

import asyncio
import os
import socket
import tty

from gateway.framing import Framer
from gateway.router import (
    Router,
    SerialEndpoint,
    TcpClientEndpoint,
    TcpServerEndpoint,
    UdpEndpoint,
)
from tests.gateway.frames import attitude, heartbeat, sink
from tests.rhal.mavlink_emulator import MavlinkEmulator
from tests.waiting import until


def free_port(kind=socket.SOCK_DGRAM) -> int:
    with socket.socket(socket.AF_INET, kind) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


async def test_endpoints_come_and_go_while_traffic_flows_without_loss_on_the_others():
    router = Router()
    vehicle = await router.add(UdpEndpoint(address=f"127.0.0.1:{free_port()}", mode="server"))
    sinks = [await sink() for _ in range(3)]
    a = await router.add(UdpEndpoint(address=sinks[0][2]))
    await router.add(UdpEndpoint(address=sinks[1][2]))  # b: never touched
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    target = ("127.0.0.1", int(vehicle.address.rsplit(":", 1)[1]))
    sent = [attitude(1, 1, t) for t in range(600)]
    extra = None
    for i, frame in enumerate(sent):
        out.sendto(frame, target)
        if i == 200:
            extra = await router.add(UdpEndpoint(address=sinks[2][2]))
        if i == 400:
            await router.remove(extra)
        if i == 300:
            await router.remove(a)
            a = await router.add(UdpEndpoint(address=sinks[0][2]))  # changed: same address
        await asyncio.sleep(0.0005 if i % 10 else 0.002)
    await until(lambda: len(sinks[1][1].frames) == len(sent))
    assert sinks[1][1].frames == sent  # b noticed nothing
    assert 150 <= len(sinks[2][1].frames) <= 250
    assert vehicle.stats.frames_in == len(sent) and vehicle.systems.keys() == {(1, 1)}
    out.close()
    await router.close()
    for transport, _, _ in sinks:
        transport.close()


async def test_tcp_server_clients_each_get_the_stream_and_reach_the_vehicle():
    router = Router()
    vehicle_sink = await sink()
    vehicle = await router.add(UdpEndpoint(address=vehicle_sink[2]))
    port = free_port(socket.SOCK_STREAM)
    server = await router.add(TcpServerEndpoint(address=f"127.0.0.1:{port}"))
    clients = [await asyncio.open_connection("127.0.0.1", port) for _ in range(2)]
    await until(lambda: len(server.clients) == 2)
    vehicle.received(heartbeat(1, 1))
    for reader, _ in clients:
        assert await reader.readexactly(len(heartbeat(1, 1))) == heartbeat(1, 1)
    clients[0][1].write(heartbeat(255, 190))
    await until(lambda: vehicle_sink[1].frames == [heartbeat(255, 190)])
    # the other client hears the first: a client is an endpoint of its own
    assert await clients[1][0].readexactly(len(heartbeat(255, 190))) == heartbeat(255, 190)
    clients[0][1].close()
    await until(lambda: len(server.clients) == 1)
    await router.close()
    vehicle_sink[0].close()


def pty_behind(link: str) -> int:
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    if os.path.lexists(link):
        os.unlink(link)
    os.symlink(os.ttyname(slave), link)
    os.close(slave)  # the router opens it by name
    return master


async def test_a_serial_device_that_disappears_is_retried_while_the_rest_keeps_routing(tmp_path):
    link = str(tmp_path / "ttyACM0")
    router = Router()
    gcs_sink = await sink()
    gcs = await router.add(UdpEndpoint(address=gcs_sink[2]))
    other = await router.add(UdpEndpoint(address=f"127.0.0.1:{free_port()}", mode="server"))
    serial = await router.add(SerialEndpoint(device=link, baud=57600, backoff=(0.05, 0.2)))
    await asyncio.sleep(0.2)  # not there yet: retrying, no crash
    assert not serial.connected.is_set() and serial.last_error
    master = pty_behind(link)
    await asyncio.wait_for(serial.connected.wait(), 5)
    os.write(master, heartbeat(1, 1))
    await until(lambda: gcs_sink[1].frames == [heartbeat(1, 1)])

    os.close(master)  # unplugged: the slave reads EIO
    os.unlink(link)
    await until(lambda: not serial.connected.is_set())
    other.received(attitude(7, 1))  # the rest keeps routing
    await until(lambda: gcs_sink[1].frames[-1:] == [attitude(7, 1)])

    master = pty_behind(link)  # plugged in again
    await asyncio.wait_for(serial.connected.wait(), 5)
    os.write(master, heartbeat(1, 1, version=1))
    await until(lambda: gcs_sink[1].frames[-1:] == [heartbeat(1, 1, version=1)])
    gcs.received(heartbeat(255, 190))
    data = b""
    while len(data) < len(heartbeat(255, 190)):
        await asyncio.sleep(0.01)
        try:
            data += os.read(master, 1024)
        except BlockingIOError:
            pass
    assert data == heartbeat(255, 190)
    await router.close()
    os.close(master)
    gcs_sink[0].close()


async def test_a_ground_station_and_a_program_command_one_vehicle_at_once():
    from pymavlink import mavutil

    emulator = MavlinkEmulator(link="tcp", heartbeat=0.2)
    await emulator.start()
    router = Router()
    vehicle = await router.add(TcpClientEndpoint(address=emulator.url.rsplit("/", 1)[1]))
    udp_port, tcp_port = free_port(), free_port(socket.SOCK_STREAM)
    await router.add(UdpEndpoint(address=f"127.0.0.1:{udp_port}", mode="server"))
    await router.add(TcpServerEndpoint(address=f"127.0.0.1:{tcp_port}"))
    await asyncio.wait_for(vehicle.connected.wait(), 5)

    def client(url, system):
        m = mavutil.mavlink_connection(url, source_system=system, source_component=190)
        try:
            m.mav.heartbeat_send(6, 8, 0, 0, 4)
            # the other client's heartbeats come too: that is routing, not an echo
            assert m.recv_match(type="HEARTBEAT", condition="HEARTBEAT.get_srcSystem() == 1",
                                blocking=True, timeout=5)  # fmt: skip
            acks = []
            for _ in range(3):
                m.mav.command_long_send(1, 1, 511, 0, 33, 100000, 0, 0, 0, 0, 0)
                ack = m.recv_match(type="COMMAND_ACK", blocking=True, timeout=5)
                target = Framer().feed(bytes(ack.get_msgbuf()))[0][4]  # whatever dialect
                acks.append((ack.command, ack.result, target))
            return acks
        finally:
            m.close()

    gcs, program = await asyncio.gather(
        asyncio.to_thread(client, f"udpout:127.0.0.1:{udp_port}", 255),
        asyncio.to_thread(client, f"tcp:127.0.0.1:{tcp_port}", 254),
    )
    assert gcs == [(511, 0, 255)] * 3  # each gets its own acks, none of the other's
    assert program == [(511, 0, 254)] * 3
    assert {c.source for c in emulator.commands} == {(255, 190), (254, 190)}
    await emulator.stop()
    await router.close()


async def test_a_tcp_client_reconnects_when_its_server_comes_back():
    port = free_port(socket.SOCK_STREAM)
    router = Router()
    client = await router.add(TcpClientEndpoint(address=f"127.0.0.1:{port}", backoff=(0.05, 0.1)))
    got = asyncio.Queue()

    async def serve(reader, writer):
        await got.put(await reader.readexactly(len(heartbeat(255, 190))))
        writer.close()

    for _ in range(2):  # up, dropped by the server, up again
        server = await asyncio.start_server(serve, "127.0.0.1", port)
        await asyncio.wait_for(client.connected.wait(), 5)
        client.queue(heartbeat(255, 190))
        client.flush()
        assert await asyncio.wait_for(got.get(), 5) == heartbeat(255, 190)
        server.close()
        await server.wait_closed()
        await until(lambda: not client.connected.is_set())
    await router.close()
