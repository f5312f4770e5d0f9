"""Reading a run's log file: tagged lines written by runbox.supervisor, plain or compressed
(runlogs.files)."""

from collections import deque
from collections.abc import Callable, Iterator
from pathlib import Path

from django.http import HttpResponse, StreamingHttpResponse
from django.utils.html import escape

from programs.error_lines import error_place
from programs.models import program_filename
from runlogs import files as log_files
from runlogs import system_words
from runlogs.files import open_log
from runlogs.notes import pruned_text

TAIL_LINES = 2000
DOWNLOAD_CHUNK = 256 * 1024
BLOCK = 256 * 1024
CATCH_UP_BYTES = 256 * 1024
TEXT = "text/plain; charset=utf-8"


def tail(path: Path, limit: int = TAIL_LINES) -> tuple[list[tuple[str, str]], int, int]:
    """(last `limit` complete lines, how many earlier lines were left out, offset after the last).

    A plain log is read backwards from its end, a compressed one (ended) forwards, keeping
    only the last lines: either costs a bounded amount of memory. No log (none written yet,
    or pruned): no lines.
    """
    log = open_log(path)
    if log is None:
        return [], 0, 0
    with log:
        if log.compressed:
            data, start, earlier = _last_lines_read_forwards(log.file, limit)
            end = start + len(data)
        else:
            data, start, end = _last_lines_read_backwards(log.file, log.size, limit)
            earlier = count_lines(log.file, start)
    lines = data.split(b"\n")[:-1]
    kept = lines[-limit:]
    earlier += len(lines) - len(kept)
    return [_tagged(line) for line in kept], earlier, max(end, 0)


def _last_lines_read_backwards(f, size: int, limit: int) -> tuple[bytes, int, int]:
    """(the log's last complete lines, at least `limit` of them if it has them, whole; where
    they start; where they end)."""
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
    return data, start, end


def _last_lines_read_forwards(f, limit: int) -> tuple[bytes, int, int]:
    """(the log's last complete lines, at least `limit` of them if it has them; where they
    start; how many lines come before them): read once from the start, the blocks holding
    the last lines kept."""
    kept: deque[bytes] = deque()
    kept_lines = start = earlier = 0
    carry = b""  # the incomplete line a block ends with
    while block := f.read(BLOCK):
        block, carry = carry + block, b""
        cut = block.rfind(b"\n") + 1
        block, carry = block[:cut], block[cut:]
        kept.append(block)
        kept_lines += block.count(b"\n")
        while len(kept) > 1 and kept_lines - kept[0].count(b"\n") >= limit:
            dropped = kept.popleft()
            kept_lines -= dropped.count(b"\n")
            earlier += dropped.count(b"\n")
            start += len(dropped)
    return b"".join(kept), start, earlier


def lines_after(path: Path, start: int, limit: int = CATCH_UP_BYTES):
    """(complete lines from byte `start` on, offset after them); (None, start) if more than
    `limit` bytes came meanwhile: a tail serves the reader better then."""
    log = open_log(path)
    if log is None:  # nothing written yet (or pruned)
        return ([], 0) if start == 0 else (None, start)
    with log:
        if log.size - start > limit or start > log.size:
            return None, start
        log.file.seek(start)
        data = log.file.read(log.size - start)
    end = data.rfind(b"\n") + 1
    return [_tagged(line) for line in data[:end].split(b"\n")[:-1]], start + end


def count_lines_between(path: Path, start: int, end: int) -> int:
    log = open_log(path)
    if log is None:  # pruned meanwhile
        return 0
    with log:
        return count_lines(log.file, end, start)


def count_lines(f, end: int, start: int = 0) -> int:
    f.seek(start)
    count, left = 0, end - start
    while left > 0:
        chunk = f.read(min(BLOCK, left))
        if not chunk:
            break
        count += chunk.count(b"\n")
        left -= len(chunk)
    return count


def _tagged(line: bytes) -> tuple[str, str]:
    return (chr(line[0]) if line else "o"), line[2:].decode("utf-8", "replace")


def plain_text(path: Path, streams: str = "oes") -> Iterator[bytes]:
    """The log as the program printed it (tags removed), chunk by chunk, for a download;
    nothing if there is no log. Opened before the first chunk is asked for: a log pruned or
    compressed after that is still read to its end."""
    log = open_log(path)
    return _plain_chunks(log, streams) if log is not None else iter(())


def _plain_chunks(log, streams: str) -> Iterator[bytes]:
    wanted = tuple(tag.encode() for tag in streams)
    with log:
        while lines := log.file.readlines(DOWNLOAD_CHUNK):
            yield b"".join(_plain(line) for line in lines if line.startswith(wanted))


def _plain(line: bytes) -> bytes:
    """A line as downloaded: robotide's own in the reader's language (runlogs.system_words:
    written in English, which the file keeps), the program's as it printed them."""
    if not line.startswith(b"s "):
        return line[2:]
    text = line[2:].decode("utf-8", "replace").rstrip("\n")
    return (system_words.line(text) + "\n").encode()


def download(run, streams: str = "oes") -> HttpResponse:
    """The run's log as plain text (see plain_text); a pruned log's answer says when and why
    (410), also when it went while this was asked."""
    log = open_log(run.log_path)
    if log is None:
        run.refresh_from_db(fields=["log_pruned_at", "log_pruned_reason"])
        if run.log_pruned_at is not None:
            return HttpResponse(pruned_text(run), status=410, content_type=TEXT)
        return HttpResponse(b"", content_type=TEXT)
    return StreamingHttpResponse(_plain_chunks(log, streams), content_type=TEXT)


def read_for_page(run) -> tuple[list[tuple[str, str]], int, int]:
    """The tail a page shows (see tail); a log found gone has the run read again, so the page
    says it was pruned (when it went while the page was made)."""
    lines, skipped, offset = tail(run.log_path)
    if not lines and not run.ongoing and run.log_pruned_at is None:
        run.refresh_from_db(fields=["log_pruned_at", "log_pruned_reason"])
    return lines, skipped, offset


def log_exists(path: Path) -> bool:
    """Whether the run has a log: written, plain or compressed, and not pruned."""
    return log_files.exists(path)


def log_length(path: Path) -> int:
    """The log's length as written (0 if none), without reading it."""
    return log_files.written_length(path)


def render_lines(
    lines,
    place_of: Callable[[str], int | None] | None = None,
    link: Callable[[int], str | None] | None = None,
) -> str:
    """HTML for log lines: stdout, stderr and robotide's own lines told apart by class; an
    error line that points into the program carries the line (``data-line``) for the editor,
    and with ``link`` (line -> href) is a link to it, which works without scripts."""
    html = []
    for tag, text in lines:
        if tag == "s":  # robotide's own line, written in English: in the reader's language
            text = system_words.line(text)
        line = place_of(text) if place_of is not None and tag == "e" else None
        mark = f' data-line="{line}"' if line else ""
        href = link(line) if line and link is not None else None
        shown = f'<a href="{href}">{escape(text)}</a>' if href else escape(text)
        html.append(f'<div class="ln {tag}"{mark}>{shown}</div>')
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
