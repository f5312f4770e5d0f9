"""A compressed log reads as it did plain: every reader of programs.runlog (the run page's
tail, the websocket's catch-up and skipped count, the download) gives the same answer for a
log and for its gzip, and a reader that opened a log before it was compressed or pruned reads
it to its end."""

import gzip

import pytest

from programs import runlog
from runlogs import files

LINES = [f"{tag} line {i} {'x' * (i % 13)}".encode() for i, tag in enumerate("oeos" * 300)]


def a_log(folder, partial=b"") -> bytes:
    folder.mkdir()
    data = b"".join(line + b"\n" for line in LINES) + partial
    (folder / "output.log").write_bytes(data)
    return data


def compressed(folder):
    path = folder / "output.log"
    part = files.compress_aside(path)
    files.put_in_place(path, part)
    assert not path.exists() and files.gzipped(path).exists()
    return path


@pytest.fixture
def both(tmp_path):
    """The same log, plain and gzip."""
    a_log(tmp_path / "plain", partial=b"o unfinished")
    a_log(tmp_path / "gz", partial=b"o unfinished")
    return tmp_path / "plain" / "output.log", compressed(tmp_path / "gz")


@pytest.mark.parametrize("block", [7, 300, 1 << 18])
@pytest.mark.parametrize("limit", [1, 5, 1000, 2000])
def test_the_tail_of_a_compressed_log_is_the_plain_ones(both, monkeypatch, block, limit):
    monkeypatch.setattr(runlog, "BLOCK", block)
    plain, gz = both
    assert runlog.tail(gz, limit) == runlog.tail(plain, limit)
    kept, earlier, end = runlog.tail(gz, limit)
    assert len(kept) == min(limit, len(LINES)) and earlier == len(LINES) - len(kept)
    assert end == plain.stat().st_size - len(b"o unfinished")


def test_catch_up_counts_and_download_of_a_compressed_log_are_the_plain_ones(both):
    plain, gz = both
    size = plain.stat().st_size
    assert files.written_length(gz) == files.written_length(plain) == size
    for start in (0, 17, size // 2, size - 200, size - 12, size, size + 1):
        assert runlog.lines_after(gz, start) == runlog.lines_after(plain, start)
        assert runlog.lines_after(gz, start, limit=100) == runlog.lines_after(plain, start, 100)
        assert runlog.count_lines_between(gz, start // 3, start) == runlog.count_lines_between(
            plain, start // 3, start
        )
    for streams in ("oes", "o", "e"):
        assert b"".join(runlog.plain_text(gz, streams)) == b"".join(
            runlog.plain_text(plain, streams)
        )


def test_an_empty_log_compressed_is_still_empty(tmp_path):
    (tmp_path / "run").mkdir()
    (tmp_path / "run" / "output.log").write_bytes(b"")
    path = compressed(tmp_path / "run")
    assert runlog.tail(path) == ([], 0, 0) and runlog.log_length(path) == 0
    assert b"".join(runlog.plain_text(path)) == b""


def test_a_download_begun_reads_to_its_end_whatever_happens_to_the_log(tmp_path):
    data = a_log(tmp_path / "run")
    path = tmp_path / "run" / "output.log"
    want = b"".join(line[2:] + b"\n" for line in LINES)

    begun = runlog.plain_text(path)
    files.remove(path)  # pruned before its first chunk was read
    assert b"".join(begun) == want and not files.exists(path)

    path.write_bytes(data)
    begun = runlog.plain_text(path)
    first = next(begun)
    compressed(tmp_path / "run")  # compressed while it is read
    assert first + b"".join(begun) == want


def test_no_log_reads_as_nothing(tmp_path):
    path = tmp_path / "run" / "output.log"
    assert runlog.tail(path) == ([], 0, 0)
    assert runlog.lines_after(path, 0) == ([], 0) and runlog.lines_after(path, 5) == (None, 5)
    assert runlog.count_lines_between(path, 0, 10) == 0
    assert b"".join(runlog.plain_text(path)) == b"" and not runlog.log_exists(path)


def test_two_compressions_of_one_log_write_parts_of_their_own(tmp_path):
    """Its run's timer and another agent's sweep may compress one log at once: each writes a
    whole part of its own (one shared name let each truncate the other's)."""
    path = tmp_path / "output.log"
    path.write_bytes(b"".join(b"o line %d\n" % i for i in range(50_000)))
    first, second = files.compress_aside(path), files.compress_aside(path)
    assert first != second
    for part in (first, second):
        assert gzip.decompress(part.read_bytes()) == path.read_bytes()
    files.put_in_place(path, second)
    files.remove(path)
    assert list(tmp_path.iterdir()) == []  # its other part goes with the log
