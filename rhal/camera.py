"""Cameras beside the robot's driver: a V4L2 device read through an ffmpeg subprocess.

    settings = CameraSettings.parse({"device": "/dev/video0", "fps": 10})
    camera = FfmpegCamera(settings)
    await camera.start()           # spawns ffmpeg; CameraError if it cannot
    jpeg = await camera.frame()    # the newest frame not yet returned, waiting for one
    await camera.close()           # ffmpeg terminated and reaped; safe to call twice

ffmpeg reads the device (``-f v4l2 -framerate F -video_size WxH -i DEVICE``) and writes MJPEG
to a pipe, which :class:`JpegSplitter` cuts into whole JPEG images. ``device`` may also be
``lavfi:NAME``, one of ffmpeg's own test sources (``lavfi:testsrc``, ``lavfi:testsrc2``,
``lavfi:smptebars``, ...): the real ffmpeg path with no camera plugged in, for tests and
benchmarks. A missing ffmpeg, a device that cannot be opened or a camera that stops sending
raise :class:`CameraError` (a :class:`~rhal.errors.RhalError`) with ffmpeg's own words.

Plain Python with no Django; Pillow is imported only to fit a too large frame into its cap.
"""

from __future__ import annotations

import asyncio
import collections
import contextlib
import io
import math
import re
import shutil
import subprocess
from dataclasses import dataclass
from typing import Any

from rhal.errors import RhalError

DEFAULT_FPS = 10.0
DEFAULT_SIZE = (640, 480)
MAX_FPS = 30.0
MAX_SIZE = (1920, 1080)
MIN_SIDE = 16
QUALITY = 5  # ffmpeg's -q:v for MJPEG: 2 (best) .. 31; 5 is sharp at ~30 KB for 640x480
STALL_SECONDS = 10.0  # no frame for this long: the camera is gone
STOP_GRACE = 3.0  # seconds between SIGTERM and SIGKILL
MAX_FRAME_BYTES = 8 * 1024 * 1024  # a "frame" larger than this is garbage: dropped
READ_CHUNK = 256 * 1024
SOURCE_NAME = re.compile(r"[a-z][a-z0-9_]*")  # a lavfi source's name, never a filter graph

SOI, EOI, SOS = b"\xff\xd8", b"\xff\xd9", 0xDA
# Markers that stand alone, without a length after them: TEM, RST0-7, SOI, EOI.
STANDALONE = {0x01, *range(0xD0, 0xDA)}


class CameraError(RhalError):
    """The camera cannot be started or stopped sending: ffmpeg missing, device failing."""


@dataclass(frozen=True)
class CameraSettings:
    """A robot's ``camera`` setting: where frames come from, and their cap of rate and size.

    ``device`` empty means the robot driver's own camera (the sim's rendered view).
    """

    device: str = ""
    fps: float = DEFAULT_FPS
    width: int = DEFAULT_SIZE[0]
    height: int = DEFAULT_SIZE[1]

    @classmethod
    def parse(cls, value: Any) -> CameraSettings:
        """From the setting's JSON; ValueError says what is wrong with it."""
        if value is None:
            return cls()
        if not isinstance(value, dict):
            raise ValueError(f"camera settings must be an object, not {value!r}")
        unknown = set(value) - {"device", "fps", "width", "height"}
        if unknown:
            raise ValueError(
                f"unknown camera setting(s) {', '.join(sorted(unknown))}; "
                "known: device, fps, width, height"
            )
        device = value.get("device") or ""
        if not isinstance(device, str):
            raise ValueError(f"camera device must be a text, not {device!r}")
        if device.startswith("lavfi:"):
            if not SOURCE_NAME.fullmatch(device[6:]):
                raise ValueError(f"camera device {device!r}: lavfi: takes a source's name only")
        elif device and not device.startswith("/dev/"):
            raise ValueError(
                f"camera device {device!r} must be a device path (/dev/video0) or lavfi:NAME"
            )
        fps = _number("fps", value.get("fps", DEFAULT_FPS), 0.1, MAX_FPS)
        width = int(_number("width", value.get("width", DEFAULT_SIZE[0]), MIN_SIDE, MAX_SIZE[0]))
        height = int(_number("height", value.get("height", DEFAULT_SIZE[1]), MIN_SIDE, MAX_SIZE[1]))
        return cls(device, fps, width, height)

    def describe(self) -> dict[str, Any]:
        return {
            "source": self.device or "driver",
            "fps": self.fps,
            "width": self.width,
            "height": self.height,
        }


def _number(name: str, value: Any, low: float, high: float) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"camera {name} must be a number, not {value!r}")
    if not low <= value <= high:
        raise ValueError(f"camera {name} must be between {low:g} and {high:g}, not {value!r}")
    return float(value)


class JpegSplitter:
    """Cuts a byte stream of back-to-back JPEG images (ffmpeg's mjpeg muxer) into images.

    An image runs from its SOI marker to its EOI marker. The header segments before the scan
    are skipped by their lengths, so a table that happens to hold the bytes of EOI cannot cut
    an image short; in the scan itself a 0xFF data byte is always followed by 0x00.
    """

    def __init__(self, limit: int = MAX_FRAME_BYTES):
        self.limit = limit
        self.buffer = bytearray()
        self.dropped = 0  # bytes thrown away: not inside an image, or an image over the limit

    def feed(self, data: bytes) -> list[bytes]:
        self.buffer += data
        images = []
        while (image := self._next_image()) is not None:
            images.append(image)
        if len(self.buffer) > self.limit:
            self.dropped += len(self.buffer)
            self.buffer.clear()
        return images

    def _next_image(self) -> bytes | None:
        buffer = self.buffer
        start = buffer.find(SOI)
        if start < 0:
            keep = 1 if buffer.endswith(b"\xff") else 0  # half an SOI
            self.dropped += len(buffer) - keep
            del buffer[: len(buffer) - keep]
            return None
        if start:
            self.dropped += start
            del buffer[:start]
        end = self._end_of_image()
        if end is None:
            return None
        image = bytes(buffer[:end])
        del buffer[:end]
        return image

    def _end_of_image(self) -> int | None:
        """Where the image at the buffer's start ends (just after EOI), None if not yet in."""
        buffer, pos = self.buffer, 2
        while pos + 4 <= len(buffer):
            if buffer[pos] != 0xFF:
                pos += 1  # not a marker where one belongs: resynchronise
                continue
            marker = buffer[pos + 1]
            if marker == 0xFF:  # fill byte
                pos += 1
            elif marker in STANDALONE:
                pos += 2
            elif marker == EOI[1]:
                return pos + 2
            elif marker == SOS:
                end = buffer.find(EOI, pos + 2)
                return None if end < 0 else end + 2
            else:
                pos += 2 + int.from_bytes(buffer[pos + 2 : pos + 4], "big")
        return None


class FfmpegCamera:
    """A V4L2 camera (or an ffmpeg test source) through an ffmpeg subprocess."""

    def __init__(self, settings: CameraSettings, ffmpeg: str = "ffmpeg"):
        if not settings.device:
            raise ValueError("FfmpegCamera needs a device (/dev/videoN or lavfi:NAME)")
        self.settings = settings
        self.ffmpeg = ffmpeg
        self.process: asyncio.subprocess.Process | None = None
        self.frames = 0  # whole images read from ffmpeg so far
        self._latest: bytes | None = None
        self._returned = 0
        self._new = asyncio.Event()
        self._ended = False
        self._errors: collections.deque[str] = collections.deque(maxlen=4)
        self._readers: list[asyncio.Task] = []

    @property
    def device(self) -> str:
        return self.settings.device

    def argv(self, executable: str | None = None) -> list[str]:
        s = self.settings
        size, rate = f"{s.width}x{s.height}", f"{s.fps:g}"
        if s.device.startswith("lavfi:"):
            # -re: a test source is made as fast as the CPU allows, a camera in real time.
            source = f"{s.device[6:]}=size={size}:rate={rate}"
            given = ["-re", "-f", "lavfi", "-i", source]
            fit = []
        else:
            given = ["-f", "v4l2", "-framerate", rate, "-video_size", size, "-i", s.device]
            # A driver may pick another size or rate than asked: hold both to the cap.
            fit = [
                "-vf", f"scale=w='min(iw,{s.width})':h='min(ih,{s.height})'"
                ":force_original_aspect_ratio=decrease:force_divisible_by=2",
                "-fps_mode", "vfr", "-r", rate,
            ]  # fmt: skip
        return [
            executable or self.ffmpeg, "-nostdin", "-hide_banner", "-loglevel", "error",
            *given, *fit, "-an", "-f", "mjpeg", "-q:v", str(QUALITY), "pipe:1",
        ]  # fmt: skip

    async def start(self) -> None:
        executable = shutil.which(self.ffmpeg)
        if executable is None:
            raise CameraError(
                f"camera {self.device}: ffmpeg not found ({self.ffmpeg!r}); "
                "install it (apt-get install ffmpeg)"
            )
        try:
            self.process = await asyncio.create_subprocess_exec(
                *self.argv(executable),
                stdin=subprocess.DEVNULL,
                stdout=subprocess.PIPE,
                stderr=subprocess.PIPE,
                start_new_session=True,  # a terminal's Ctrl-C is the agent's to handle
            )
        except OSError as exc:
            raise CameraError(f"camera {self.device}: cannot start ffmpeg: {exc}") from exc
        self._readers = [
            asyncio.create_task(self._read_frames(), name=f"ffmpeg-{self.process.pid}-out"),
            asyncio.create_task(self._read_errors(), name=f"ffmpeg-{self.process.pid}-err"),
        ]

    async def frame(self, timeout: float = STALL_SECONDS) -> bytes:
        """The newest image not returned yet, waiting for one; CameraError once ffmpeg ends."""
        if self.process is None:
            raise CameraError(f"camera {self.device} is not started")
        while self.frames == self._returned:
            if self._ended:
                raise CameraError(await self._why())
            self._new.clear()
            try:
                await asyncio.wait_for(self._new.wait(), timeout)
            except TimeoutError:
                raise CameraError(
                    f"camera {self.device}: no frame for {timeout:g} s"
                    + (f" ({'; '.join(self._errors)})" if self._errors else "")
                ) from None
        self._returned = self.frames
        return self._latest

    async def close(self) -> None:
        process, self.process = self.process, None
        if process is None:
            return
        if process.returncode is None:
            with contextlib.suppress(ProcessLookupError):
                process.terminate()
            try:
                await asyncio.wait_for(process.wait(), STOP_GRACE)
            except TimeoutError:
                with contextlib.suppress(ProcessLookupError):
                    process.kill()
                await process.wait()
        for reader in self._readers:
            reader.cancel()
        await asyncio.gather(*self._readers, return_exceptions=True)
        self._ended = True
        self._new.set()

    async def _read_frames(self) -> None:
        splitter = JpegSplitter()
        stream = self.process.stdout
        try:
            while chunk := await stream.read(READ_CHUNK):
                images = splitter.feed(chunk)
                if images:
                    self._latest = images[-1]  # older ones are already stale
                    self.frames += len(images)
                    self._new.set()
        finally:
            self._ended = True
            self._new.set()

    async def _read_errors(self) -> None:
        while line := await self.process.stderr.readline():
            if text := line.decode(errors="replace").strip():
                self._errors.append(text)

    async def _why(self) -> str:
        process = self.process
        status = ""
        if process is not None:
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(process.wait(), 1.0)
            status = f" with status {process.returncode}" if process.returncode is not None else ""
            with contextlib.suppress(TimeoutError):  # its last words come after its output
                await asyncio.wait_for(asyncio.gather(*self._readers), 1.0)
        said = "; ".join(self._errors) or "no message"
        return f"camera {self.device}: ffmpeg stopped{status}: {said}"


def fit_jpeg(jpeg: bytes, width: int, height: int, quality: int = 80) -> bytes:
    """The image scaled down (aspect kept) to fit width x height; unchanged if it does.

    Blocking (Pillow): call it in a worker thread.
    """
    from PIL import Image

    with Image.open(io.BytesIO(jpeg)) as image:
        if image.width <= width and image.height <= height:
            return jpeg
        image.draft("RGB", (width, height))  # let the decoder do most of the shrinking
        image = image.convert("RGB")
        image.thumbnail((width, height))
        out = io.BytesIO()
        image.save(out, "JPEG", quality=quality)
        return out.getvalue()
