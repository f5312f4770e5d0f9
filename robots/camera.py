"""The live camera: an MJPEG stream per viewer, one producer per robot while anyone watches.

Agent side, :class:`CameraHub`: the robot's frames come from its ``camera`` setting's device
(a V4L2 camera through ffmpeg, see rhal/camera.py) or else from its driver's own camera (the
sim's rendered view). The hub produces only while it has viewers, at most at the setting's
rate, and sends each JPEG to the group ``camera-<robot>``.

Web side, :class:`CameraStream`: ``GET /robots/<name>/camera.mjpg`` answered on the event loop
(no WSGI worker held per viewer) as ``multipart/x-mixed-replace``, which a plain ``<img>``
shows in any browser. It joins the group, and writes the newest frame whenever its client has
taken the last one: a slow client gets fewer frames, never a growing buffer.

Messages, over the channel layer::

    viewer -> agent  camera.watch {viewer}   now, then every WATCH_RENEW s while it watches;
                                             a viewer not heard of for WATCH_LEASE s is
                                             forgotten (a crashed web process lets go)
                     camera.unwatch {viewer}
                     camera.info {reply_to}  -> {camera: bool, source, fps, width, height}
                     camera.snapshot {reply_to} -> {jpeg}: one frame, for camera.jpg
    agent -> group   camera.frame {jpeg}     JPEG bytes
                     camera.error {error}    the camera failed: streams show it and end
"""

import asyncio
import contextlib
import io
import logging
import textwrap

from channels.db import database_sync_to_async
from channels.exceptions import StopConsumer
from channels.generic.http import AsyncHttpConsumer
from django.contrib.auth.views import redirect_to_login
from django.http import Http404

import rhal
from rhal.camera import CameraError, CameraSettings, FfmpegCamera, fit_jpeg
from robotide.consumers import DirectDispatch
from robots.bus import AgentUnavailable, ask_agent, send_to_agent
from robots.models import Robot, get_robot_for_user

log = logging.getLogger(__name__)

WATCH_RENEW = 3.0  # seconds between a viewer's camera.watch messages
WATCH_LEASE = 10.0  # a viewer silent this long is forgotten
ASK_TIMEOUT = 2.0  # for camera.info, before a stream starts
BOUNDARY = b"frame"
CLOSE_WAIT = 2.0  # seconds a stream has to send its last frame when the server stops


def camera_group(robot_name: str) -> str:
    return f"camera-{robot_name}"


def has_camera(robot: Robot, state: dict) -> bool:
    """Whether a robot's page shows its camera: a device configured in its ``camera``
    setting, or its driver's own camera (``state``: the agent's robot.state reply)."""
    configured = robot.settings.get("camera")
    return bool(isinstance(configured, dict) and configured.get("device")) or bool(
        state.get("camera")
    )


# -- agent side ---------------------------------------------------------------------------------


class DriverCamera:
    """The robot driver's own camera, its frames fitted into the cap when they are larger."""

    def __init__(self, agent, settings: CameraSettings):
        self.agent = agent
        self.settings = settings
        self.too_large = False

    async def start(self) -> None:
        spec = self.agent.driver.capabilities().get("camera")
        if spec is None:
            raise CameraError(f"robot {self.agent.name} has no camera")
        s = self.settings
        self.too_large = spec.get("width", 0) > s.width or spec.get("height", 0) > s.height

    async def frame(self) -> bytes:
        # agent.driver each time: a reconfigure may have replaced it.
        jpeg = await self.agent.driver.camera_jpeg()
        if self.too_large:
            s = self.settings
            jpeg = await asyncio.to_thread(fit_jpeg, jpeg, s.width, s.height)
        return jpeg

    async def close(self) -> None:
        pass


def open_source(agent, settings: CameraSettings):
    """The configured device if there is one, else the driver's own camera."""
    return FfmpegCamera(settings) if settings.device else DriverCamera(agent, settings)


class CameraHub:
    """One robot's camera producer; ``handlers`` go into the agent's message handlers."""

    def __init__(self, agent):
        self.agent = agent
        self.group = camera_group(agent.name)
        self.lease = WATCH_LEASE
        self.viewers: dict[str, float] = {}  # viewer -> when its lease ends (loop time)
        self.task: asyncio.Task | None = None
        self.published = 0  # frames sent to the group so far
        self.source: FfmpegCamera | DriverCamera | None = None  # while producing
        self.latest: bytes | None = None  # the last frame sent, while producing
        self._snapshots: set[asyncio.Task] = set()
        self._snapshot_lock = asyncio.Lock()  # one device, one ffmpeg at a time
        self._nobody = asyncio.Event()  # the last viewer left: stop without waiting a tick

    @property
    def handlers(self) -> dict:
        return {
            "camera.watch": self.watch,
            "camera.unwatch": self.unwatch,
            "camera.info": self.info,
            "camera.snapshot": self.snapshot,
        }

    async def watch(self, message: dict) -> None:
        viewer = message.get("viewer")
        if not isinstance(viewer, str):
            return
        self.viewers[viewer] = asyncio.get_running_loop().time() + self.lease
        self._nobody.clear()
        if self.task is None or self.task.done():
            self.task = asyncio.create_task(self._produce(), name=f"{self.agent.name}-camera")

    async def unwatch(self, message: dict) -> None:
        self.viewers.pop(message.get("viewer"), None)
        if not self.viewers:
            self._nobody.set()

    async def info(self, message: dict) -> None:
        """Whether the robot has a camera; a broken setting counts: the stream will say why."""
        try:
            settings = await self.settings()
        except ValueError:
            await self.agent.reply(message, {"camera": True, "source": "misconfigured"})
            return
        driver_camera = self.agent.driver.capabilities().get("camera") is not None
        has = bool(settings.device) or driver_camera
        await self.agent.reply(message, {"camera": has, **settings.describe()})

    async def snapshot(self, message: dict) -> None:
        """One JPEG (for camera.jpg): the newest frame sent if the camera is on, else one
        taken now. In a task: starting a device takes a while, and an emergency stop must
        not wait behind it."""
        task = asyncio.create_task(self._snapshot(message))
        self._snapshots.add(task)
        task.add_done_callback(self._snapshots.discard)

    async def _snapshot(self, message: dict) -> None:
        try:
            jpeg = await self.frame()
        except Exception as exc:  # told to whoever asked; the agent carries on
            await self.agent.reply(message, {"error": f"robot {self.agent.name}: {exc}"})
            return
        await self.agent.reply(message, {"jpeg": jpeg})

    async def frame(self) -> bytes:
        """The newest frame sent if the camera is on, else one taken now (one at a time: one
        device, one ffmpeg)."""
        if self.latest is not None:
            return self.latest
        async with self._snapshot_lock:
            source = open_source(self.agent, await self.settings())
            try:
                await source.start()
                return await source.frame()
            finally:
                await source.close()

    async def settings(self) -> CameraSettings:
        robot = await database_sync_to_async(Robot.objects.get)(name=self.agent.name)
        return CameraSettings.parse(robot.settings.get("camera"))

    def watched(self) -> bool:
        """Forget the viewers whose lease ran out; True while any is left."""
        now = asyncio.get_running_loop().time()
        for viewer, until in list(self.viewers.items()):
            if until < now:
                del self.viewers[viewer]
                log.info("agent %s: camera viewer %s went quiet", self.agent.name, viewer)
        return bool(self.viewers)

    async def close(self) -> None:
        """The agent shuts down: the producer stops (and its ffmpeg with it)."""
        tasks = [*self._snapshots, *([self.task] if self.task else [])]
        for task in tasks:
            task.cancel()
        await asyncio.gather(*tasks, return_exceptions=True)

    async def _produce(self) -> None:
        name = self.agent.name
        try:
            settings = await self.settings()
            source = open_source(self.agent, settings)
        except Exception as exc:  # a wrong setting, or the database away for a moment
            await self._failed(f"camera settings of robot {name}: {exc}")
            return
        log.info("agent %s: camera on (%s)", name, settings.describe())
        self.source = source
        try:
            await source.start()
            await self._send_frames(source, 1.0 / settings.fps)
        except (CameraError, rhal.RhalError) as exc:
            await self._failed(str(exc))
            return
        except Exception as exc:  # whatever it is, the agent goes on serving its robot
            log.exception("agent %s: camera failed", name)
            await self._failed(f"camera of robot {name} failed: {exc!r}")
            return
        finally:
            self.source = self.latest = None
            await source.close()
            log.info("agent %s: camera off", name)
        if self.watched():  # someone came while it was stopping
            self.task = asyncio.create_task(self._produce(), name=f"{name}-camera")

    async def _send_frames(self, source, interval: float) -> None:
        loop = asyncio.get_running_loop()
        next_at = loop.time()
        while self.watched():
            jpeg = await source.frame()
            await self.agent.layer.group_send(self.group, {"type": "camera.frame", "jpeg": jpeg})
            self.latest = jpeg
            self.published += 1
            # Never a burst to catch up: a late frame moves the schedule on.
            next_at = max(next_at + interval, loop.time())
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._nobody.wait(), next_at - loop.time())

    async def _failed(self, why: str) -> None:
        log.error("agent %s: %s", self.agent.name, why)
        self.viewers.clear()  # each is told, and ends its stream; a new viewer tries again
        with contextlib.suppress(Exception):
            await self.agent.layer.group_send(self.group, {"type": "camera.error", "error": why})


# -- web side -----------------------------------------------------------------------------------

STREAMS: set["CameraStream"] = set()
_closing = False


async def close_streams(why: str = "the server is shutting down") -> None:
    """End every open stream and refuse new ones: the web server is stopping, and it waits
    for open responses to end (uvicorn's graceful shutdown), which a stream never does."""
    global _closing
    _closing = True
    streams = list(STREAMS)
    for stream in streams:
        stream.end(why)
    writers = {s.writer: s for s in streams if s.writer}
    if writers:
        _, stuck = await asyncio.wait(writers, timeout=CLOSE_WAIT)
        for writer in stuck:  # a client that reads nothing more: its connection is dropped
            writers[writer].task.cancel()


@database_sync_to_async
def _robot_for(user, name: str) -> Robot | None:
    try:
        return get_robot_for_user(user, name)
    except Http404:
        return None


class CameraStream(DirectDispatch, AsyncHttpConsumer):
    """``GET /robots/<name>/camera.mjpg`` for signed-in users who may see the robot."""

    group: str | None = None
    writer: asyncio.Task | None = None
    renewer: asyncio.Task | None = None

    async def http_request(self, message: dict) -> None:
        # AsyncHttpConsumer ends the consumer when handle() returns; a stream goes on.
        if "body" in message:
            self.body.append(message["body"])
        if message.get("more_body"):
            return
        if not await self.handle(b"".join(self.body)):
            await self.disconnect()
            raise StopConsumer()

    async def handle(self, body: bytes) -> bool:
        """Answer the request; True if a stream was started."""
        if _closing:
            await self._text(503, "The server is shutting down.")
            return False
        if self.scope["method"] != "GET":
            await self._text(405, "GET only", [(b"allow", b"GET")])
            return False
        user = self.scope.get("user")
        if user is None or not user.is_authenticated:
            location = redirect_to_login(self.scope["path"])["Location"]
            await self.send_response(302, b"", headers=[(b"location", location.encode())])
            return False
        name = self.scope["url_route"]["kwargs"]["name"]
        robot = await _robot_for(user, name)
        if robot is None:
            await self._text(404, f"No robot named {name!r}.")
            return False
        try:
            info = await ask_agent(robot.name, "camera.info", timeout=ASK_TIMEOUT)
        except AgentUnavailable as exc:
            await self._text(503, str(exc))
            return False
        if not info.get("camera"):
            message = f"Robot {robot.name} has no camera: its driver has none and none is set up."
            await self._text(404, message)
            return False
        await self._start(robot.name)
        return True

    async def _text(self, status: int, text: str, headers: list | None = None) -> None:
        headers = [(b"content-type", b"text/plain; charset=utf-8"), *(headers or [])]
        await self.send_response(status, text.encode(), headers=headers)

    async def _start(self, robot_name: str) -> None:
        self.robot_name = robot_name
        self.frame: bytes | None = None
        self.ending: str | None = None
        self.wake = asyncio.Event()
        self.group = camera_group(robot_name)
        await self.channel_layer.group_add(self.group, self.channel_name)
        await self.send_headers(
            status=200,
            headers=[
                (b"content-type", b"multipart/x-mixed-replace; boundary=" + BOUNDARY),
                (b"cache-control", b"no-store"),
                (b"x-content-type-options", b"nosniff"),
            ],
        )
        await self.send_body(b"--" + BOUNDARY + b"\r\n", more_body=True)
        STREAMS.add(self)
        self.writer = asyncio.create_task(self._write())
        self.renewer = asyncio.create_task(self._keep_watching())

    # Events from the agent: kept, not written here, so a slow client never holds this loop.

    async def camera_frame(self, event: dict) -> None:
        self.frame = event["jpeg"]
        self.wake.set()

    async def camera_error(self, event: dict) -> None:
        self.end(event["error"])

    def end(self, why: str) -> None:
        """Show ``why`` as the last frame and end the response."""
        if self.group is not None and self.ending is None:
            self.ending = why
            self.wake.set()

    async def _write(self) -> None:
        while self.ending is None:
            await self.wake.wait()
            self.wake.clear()
            frame, self.frame = self.frame, None
            if frame is not None and self.ending is None:
                await self.send_body(part(frame), more_body=True)
        STREAMS.discard(self)
        last = await asyncio.to_thread(error_jpeg, self.ending)
        await self.send_body(part(last, final=True), more_body=False)

    async def _keep_watching(self) -> None:
        while not self.writer.done():  # a stream that cannot write keeps no camera on
            try:
                await send_to_agent(self.robot_name, "camera.watch", viewer=self.channel_name)
            except Exception:  # the layer away for a moment: the next renewal may get through
                log.exception("camera of %s: could not renew the watch", self.robot_name)
            await asyncio.sleep(WATCH_RENEW)

    async def disconnect(self) -> None:
        """The browser went away (or the response was a short one)."""
        await self._stop_watching()

    async def _stop_watching(self) -> None:
        """Leave the group and tell the agent, once, however the consumer ends."""
        STREAMS.discard(self)
        for task in (self.renewer, self.writer):
            if task is not None:
                task.cancel()
                await asyncio.gather(task, return_exceptions=True)
        group, self.group = self.group, None
        if group is not None:
            await self.channel_layer.group_discard(group, self.channel_name)
            await send_to_agent(self.robot_name, "camera.unwatch", viewer=self.channel_name)

    async def __call__(self, scope, receive, send):
        self.task = asyncio.current_task()
        try:
            await super().__call__(scope, receive, send)
        finally:  # an error or a cancellation too: never a camera left on for nobody
            await self._stop_watching()


def part(jpeg: bytes, final: bool = False) -> bytes:
    """One JPEG of the stream, followed at once by the boundary: a browser shows a part only
    once it has seen the boundary after it."""
    closing = b"\r\n--" + BOUNDARY + (b"--\r\n" if final else b"\r\n")
    head = b"Content-Type: image/jpeg\r\nContent-Length: %d\r\n\r\n" % len(jpeg)
    return head + jpeg + closing


def error_jpeg(text: str, size: tuple[int, int] = (320, 240)) -> bytes:
    """A frame that says what went wrong, for the <img> that shows the stream."""
    from PIL import Image, ImageDraw, ImageFont

    image = Image.new("RGB", size, (48, 16, 16))
    draw = ImageDraw.Draw(image)
    wrapped = "\n".join(textwrap.wrap(f"Camera stopped: {text}", width=size[0] // 7)[:12])
    draw.multiline_text((8, 8), wrapped, fill=(240, 220, 220), font=ImageFont.load_default())
    out = io.BytesIO()
    image.save(out, "JPEG", quality=80)
    return out.getvalue()
