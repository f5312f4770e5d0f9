""".tlog recording and replay.

The format MAVProxy, QGroundControl and pymavlink write: each MAVLink frame as it was on the
wire, preceded by an 8-byte big-endian timestamp, microseconds since the Unix epoch. Nothing
else: no header, so a file cut short or with a damaged stretch is read up to the damage and
again after it.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
import struct
import threading
import time

from gateway.framing import CRC_EXTRA, SIGNED, STX_V1, STX_V2, frame_crc_ok
from gateway.router import Router

log = logging.getLogger(__name__)
_STAMP = struct.Struct(">Q")
FLUSH_SECONDS = 0.5
FLUSH_BYTES = 64 * 1024
BUFFER_LIMIT = 8 << 20  # bytes waiting for the disk before frames are dropped
MAX_GAP_US = 3 * 24 * 3600 * 10**6  # a later stamp further off is damage (pymavlink's rule too)
# Stamps past 2100 are damage. No lower bound: a Raspberry Pi without a clock records in 1970.
MAX_STAMP_US = 4102444800 * 10**6
MAX_FRAME = 280  # MAVLink 2: 10 header + 255 payload + 2 CRC + 13 signature
READ_CHUNK = 64 * 1024
FAST_BATCH = 32 * 1024  # bytes sent before pausing, so a loopback reader's buffer never fills
FAST_PAUSE = 0.005
TICK = 0.002  # frames due within this of each other are sent together
CONNECT_TIMEOUT = 5.0


class TlogRecorder:
    """A router tap (``router.taps.append(recorder)``) writing every frame it is given.

    The tap only stamps the frames and appends them to a list; a thread writes the list out
    every 0.5 s or 64 KiB. A thread, not writes on the event loop: an SD card or a busy disk
    can hold a write for a second or more, and the router must not wait with it. When more
    than ``BUFFER_LIMIT`` bytes wait (the disk is not keeping up) new frames are dropped, and
    once ``max_bytes`` would be passed the recording ends; both count ``drops``. A write error
    (disk full, the file or its folder removed) ends the recording with ``error`` set.

    ``start()`` and ``close()`` are synchronous: start opens the file (OSError if it cannot);
    close writes what is left and waits for the thread, so call it through
    ``asyncio.to_thread`` where a slow disk must not hold the loop.
    """

    def __init__(self, path, *, max_bytes: int | None = None):
        self.path = os.fspath(path)
        self.max_bytes = max_bytes
        self.frames = self.bytes = self.drops = 0  # written, and not written
        self.started: float | None = None
        self.error = ""
        self._cond = threading.Condition()
        self._chunks: list[bytes] = []
        self._waiting = self._waiting_bytes = 0
        self._accepted = 0  # bytes written or waiting: what max_bytes limits
        self._full = self._closing = False
        self._last = 0
        self._file = None
        self._thread: threading.Thread | None = None

    def start(self) -> None:
        self._file = open(self.path, "wb")  # the writer thread closes it
        self.started = time.time()
        self._thread = threading.Thread(target=self._write, name=f"tlog {self.path}", daemon=True)
        self._thread.start()

    def __call__(self, frames: list[bytes]) -> None:
        # One stamp per read: those frames arrived together. Never earlier than the last one,
        # so a clock stepped back (NTP) cannot make replay's delays negative.
        self._last = stamp = max(time.time_ns() // 1000, self._last)
        prefix = _STAMP.pack(stamp)
        data = b"".join([prefix + frame for frame in frames])
        with self._cond:
            if self._thread is None or self._closing or self.error or self._full:
                self.drops += len(frames)
                return
            if self.max_bytes is not None and self._accepted + len(data) > self.max_bytes:
                self._full = True  # a recording that ends, rather than one with holes
                self.drops += len(frames)
                return
            if self._waiting_bytes + len(data) > BUFFER_LIMIT:
                self.drops += len(frames)
                return
            self._chunks.append(data)
            self._waiting += len(frames)
            self._waiting_bytes += len(data)
            self._accepted += len(data)
            if self._waiting_bytes >= FLUSH_BYTES:
                self._cond.notify()

    def _write(self) -> None:
        out = self._file
        closing = False
        while not closing:
            with self._cond:
                self._cond.wait_for(
                    lambda: self._closing or self._waiting_bytes >= FLUSH_BYTES, FLUSH_SECONDS
                )
                chunks, count, size = self._chunks, self._waiting, self._waiting_bytes
                self._chunks, self._waiting, self._waiting_bytes = [], 0, 0
                closing = self._closing
            if not chunks:
                continue
            try:
                out.write(b"".join(chunks))
                out.flush()
                # Linux writes on into a file whose folder was removed: nobody would see it.
                if os.fstat(out.fileno()).st_nlink == 0:
                    raise OSError(f"{self.path} was removed")
            except OSError as exc:
                with self._cond:
                    self.error = str(exc)
                    self.drops += count + self._waiting
                    self._chunks, self._waiting, self._waiting_bytes = [], 0, 0
                log.warning("tlog recording stopped: %s", exc)
                break
            with self._cond:
                self.frames += count
                self.bytes += size
        with contextlib.suppress(OSError):  # the unflushed rest was counted as dropped
            out.close()

    def close(self) -> None:
        with self._cond:
            self._closing = True
            self._cond.notify()
        if self._thread is not None:
            self._thread.join()

    def as_dict(self) -> dict:
        with self._cond:
            return {"path": self.path, "frames": self.frames, "bytes": self.bytes,
                    "drops": self.drops, "started": self.started, "error": self.error}  # fmt: skip


# ---------------------------------------------------------------- reading


def _record_at(buf: bytes, i: int, last: int | None, eof: bool) -> int:
    """The length of the record at ``buf[i]``; 0: more bytes are needed; -1: none starts there.

    Frames are checked as framing.Framer checks them (header, CRC with CRC_EXTRA), but one at
    a time: the Framer confirms an unknown message id by the start byte after the frame, which
    here is the next record's timestamp, so that check is done on the next record instead.
    """
    n = len(buf)
    j = i + 8
    if j + 3 > n:
        return 0
    stx = buf[j]
    if stx == STX_V2:
        incompat = buf[j + 2]
        if incompat & ~SIGNED:
            return -1
        flen = 12 + buf[j + 1] + (13 if incompat & SIGNED else 0)
    elif stx == STX_V1:
        flen = 8 + buf[j + 1]
    else:
        return -1
    stamp = _STAMP.unpack_from(buf, i)[0]
    if stamp > MAX_STAMP_US or last is not None and abs(stamp - last) > MAX_GAP_US:
        return -1
    end = j + flen
    if end > n:
        return 0
    if not frame_crc_ok(buf[j:end]):
        return -1
    msgid = buf[j + 7] | buf[j + 8] << 8 | buf[j + 9] << 16 if stx == STX_V2 else buf[j + 5]
    if msgid not in CRC_EXTRA and end < n:
        if end + 9 > n:
            return 8 + flen if eof else 0  # the last whole record, and a piece of another
        if buf[end + 8] not in (STX_V1, STX_V2):
            return -1
    return 8 + flen


class TlogReader:
    """Iterates ``(timestamp_us, frame)`` over a .tlog, reading it in chunks.

    ``skipped``: bytes of damage passed over; ``truncated``: the bytes of a last record cut short
    (a recording stopped mid-write).
    """

    def __init__(self, path):
        self.path = os.fspath(path)
        self.records = self.skipped = self.truncated = 0

    def __iter__(self):
        with open(self.path, "rb") as f:
            buf, i, eof, last = b"", 0, False, None
            gap, cut = 0, False  # bytes since the last record; whether they began as one cut short
            while True:
                if not eof and len(buf) - i < 8 + MAX_FRAME + 9:
                    data = f.read(READ_CHUNK)
                    eof = not data
                    buf, i = buf[i:] + data, 0
                    continue
                if i >= len(buf):
                    break
                size = _record_at(buf, i, last, eof)
                if size > 0:
                    self.skipped += gap
                    gap = 0
                    last = _STAMP.unpack_from(buf, i)[0]
                    self.records += 1
                    yield last, buf[i + 8 : i + size]
                    i += size
                else:
                    # 0 (wants more bytes) comes only at the end: there is always enough buffered
                    # before it. It may still be damage that a whole record follows, so go on.
                    if not gap:
                        cut = size == 0
                    gap += 1
                    i += 1
            if cut:
                self.truncated = gap
            else:
                self.skipped += gap


def read_tlog(path) -> TlogReader:
    """``(timestamp_us, frame)`` pairs; the reader it returns counts what it skipped."""
    return TlogReader(path)


def check_tlog(path) -> None:
    """OSError if it cannot be read; ValueError if its first 64 KiB hold no two records in a row
    (one alone: random bytes have that by chance). An empty file is a recording of nothing."""
    with open(path, "rb") as f:
        head = f.read(READ_CHUNK)
    eof = len(head) < READ_CHUNK
    for i in range(len(head)):
        size = _record_at(head, i, None, eof)
        if size > 0 and (i + size == len(head) or _record_at(head, i + size, None, eof) >= 0):
            return
    if head:
        raise ValueError(f"{path}: not a .tlog (no timestamped MAVLink frames in it)")


# ---------------------------------------------------------------- replay


async def replay(path, endpoints, *, speed: float = 1.0, loop: bool = False,
                 stop: asyncio.Event | None = None) -> int:  # fmt: skip
    """Send the frames of a .tlog to the endpoints with their recorded timing divided by
    ``speed`` (0: as fast as loopback UDP takes them without loss); the number of frames sent.

    The endpoints are opened here, in a Router of their own, and closed at the end: every frame
    goes to every endpoint (a replay has heard no one, so targets cannot be routed on), and
    what the endpoints say is dropped (``read_only``). Ends early when ``stop`` is set.
    Raises OSError or ValueError, naming the endpoint, when one cannot be opened.
    """
    if speed < 0:
        raise ValueError(f"speed must be 0 or more, not {speed}")
    stop = stop or asyncio.Event()
    router = Router()
    try:
        for endpoint in endpoints:
            endpoint.read_only = True
            await _open(router, endpoint, stop)
        sent = 0
        while not stop.is_set():
            played = await _play(path, router, speed, stop)
            sent += played
            if not loop or not played:
                break
        return sent
    finally:
        await router.close()


async def _open(router: Router, endpoint, stop: asyncio.Event) -> None:
    try:
        await router.add(endpoint)
    except (OSError, ValueError) as exc:
        raise type(exc)(f"{endpoint.name}: {exc}") from exc
    connected = getattr(endpoint, "connected", None)  # TCP and serial connect in the background
    deadline = time.monotonic() + CONNECT_TIMEOUT
    while connected is not None and not connected.is_set() and not stop.is_set():
        if time.monotonic() > deadline:
            raise OSError(f"{endpoint.name}: not connected after {CONNECT_TIMEOUT:g} s: "
                          f"{endpoint.last_error}")  # fmt: skip
        await asyncio.sleep(0.05)


async def _play(path, router: Router, speed: float, stop: asyncio.Event) -> int:
    clock = asyncio.get_running_loop().time
    first = start = None
    batch, size, sent = [], 0, 0
    for stamp, frame in read_tlog(path):
        if first is None:
            first, start = stamp, clock()
        if speed:
            wait = start + (stamp - first) / 1e6 / speed - clock()
            if wait > TICK:
                sent += _send(router, batch)
                batch, size = [], 0
                if await _pause(router, wait, stop):
                    return sent
        batch.append(frame)
        size += len(frame)
        if size >= FAST_BATCH:
            sent += _send(router, batch)
            batch, size = [], 0
            if await _pause(router, FAST_PAUSE, stop):
                return sent
    return sent + _send(router, batch)


def _send(router: Router, frames: list[bytes]) -> int:
    for endpoint in list(router.endpoints.values()):  # TCP server clients come and go
        for frame in frames:
            endpoint.queue(frame)
        endpoint.flush()
    return len(frames)


async def _pause(router: Router, seconds: float, stop: asyncio.Event) -> bool:
    """Wait, and on while a TCP endpoint holds much unsent (its queue would drop); True: stop."""
    while True:
        with contextlib.suppress(TimeoutError):
            await asyncio.wait_for(stop.wait(), seconds)
            return True
        if all(e.backlog() < e.queue_limit // 2 for e in router.endpoints.values()):
            return False
        seconds = 0.01
