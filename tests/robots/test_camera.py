"""The live camera: the agent's producer, the ffmpeg camera and the MJPEG endpoint.

Real parts throughout: robot agents in this process on the in-memory channel layer, ffmpeg
reading its own test source (``lavfi:testsrc``) as a camera, and the ASGI application of
robotide.asgi answering ``/robots/<name>/camera.mjpg``.
"""

import asyncio
import contextlib
import io
import os
import time
from pathlib import Path

import pytest
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer
from channels.testing import HttpCommunicator
from django.contrib.auth.models import User
from django.test import Client
from PIL import Image

from rhal.camera import CameraError, CameraSettings, FfmpegCamera, JpegSplitter
from robotide.asgi import application
from robots import camera
from robots.agent import RobotAgent
from robots.bus import ask_agent, send_to_agent
from robots.camera import camera_group, close_streams, has_camera
from robots.models import Robot
from tests.peers import start_peer

TESTSRC = {"device": "lavfi:testsrc", "width": 160, "height": 120, "fps": 10}


async def until(predicate, timeout=10.0, what="condition"):
    deadline = time.monotonic() + timeout
    while not (result := predicate()):
        assert time.monotonic() < deadline, f"{what} not met within {timeout} s"
        await asyncio.sleep(0.02)
    return result


def decode(jpeg: bytes) -> Image.Image:
    image = Image.open(io.BytesIO(jpeg))
    image.load()  # the whole image, not only its header
    return image


def reaped(pid: int) -> bool:
    """Gone for good: no process, not even a zombie waiting for its parent."""
    try:
        os.waitpid(pid, os.WNOHANG)
    except ChildProcessError:
        return not Path(f"/proc/{pid}").exists()
    return False


# -- the ffmpeg camera, no Django ------------------------------------------------------------


async def test_ffmpeg_reads_frames_of_the_asked_size_and_is_reaped_when_closed():
    cam = FfmpegCamera(CameraSettings.parse(TESTSRC))
    await cam.start()
    pid = cam.process.pid
    try:
        frames = [await cam.frame() for _ in range(3)]
    finally:
        await cam.close()
    assert len(set(frames)) == 3  # each a new frame
    for jpeg in frames:
        assert decode(jpeg).size == (160, 120)
    assert reaped(pid)
    await cam.close()  # twice is fine


async def test_a_missing_ffmpeg_is_a_clear_error():
    cam = FfmpegCamera(CameraSettings.parse(TESTSRC), ffmpeg="/nonexistent/ffmpeg")
    with pytest.raises(CameraError, match="ffmpeg not found.*apt-get install ffmpeg"):
        await cam.start()


async def test_a_device_that_fails_is_a_clear_error_with_ffmpegs_words():
    cam = FfmpegCamera(CameraSettings.parse({"device": "/dev/robotide-no-such-camera"}))
    await cam.start()
    pid = cam.process.pid
    try:
        with pytest.raises(CameraError, match="no-such-camera.*No such file or directory"):
            await cam.frame()
    finally:
        await cam.close()
    assert reaped(pid)


@pytest.mark.parametrize(
    "value, why",
    [
        ([], "must be an object"),
        ({"fps": 100}, "fps must be between"),
        ({"fps": "fast"}, "fps must be a number"),
        ({"width": 4000}, "width must be between"),
        ({"device": "http://example.invalid/cam"}, "must be a device path"),
        ({"device": "lavfi:movie=/etc/passwd"}, "source's name only"),
        ({"colour": "red"}, "unknown camera setting"),
    ],
)
def test_camera_settings_are_checked(value, why):
    with pytest.raises(ValueError, match=why):
        CameraSettings.parse(value)


def test_camera_settings_default_to_10_fps_and_640x480():
    assert CameraSettings.parse(None) == CameraSettings("", 10.0, 640, 480)


def test_the_splitter_cuts_a_stream_into_whole_jpegs():
    images = []
    for colour in ("red", "green", "blue"):
        out = io.BytesIO()
        Image.new("RGB", (32, 24), colour).save(out, "JPEG")
        images.append(out.getvalue())
    stream = b"junk" + images[0] + images[1] + b"\xff\x00 more junk" + images[2]
    splitter, found = JpegSplitter(), []
    for i in range(0, len(stream), 7):  # in pieces that cut markers in half
        found += splitter.feed(stream[i : i + 7])
    assert found == images


# -- the agent's producer -------------------------------------------------------------------

uses_db = pytest.mark.django_db(transaction=True)


@pytest.fixture
async def start_agent():
    """``await start_agent(name, url, settings)`` -> a serving RobotAgent, torn down after."""
    tasks = []

    async def start(name, url="sim://", settings=None):
        await database_sync_to_async(Robot.objects.create)(
            name=name, url=url, settings=settings or {}
        )
        agent = RobotAgent(name)
        agent.serving = asyncio.create_task(agent.serve())
        tasks.append(agent.serving)
        await asyncio.wait_for(agent.ready.wait(), 15)
        return agent

    yield start
    for task in tasks:
        task.cancel()
        with contextlib.suppress(asyncio.CancelledError):
            await task
    await get_channel_layer().flush()


class Renders:
    """Counts the frames the agent's driver renders."""

    def __init__(self, agent):
        self.count = 0
        real = agent.driver.camera_jpeg

        async def counted():
            self.count += 1
            return await real()

        agent.driver.camera_jpeg = counted


class Viewer:
    """What a stream does on the channel layer, without HTTP."""

    def __init__(self, robot: str):
        self.robot = robot
        self.layer = get_channel_layer()

    async def watch(self) -> "Viewer":
        self.channel = await self.layer.new_channel()
        await self.layer.group_add(camera_group(self.robot), self.channel)
        await send_to_agent(self.robot, "camera.watch", viewer=self.channel)
        return self

    async def next(self, timeout=5.0) -> dict:
        return await asyncio.wait_for(self.layer.receive(self.channel), timeout)

    async def frames(self, n: int) -> list[bytes]:
        return [(await self.next())["jpeg"] for _ in range(n)]

    async def leave(self) -> None:
        await self.layer.group_discard(camera_group(self.robot), self.channel)
        await send_to_agent(self.robot, "camera.unwatch", viewer=self.channel)


async def idle(hub, renders: Renders, seconds=0.3) -> None:
    """The producer has stopped, well before a viewer's lease (10 s) would have run out,
    and nothing is rendered any more."""
    stopped = lambda: hub.task is None or hub.task.done()  # noqa: E731
    await until(stopped, timeout=4.0, what="the producer stopped")
    before = renders.count
    await asyncio.sleep(seconds)
    assert renders.count == before


@uses_db
async def test_nothing_is_rendered_until_someone_watches_and_after_they_leave(start_agent):
    agent = await start_agent("cam-idle")
    renders = Renders(agent)
    await asyncio.sleep(0.5)
    assert renders.count == 0 and agent.camera.task is None

    viewer = await Viewer("cam-idle").watch()
    frames = await viewer.frames(3)
    assert decode(frames[0]).size == (320, 240)  # the sim's rendered view
    assert renders.count >= 3

    await viewer.leave()
    await idle(agent.camera, renders)
    assert agent.camera.viewers == {}


@uses_db
async def test_a_viewer_that_stops_renewing_is_forgotten(start_agent):
    agent = await start_agent("cam-lease")
    agent.camera.lease = 0.5
    renders = Renders(agent)
    viewer = await Viewer("cam-lease").watch()
    await viewer.frames(2)
    # No renewal, no goodbye (its web process crashed): forgotten after its lease.
    await idle(agent.camera, renders)
    assert agent.camera.viewers == {}


@uses_db
async def test_the_frame_rate_is_capped_by_the_robots_setting(start_agent):
    agent = await start_agent("cam-rate", settings={"camera": {"fps": 5}})
    renders = Renders(agent)
    viewer = await Viewer("cam-rate").watch()
    await viewer.next()
    started, count = time.monotonic(), 0
    while time.monotonic() - started < 1.0:
        await viewer.next()
        count += 1
    # 5 fps: about 5 frames in that second, never a burst (an upper bound only: a slow
    # machine may deliver fewer).
    assert 1 <= count <= 6
    assert renders.count <= agent.camera.published + 1
    await viewer.leave()


@uses_db
async def test_two_viewers_share_one_producer(start_agent):
    agent = await start_agent("cam-two")
    renders = Renders(agent)
    first = await Viewer("cam-two").watch()
    second = await Viewer("cam-two").watch()
    await first.frames(2)
    await second.frames(2)
    published = agent.camera.published
    seen_first, seen_second = await first.frames(4), await second.frames(4)
    assert seen_first == seen_second  # the very same frames, each rendered once
    assert renders.count <= agent.camera.published + 1
    assert agent.camera.published >= published + 4

    await first.leave()
    await second.frames(2)  # one leaving does not stop the other's stream
    await second.leave()
    await idle(agent.camera, renders)


@uses_db
async def test_a_configured_camera_runs_ffmpeg_only_while_watched(start_agent):
    agent = await start_agent("cam-ffmpeg", settings={"camera": TESTSRC})
    renders = Renders(agent)
    viewer = await Viewer("cam-ffmpeg").watch()
    frames = await viewer.frames(3)
    assert {decode(jpeg).size for jpeg in frames} == {(160, 120)}
    assert renders.count == 0  # the device, not the driver's camera
    pid = agent.camera.source.process.pid

    await viewer.leave()
    await until(lambda: agent.camera.task.done(), what="the producer stopped")
    assert reaped(pid)


@uses_db
async def test_an_agent_that_shuts_down_stops_its_ffmpeg(start_agent):
    agent = await start_agent("cam-down", settings={"camera": TESTSRC})
    viewer = await Viewer("cam-down").watch()
    await viewer.frames(1)
    pid = agent.camera.source.process.pid
    agent.serving.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await agent.serving
    assert reaped(pid)


@uses_db
async def test_a_failing_camera_is_reported_and_the_agent_carries_on(start_agent):
    device = {"device": "/dev/robotide-no-such-camera"}
    agent = await start_agent("cam-fail", settings={"camera": device})
    viewer = await Viewer("cam-fail").watch()
    message = await viewer.next()
    assert message["type"] == "camera.error"
    assert "robotide-no-such-camera" in message["error"] and "No such file" in message["error"]
    assert agent.camera.viewers == {}
    assert "sensors" in await ask_agent("cam-fail", "robot.state")  # still serving


@uses_db
async def test_a_snapshot_is_one_frame_from_whichever_camera_the_robot_has(start_agent):
    sim = await start_agent("cam-snap")
    jpeg = (await ask_agent("cam-snap", "camera.snapshot"))["jpeg"]
    assert decode(jpeg).size == (320, 240)
    assert sim.camera.task is None  # no stream started for it

    await start_agent("cam-snap-dev", settings={"camera": TESTSRC})
    jpeg = (await ask_agent("cam-snap-dev", "camera.snapshot", timeout=5))["jpeg"]
    assert decode(jpeg).size == (160, 120)

    viewer = await Viewer("cam-snap").watch()  # while streaming: the newest frame sent
    await viewer.frames(2)
    assert (await ask_agent("cam-snap", "camera.snapshot"))["jpeg"] == sim.camera.latest
    await viewer.leave()


@uses_db
async def test_configured_cameras_count_as_the_robots_camera(start_agent, tmp_path):
    peer = await start_peer("dtmf", tmp_path)  # a robot whose driver has no camera
    try:
        await start_agent("tones", url=peer.url)
        await start_agent("tones-cam", url=peer.url, settings={"camera": TESTSRC})
        assert (await ask_agent("tones", "camera.info"))["camera"] is False
        info = await ask_agent("tones-cam", "camera.info")
        assert info["camera"] is True and info["source"] == "lavfi:testsrc"
        robot = await database_sync_to_async(Robot.objects.get)(name="tones-cam")
        assert has_camera(robot, {"camera": False})
    finally:
        await peer.stop()


# -- the endpoint ---------------------------------------------------------------------------


@database_sync_to_async
def session_cookie(username: str) -> bytes:
    user = User.objects.create_user(username)
    client = Client()
    client.force_login(user)
    return f"sessionid={client.cookies['sessionid'].value}".encode()


def get(path: str, cookie: bytes | None = None) -> HttpCommunicator:
    headers = [(b"cookie", cookie)] if cookie else []
    return HttpCommunicator(application, "GET", path, headers=headers)


class Stream:
    """Reads an MJPEG response part by part."""

    def __init__(self, communicator: HttpCommunicator):
        self.communicator = communicator
        self.buffer = b""
        self.ended = False

    async def open(self) -> dict:
        await self.communicator.send_input({"type": "http.request", "body": b""})
        return await self.communicator.receive_output(5)

    async def part(self) -> tuple[dict, bytes]:
        while True:
            head, sep, rest = self.buffer.partition(b"\r\n\r\n")
            if sep and head.startswith(b"--frame\r\n"):
                fields = dict(
                    line.split(b": ", 1) for line in head.split(b"\r\n")[1:] if b": " in line
                )
                length = int(fields[b"Content-Length"])
                if len(rest) >= length:
                    self.buffer = rest[length:].removeprefix(b"\r\n")
                    return fields, rest[:length]
            assert not self.ended, "the stream ended"
            chunk = await self.communicator.receive_output(5)
            assert chunk["type"] == "http.response.body"
            self.buffer += chunk["body"]
            self.ended = not chunk.get("more_body", False)

    async def close(self) -> None:
        await self.communicator.send_input({"type": "http.disconnect"})
        await self.communicator.wait(5)


async def status_and_text(communicator: HttpCommunicator) -> tuple[int, dict, str]:
    response = await communicator.get_response(timeout=5)
    await communicator.wait(5)
    return response["status"], dict(response["headers"]), response["body"].decode()


@uses_db
async def test_the_stream_needs_a_signed_in_user_who_may_see_the_robot(start_agent):
    await start_agent("cam-access")
    status, headers, _ = await status_and_text(get("/robots/cam-access/camera.mjpg"))
    assert status == 302
    assert headers[b"location"] == b"/accounts/login/?next=/robots/cam-access/camera.mjpg"

    cookie = await session_cookie("alice")
    status, _, text = await status_and_text(get("/robots/nobody-here/camera.mjpg", cookie))
    assert status == 404 and "No robot named 'nobody-here'" in text


@uses_db
async def test_a_robot_without_a_camera_answers_404(start_agent, tmp_path):
    peer = await start_peer("dtmf", tmp_path)
    try:
        await start_agent("tones", url=peer.url)
        cookie = await session_cookie("alice")
        status, _, text = await status_and_text(get("/robots/tones/camera.mjpg", cookie))
        assert status == 404 and "Robot tones has no camera" in text
    finally:
        await peer.stop()


@uses_db
async def test_the_sim_robots_view_streams_as_multipart_jpeg(start_agent):
    agent = await start_agent("cam-web")
    renders = Renders(agent)
    stream = Stream(get("/robots/cam-web/camera.mjpg", await session_cookie("alice")))
    start = await stream.open()
    headers = dict(start["headers"])
    assert start["status"] == 200
    assert headers[b"content-type"] == b"multipart/x-mixed-replace; boundary=frame"
    assert headers[b"cache-control"] == b"no-store"
    for _ in range(4):
        fields, jpeg = await stream.part()
        assert fields[b"Content-Type"] == b"image/jpeg"
        assert decode(jpeg).size == (320, 240)
    assert len(agent.camera.viewers) == 1

    await stream.close()  # the browser went away: the camera stops
    await idle(agent.camera, renders)
    assert agent.camera.viewers == {}


@uses_db
async def test_streams_end_when_the_server_shuts_down(start_agent, monkeypatch):
    monkeypatch.setattr(camera, "_closing", False)  # put back after the test
    await start_agent("cam-bye")
    stream = Stream(get("/robots/cam-bye/camera.mjpg", await session_cookie("alice")))
    assert (await stream.open())["status"] == 200
    await stream.part()
    await close_streams()
    while not stream.ended:  # the last part says why, then the response ends
        fields, last = await stream.part()
    assert decode(last).size == (320, 240)
    assert not camera.STREAMS
    await stream.close()
    late = get("/robots/cam-bye/camera.mjpg", await session_cookie("bob"))
    status, _, text = await status_and_text(late)
    assert status == 503 and "shutting down" in text


@uses_db
async def test_a_failing_camera_ends_the_stream_with_a_frame_that_says_why(start_agent):
    device = {"device": "/dev/robotide-no-such-camera"}
    agent = await start_agent("cam-broken", settings={"camera": device})
    stream = Stream(get("/robots/cam-broken/camera.mjpg", await session_cookie("alice")))
    assert (await stream.open())["status"] == 200
    fields, jpeg = await stream.part()
    assert stream.ended and decode(jpeg).size == (320, 240)
    await stream.close()
    assert agent.camera.viewers == {}


@uses_db
async def test_a_stream_renews_its_watch_while_open(start_agent, monkeypatch):
    monkeypatch.setattr(camera, "WATCH_RENEW", 0.1)
    agent = await start_agent("cam-renew")
    agent.camera.lease = 0.5
    stream = Stream(get("/robots/cam-renew/camera.mjpg", await session_cookie("alice")))
    assert (await stream.open())["status"] == 200
    started = time.monotonic()
    while time.monotonic() - started < 1.5:  # three leases long
        await stream.part()
    assert len(agent.camera.viewers) == 1 and not agent.camera.task.done()
    await stream.close()


@uses_db
async def test_a_slow_client_gets_the_newest_frame_not_a_backlog(start_agent):
    agent = await start_agent("cam-slow", settings={"camera": {"fps": 20}})
    await agent.driver.drive(0.0, 1.0)  # turning: every frame differs
    published = await Viewer("cam-slow").watch()  # sees every frame the agent sends
    scope = {
        "type": "http",
        "http_version": "1.1",
        "method": "GET",
        "path": "/robots/cam-slow/camera.mjpg",
        "query_string": b"",
        "headers": [(b"cookie", await session_cookie("alice"))],
    }
    requests, sent, reading = asyncio.Queue(), [], asyncio.Event()
    await requests.put({"type": "http.request", "body": b""})

    async def send(message):
        sent.append(message)
        if len(sent) == 3:  # headers, the first boundary, one frame: then it stops reading
            await reading.wait()

    app = asyncio.create_task(application(scope, requests.get, send))
    await until(lambda: len(sent) == 3, what="the first frame")
    seen = []
    while len(seen) < 10:  # the agent goes on sending meanwhile
        seen.append((await published.next())["jpeg"])
    reading.set()
    await until(lambda: len(sent) >= 4, what="a frame after the pause")
    after = sent[3]["body"]
    # The newest frame at that moment, not the one that followed the first: the ones the
    # client was too slow for were dropped, not queued.
    assert seen[0] not in after and seen[1] not in after

    # However the stream's task ends (here: cancelled, as a server that gives up on it
    # does), it stops watching.
    assert len(agent.camera.viewers) == 2
    app.cancel()
    with contextlib.suppress(asyncio.CancelledError):
        await app
    await until(lambda: len(agent.camera.viewers) == 1, timeout=3, what="the stream let go")
    await published.leave()
