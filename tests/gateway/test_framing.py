from hypothesis import given, settings
from hypothesis import strategies as st

from gateway.framing import Framer, _x25_python, x25
from tests.gateway.frames import attitude, command, heartbeat, signed_heartbeat

VALID = [heartbeat(), heartbeat(7, 3, version=1), command(255, 190, 1, 1), attitude(1, 1, 42),
         command(255, 190, 5, 0, version=1), signed_heartbeat()]  # fmt: skip


def test_it_frames_v1_and_v2_with_header_and_targets():
    framer = Framer()
    out = framer.feed(b"".join(VALID))
    assert [f[0] for f in out] == VALID
    assert [f[1:] for f in out] == [
        (1, 1, 0, 0, 0), (7, 3, 0, 0, 0), (255, 190, 76, 1, 1), (1, 1, 30, 0, 0),
        (255, 190, 76, 5, 0), (1, 1, 0, 0, 0),
    ]  # fmt: skip
    assert framer.errors == 0 and framer.pending == 0


def test_it_passes_signed_frames_intact():
    frame = signed_heartbeat()
    assert frame[2] & 1 and len(frame) == 12 + 9 + 13
    assert Framer().feed(frame)[0][0] == frame


def test_it_finds_targets_in_truncated_v2_payloads():
    # MAVLink 2 drops trailing zero bytes: COMMAND_LONG to system 3, component 0
    frame = command(255, 190, 3, 0)
    assert frame[1] < 33
    assert Framer().feed(frame)[0][4:] == (3, 0)


def test_it_reassembles_frames_fed_byte_by_byte():
    framer = Framer()
    data = b"".join(VALID)
    out = [f[0] for i in range(len(data)) for f in framer.feed(data[i : i + 1])]
    assert out == VALID


def test_it_skips_a_bad_crc_and_counts_it():
    bad = bytearray(attitude())
    bad[12] ^= 0xFF
    framer = Framer()
    out = framer.feed(heartbeat() + bytes(bad) + heartbeat(2))
    assert [f[1] for f in out] == [1, 2]
    assert framer.errors == 1


def test_unknown_ids_pass_when_the_next_frame_follows():
    frame = bytearray(heartbeat())
    frame[7:10] = (0x34, 0x12, 0x0F)  # an id no dialect of ours has: CRC unchecked
    framer = Framer()
    assert framer.feed(bytes(frame)) == []  # waits to see what follows
    out = framer.feed(heartbeat())
    assert [f[0] for f in out] == [bytes(frame), heartbeat()]
    assert framer.unknown == 1


def test_fastcrc_and_the_python_table_agree():
    for data in (b"", b"123456789", bytes(range(256))):
        assert x25(data) == _x25_python(data)


garbage = st.binary(max_size=80).map(lambda b: bytes(x for x in b if x not in (0xFD, 0xFE)))


@settings(max_examples=300, deadline=None)
@given(st.lists(st.tuples(garbage, st.sampled_from(VALID)), max_size=8), garbage,
       st.lists(st.integers(1, 64), min_size=1, max_size=10))  # fmt: skip
def test_garbage_around_valid_frames_leaves_the_valid_frames(pairs, tail, cuts):
    data = b"".join(g + f for g, f in pairs) + tail
    framer = Framer()
    out, i, k = [], 0, 0
    while i < len(data):
        step = cuts[k % len(cuts)]
        out += [f[0] for f in framer.feed(data[i : i + step])]
        i, k = i + step, k + 1
    assert out == [f for _, f in pairs]
    assert framer.skipped == sum(len(g) for g, _ in pairs) + len(tail) - framer.pending


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=600), st.lists(st.sampled_from(VALID), max_size=4))
def test_any_bytes_never_raise_and_a_clean_stream_resyncs(noise, frames):
    framer = Framer()
    framer.feed(noise)
    # 300 zero bytes complete any false start, which then fails its CRC or structure check
    framer.feed(bytes(300))
    out = [f[0] for f in framer.feed(b"".join(frames))]
    assert out == frames
