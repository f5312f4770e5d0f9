"""A run's log file on disk, by its path alone (no Django here): plain while it is written and
for a while after, then gzip beside it (``output.log.gz``). Readers open whichever is there;
neither is there once the log was pruned (or before its run wrote anything).

Compressing writes the gzip file whole and renames it into place before the plain file goes,
so a reader finds one or the other at every moment; a reader that opened a file before it was
compressed or pruned reads it to its end (an open file outlives its name).
"""

import gzip
import os
import shutil
import struct
import tempfile
import zlib
from dataclasses import dataclass
from pathlib import Path
from typing import BinaryIO

COPY_CHUNK = 1024 * 1024
# Level 1: a log of text shrinks 7x (level 6: 8.6x) in a quarter of the CPU time (64 MB: 0.45
# against 2 s here), on a machine the whole class shares.
LEVEL = 1
# A log whose first megabyte shrinks by less than this is kept plain: random output would cost
# seconds of CPU for nothing (an attacker's flood, say).
WORTH_IT = 0.75


class DoesNotCompress(Exception):
    """The log is kept as written: compressing it would save little."""


def gzipped(path: Path) -> Path:
    return path.with_name(path.name + ".gz")


def _parts(path: Path) -> list[Path]:
    return list(path.parent.glob(f"{path.name}.*.gz.part"))


@dataclass
class OpenLog:
    """A log opened for reading: ``file`` reads it as it was written, ``size`` bytes long."""

    file: BinaryIO
    size: int
    compressed: bool
    _raw: BinaryIO | None = None

    def close(self) -> None:
        self.file.close()
        if self._raw is not None:
            self._raw.close()

    def __enter__(self) -> "OpenLog":
        return self

    def __exit__(self, *_exc) -> None:
        self.close()


def open_log(path: Path) -> OpenLog | None:
    """The log at ``path``, plain or compressed; None if there is none (not written, pruned)."""
    try:
        plain = open(path, "rb")  # noqa: SIM115
    except FileNotFoundError:
        pass
    else:
        return OpenLog(plain, os.fstat(plain.fileno()).st_size, False)
    try:
        raw = open(gzipped(path), "rb")  # noqa: SIM115
    except FileNotFoundError:
        return None
    size = _written_length(raw)
    return OpenLog(gzip.GzipFile(fileobj=raw, mode="rb"), size, True, raw)


def _written_length(raw: BinaryIO) -> int:
    """A gzip file's length uncompressed, from its last four bytes (ISIZE: exact for one
    member under 4 GiB, as a run's log always is)."""
    end = raw.seek(0, os.SEEK_END)
    if end < 18:  # not even an empty member's header and trailer
        raw.seek(0)
        return 0
    raw.seek(end - 4)
    (size,) = struct.unpack("<I", raw.read(4))
    raw.seek(0)
    return size


def written_length(path: Path) -> int:
    """How long the log is as written (0 if there is none), without reading it."""
    try:
        return path.stat().st_size
    except FileNotFoundError:
        pass
    try:
        with open(gzipped(path), "rb") as raw:
            return _written_length(raw)
    except FileNotFoundError:
        return 0


def exists(path: Path) -> bool:
    return path.exists() or gzipped(path).exists()


def disk_bytes(path: Path) -> int:
    """The bytes the log takes on disk, plain or compressed (0 if there is none)."""
    for each in (path, gzipped(path)):
        try:
            return each.stat().st_size
        except FileNotFoundError:
            continue
    return 0


def compress_aside(path: Path) -> Path | None:
    """The plain log gzipped into a part file beside it (the plain one left as it is); None if
    there is no plain log; DoesNotCompress if its start barely shrinks. Slow for a big log:
    run it in a worker thread."""
    try:
        source = open(path, "rb")  # noqa: SIM115
    except FileNotFoundError:
        return None
    # A part of its own: two compressions of one log (its run's timer, another agent's sweep
    # of leftovers) must not write into one file; each is whole, and either may be put.
    handle, name = tempfile.mkstemp(dir=path.parent, prefix=f"{path.name}.", suffix=".gz.part")
    part = Path(name)
    sample = source.read(COPY_CHUNK)
    if len(sample) > 4096 and len(zlib.compress(sample, LEVEL)) > WORTH_IT * len(sample):
        source.close()
        os.close(handle)
        part.unlink()
        raise DoesNotCompress(path)
    source.seek(0)
    with source, open(handle, "wb") as raw:
        with gzip.GzipFile(filename="", mode="wb", fileobj=raw, compresslevel=LEVEL, mtime=0) as gz:
            shutil.copyfileobj(source, gz, COPY_CHUNK)
        raw.flush()
        os.fsync(raw.fileno())  # whole on disk before the plain log goes
    return part


def put_in_place(path: Path, part: Path) -> int:
    """The compressed part becomes the log, the plain file goes: the bytes it takes now."""
    compressed = gzipped(path)
    os.replace(part, compressed)
    remove_plain(path)
    return compressed.stat().st_size


def remove_plain(path: Path) -> None:
    try:
        path.unlink()
    except FileNotFoundError:
        pass


def remove(path: Path) -> None:
    """The log gone, plain, compressed or half compressed."""
    for each in (path, gzipped(path), *_parts(path)):
        try:
            each.unlink()
        except FileNotFoundError:
            pass
