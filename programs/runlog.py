"""Reading a run's log file: tagged lines written by programs.supervisor."""

import asyncio
from collections import deque
from collections.abc import AsyncIterator, Iterator
from pathlib import Path

from django.utils.html import escape

TAIL_LINES = 2000
DOWNLOAD_CHUNK = 256 * 1024


def read_complete(path: Path) -> tuple[bytes, int]:
    """The log up to its last complete line, and that length (where the live stream goes on)."""
    try:
        data = path.read_bytes()
    except FileNotFoundError:
        return b"", 0
    end = data.rfind(b"\n") + 1
    return data[:end], end


def tagged_lines(data: bytes) -> Iterator[tuple[str, str]]:
    for line in data.split(b"\n")[:-1]:
        yield chr(line[0]) if line else "o", line[2:].decode("utf-8", "replace")


def tail(path: Path, limit: int = TAIL_LINES) -> tuple[list[tuple[str, str]], int, int]:
    """(last `limit` lines, how many earlier lines were left out, offset after the last line)."""
    data, end = read_complete(path)
    lines = deque(tagged_lines(data), maxlen=limit)
    total = data.count(b"\n")
    return list(lines), total - len(lines), end


async def plain_text(path: Path, streams: str = "oes") -> AsyncIterator[bytes]:
    """The log as the program printed it (tags removed), read in a thread chunk by chunk."""
    wanted = tuple(tag.encode() for tag in streams)
    with open(path, "rb") as f:
        while lines := await asyncio.to_thread(f.readlines, DOWNLOAD_CHUNK):
            yield b"".join(line[2:] for line in lines if line.startswith(wanted))


def render_lines(lines) -> str:
    """HTML for log lines: stdout, stderr and robotide's own lines told apart by class."""
    return "".join(f'<div class="ln {tag}">{escape(text)}</div>' for tag, text in lines)
