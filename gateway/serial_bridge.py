"""The serial bridge: one serial device of the robot shared over TCP, raw or RFC 2217.

A remote tool (a Pioneer client library, a terminal, a flasher) reaches the device as if it were
plugged into its own machine. The robot's exclusive-ownership rule holds here too:

- the device is opened (``exclusive=True``: no one else on the machine opens it meanwhile) only
  while a client needs it, and closed when the last one leaves, so the robot's own driver can
  have it back;
- before opening, the bridge awaits ``acquire(peer)``: the agent takes the robot's control lease
  for that client and closes its driver if the driver uses this device. It returns None when
  granted, or the reason it is not ("driven by run 12 (alice)");
- refused, ``when_busy="refuse"`` closes the connection; ``"read_only"`` admits the client as a
  watcher of what the driver reads, through ``tap`` (without a tap, it is refused after all);
- one owner at a time: a client that comes while the bridge holds the device watches it;
  the role is decided on arrival and never changes while connected. A client that comes while
  the device is open and nobody owns it (the owner left, watchers stayed) is the owner;
- the lease is held from the first grant until the device is closed, then ``release()``.

Watchers' writes are dropped and counted; RFC 2217 settings they negotiate are answered but never
reach the device. Memory stays bounded: the owner and the device pause each other (the owner's
socket full pauses reading the device, the device's write buffer full pauses reading the owner);
a watcher that does not keep up loses bytes, counted.
"""

from __future__ import annotations

import asyncio
import contextlib
import inspect
import logging
import termios
import time
from collections.abc import Awaitable, Callable

from gateway.router import split_address

log = logging.getLogger(__name__)
QUEUE_LIMIT = 256 * 1024
READ_SIZE = 65536  # serial_asyncio reads 1 KiB a wakeup; a 921600-baud burst wants bigger reads
CLOSE_TIMEOUT = 2.0
NO_TAP = "read-only watching needs the driver's tap"

Acquire = Callable[[str], "Awaitable[str | None] | str | None"]
Release = Callable[[], "Awaitable[None] | None"]
Tap = Callable[[Callable[[bytes], None]], Callable[[], None]]


async def _maybe_await(result):
    if inspect.isawaitable(result):
        return await result
    return result


class _Port:
    """The device's pyserial object as a PortManager sees it. A pty or a USB adapter without
    modem lines reads them as off instead of raising, a DTR/RTS/break it cannot set is ignored,
    and a setting the driver rejects is a ValueError, which PortManager answers with the setting
    kept (the client then knows its change did not happen)."""

    _SETTINGS = frozenset({"baudrate", "bytesize", "parity", "stopbits", "xonxoff", "rtscts"})
    _LINES_IN = frozenset({"cts", "dsr", "ri", "cd"})

    def __init__(self, port):
        object.__setattr__(self, "_port", port)

    def __getattr__(self, name):
        try:
            return getattr(self._port, name)
        except (OSError, termios.error):  # SerialException is an OSError
            if name in self._LINES_IN:
                return False
            raise

    def __setattr__(self, name, value):
        try:
            setattr(self._port, name, value)
        except (OSError, termios.error) as exc:
            if name in self._SETTINGS:
                raise ValueError(str(exc)) from exc

    def reset_input_buffer(self):
        self._quietly(self._port.reset_input_buffer)

    def reset_output_buffer(self):
        self._quietly(self._port.reset_output_buffer)

    @staticmethod
    def _quietly(call):
        try:
            call()
        except (OSError, termios.error):
            pass


class _Settings:
    """What a watcher's RFC 2217 negotiation talks to: its settings are answered, never applied."""

    def __init__(self, baud: int):
        self.baudrate, self.bytesize, self.parity, self.stopbits = baud, 8, "N", 1
        self.xonxoff = self.rtscts = self.dtr = self.rts = self.break_condition = False
        self.cts = self.dsr = self.ri = self.cd = False

    def reset_input_buffer(self):
        pass

    def reset_output_buffer(self):
        pass


class _Client(asyncio.Protocol):
    """One TCP client. ``mode`` is None until admitted, then "owner" or "read_only"."""

    def __init__(self, bridge: SerialBridge):
        self.bridge = bridge
        self.transport = None
        self.peer = ""
        self.mode: str | None = None
        self.via_tap = False  # watching the driver's reads, not the bridge's
        self.since = time.time()
        self.bytes_in = self.bytes_out = 0  # from / to the client
        self.dropped_in = 0  # bytes it sent that never went to the device (read-only)
        self.dropped_out = 0  # bytes for it dropped because it did not keep up
        self.port_manager = None  # RFC 2217
        self.unsubscribe: Callable[[], None] | None = None
        self.gone = False

    # -- asyncio
    def connection_made(self, transport):
        self.transport = transport
        transport.pause_reading()  # nothing goes anywhere before the bridge decides
        transport.set_write_buffer_limits(high=self.bridge.queue_limit)
        peer = transport.get_extra_info("peername")
        self.peer = f"{peer[0]}:{peer[1]}" if peer else "?"
        self.bridge._arrived(self)

    def data_received(self, data):
        self.bridge._from_client(self, data)

    def pause_writing(self):
        if self.mode == "owner":
            self.bridge._hold_device(True)

    def resume_writing(self):
        if self.mode == "owner":
            self.bridge._hold_device(False)

    def connection_lost(self, exc):
        self.gone = True
        self.bridge._left(self)

    # -- the bridge
    def write(self, data: bytes) -> None:
        """Telnet answers (PortManager's connection) and device bytes both come here."""
        transport = self.transport
        if transport.is_closing():
            return
        # The owner is held back by pausing the device instead (see _hold_device).
        if self.mode != "owner" and transport.get_write_buffer_size() > self.bridge.queue_limit:
            self.dropped_out += len(data)
            return
        transport.write(data)
        self.bytes_out += len(data)

    def close(self) -> None:
        """Close after what is queued for it went out, or soon anyway (it may not be reading)."""
        transport = self.transport
        if transport is not None and not transport.is_closing():
            transport.close()
            asyncio.get_running_loop().call_later(CLOSE_TIMEOUT, transport.abort)

    def as_dict(self) -> dict:
        return {
            "peer": self.peer,
            "mode": self.mode,
            "since": self.since,
            "bytes_in": self.bytes_in,
            "bytes_out": self.bytes_out,
            "dropped_in": self.dropped_in,
            "dropped_out": self.dropped_out,
            "queued": self.transport.get_write_buffer_size() if self.transport else 0,
        }


class _Device(asyncio.Protocol):
    """The serial side: one instance per open, so a late callback of an old one is told apart."""

    def __init__(self, bridge: SerialBridge, transport=None):
        self.bridge = bridge
        self.transport = transport
        self.closed = asyncio.get_running_loop().create_future()

    def data_received(self, data):
        self.bridge._from_device(data)

    def pause_writing(self):
        self.bridge._hold_owner(True)

    def resume_writing(self):
        self.bridge._hold_owner(False)

    def connection_lost(self, exc):
        if not self.closed.done():
            self.closed.set_result(exc)
        self.bridge._device_gone(self, exc)


class SerialBridge:
    """Share ``device`` on ``address`` (``HOST:PORT``; port 0 picks one, ``as_dict`` tells it).

    ``acquire(peer) -> None | reason`` and ``release()`` may be plain or async; ``tap(feed)``
    subscribes ``feed(bytes)`` to what the robot's driver reads from the device and returns the
    unsubscribe function (``feed`` may be called from any thread).
    """

    def __init__(
        self,
        device: str,
        baud: int = 115200,
        address: str = "127.0.0.1:0",
        protocol: str = "raw",
        when_busy: str = "read_only",
        acquire: Acquire | None = None,
        release: Release | None = None,
        tap: Tap | None = None,
        *,
        queue_limit: int = QUEUE_LIMIT,
        modem_poll: float = 1.0,
    ):
        if protocol not in ("raw", "rfc2217"):
            raise ValueError(f"protocol: 'raw' or 'rfc2217', not {protocol!r}")
        if when_busy not in ("read_only", "refuse"):
            raise ValueError(f"when_busy: 'read_only' or 'refuse', not {when_busy!r}")
        self.device, self.baud, self.address = device, baud, address
        self.protocol, self.when_busy = protocol, when_busy
        self.acquire, self.release, self.tap = acquire, release, tap
        self.queue_limit, self.modem_poll = queue_limit, modem_poll
        self.refused = 0
        self.last_error = ""
        self._server = None
        self._loop = None
        self._clients: list[_Client] = []  # admitted, in order of arrival
        self._waiting: set[_Client] = set()  # connected, not decided yet
        self._device: _Device | None = None
        self._leased = False
        self._device_full = False  # its write buffer is over the limit: the owner is paused
        self._lock = asyncio.Lock()  # one decision at a time: acquire, open, close, release
        self._tasks: set[asyncio.Task] = set()
        self._stopping = False

    # ------------------------------------------------------------ lifecycle

    async def start(self) -> None:
        host, port = split_address(self.address)
        self._loop = asyncio.get_running_loop()
        self._server = await self._loop.create_server(lambda: _Client(self), host, port)
        bound = self._server.sockets[0].getsockname()
        self.address = f"{bound[0]}:{bound[1]}"
        if self.protocol == "rfc2217":
            self._spawn(self._poll_modem_lines(), name="modem-lines")
        log.info("serial bridge %s on %s (%s)", self.device, self.address, self.protocol)

    async def stop(self) -> None:
        self._stopping = True
        if self._server is not None:
            self._server.close()
        for client in [*self._clients, *self._waiting]:
            client.transport.abort()
        await asyncio.sleep(0)  # their connection_lost runs
        await self._drain_tasks()
        async with self._lock:
            await self._give_back()
        if self._server is not None:
            await self._server.wait_closed()
            self._server = None

    def evict(self) -> int:
        """Every client goes now (an emergency stop): the device is given back once they
        have. How many there were."""
        clients = [*self._clients, *self._waiting]
        for client in clients:
            client.transport.abort()
        return len(clients)

    async def _drain_tasks(self) -> None:
        while self._tasks:
            for task in list(self._tasks):
                if task.get_name() == "modem-lines":
                    task.cancel()
            await asyncio.gather(*self._tasks, return_exceptions=True)

    def as_dict(self) -> dict:
        device = self._device
        return {
            "device": self.device,
            "baud": self.baud,
            "address": self.address,
            "protocol": self.protocol,
            "when_busy": self.when_busy,
            "clients": [c.as_dict() for c in self._clients],
            "refused": self.refused,
            "device_open": device is not None,
            "device_queued": device.transport.get_write_buffer_size() if device else 0,
            "last_error": self.last_error,
        }

    def _spawn(self, coro, name=None) -> None:
        task = asyncio.get_running_loop().create_task(coro, name=name)
        self._tasks.add(task)
        task.add_done_callback(self._task_done)

    def _task_done(self, task) -> None:
        self._tasks.discard(task)
        if not task.cancelled() and task.exception() is not None:
            log.error("serial bridge %s", self.device, exc_info=task.exception())

    # ------------------------------------------------------------ admission

    def _arrived(self, client: _Client) -> None:
        if self._stopping:
            client.transport.abort()
            return
        self._waiting.add(client)
        self._spawn(self._admit(client))

    async def _admit(self, client: _Client) -> None:
        async with self._lock:
            try:
                if not client.gone:
                    await self._seat(client)
            finally:
                self._waiting.discard(client)
            await self._settle()

    async def _seat(self, client: _Client) -> None:
        if self._device is None:
            reason = None if self._leased else await self._ask(client.peer)
            if reason is not None:
                return self._watch_driver(client, reason)
            self._leased = True
            if client.gone:
                return  # _settle gives the lease back
            try:
                await self._open_device()
            except Exception as exc:  # pyserial raises its own, and ValueError
                self.last_error = f"cannot open {self.device}: {exc}"
                log.warning("serial bridge: %s", self.last_error)
                client.close()
                return
            if client.gone:
                return
        owned = any(c.mode == "owner" for c in self._clients)
        self._admit_as(client, "read_only" if owned else "owner")

    async def _ask(self, peer: str) -> str | None:
        if self.acquire is None:
            return None
        try:
            return await _maybe_await(self.acquire(peer))
        except Exception as exc:  # the agent failing is a refusal, not a crash
            log.exception("serial bridge: acquire failed")
            return f"acquire failed: {exc}"

    def _watch_driver(self, client: _Client, reason: str) -> None:
        """The robot is busy: the client watches the driver's reads, or is turned away."""
        if self.when_busy == "read_only" and self.tap is None:
            reason = NO_TAP
        if self.when_busy == "refuse" or self.tap is None:
            return self._refuse(client, reason)
        try:
            client.unsubscribe = self.tap(self._feeder(client))
        except Exception as exc:  # the agent failing is a refusal, not a crash
            log.exception("serial bridge: tap failed")
            return self._refuse(client, f"tap failed: {exc}")
        client.via_tap = True
        self._admit_as(client, "read_only")

    def _refuse(self, client: _Client, reason: str) -> None:
        self.refused += 1
        self.last_error = str(reason) or "refused"
        log.info("serial bridge %s: %s refused: %s", self.device, client.peer, self.last_error)
        client.close()

    def _admit_as(self, client: _Client, mode: str) -> None:
        client.mode = mode
        self._clients.append(client)
        if self.protocol == "rfc2217":
            client.port_manager = self._port_manager(client)
        if not (mode == "owner" and self._device_full):
            client.transport.resume_reading()
        log.info("serial bridge %s: %s connected (%s)", self.device, client.peer, mode)

    def _port_manager(self, client: _Client):
        from serial.rfc2217 import PortManager

        if client.mode == "owner":
            port = _Port(self._device.transport.serial)
        else:
            port = _Settings(self.baud)
        return PortManager(port, client)  # it sends its telnet option requests now

    def _feeder(self, client: _Client) -> Callable[[bytes], None]:
        loop = self._loop

        def deliver(data: bytes) -> None:
            if not client.gone:
                client.write(self._escaped(data))

        def feed(data: bytes) -> None:
            try:
                running = asyncio.get_running_loop()
            except RuntimeError:
                running = None
            if running is loop:
                deliver(data)
            elif not loop.is_closed():  # the driver reads in a thread of its own
                loop.call_soon_threadsafe(deliver, bytes(data))

        return feed

    def _left(self, client: _Client) -> None:
        if client in self._clients:
            self._clients.remove(client)
            log.info("serial bridge %s: %s left", self.device, client.peer)
            if client.mode == "owner":
                self._hold_device(False)  # it may have left while the device waited for it
        if client.unsubscribe is not None:
            unsubscribe, client.unsubscribe = client.unsubscribe, None
            try:
                unsubscribe()
            except Exception:  # the tap failing must not stop the bridge
                log.exception("serial bridge: tap unsubscribe failed")
        if self._loop is not None and not self._loop.is_closed():
            self._spawn(self._settled())

    async def _settled(self) -> None:
        async with self._lock:
            await self._settle()

    async def _settle(self) -> None:
        """Give the device back when no client needs it any more (the lock is held)."""
        if any(not c.via_tap for c in self._clients):
            return
        if any(not c.gone for c in self._waiting):
            return  # it decides once it has the lock; closing first would only churn
        await self._give_back()

    async def _give_back(self) -> None:
        await self._close_device()
        if self._leased:
            self._leased = False
            if self.release is not None:
                try:
                    await _maybe_await(self.release())
                except Exception:
                    log.exception("serial bridge: release failed")

    # ------------------------------------------------------------ the device

    async def _open_device(self) -> None:
        import serial
        import serial_asyncio

        port = await asyncio.to_thread(
            serial.serial_for_url, self.device, baudrate=self.baud, exclusive=True
        )
        device = _Device(self)
        transport, _ = await serial_asyncio.connection_for_serial(
            asyncio.get_running_loop(), lambda: device, port
        )
        transport._max_read_size = READ_SIZE
        transport.set_write_buffer_limits(high=self.queue_limit)
        device.transport = transport
        self._device, self._device_full = device, False
        self.last_error = ""
        log.info("serial bridge: %s opened", self.device)

    async def _close_device(self) -> None:
        device, self._device = self._device, None
        if device is None:
            return
        await self._drain(device)
        device.transport.abort()  # nothing left to write, or given up on
        await device.closed
        log.info("serial bridge: %s closed", self.device)

    @staticmethod
    async def _drain(device: _Device) -> None:
        """Let what the owner sent last go out, for CLOSE_TIMEOUT at most. serial_asyncio's own
        close waits for the line (tcdrain) in the event loop: a line held by flow control would
        stall the whole agent, so it waits here in a thread and the rest is discarded."""
        transport, port = device.transport, device.transport.serial
        deadline = time.monotonic() + CLOSE_TIMEOUT
        while transport.get_write_buffer_size() and time.monotonic() < deadline:
            await asyncio.sleep(0.01)
        try:
            left = max(deadline - time.monotonic(), 0.01)
            await asyncio.wait_for(asyncio.to_thread(port.flush), left)
        except (TimeoutError, OSError, termios.error):
            with contextlib.suppress(OSError, termios.error):
                port.reset_output_buffer()  # also ends the waiting tcdrain

    def _device_gone(self, device: _Device, exc) -> None:
        if device is not self._device:
            return  # closed by the bridge
        self._device = None
        self.last_error = f"device lost: {exc}" if exc else "device lost"
        log.warning("serial bridge %s: %s", self.device, self.last_error)
        # Out of the list now, so the lease goes back without waiting for their sockets.
        for client in [c for c in self._clients if not c.via_tap]:
            self._clients.remove(client)
            client.close()
        self._spawn(self._settled())

    # ------------------------------------------------------------ the bytes

    def _from_device(self, data: bytes) -> None:
        data = self._escaped(data)
        for client in self._clients:
            if not client.via_tap:
                client.write(data)

    def _from_client(self, client: _Client, data: bytes) -> None:
        client.bytes_in += len(data)
        if client.port_manager is not None:
            data = self._filtered(client, data)
            if not data:
                return
        device = self._device
        if client.mode != "owner" or device is None:
            client.dropped_in += len(data)
            return
        device.transport.write(data)

    def _escaped(self, data: bytes) -> bytes:
        # PortManager.escape() byte by byte, without a generator step per byte
        return data.replace(b"\xff", b"\xff\xff") if self.protocol == "rfc2217" else data

    def _filtered(self, client: _Client, data: bytes) -> bytes:
        """Telnet commands out (applied to the port), the payload left."""
        from serial.rfc2217 import IAC, M_NORMAL

        manager = client.port_manager
        if IAC not in data and manager.mode == M_NORMAL and manager.suboption is None:
            return data  # the common case, without a Python step per byte
        out = bytearray()
        try:
            for byte in manager.filter(data):
                out += byte
        except Exception:  # one bad negotiation must not drop the client
            log.exception(
                "serial bridge %s: RFC 2217 negotiation from %s", self.device, client.peer
            )
        return bytes(out)

    def _hold_device(self, full: bool) -> None:
        """The owner's socket is full (or no longer): stop (resume) reading the device."""
        device = self._device
        if device is None or device.transport.is_closing():
            return
        if full:
            device.transport.pause_reading()
        else:
            device.transport.resume_reading()

    def _hold_owner(self, full: bool) -> None:
        """The device's write buffer is full (or no longer): stop (resume) reading the owner."""
        self._device_full = full
        for client in self._clients:
            if client.mode == "owner" and not client.transport.is_closing():
                if full:
                    client.transport.pause_reading()
                else:
                    client.transport.resume_reading()

    async def _poll_modem_lines(self) -> None:
        # RFC 2217 clients hear of CTS/DSR/RI/CD changes only if someone looks.
        while True:
            await asyncio.sleep(self.modem_poll)
            for client in self._clients:
                if client.port_manager is not None:
                    try:
                        client.port_manager.check_modem_lines()
                    except Exception:
                        log.debug("modem lines of %s", self.device, exc_info=True)
