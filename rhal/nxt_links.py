"""The links under the nxt:// driver: nxt-python's sockets reading replies with a timeout and
resynchronising, opening the brick a URL names, and parsing that URL."""

from __future__ import annotations

import os
import re
import select
import termios
import threading
import time
import tty
from typing import TYPE_CHECKING, Any
from urllib.parse import unquote, urlsplit

import nxt.backend.bluetooth
import nxt.backend.devfile
import nxt.brick
import nxt.error
import nxt.locator
import nxt.sensor
import nxt.telegram

from rhal.errors import RobotConnectionError

if TYPE_CHECKING:
    from rhal.nxt_brick import NxtRobot

MAX_TELEGRAM = 64  # bytes: the NXT's largest telegram
#: Length of each reply nxt-python waits for here (type, opcode, status, data).
REPLY_LENGTHS = {
    0x06: 25,  # GetOutputState
    0x07: 16,  # GetInputValues
    0x0B: 5,  # GetBatteryLevel
    0x0D: 7,  # KeepAlive
    0x0E: 4,  # LSGetStatus
    0x0F: 3,  # LSWrite
    0x10: 20,  # LSRead
    0x88: 7,  # GetFirmwareVersion
    0x9B: 33,  # GetDeviceInfo
}
#: Replies that are not what was asked for: a corrupted or misframed telegram. The brick
BT_ADDRESS = re.compile(r"^[0-9A-F]{2}(:[0-9A-F]{2}){5}$")


# -- links: nxt-python's sockets, reading replies with a timeout and resynchronising ------


class ErrorCounter:
    """Replies dropped, counted on the worker thread and on the event loop."""

    def __init__(self) -> None:
        self.count = 0
        self._lock = threading.Lock()

    def add(self) -> None:
        with self._lock:
            self.count += 1


class ReplyScanner:
    """Cuts replies out of a stream of length-prefixed telegrams, skipping anything else.

    A reply starts with its length (3..64, little-endian, so the high byte is 0), then type
    0x02 and the opcode of the command it answers, then a status nxt-python knows; its
    length is the one that opcode's reply has (or shorter, with an error status). Bytes
    before such a header are noise: skipped, and each run of them counted once.
    """

    def __init__(self) -> None:
        self.buffer = bytearray()
        self.skipped = 0  # runs of bytes dropped

    def feed(self, data: bytes) -> None:
        self.buffer += data

    def take(self, opcode: int) -> bytes | None:
        """The next reply to ``opcode`` (without its length prefix), or None for now."""
        buffer = self.buffer
        start = _find_header(buffer, opcode)
        if start is None:
            # No whole header yet: keep only a tail that could still grow into one.
            start = len(buffer)
            for tail in range(max(0, len(buffer) - 4), len(buffer)):
                if _could_start(buffer[tail:], opcode):
                    start = tail
                    break
        if start:
            del buffer[:start]
            self.skipped += 1
        if len(buffer) < 5 or len(buffer) < 2 + buffer[0]:
            return None
        size = buffer[0]
        reply = bytes(buffer[2 : 2 + size])
        del buffer[: 2 + size]
        return reply


def _find_header(buffer: bytearray, opcode: int) -> int | None:
    for start in range(len(buffer) - 4):
        if _is_header(buffer[start : start + 5], opcode):
            return start
    return None


def _is_header(head: bytes | bytearray, opcode: int) -> bool:
    size, high, kind, code, status = head
    if high != 0 or kind != 0x02 or code != opcode or status not in nxt.telegram.CODES:
        return False
    expected = REPLY_LENGTHS.get(opcode, MAX_TELEGRAM)
    if status == 0 and opcode in REPLY_LENGTHS:
        return size == expected
    return 3 <= size <= expected


def _could_start(tail: bytes | bytearray, opcode: int) -> bool:
    """Whether ``tail`` (under 5 bytes) can still grow into a header."""
    pattern = (None, 0, 0x02, opcode)
    if tail and not 3 <= tail[0] <= MAX_TELEGRAM:
        return False
    return all(want is None or got == want for got, want in zip(tail, pattern, strict=False))


class ScanningReader:
    """``recv`` for a stream link: waits ``timeout`` at most and resynchronises on noise.

    Mixed into nxt-python's socket classes, whose ``send`` frames each telegram.
    """

    timeout: float
    errors: ErrorCounter
    _scanner: ReplyScanner
    _expect: int | None = None

    def _reader_init(self, timeout: float, errors: ErrorCounter) -> None:
        self.timeout, self.errors = timeout, errors
        self._scanner = ReplyScanner()

    def _before_sending(self, data: bytes) -> None:
        # The brick only speaks when spoken to: whatever came in since the last reply is
        # stale (a reply that came too late) or noise. Drop it, so it cannot pass for the
        # reply to this command.
        stale = bool(self._scanner.buffer)
        self._scanner.buffer.clear()
        while self._read_some(0):
            stale = True
        if stale:
            self.errors.add()
        # Telegram type bit 7 set: no reply wanted. Otherwise byte 1 is the opcode.
        self._expect = None if data[0] & 0x80 else data[1]

    def _read_some(self, timeout: float) -> bytes | None:
        """What has arrived, b"" at end of stream, None if nothing came within timeout."""
        raise NotImplementedError

    def recv(self) -> bytes:
        deadline = time.monotonic() + self.timeout
        scanner, opcode = self._scanner, self._expect
        if opcode is None:
            raise nxt.error.ProtocolError("waiting for a reply to nothing")
        while True:
            before = scanner.skipped
            reply = scanner.take(opcode)
            if scanner.skipped != before:
                self.errors.add()
            if reply is not None:
                self._expect = None
                return reply
            remaining = deadline - time.monotonic()
            if remaining <= 0:
                raise TimeoutError(f"no reply from the brick within {self.timeout:g} s")
            data = self._read_some(remaining)
            if data == b"":
                raise ConnectionResetError("the brick closed the link")
            if data:
                scanner.feed(data)


class DevFileLink(ScanningReader, nxt.backend.devfile.DevFileSock):
    """nxt-python's device-file socket (``/dev/rfcomm0``), opened O_NOCTTY."""

    def __init__(self, filename: str, timeout: float, errors: ErrorCounter) -> None:
        super().__init__(filename)
        self._device = None
        self._reader_init(timeout, errors)

    def connect(self) -> nxt.brick.Brick:
        fd = os.open(self._filename, os.O_RDWR | os.O_NOCTTY | os.O_CLOEXEC)
        try:
            self._device = open(fd, "r+b", buffering=0)  # noqa: SIM115 - closed by close()
        except BaseException:
            os.close(fd)
            raise
        try:
            tty.setraw(fd)
            termios.tcflush(fd, termios.TCIOFLUSH)  # nothing stale from an earlier session
        except termios.error:
            pass  # not a terminal (a FIFO, a socket file): nothing to set
        return nxt.brick.Brick(self)

    def send(self, data: bytes) -> None:
        if self._device is None:
            raise ConnectionResetError("the link is closed")
        self._before_sending(data)
        super().send(data)

    def _read_some(self, timeout: float) -> bytes | None:
        if self._device is None:
            raise ConnectionResetError("the link is closed")
        readable, _, _ = select.select([self._device], [], [], timeout)
        if not readable:
            return None
        return os.read(self._device.fileno(), 4096)


class BluetoothLink(ScanningReader, nxt.backend.bluetooth.BluetoothSock):
    """nxt-python's Bluetooth (RFCOMM) socket, through PyBluez."""

    def __init__(self, bluetooth: Any, host: str, timeout: float, errors: ErrorCounter) -> None:
        super().__init__(bluetooth, host)
        self._reader_init(timeout, errors)

    def send(self, data: bytes) -> None:
        if self._sock is None:
            raise ConnectionResetError("the link is closed")
        self._before_sending(data)
        super().send(data)

    def _read_some(self, timeout: float) -> bytes | None:
        if self._sock is None:
            raise ConnectionResetError("the link is closed")
        self._sock.settimeout(timeout)  # 0: non-blocking
        try:
            return self._sock.recv(4096)
        except (TimeoutError, BlockingIOError):  # TimeoutError is socket.timeout
            return None


def _open_brick(robot: NxtRobot) -> nxt.brick.Brick:
    """Connect the link the URL names; blocking, on the worker thread."""
    if robot.link == "dev":
        return DevFileLink(robot.target, robot.timeout, robot._errors).connect()
    if robot.link == "bt":
        try:
            import bluetooth  # PyBluez; its BluetoothError is an OSError
        except ImportError as exc:
            raise RobotConnectionError(
                "Bluetooth by address needs PyBluez (pip install pybluez), which is not "
                "installed; or bind the brick to a serial device (sudo rfcomm bind 0 "
                f"{robot.target}) and use nxt:///dev/rfcomm0"
            ) from exc
        return BluetoothLink(bluetooth, robot.target, robot.timeout, robot._errors).connect()
    filters = {"name": robot.target} if robot.target else {}
    if robot.target and BT_ADDRESS.match(robot.target):
        filters = {"host": robot.target}
    try:
        return nxt.locator.find(backends=["usb"], config=None, **filters)
    except ImportError as exc:
        raise RobotConnectionError(f"NXT over USB needs pyusb: {exc}") from exc
    except nxt.locator.BrickNotFoundError:
        which = f" matching {robot.target!r}" if robot.target else ""
        raise RobotConnectionError(f"no NXT brick{which} found on USB") from None
    except ValueError as exc:
        if type(exc).__name__ != "NoBackendError":  # pyusb's: no libusb
            raise
        raise RobotConnectionError(
            f"NXT over USB needs libusb (e.g. apt install libusb-1.0-0): {exc}"
        ) from exc


def parse_url(url: str) -> tuple[str, str | None]:
    """``("usb", name or address or None)``, ``("bt", address)`` or ``("dev", path)``."""
    parts = urlsplit(url)
    if parts.scheme.lower() != "nxt":
        raise ValueError(f"not an nxt URL: {url!r}")
    where, path = parts.netloc.lower(), unquote(parts.path)
    if not where:
        return ("dev", path) if path.strip("/") else ("usb", None)
    target = path.strip("/")
    if where == "usb":
        return "usb", _address(target) or target or None
    if where in ("bt", "bluetooth"):
        address = _address(target)
        if address is None:
            raise ValueError(
                f"nxt://bt/ needs the brick's Bluetooth address, like "
                f"nxt://bt/00:16:53:01:02:03, not {target!r}"
            )
        return "bt", address
    raise ValueError(
        f"unknown NXT link {parts.netloc!r} in {url!r}; use nxt://, nxt://usb/NAME, "
        "nxt://bt/00:16:53:01:02:03 or nxt:///dev/rfcomm0"
    )


def _address(text: str) -> str | None:
    """``00:16:53:01:02:03`` for that or ``001653010203`` (the NXT's USB serial number)."""
    digits = text.upper().replace(":", "")
    if len(digits) != 12 or not all(c in "0123456789ABCDEF" for c in digits):
        return None
    address = ":".join(digits[i : i + 2] for i in range(0, 12, 2))
    return address if BT_ADDRESS.match(text.upper()) or ":" not in text else None
