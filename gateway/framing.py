"""MAVLink 1 and 2 framing for the router: bytes in, whole frames out, nothing decoded.

The forwarding path only needs a frame's bounds, its CRC, and five numbers: source system and
component, message id, and target system and component for the messages that have them. Those
come from fixed offsets (header fields; target offsets computed once from pymavlink's dialect
tables), never from decoding the message.

Decisions:
- CRC: X.25 (CRC-16/MCRF4XX) over header and payload, then the message's CRC_EXTRA from the
  ardupilotmega dialect (a superset of common). fastcrc (a pymavlink extra, in Rust) is used
  when installed; otherwise a precomputed-table loop in Python (about 4x slower).
- Unknown message ids (custom dialects) have no CRC_EXTRA, so their CRC cannot be checked. They
  pass through when their structure is sane: MAVLink 2 incompat flags only 0 or 1 (signed), and
  the byte right after the frame is the start of the next one. So such a frame waits for the
  next frame to arrive before it is forwarded; a known one goes at once.
- Signed frames (incompat flag 0x01) are forwarded with their 13 signature bytes untouched; the
  router does not check signatures (the vehicle does).
- After garbage or a bad CRC the framer resynchronises on the next start byte (0xFE / 0xFD)
  after the one that failed, so a valid frame hidden behind a false start is still found.
  ``errors`` counts rejected candidates; ``skipped`` counts bytes thrown away.
"""

from __future__ import annotations

from pymavlink.dialects.v20 import ardupilotmega as _dialect

STX_V1, STX_V2 = 0xFE, 0xFD
SIGNED = 0x01
HEARTBEAT = 0

_SIZES = {"c": 1, "b": 1, "B": 1, "h": 2, "H": 2, "i": 4, "I": 4, "q": 8, "Q": 8, "f": 4,
          "d": 8}  # fmt: skip


def _tables():
    crc_extra: dict[int, int] = {}
    targets: dict[int, tuple[int, int]] = {}  # msgid -> (target_system ofs, target_component ofs)
    for msgid, cls in _dialect.mavlink_map.items():
        crc_extra[msgid] = cls.crc_extra
        fmt = cls.native_format.decode()[1:]
        offsets, ofs = {}, 0
        for name, code, alen in zip(cls.ordered_fieldnames, fmt, cls.array_lengths, strict=True):
            offsets[name] = ofs
            ofs += _SIZES[code] * max(1, alen)
        if "target_system" in offsets:
            targets[msgid] = (offsets["target_system"], offsets.get("target_component", -1))
    return crc_extra, targets


CRC_EXTRA, TARGETS = _tables()


def _crc_table():
    table = []
    for byte in range(256):
        tmp = byte ^ (byte << 4) & 0xFF
        table.append(((tmp << 8) ^ (tmp << 3) ^ (tmp >> 4)) & 0xFFFF)
    return table


_TABLE = _crc_table()


def _x25_python(data, crc: int = 0xFFFF) -> int:
    table = _TABLE
    for b in data:
        crc = (crc >> 8) ^ table[(crc ^ b) & 0xFF]
    return crc


try:
    from fastcrc.crc16 import mcrf4xx as _x25_fast
except ImportError:  # pragma: no cover - depends on the environment
    _x25_fast = None

x25 = _x25_fast or _x25_python


def frame_crc_ok(frame: bytes, crc=None) -> bool:
    """True if a whole frame's CRC is right (or its message id is unknown)."""
    crc = crc or x25
    header = 10 if frame[0] == STX_V2 else 6
    msgid = frame[7] | frame[8] << 8 | frame[9] << 16 if frame[0] == STX_V2 else frame[5]
    extra = CRC_EXTRA.get(msgid)
    if extra is None:
        return True
    end = header + frame[1]
    c = crc(memoryview(frame)[1:end])
    c = (c >> 8) ^ _TABLE[(c ^ extra) & 0xFF]
    return c == frame[end] | frame[end + 1] << 8


class Framer:
    """Feed bytes, get frames: ``(frame, sysid, compid, msgid, target_sys, target_comp)``.

    Targets are 0 when the message has none (broadcast). Keeps the tail of an incomplete frame
    for the next feed.
    """

    __slots__ = ("_buf", "_crc", "frames", "errors", "skipped", "unknown")

    def __init__(self, crc=None):
        self._buf = b""
        self._crc = crc or x25
        self.frames = 0
        self.errors = 0  # candidates rejected: bad CRC, bad header, insane unknown frame
        self.skipped = 0  # bytes dropped while resynchronising
        self.unknown = 0  # frames of unknown ids passed on structure alone

    def feed(self, data: bytes) -> list[tuple]:
        buf = self._buf + data if self._buf else bytes(data)
        out = []
        append = out.append
        n = len(buf)
        i = 0
        crc = self._crc
        table = _TABLE
        extras = CRC_EXTRA
        targets = TARGETS
        errors = skipped = 0
        find = buf.find
        while i < n:
            c = buf[i]
            if c == STX_V2:
                if i + 10 > n:
                    break
                plen = buf[i + 1]
                incompat = buf[i + 2]
                hdr = 10
                end = i + 10 + plen  # CRC starts here
                flen = 12 + plen + (13 if incompat & SIGNED else 0)
                msgid = buf[i + 7] | buf[i + 8] << 8 | buf[i + 9] << 16
                sysid = buf[i + 5]
                compid = buf[i + 6]
            elif c == STX_V1:
                if i + 6 > n:
                    break
                plen = buf[i + 1]
                incompat = 0
                hdr = 6
                end = i + 6 + plen
                flen = 8 + plen
                msgid = buf[i + 5]
                sysid = buf[i + 3]
                compid = buf[i + 4]
            else:
                j = find(b"\xfd", i)
                k = find(b"\xfe", i)
                if j < 0 or 0 <= k < j:
                    j = k
                if j < 0:
                    j = n
                skipped += j - i
                i = j
                continue
            if i + flen > n:
                break
            extra = extras.get(msgid)
            if extra is None:
                # Unknown id: structure only. Wait for the next start byte to confirm.
                if incompat & ~SIGNED:
                    errors += 1
                    skipped += 1
                    i += 1
                    continue
                if i + flen == n:
                    break
                if buf[i + flen] not in (STX_V1, STX_V2):
                    errors += 1
                    skipped += 1
                    i += 1
                    continue
                self.unknown += 1
            else:
                if incompat & ~SIGNED:
                    errors += 1
                    skipped += 1
                    i += 1
                    continue
                x = crc(buf[i + 1 : end])
                x = (x >> 8) ^ table[(x ^ extra) & 0xFF]
                if x != buf[end] | buf[end + 1] << 8:
                    errors += 1
                    skipped += 1
                    i += 1
                    continue
            tsys = tcomp = 0
            t = targets.get(msgid)
            if t is not None:
                ofs = t[0]
                if ofs < plen:
                    tsys = buf[i + hdr + ofs]
                ofs = t[1]
                if 0 <= ofs < plen:
                    tcomp = buf[i + hdr + ofs]
            append((buf[i : i + flen], sysid, compid, msgid, tsys, tcomp))
            i += flen
        self._buf = buf[i:] if i < n else b""
        self.frames += len(out)
        self.errors += errors
        self.skipped += skipped
        return out

    @property
    def pending(self) -> int:
        """Bytes held back waiting for the rest of a frame."""
        return len(self._buf)
