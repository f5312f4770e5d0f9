"""The serial bridge against a real pseudo-terminal: the test plays the robot on the master side,
the bridge opens the slave by name. TCP clients only on 127.0.0.1."""

import asyncio
import contextlib
import hashlib
import os
import socket
import termios
import time
import tty

import pytest
import serial

from gateway.serial_bridge import NO_TAP, SerialBridge
from tests.waiting import until

RUN = "driven by run 12 (alice)"


def pty() -> tuple[int, int, str]:
    """(master, slave, slave's path); the test keeps the slave open to read its termios."""
    master, slave = os.openpty()
    tty.setraw(master)
    tty.setraw(slave)
    os.set_blocking(master, False)
    return master, slave, os.ttyname(slave)


def pty_behind(link: str) -> int:
    """A device plugged in at ``link`` (a symlink, as udev makes them); returns the master."""
    master, slave, path = pty()
    if os.path.lexists(link):
        os.unlink(link)
    os.symlink(path, link)
    os.close(slave)
    return master


async def read_master(master: int, size: int) -> bytes:
    data = b""

    def enough():
        nonlocal data
        with contextlib.suppress(BlockingIOError):
            data += os.read(master, 65536)
        return len(data) >= size

    await until(enough)
    return data


def nothing_on(master: int) -> bool:
    try:
        os.read(master, 65536)
    except BlockingIOError:
        return True
    return False


def free_to_open(path: str) -> bool:
    """Nobody holds the device exclusively (the robot's driver could open it)."""
    try:
        serial.Serial(path, exclusive=True).close()
    except serial.SerialException:
        return False
    return True


class Lease:
    """The agent's side: grants or refuses, and counts. With ``path``, it notes whether the
    driver could open the device at each call (it must, for the agent to hand it over)."""

    def __init__(self, refuse=None, path=None):
        self.refuse, self.path = refuse, path
        self.acquired: list[str] = []
        self.released = 0
        self.free: list[tuple[str, bool]] = []

    async def acquire(self, peer):
        self.acquired.append(peer)
        if self.path:
            self.free.append(("acquire", free_to_open(self.path)))
        return self.refuse

    async def release(self):
        self.released += 1
        if self.path:
            self.free.append(("release", free_to_open(self.path)))


class Driver:
    """The robot's driver as the bridge's tap sees it."""

    def __init__(self):
        self.feeds = []

    def tap(self, feed):
        self.feeds.append(feed)
        return lambda: self.feeds.remove(feed)

    def reads(self, data):
        for feed in list(self.feeds):
            feed(data)


@contextlib.asynccontextmanager
async def running(bridge: SerialBridge):
    await bridge.start()
    try:
        yield bridge
    finally:
        await bridge.stop()


async def connect(bridge, rcvbuf=None):
    host, port = bridge.as_dict()["address"].rsplit(":", 1)
    sock = socket.socket()
    if rcvbuf:
        sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, rcvbuf)
    sock.setblocking(False)
    await asyncio.get_running_loop().sock_connect(sock, (host, int(port)))
    return await asyncio.open_connection(sock=sock)


async def closed_by_bridge(reader) -> bytes:
    return await asyncio.wait_for(reader.read(), 5)  # up to EOF


def modes(bridge):
    return [c["mode"] for c in bridge.as_dict()["clients"]]


# ---------------------------------------------------------------- raw


async def test_raw_bytes_go_both_ways_unchanged():
    master, slave, path = pty()
    async with running(SerialBridge(path, baud=57600, address="127.0.0.1:0")) as bridge:
        state = bridge.as_dict()
        assert state["address"].startswith("127.0.0.1:") and not state["address"].endswith(":0")
        assert state["device_open"] is False  # nobody asked yet
        reader, writer = await connect(bridge)
        await until(lambda: bridge.as_dict()["device_open"])
        everything = bytes(range(256))
        os.write(master, everything)
        assert await asyncio.wait_for(reader.readexactly(256), 5) == everything
        writer.write(everything[::-1])
        assert await read_master(master, 256) == everything[::-1]
        [client] = bridge.as_dict()["clients"]
        assert client["mode"] == "owner" and client["bytes_in"] == client["bytes_out"] == 256
        assert termios.tcgetattr(slave)[4] == termios.B57600
        writer.close()
        await until(lambda: not bridge.as_dict()["device_open"])
        assert bridge.as_dict()["clients"] == []
    os.close(master)
    os.close(slave)


async def test_a_bad_address_or_a_port_in_use_fails_at_start():
    with pytest.raises(ValueError):
        await SerialBridge("/dev/null", address="nowhere").start()
    with pytest.raises(ValueError):
        SerialBridge("/dev/null", protocol="telnet")
    with socket.socket() as taken:
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        with pytest.raises(OSError):
            await SerialBridge("/dev/null", address=f"127.0.0.1:{port}").start()


# ---------------------------------------------------------------- RFC 2217


async def test_rfc2217_with_pyserials_client_bytes_and_settings_reach_the_pty():
    master, slave, path = pty()
    bridge = SerialBridge(path, baud=115200, protocol="rfc2217", modem_poll=0.05)
    async with running(bridge):
        url = f"rfc2217://{bridge.as_dict()['address']}"
        client = await asyncio.to_thread(serial.serial_for_url, url, baudrate=9600, timeout=5)
        try:
            assert termios.tcgetattr(slave)[4:6] == [termios.B9600, termios.B9600]
            await asyncio.to_thread(client.write, b"\xffhello\x00\xff")
            assert await read_master(master, 8) == b"\xffhello\x00\xff"
            os.write(master, b"\xff\xfeworld\xff")
            assert await asyncio.to_thread(client.read, 8) == b"\xff\xfeworld\xff"

            # a change while open, not only the opening settings (it waits for the answer)
            await asyncio.to_thread(setattr, client, "baudrate", 57600)
            await until(lambda: termios.tcgetattr(slave)[4] == termios.B57600)

            # A second client watches: its settings are answered but never reach the device.
            watcher = await asyncio.to_thread(serial.serial_for_url, url, baudrate=300, timeout=5)
            try:
                assert modes(bridge) == ["owner", "read_only"]
                assert termios.tcgetattr(slave)[4] == termios.B57600
                await asyncio.to_thread(watcher.write, b"nope")
                await until(lambda: bridge.as_dict()["clients"][1]["dropped_in"] == 4)
                os.write(master, b"both")
                assert await asyncio.to_thread(client.read, 4) == b"both"
                assert await asyncio.to_thread(watcher.read, 4) == b"both"
                assert nothing_on(master)
            finally:
                await asyncio.to_thread(watcher.close)
        finally:
            await asyncio.to_thread(client.close)
        await until(lambda: not bridge.as_dict()["device_open"])
    os.close(master)
    os.close(slave)


# ---------------------------------------------------------------- ownership


async def test_a_busy_robot_refuses_the_client_at_once():
    master, slave, path = pty()
    lease = Lease(refuse=RUN)
    bridge = SerialBridge(path, when_busy="refuse", acquire=lease.acquire, release=lease.release)
    async with running(bridge):
        reader, writer = await connect(bridge)
        assert await closed_by_bridge(reader) == b""
        state = bridge.as_dict()
        assert state["refused"] == 1 and state["last_error"] == RUN
        assert state["clients"] == [] and not state["device_open"]
        assert len(lease.acquired) == 1 and lease.released == 0  # never granted: nothing to give
        assert free_to_open(path)
        writer.close()
    os.close(master)
    os.close(slave)


async def test_read_only_without_a_tap_is_a_refusal_that_says_why():
    master, slave, path = pty()
    lease = Lease(refuse=RUN)
    bridge = SerialBridge(path, when_busy="read_only", acquire=lease.acquire)
    async with running(bridge):
        reader, writer = await connect(bridge)
        assert await closed_by_bridge(reader) == b""
        assert bridge.as_dict()["refused"] == 1
        assert bridge.as_dict()["last_error"] == NO_TAP
        writer.close()
    os.close(master)
    os.close(slave)


async def test_a_watcher_gets_the_drivers_reads_and_its_writes_never_reach_the_device():
    master, slave, path = pty()
    lease, driver = Lease(refuse=RUN), Driver()
    bridge = SerialBridge(path, acquire=lease.acquire, release=lease.release, tap=driver.tap)
    async with running(bridge):
        reader, writer = await connect(bridge)
        await until(lambda: driver.feeds)
        assert modes(bridge) == ["read_only"]
        driver.reads(b"abc")
        assert await asyncio.wait_for(reader.readexactly(3), 5) == b"abc"
        await asyncio.to_thread(driver.reads, b"from the driver's thread")
        assert await asyncio.wait_for(reader.readexactly(24), 5) == b"from the driver's thread"

        writer.write(b"xyz")
        await until(lambda: bridge.as_dict()["clients"][0]["dropped_in"] == 3)
        assert nothing_on(master)
        assert not bridge.as_dict()["device_open"] and free_to_open(path)
        writer.close()
        await until(lambda: not driver.feeds)  # unsubscribed when it leaves
        assert lease.released == 0
    os.close(master)
    os.close(slave)


async def test_one_owner_at_a_time_and_the_device_goes_back_when_the_last_leaves():
    master, slave, path = pty()
    lease = Lease(path=path)
    bridge = SerialBridge(path, acquire=lease.acquire, release=lease.release)
    async with running(bridge):
        (a_reader, a_writer), (b_reader, b_writer) = await connect(bridge), await connect(bridge)
        await until(lambda: modes(bridge) == ["owner", "read_only"])
        assert lease.acquired == [bridge.as_dict()["clients"][0]["peer"]]
        assert not free_to_open(path)  # held exclusively while clients need it

        os.write(master, b"hi")
        assert await asyncio.wait_for(a_reader.readexactly(2), 5) == b"hi"
        assert await asyncio.wait_for(b_reader.readexactly(2), 5) == b"hi"
        b_writer.write(b"nope")
        await until(lambda: bridge.as_dict()["clients"][1]["dropped_in"] == 4)
        a_writer.write(b"yes")
        assert await read_master(master, 3) == b"yes"

        a_writer.close()  # the owner leaves, the watcher stays: the device stays with the bridge
        await until(lambda: modes(bridge) == ["read_only"])
        assert bridge.as_dict()["device_open"] and lease.released == 0
        c_reader, c_writer = await connect(bridge)  # nobody owns it: the newcomer does
        await until(lambda: modes(bridge) == ["read_only", "owner"])
        c_writer.write(b"c")
        assert await read_master(master, 1) == b"c"
        assert len(lease.acquired) == 1  # the lease was still held

        b_writer.close()
        c_writer.close()
        await until(lambda: lease.released == 1)
        assert not bridge.as_dict()["device_open"]
        assert free_to_open(path)  # the robot's driver can have it back
    assert lease.released == 1
    # asked before the bridge opened it, given back after it closed it
    assert lease.free == [("acquire", True), ("release", True)]
    os.close(master)
    os.close(slave)


# ---------------------------------------------------------------- unplugged


async def test_an_unplugged_device_closes_its_clients_and_works_again_after_replug(tmp_path):
    link = str(tmp_path / "ttyUSB0")
    master = pty_behind(link)
    lease = Lease()
    bridge = SerialBridge(link, acquire=lease.acquire, release=lease.release)
    async with running(bridge):
        reader, writer = await connect(bridge)
        await until(lambda: bridge.as_dict()["device_open"])
        os.write(master, b"before")
        assert await asyncio.wait_for(reader.readexactly(6), 5) == b"before"

        os.close(master)  # unplugged: the slave reads EIO
        os.unlink(link)
        assert await closed_by_bridge(reader) == b""
        await until(lambda: lease.released == 1)
        state = bridge.as_dict()
        assert state["last_error"].startswith("device lost") and not state["device_open"]
        writer.close()

        reader, writer = await connect(bridge)  # still unplugged: a clear refusal
        assert await closed_by_bridge(reader) == b""
        assert bridge.as_dict()["last_error"].startswith(f"cannot open {link}")
        await until(lambda: lease.released == 2)  # granted, then given back
        writer.close()

        master = pty_behind(link)  # plugged in again
        reader, writer = await connect(bridge)
        await until(lambda: bridge.as_dict()["device_open"])
        assert bridge.as_dict()["last_error"] == ""
        os.write(master, b"after")
        assert await asyncio.wait_for(reader.readexactly(5), 5) == b"after"
        writer.write(b"back")
        assert await read_master(master, 4) == b"back"
        writer.close()
        await until(lambda: lease.released == 3)
    os.close(master)


# ---------------------------------------------------------------- floods


async def stalled(progress, quiet=0.3, timeout=20.0):
    """Wait for ``progress()`` (a growing count) to stop growing for ``quiet`` seconds."""
    deadline = time.monotonic() + timeout
    last, since = progress(), time.monotonic()
    while time.monotonic() - since < quiet:
        assert time.monotonic() < deadline, "never stalled"
        await asyncio.sleep(0.02)
        now = progress()
        if now != last:
            last, since = now, time.monotonic()
    return last


async def test_a_flooding_device_is_held_back_by_the_owner_and_dropped_for_a_watcher():
    master, slave, path = pty()
    limit = 16 * 1024
    bridge = SerialBridge(path, queue_limit=limit)
    async with running(bridge):
        owner_reader, owner_writer = await connect(bridge, rcvbuf=4096)
        watcher_reader, watcher_writer = await connect(bridge, rcvbuf=4096)
        await until(lambda: modes(bridge) == ["owner", "read_only"])
        sent, total = hashlib.sha256(), 0
        chunk = os.urandom(65536)

        def flood():
            nonlocal total
            with contextlib.suppress(BlockingIOError):
                n = os.write(master, chunk)
                sent.update(chunk[:n])
                total += n
            return total

        async def flooding():
            while True:
                flood()
                await asyncio.sleep(0)

        flooder = asyncio.create_task(flooding())
        await stalled(lambda: total)  # nobody reads: the device is no longer read either
        for client in bridge.as_dict()["clients"]:  # bounded: the limit and one read
            assert client["queued"] <= limit + 65536
        flooder.cancel()

        got, received = hashlib.sha256(), 0
        while received < total:  # the owner lost nothing
            data = await asyncio.wait_for(owner_reader.read(1 << 20), 5)
            got.update(data)
            received += len(data)
        assert got.digest() == sent.digest()
        watcher = bridge.as_dict()["clients"][1]
        assert watcher["dropped_out"] > 0 and watcher["bytes_out"] + watcher["dropped_out"] == total
        owner_writer.close()
        watcher_writer.close()
    os.close(master)
    os.close(slave)


async def test_a_flooding_client_is_held_back_by_the_device():
    master, slave, path = pty()
    limit = 16 * 1024
    bridge = SerialBridge(path, queue_limit=limit)
    async with running(bridge):
        reader, writer = await connect(bridge)
        await until(lambda: bridge.as_dict()["device_open"])
        sent, chunk, total = hashlib.sha256(), os.urandom(65536), 0

        async def flooding():
            nonlocal total
            while True:
                writer.write(chunk)
                sent.update(chunk)
                total += len(chunk)
                await writer.drain()

        flooder = asyncio.create_task(flooding())
        await stalled(lambda: bridge.as_dict()["clients"][0]["bytes_in"])
        # bounded: the limit and one socket read (asyncio reads up to 256 KiB at once)
        assert bridge.as_dict()["device_queued"] <= limit + 256 * 1024
        flooder.cancel()
        got, received = hashlib.sha256(), 0
        done = asyncio.get_running_loop().create_future()

        def drain_master():  # everything written reaches the device, in order
            nonlocal received
            with contextlib.suppress(BlockingIOError):
                while received < total:  # a pty hands out a few KiB a read
                    data = os.read(master, 1 << 20)
                    got.update(data)
                    received += len(data)
            if received >= total and not done.done():
                done.set_result(None)

        asyncio.get_running_loop().add_reader(master, drain_master)
        try:
            await asyncio.wait_for(done, 20)
        finally:
            asyncio.get_running_loop().remove_reader(master)
        assert received == total and got.digest() == sent.digest()
        writer.close()
    os.close(master)
    os.close(slave)
