import pytest

from programs import runlog


def write(tmp_path, lines, partial=b""):
    path = tmp_path / "output.log"
    path.write_bytes(b"".join(line + b"\n" for line in lines) + partial)
    return path


def test_tail_of_a_missing_log(tmp_path):
    assert runlog.tail(tmp_path / "none.log") == ([], 0, 0)


@pytest.mark.parametrize("block", [1, 3, 7, 64, 1 << 18])
@pytest.mark.parametrize("limit", [1, 5, 1000])
def test_tail_keeps_the_last_complete_lines_and_counts_the_rest(
    tmp_path, monkeypatch, block, limit
):
    monkeypatch.setattr(runlog, "BLOCK", block)
    lines = [f"{tag} line {i}".encode() for i, tag in zip(range(40), "oeos" * 10, strict=True)]
    path = write(tmp_path, lines, partial=b"o unfinished")
    kept, earlier, end = runlog.tail(path, limit)
    expected = [(line[:1].decode(), line[2:].decode()) for line in lines][-limit:]
    assert kept == expected
    assert earlier == 40 - len(expected)
    assert end == path.stat().st_size - len(b"o unfinished")


def test_tail_decodes_bad_utf8_and_keeps_empty_lines(tmp_path):
    path = write(tmp_path, [b"o \xff\xfe", b"o ", b"e x"])
    assert runlog.tail(path)[0] == [("o", "\ufffd\ufffd"), ("o", ""), ("e", "x")]


def test_plain_text_strips_tags_and_filters_streams(tmp_path, monkeypatch):
    monkeypatch.setattr(runlog, "DOWNLOAD_CHUNK", 8)
    path = write(tmp_path, [b"o out", b"e err", b"s [robotide] finished", b"o again"])
    everything = b"".join(runlog.plain_text(path))
    assert everything == b"out\nerr\n[robotide] finished\nagain\n"
    stderr = b"".join(runlog.plain_text(path, "e"))
    assert stderr == b"err\n"
