"""Reading a run's log file: tagged lines written by runbox.supervisor."""

import os
from collections.abc import Callable, Iterator
from pathlib import Path

from django.utils.html import escape

from programs.error_lines import error_place
from programs.models import program_filename

TAIL_LINES = 2000
DOWNLOAD_CHUNK = 256 * 1024
BLOCK = 256 * 1024
CATCH_UP_BYTES = 256 * 1024


def tail(path: Path, limit: int = TAIL_LINES) -> tuple[list[tuple[str, str]], int, int]:
    """(last `limit` complete lines, how many earlier lines were left out, offset after the last).

    Reads backwards from the end, so a big log costs a bounded amount of memory.
    """
    try:
        f = open(path, "rb")  # noqa: SIM115
    except FileNotFoundError:
        return [], 0, 0
    with f:
        size = f.seek(0, os.SEEK_END)
        start, data = size, b""
        while start > 0 and data.count(b"\n") <= limit:
            step = min(BLOCK, start)
            start -= step
            f.seek(start)
            data = f.read(step) + data
        end = start + data.rfind(b"\n") + 1  # the stream goes on from the last complete line
        data = data[: end - start]
        if start > 0:  # the first piece read may begin inside a line
            cut = data.find(b"\n") + 1
            data, start = data[cut:], start + cut
        lines = data.split(b"\n")[:-1]
        kept = lines[-limit:]
        earlier = len(lines) - len(kept) + count_lines(f, start)
    return [_tagged(line) for line in kept], earlier, max(end, 0)


def lines_after(path: Path, start: int, limit: int = CATCH_UP_BYTES):
    """(complete lines from byte `start` on, offset after them); (None, start) if more than
    `limit` bytes came meanwhile: a tail serves the reader better then."""
    try:
        f = open(path, "rb")  # noqa: SIM115
    except FileNotFoundError:  # nothing written yet
        return ([], 0) if start == 0 else (None, start)
    with f:
        size = f.seek(0, os.SEEK_END)
        if size - start > limit or start > size:
            return None, start
        f.seek(start)
        data = f.read(size - start)
    end = data.rfind(b"\n") + 1
    return [_tagged(line) for line in data[:end].split(b"\n")[:-1]], start + end


def count_lines_between(path: Path, start: int, end: int) -> int:
    with open(path, "rb") as f:
        return count_lines(f, end, start)


def count_lines(f, end: int, start: int = 0) -> int:
    f.seek(start)
    count, left = 0, end - start
    while left > 0:
        chunk = f.read(min(BLOCK, left))
        count += chunk.count(b"\n")
        left -= len(chunk)
    return count


def _tagged(line: bytes) -> tuple[str, str]:
    return (chr(line[0]) if line else "o"), line[2:].decode("utf-8", "replace")


def plain_text(path: Path, streams: str = "oes") -> Iterator[bytes]:
    """The log as the program printed it (tags removed), chunk by chunk, for a download."""
    wanted = tuple(tag.encode() for tag in streams)
    with open(path, "rb") as f:
        while lines := f.readlines(DOWNLOAD_CHUNK):
            yield b"".join(line[2:] for line in lines if line.startswith(wanted))


def render_lines(lines, place_of: Callable[[str], int | None] | None = None) -> str:
    """HTML for log lines: stdout, stderr and robotide's own lines told apart by class; an
    error line that points into the program carries the line (``data-line``) for the editor."""
    html = []
    for tag, text in lines:
        line = place_of(text) if place_of is not None and tag == "e" else None
        mark = f' data-line="{line}"' if line else ""
        html.append(f'<div class="ln {tag}"{mark}>{escape(text)}</div>')
    return "".join(html)


def places_in(run) -> Callable[[str], int | None]:
    """What line of ``run``'s program an output line points at, if any."""
    return places_for(run.language, run.program_name)


def places_for(language: str, program_name: str) -> Callable[[str], int | None]:
    """What line of the program an output line points at, if any: known from its language and
    name alone (programs.watch_pass)."""
    try:
        program_file = program_filename(program_name, language)
    except ValueError:  # a language this robotide no longer has
        return lambda _text: None

    def place_of(text: str) -> int | None:
        try:
            found = error_place(language, text, program_file)
        except (ValueError, LookupError):
            return None
        return found.line if found else None

    return place_of
