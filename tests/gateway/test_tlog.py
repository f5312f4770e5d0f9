""".tlog recording and replay: the router's frames to a file that pymavlink reads, the file back
to UDP with its timing, and the robotide commands for both. Only 127.0.0.1."""

import asyncio
import os
import random
import shutil
import signal
import socket
import struct
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field

from hypothesis import given, settings
from hypothesis import strategies as st
from pymavlink import mavutil

from gateway.framing import Framer
from gateway.router import Endpoint, Router, UdpEndpoint
from gateway.tlog import TlogRecorder, read_tlog, replay
from tests.gateway.frames import attitude, command, heartbeat, signed_heartbeat, sink
from tests.waiting import until

ROBOTIDE = os.path.join(os.path.dirname(sys.executable), "robotide")
T0 = 1_700_000_000_000_000  # µs: 2023


def write_tlog(path, records) -> bytes:
    data = b"".join(struct.pack(">Q", stamp) + frame for stamp, frame in records)
    with open(path, "wb") as f:
        f.write(data)
    return data


def free_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


@dataclass(eq=False)
class Memory(Endpoint):
    sent: list = field(default_factory=list)

    async def start(self):
        pass

    async def stop(self):
        pass

    def send(self, frames):
        self.sent.extend(frames)


# ---------------------------------------------------------------- recording


async def test_routed_frames_round_trip_through_a_tlog_that_pymavlink_reads(tmp_path):
    path = tmp_path / "flight.tlog"
    router = Router()
    recorder = TlogRecorder(path)
    recorder.start()
    router.taps.append(recorder)
    vehicle = await router.add(UdpEndpoint(address=f"127.0.0.1:{free_port()}", mode="server"))
    gcs_transport, gcs, gcs_address = await sink()
    await router.add(UdpEndpoint(address=gcs_address))
    sent = [heartbeat(1, 1, version=1), signed_heartbeat(1, 1)]
    sent += [attitude(1, 1, t) for t in range(50)] + [command(1, 1, 0, 0)]
    out = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    began = time.time()
    for i, frame in enumerate(sent):
        out.sendto(frame, ("127.0.0.1", int(vehicle.address.rsplit(":", 1)[1])))
        if i % 10 == 0:
            await asyncio.sleep(0.01)
    await until(lambda: len(gcs.frames) == len(sent))
    await asyncio.to_thread(recorder.close)
    ended = time.time()
    await router.close()
    gcs_transport.close()
    out.close()
    assert gcs.frames == sent  # recording took nothing from the routing

    reader = read_tlog(path)
    records = list(reader)
    assert [frame for _, frame in records] == sent  # bytes identical: v1, signed v2 and all
    assert reader.skipped == reader.truncated == 0
    stats = recorder.as_dict()
    assert stats["frames"] == len(sent) and stats["drops"] == 0 and not stats["error"]
    assert stats["bytes"] == os.path.getsize(path) == sum(8 + len(f) for f in sent)
    assert began - 1 <= stats["started"] <= began

    log = mavutil.mavlink_connection(str(path))
    messages = []
    while (message := log.recv_match()) is not None:
        messages.append(message)
    log.close()
    assert [m.get_msgbuf() for m in messages] == sent
    assert [m.get_type() for m in messages[:3]] == ["HEARTBEAT", "HEARTBEAT", "ATTITUDE"]
    stamps = [m._timestamp for m in messages]
    assert stamps == sorted(stamps)
    assert began - 0.01 <= stamps[0] and stamps[-1] <= ended + 0.01
    assert stamps[-1] > stamps[0]  # stamped as they came, not all at once


async def test_max_bytes_ends_the_recording_and_counts_the_rest(tmp_path):
    record = 8 + len(attitude(1, 1))
    recorder = TlogRecorder(tmp_path / "x.tlog", max_bytes=10 * record + 30)
    recorder.start()
    for t in range(20):
        recorder([attitude(1, 1, t)])
    recorder([heartbeat(1, 1)])  # would fit in the 30 bytes left: a hole, though
    recorder.close()
    kept = 10
    assert recorder.frames == kept and recorder.drops == 20 - kept + 1
    recorded = [f for _, f in read_tlog(tmp_path / "x.tlog")]
    assert recorded == [attitude(1, 1, t) for t in range(kept)]


async def routes_on_through_a_failing_recorder(recorder, break_it=lambda: None):
    router = Router()
    vehicle = await router.add(Memory(name="vehicle"))
    gcs = await router.add(Memory(name="gcs"))
    recorder.start()
    router.taps.append(recorder)
    vehicle.received(heartbeat(1, 1))
    break_it()
    for t in range(10):
        vehicle.received(attitude(1, 1, t))
        await asyncio.sleep(0.02)
    await until(lambda: recorder.error)
    vehicle.received(attitude(1, 1, 99))  # after the error: still routed, not recorded
    assert gcs.sent == [heartbeat(1, 1)] + [attitude(1, 1, t) for t in (*range(10), 99)]
    await asyncio.to_thread(recorder.close)  # no exception either
    assert recorder.frames + recorder.drops == 12 and recorder.drops >= 1
    return recorder.as_dict()


async def test_a_full_disk_stops_the_recording_not_the_router():
    stats = await routes_on_through_a_failing_recorder(TlogRecorder("/dev/full"))
    assert "No space left" in stats["error"]


async def test_a_removed_folder_stops_the_recording_not_the_router():
    folder = tempfile.mkdtemp()
    recorder = TlogRecorder(os.path.join(folder, "x.tlog"))
    stats = await routes_on_through_a_failing_recorder(recorder, lambda: shutil.rmtree(folder))
    assert "removed" in stats["error"]


# ---------------------------------------------------------------- reading


def test_a_truncated_last_record_ends_the_reading_cleanly(tmp_path):
    records = [(T0 + i, attitude(1, 1, i)) for i in range(5)]
    data = write_tlog(tmp_path / "x.tlog", records)
    last = 8 + len(records[-1][1])
    for cut in (1, 7, 8, 9, 20, last - 1):
        (tmp_path / "x.tlog").write_bytes(data[:-cut])
        reader = read_tlog(tmp_path / "x.tlog")
        assert list(reader) == records[:-1]
        assert reader.truncated == last - cut and reader.skipped == 0
    (tmp_path / "x.tlog").write_bytes(data[:3])
    assert list(read_tlog(tmp_path / "x.tlog")) == []


FRAMES = [heartbeat(1, 1, version=1), signed_heartbeat(1, 1), attitude(1, 1, 7),
          command(255, 190, 1, 1), heartbeat(2, 1)]  # fmt: skip


@settings(max_examples=200, deadline=None)
@given(st.lists(st.binary(max_size=40), min_size=len(FRAMES), max_size=len(FRAMES)))
def test_garbage_between_records_is_skipped_and_counted(garbage):
    records = [(T0 + 1000 * i, frame) for i, frame in enumerate(FRAMES)]
    pairs = zip(records, garbage, strict=True)
    data = b"".join(struct.pack(">Q", t) + f + g for (t, f), g in pairs)
    with tempfile.NamedTemporaryFile(suffix=".tlog") as f:
        f.write(data)
        f.flush()
        reader = read_tlog(f.name)
        assert list(reader) == records
    assert reader.skipped + reader.truncated == sum(map(len, garbage))


def test_random_bytes_before_the_records_do_not_hide_them(tmp_path):
    """An overwritten start: random bytes hold frame-like stretches (unknown message ids have no
    CRC), but none with a plausible stamp, which would make the real ones look like damage."""
    records = [(T0 + 1000 * i, attitude(1, 1, i)) for i in range(5)]
    damage = random.Random(3).randbytes(256 * 1024)
    (tmp_path / "x.tlog").write_bytes(damage + write_tlog(tmp_path / "x.tlog", records))
    reader = read_tlog(tmp_path / "x.tlog")
    assert list(reader) == records and reader.skipped == len(damage)


# ---------------------------------------------------------------- replay


async def replayed(records, tmp_path, **options):
    write_tlog(tmp_path / "x.tlog", records)
    transport, got, address = await sink()
    count = await replay(tmp_path / "x.tlog", [UdpEndpoint(address=address)], **options)
    await until(lambda: len(got.frames) >= count)
    transport.close()
    return count, got


async def test_replay_keeps_the_order_and_the_timing_divided_by_speed(tmp_path):
    records = [(T0 + 250_000 * i, attitude(1, 1, i)) for i in range(5)]  # over 1 s
    spans = {}
    for speed in (1, 10):
        count, got = await replayed(records, tmp_path, speed=speed)
        assert count == 5 and got.frames == [f for _, f in records]
        gaps = [b - a for a, b in zip(got.times, got.times[1:], strict=False)]
        assert all(gap > 0.25 / speed * 0.6 for gap in gaps)  # waits; loose above: loaded CI
        spans[speed] = got.times[-1] - got.times[0]
        assert 1.0 / speed * 0.8 < spans[speed] < 1.0 / speed + 2
    assert spans[10] < spans[1] / 3


async def test_fast_replay_loses_nothing_on_loopback(tmp_path):
    records = [(T0 + i, attitude(1, 1, i)) for i in range(20000)]
    count, got = await replayed(records, tmp_path, speed=0)
    assert count == 20000
    assert got.frames == [f for _, f in records]


async def test_replay_loops_until_stopped(tmp_path):
    records = [(T0 + 1000 * i, attitude(1, 1, i)) for i in range(10)]
    write_tlog(tmp_path / "x.tlog", records)
    transport, got, address = await sink()
    stop = asyncio.Event()
    task = asyncio.create_task(
        replay(tmp_path / "x.tlog", [UdpEndpoint(address=address)], loop=True, stop=stop)
    )
    await until(lambda: len(got.frames) >= 30)
    stop.set()
    count = await asyncio.wait_for(task, 5)
    assert count >= 30
    await until(lambda: len(got.frames) == count)
    assert got.frames == ([f for _, f in records] * (count // 10 + 1))[:count]
    transport.close()


# ---------------------------------------------------------------- the commands


def udp_socket():
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.bind(("127.0.0.1", 0))
    s.settimeout(5)
    return s, s.getsockname()[1]


def receive(s, count) -> list[bytes]:
    framer, frames = Framer(), []
    while len(frames) < count:
        frames += [f[0] for f in framer.feed(s.recvfrom(65536)[0])]
    return frames


def test_robotide_replay_sends_a_tlog_to_udp(tmp_path):
    records = [(T0 + 1000 * i, attitude(1, 1, i)) for i in range(200)]
    write_tlog(tmp_path / "x.tlog", records)
    gcs, port = udp_socket()
    with gcs:
        for speed in (["--speed", "10"], ["--fast"]):
            result = subprocess.run(
                [ROBOTIDE, "replay", str(tmp_path / "x.tlog"), "--to", f"udp:127.0.0.1:{port}",
                 *speed], cwd="/", capture_output=True, text=True, timeout=30,
            )  # fmt: skip
            assert result.returncode == 0, result.stderr
            assert receive(gcs, 200) == [f for _, f in records]
            assert result.stdout.startswith("replayed 200 frames in ")
            assert len(result.stdout.splitlines()) == 1


def test_robotide_replay_refuses_what_it_cannot_replay(tmp_path):
    (tmp_path / "junk.tlog").write_bytes(bytes(range(256)) * 40)
    write_tlog(tmp_path / "x.tlog", [(T0, heartbeat(1, 1))])
    for args, says in [
        ([str(tmp_path / "missing.tlog"), "--to", "udp:127.0.0.1:9"], "No such file"),
        ([str(tmp_path / "junk.tlog"), "--to", "udp:127.0.0.1:9"], "not a .tlog"),
        ([str(tmp_path / "x.tlog"), "--to", "udp:nonsense"], "nonsense"),
    ]:
        result = subprocess.run([ROBOTIDE, "replay", *args], capture_output=True, text=True,
                                timeout=30)  # fmt: skip
        assert result.returncode == 2, args
        assert says in result.stderr and "Traceback" not in result.stderr


def test_robotide_replay_loop_stops_on_sigterm(tmp_path):
    write_tlog(tmp_path / "x.tlog", [(T0 + 10_000 * i, attitude(1, 1, i)) for i in range(10)])
    gcs, port = udp_socket()
    process = subprocess.Popen(
        [ROBOTIDE, "replay", str(tmp_path / "x.tlog"), "--to", f"udp:127.0.0.1:{port}", "--loop"],
        cwd="/", stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    try:
        assert len(receive(gcs, 25)) >= 25  # round more than twice
        process.send_signal(signal.SIGTERM)
        out, err = process.communicate(timeout=5)
        assert process.returncode == 0 and "Traceback" not in err
        assert out.startswith("replayed ") and int(out.split()[1]) >= 25
    finally:
        if process.poll() is None:
            process.kill()
            process.wait()
        gcs.close()
