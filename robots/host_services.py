"""Host services as Robot API methods: what the paper's phone gave its programs besides the
robot itself, done by the computer the agent runs on, offline.

- ``say(text)``: speech through espeak-ng; the text is shown on the robot's page too, as the
  value named ``said``, so a robot without sound (or without espeak-ng) still says it.
  Utterances take turns, one at a time per robot, in the order they came (a queue of at most
  ``MAX_SAY_WAITING``); the call returns once the utterance has been spoken.
- ``snapshot()``: the camera's current frame, a JPEG in base64.
- ``scan_barcode()``: the barcodes and QR codes in the current frame (zxing-cpp).
- ``listen(seconds, wav, words)``: speech recognised by pocketsphinx with the en-us model its
  package ships, from the robot's microphone or a WAV file in the program's folder; ``words``
  narrows what it listens for to a few commands, which makes them far more reliable. Heard
  in a process of its own (robots/hearing.py: 1 GB, 120 s, a lower priority), one recording
  at a time per robot with ``MAX_LISTEN_WAITING`` more waiting: the server never holds a
  recording, and its loop never waits for one. Without ``wav``, a phrase typed into the
  robot page's "Say to the robot" box is heard as well (robots.typed_speech): on the sim
  robot, which has no microphone, it is all listen() hears.

Which camera: the device in the robot's ``camera`` setting (a V4L2 camera through ffmpeg, as
the agent's camera hub streams it to the page) when there is one; else the driver's front
camera (``front_camera_jpeg()``: the sim robot's view from its nose, where the landmarks are);
else the driver's own camera (``camera_jpeg()``).

The robot's setting ``speech`` (an object) configures speech: ``voice`` (espeak-ng's, default
en-us), ``speed`` (words per minute, 80-450, default 160), ``pitch`` (0-99), ``amplitude``
(0-200), ``device`` (the sound device espeak-ng plays on), ``wav`` (a file to write the speech
to instead of playing it), ``microphone`` (the device listen() records from). It is read from
the robot's row at each call, so a change applies at once.
"""

from __future__ import annotations

import asyncio
import base64
import contextlib
import io
import json
import logging
import math
import os
import re
import shutil
import stat
import sys
import time
import wave
from collections.abc import Awaitable, Callable
from functools import partial
from pathlib import Path, PurePosixPath

from channels.db import database_sync_to_async
from django.conf import settings
from django.utils.translation import gettext as _

import rhal
from robots import typed_speech
from robots.models import Robot
from robots.rpc import ROBOT_ERROR, RpcError, bind_params
from runbox import SYSTEM_PATH
from runbox.isolation import InForce, tool

MAX_SAY_CHARS = 500
MAX_SAY_WAITING = 8  # utterances queued behind the one being spoken
SAY_TIMEOUT = 120.0  # s: longer than the longest text takes at the slowest speed
DEFAULT_VOICE = "en-us"  # the accent listen()'s model knows best
DEFAULT_SPEED = 160  # words per minute
MAX_LISTEN_SECONDS = 30.0
MAX_AUDIO_BYTES = 32 * 1024 * 1024
MAX_LISTEN_WAITING = 4  # listen() calls queued behind the one being heard, per robot
# The recogniser's process (robots/hearing.py): its wall and CPU seconds, its address space.
HEARING = Path(__file__).with_name("hearing.py")
HEARING_SECONDS = 120.0
HEARING_MEMORY = 1024 * 2**20
HEARING_ENV = {"PATH": SYSTEM_PATH, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1"}
MAX_PHRASES = 100
SAMPLE_RATE = 16000  # what the recogniser's model was trained on

log = logging.getLogger(__name__)
SPEECH_SETTINGS = ("voice", "speed", "pitch", "amplitude", "device", "wav", "microphone")
_VOICE = re.compile(r"[A-Za-z0-9][A-Za-z0-9_+/-]{0,63}")
_WORD = re.compile(r"[a-z][a-z'.-]*")


class HostServices:
    """The host's services for the programs of one agent's robot."""

    def __init__(self, agent):
        self.agent = agent
        self._speaking = asyncio.Lock()
        self._waiting = 0
        self._hearing = asyncio.Lock()
        self._listeners = 0  # listen() calls being heard or waiting
        self.typed = typed_speech.TypedSpeech()  # the robot page's "Say to the robot" box
        self.last_heard: dict | None = None  # what the last listen() heard, for the box
        self.handlers = {"robot.hear": self.hear_typed}
        self.methods = {
            "say": self.say,
            "snapshot": self.snapshot,
            "scan_barcode": self.scan_barcode,
            "listen": self.listen,
        }

    # -- speech -----------------------------------------------------------------------------

    async def say(self, active, params):
        (text,) = bind_params(params, ("text",), 1)
        if not isinstance(text, str) or not text.strip():
            raise ValueError("say() needs a text to say")
        if len(text) > MAX_SAY_CHARS:
            raise ValueError(f"say() says at most {MAX_SAY_CHARS} characters at a time")
        speech = await self.speech_settings()
        if self._waiting >= MAX_SAY_WAITING:
            raise RpcError(
                ROBOT_ERROR, f"the robot has {MAX_SAY_WAITING} things to say already: wait"
            )
        self._waiting += 1
        try:
            await self._speaking.acquire()
        finally:
            self._waiting -= 1
        try:
            await self._show_said(active, text)
            return await speak(text, speech)
        finally:
            self._speaking.release()

    async def _show_said(self, active, text: str) -> None:
        """The robot's page shows what it says, as the value named "said"; a sim recording
        a check run's trace keeps it there (rhal.sim, classroom.checks' output_matches)."""
        if (note := getattr(getattr(self.agent, "driver", None), "note_said", None)) is not None:
            note(text)
        with contextlib.suppress(ValueError):  # no room among the shown values: still speak
            await self.agent.api.show(active, ["said", text])

    async def speech_settings(self) -> dict:
        """The robot's ``speech`` setting, checked; {} for a robot without one."""
        raw = await database_sync_to_async(_speech_setting)(self.agent.name)
        try:
            return check_speech_settings(raw)
        except ValueError as exc:
            raise RpcError(ROBOT_ERROR, f"the robot's speech setting is wrong: {exc}") from None

    async def listen(self, active, params):
        """One listen() heard at a time on the robot, MAX_LISTEN_WAITING more waiting; each
        recording in a recogniser process of its own (robots/hearing.py), never in the
        server. Without a recording, a phrase typed into the robot page's box is heard too
        (robots.typed_speech)."""
        seconds, wav, words = bind_params(params, ("seconds", "wav", "words"), 0)
        seconds = _listen_seconds(seconds)
        phrases = _phrases(words)
        if self._listeners > MAX_LISTEN_WAITING:
            raise RpcError(
                ROBOT_ERROR,
                f"the robot is hearing {self._listeners} recordings already: wait for one",
            )
        self._listeners += 1
        try:
            async with self._hearing:
                if wav is not None:  # the recogniser reads it, not the server
                    fd = await asyncio.to_thread(open_program_file, wav, workdir_of(active))
                    try:
                        return await hear(phrases, recording=fd)
                    finally:
                        os.close(fd)
                return await self._hear_live(seconds, phrases)
        finally:
            self._listeners -= 1

    async def _hear_live(self, seconds: float, phrases: tuple[str, ...]) -> dict:
        """A phrase typed (waiting already, or typed within `seconds`) on a robot without a
        microphone (the sim's driver says ``hearing = "typed"``); on one with a microphone,
        whichever comes first: a phrase typed or what the recording says."""
        phrase = self.typed.take()
        if phrase is not None:
            return self._heard(typed_speech.heard(phrase, phrases), phrase.user)
        self._tell_hearing(listening=True)
        try:
            if getattr(self.agent.driver, "hearing", "microphone") == "typed":
                phrase = await self.typed.wait(seconds)
                if phrase is None:
                    return {"text": "", "words": []}
                return self._heard(typed_speech.heard(phrase, phrases), phrase.user)
            microphone = (await self.speech_settings()).get("microphone")
            recording = hear(phrases, record=partial(record, seconds, microphone))
            return await self._first_heard(recording, phrases)
        finally:
            self._tell_hearing(listening=False)

    async def _first_heard(self, recording: Awaitable[dict], phrases: tuple[str, ...]) -> dict:
        """A phrase typed while the microphone is heard wins: the recording is given up."""
        hearing = asyncio.ensure_future(recording)
        typing = asyncio.ensure_future(self.typed.wait(None))
        try:
            await asyncio.wait({hearing, typing}, return_when=asyncio.FIRST_COMPLETED)
            if typing.done():
                phrase = typing.result()
                return self._heard(typed_speech.heard(phrase, phrases), phrase.user)
            return self._heard(hearing.result(), None)
        finally:
            for task in (hearing, typing):
                task.cancel()
            await asyncio.gather(hearing, typing, return_exceptions=True)

    def _heard(self, heard: dict, typed_by: str | None) -> dict:
        """What listen() heard, as the robot's "Say to the robot" box notes it."""
        if heard["text"]:
            self.last_heard = {"text": heard["text"], "typed_by": typed_by, "at": time.time()}
            self._tell_hearing(listening=self.typed.listening)
        return heard

    def _tell_hearing(self, listening: bool) -> None:
        self.agent.publish(
            self.agent.group,
            {"type": "robot.hearing", "robot": self.agent.name, "listening": listening,
             "last": self.last_heard},
        )  # fmt: skip

    async def hear_typed(self, message: dict) -> None:
        """``robot.hear`` from the web tier (the robot page's box, the API): a phrase typed,
        for the listen() waiting or the next one. Who may say it was checked there."""
        try:
            taken = self.typed.say(message["text"], message.get("user", ""),
                                   queue=message.get("queue", True))  # fmt: skip
        except typed_speech.Refused as exc:
            await self.agent.reply(message, {"refused": exc.code, "detail": str(exc)})
            return
        await self.agent.reply(message, {"listening": taken})

    # -- the camera -------------------------------------------------------------------------

    async def snapshot(self, active, params):
        bind_params(params, (), 0)
        jpeg, width, height = await asyncio.to_thread(as_jpeg, await self.frame())
        return {"jpeg": base64.b64encode(jpeg).decode("ascii"), "width": width, "height": height}

    async def scan_barcode(self, active, params):
        bind_params(params, (), 0)
        return await asyncio.to_thread(read_barcodes, await self.frame())

    async def frame(self) -> bytes:
        """The current camera frame, as image bytes (JPEG), from the best camera there is."""
        jpeg = await self._camera_device_frame()
        if jpeg is not None:
            return jpeg
        driver = self.agent.driver
        front = getattr(driver, "front_camera_jpeg", None)
        if front is not None:
            return await front()
        if driver.capabilities().get("camera") is None:
            raise rhal.NotSupportedError(
                f"the {driver.kind} robot has no camera: snapshot() and scan_barcode() need one"
            )
        return await driver.camera_jpeg()

    async def _camera_device_frame(self) -> bytes | None:
        """A frame of the device in the robot's ``camera`` setting (a V4L2 camera through
        ffmpeg), or None when it names none. While the robot's page shows the camera, that
        stream's newest frame; else one taken now (the hub's lock: one ffmpeg per device)."""
        hub = getattr(self.agent, "camera", None)
        if hub is None:
            return None
        try:
            camera = await hub.settings()
        except Robot.DoesNotExist:
            return None
        except ValueError as exc:
            raise RpcError(ROBOT_ERROR, f"the robot's camera setting is wrong: {exc}") from None
        if not camera.device:
            return None
        return await hub.frame()


# -- speaking -------------------------------------------------------------------------------


def _speech_setting(name: str):
    robot = Robot.objects.filter(name=name).only("settings").first()
    return {} if robot is None else robot.settings.get("speech", {})


def check_speech_settings(raw) -> dict:
    """A robot's ``speech`` setting as say() and listen() use it; ValueError if it is wrong."""
    if raw is None:
        return {}
    if not isinstance(raw, dict):
        raise ValueError(_('speech must be an object, e.g. {"voice": "en-us", "speed": 160}'))
    unknown = set(raw) - set(SPEECH_SETTINGS)
    if unknown:
        known = ", ".join(SPEECH_SETTINGS)
        raise ValueError(
            _("unknown speech setting(s) %(names)s; known: %(known)s")
            % {"names": ", ".join(sorted(unknown)), "known": known}
        )
    speech = dict(raw)
    if "voice" in speech and not (
        isinstance(speech["voice"], str) and _VOICE.fullmatch(speech["voice"])
    ):
        raise ValueError(
            _("voice must be an espeak-ng voice name, e.g. en-us, not %(voice)s")
            % {"voice": repr(speech["voice"])}
        )
    for name, low, high in (("speed", 80, 450), ("pitch", 0, 99), ("amplitude", 0, 200)):
        value = speech.get(name)
        if value is not None and (
            isinstance(value, bool) or not isinstance(value, int) or not low <= value <= high
        ):
            raise ValueError(
                _("%(name)s must be a whole number from %(low)s to %(high)s")
                % {"name": name, "low": low, "high": high}
            )
    for name in ("device", "microphone"):
        value = speech.get(name)
        if name == "microphone" and isinstance(value, int) and not isinstance(value, bool):
            continue  # a device's index, as sounddevice numbers them
        if value is not None and not (isinstance(value, str) and 0 < len(value) <= 200):
            raise ValueError(_("%(name)s must be a sound device's name") % {"name": name})
        if isinstance(value, str) and value.startswith("-"):
            raise ValueError(
                _("%(name)s must be a sound device's name, not %(value)s")
                % {"name": name, "value": repr(value)}
            )
    wav = speech.get("wav")
    if wav is not None and not (isinstance(wav, str) and os.path.isabs(wav)):
        raise ValueError(_("wav must be the absolute path of a file to write the speech to"))
    return speech


async def speak(text: str, speech: dict) -> dict:
    """Say ``text`` with espeak-ng, on the sound device or into the speech setting's WAV file.

    Returns {"spoken": true, "seconds": how long it took (or lasts, in a file)}, or
    {"spoken": false, "reason": why}: a computer without sound still shows what was said.
    """
    espeak = shutil.which("espeak-ng")
    if espeak is None:
        return {
            "spoken": False,
            "reason": "espeak-ng is not installed on this computer (apt-get install espeak-ng):"
            " the text is only shown on the robot's page",
        }
    argv = [
        espeak, "--stdin", "-v", speech.get("voice", DEFAULT_VOICE),
        "-s", str(speech.get("speed", DEFAULT_SPEED)),
    ]  # fmt: skip
    for name, option in (("pitch", "-p"), ("amplitude", "-a")):
        if name in speech:
            argv += [option, str(speech[name])]
    wav = speech.get("wav")
    if wav is not None:
        argv += ["-w", wav]
    elif "device" in speech:
        argv += ["-d", speech["device"]]
    started = time.monotonic()
    process = await asyncio.create_subprocess_exec(
        *argv,
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.DEVNULL,
        stderr=asyncio.subprocess.PIPE,
    )
    try:
        _out, err = await asyncio.wait_for(process.communicate(text.encode()), SAY_TIMEOUT)
    except TimeoutError:
        return {"spoken": False, "reason": f"espeak-ng was still speaking after {SAY_TIMEOUT} s"}
    finally:
        if process.returncode is None:  # timed out, or the call was cancelled
            process.kill()
            await process.wait()
    problems = _espeak_problems(err.decode(errors="replace"))
    if process.returncode != 0 or problems:
        why = "; ".join(problems) or f"espeak-ng ended with status {process.returncode}"
        if wav is None:
            why = f"no sound: {why}"
            if not Path("/dev/snd").exists():
                why += " (this computer has no sound card)"
        return {"spoken": False, "reason": f"{why}; the text is only shown on the robot's page"}
    if wav is not None:
        return {"spoken": True, "seconds": round(_wav_seconds(wav), 3), "wav": wav}
    return {"spoken": True, "seconds": round(time.monotonic() - started, 3)}


def _espeak_problems(stderr: str) -> list[str]:
    """espeak-ng's own complaints (it may still exit 0), without ALSA's chatter before them."""
    lines = [line.strip() for line in stderr.splitlines() if line.strip()]
    return [
        line
        for line in lines
        if not line.startswith("ALSA lib") and re.match(r"(error|can't|cannot)\b", line, re.I)
    ]


def _wav_seconds(path: str) -> float:
    with wave.open(path) as recording:
        return recording.getnframes() / recording.getframerate()


# -- images and barcodes --------------------------------------------------------------------


def as_jpeg(image: bytes) -> tuple[bytes, int, int]:
    """The frame as JPEG bytes (converted if it is another format), and its size."""
    from PIL import Image

    with Image.open(io.BytesIO(image)) as picture:
        width, height = picture.size
        if picture.format == "JPEG":
            return image, width, height
        buffer = io.BytesIO()
        picture.convert("RGB").save(buffer, "JPEG", quality=90)
        return buffer.getvalue(), width, height


def read_barcodes(image: bytes) -> list[dict]:
    """Every barcode and QR code zxing-cpp finds in the image: its text, its format (a name
    such as QRCode or EAN13) and its corners in pixels, clockwise from its top left."""
    import numpy as np
    import zxingcpp
    from PIL import Image

    with Image.open(io.BytesIO(image)) as picture:
        grey = np.asarray(picture.convert("L"))
    found = []
    for code in zxingcpp.read_barcodes(grey):
        corners = code.position
        found.append(
            {
                "text": code.text,
                "format": code.format.name,
                "position": [
                    [point.x, point.y]
                    for point in (
                        corners.top_left,
                        corners.top_right,
                        corners.bottom_right,
                        corners.bottom_left,
                    )
                ],
            }
        )
    return found


# -- listening ------------------------------------------------------------------------------


def _listen_seconds(seconds) -> float:
    if seconds is None:
        return 5.0
    if (
        isinstance(seconds, bool)
        or not isinstance(seconds, int | float)
        or not 0 < seconds <= MAX_LISTEN_SECONDS
    ):
        raise ValueError(f"seconds must be a number above 0, at most {MAX_LISTEN_SECONDS:g}")
    return float(seconds)


def _phrases(words) -> tuple[str, ...]:
    """The words or phrases to listen for, lower case and single-spaced; () for any speech."""
    if words is None:
        return ()
    if isinstance(words, str):
        words = [words]
    if not isinstance(words, list) or not 0 < len(words) <= MAX_PHRASES:
        raise ValueError(f"words must be a list of 1 to {MAX_PHRASES} words or phrases")
    phrases = []
    for phrase in words:
        if not isinstance(phrase, str) or not phrase.strip() or len(phrase) > 100:
            raise ValueError(f"each of words must be a word or a short phrase, not {phrase!r}")
        normal = " ".join(phrase.lower().split())
        for word in normal.split():
            if not _WORD.fullmatch(word):
                raise ValueError(f"{word!r} in words is not a word")
        if normal not in phrases:
            phrases.append(normal)
    return tuple(phrases)


def workdir_of(active) -> Path:
    """The run's folder as the agent reaches it: inside its box, or (tests) a plain folder."""
    box = getattr(active.process, "box", None)
    if box is not None and box.folder is not None:
        return box.folder
    return settings.RUNS_DIR / str(active.run_id) / "work"


def open_program_file(path, workdir: Path) -> int:
    """A file in the run's folder, opened for reading (its descriptor, the caller's to close),
    named as the program sees it: relative to its folder, or absolute under /home/robot (its
    folder in the box) or under `workdir`. Nothing outside the folder is opened, not even
    through a symbolic link: the name is walked one folder at a time from the folder's own
    descriptor, never following a link."""
    if not isinstance(path, str) or not path or "\0" in path:
        raise ValueError("wav must be the name of a file in the program's folder")
    named = PurePosixPath(path)
    if named.is_absolute():
        for seen_as in (InForce.HOME, workdir):
            if named.is_relative_to(seen_as):
                named = named.relative_to(seen_as)
                break
        else:
            raise ValueError(f"wav must be a file in the program's folder ({InForce.HOME}): {path}")
    parts = named.parts
    if not parts or any(part in ("..", ".") for part in parts):
        raise ValueError(f"wav must be a file in the program's folder: {path}")
    try:
        folder = os.open(workdir, os.O_RDONLY | os.O_DIRECTORY)
    except OSError as exc:
        raise ValueError(f"cannot read {path}: {exc.strerror}") from None
    try:
        fd = _open_beneath(folder, parts)
    except OSError as exc:
        raise ValueError(f"no file {path} in the program's folder ({exc.strerror})") from None
    try:
        status = os.fstat(fd)
        if not stat.S_ISREG(status.st_mode):
            raise ValueError(f"{path} is not a file")
        if status.st_size > MAX_AUDIO_BYTES:
            raise ValueError(f"{path} is larger than {MAX_AUDIO_BYTES // 2**20} MB")
        os.set_blocking(fd, True)
        return fd
    except BaseException:
        os.close(fd)
        raise


def _open_beneath(folder: int, parts: tuple[str, ...]) -> int:
    """Open folder/parts[0]/.../parts[-1] without following links; closes `folder`."""
    try:
        for part in parts[:-1]:
            inner = os.open(part, os.O_RDONLY | os.O_DIRECTORY | os.O_NOFOLLOW, dir_fd=folder)
            os.close(folder)
            folder = inner
        return os.open(parts[-1], os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK, dir_fd=folder)
    finally:
        os.close(folder)


async def record(seconds: float, device) -> bytes:
    """``seconds`` of 16 kHz mono sound from the microphone: through sounddevice (PortAudio)
    if it is installed, else arecord (alsa-utils)."""
    try:
        import sounddevice
    except (ImportError, OSError):  # OSError: installed, but PortAudio is not
        sounddevice = None
    if sounddevice is not None:
        return await asyncio.to_thread(_record_sounddevice, sounddevice, seconds, device)
    arecord = shutil.which("arecord")
    if arecord is None:
        raise RpcError(
            ROBOT_ERROR,
            "listen() hears the microphone through sounddevice (with PortAudio) or arecord"
            " (alsa-utils), and neither is installed on this computer"
            + _no_sound_card()
            + ": give it a recording instead, listen(wav=FILE), or type what to hear into the"
            " robot page's 'Say to the robot' box",
        )
    argv = [arecord, "-q", "-t", "raw", "-f", "S16_LE", "-r", str(SAMPLE_RATE), "-c", "1"]
    argv += ["-d", str(math.ceil(seconds))]
    if device is not None:
        argv += ["-D", str(device)]
    process = await asyncio.create_subprocess_exec(
        *argv, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE
    )
    try:
        out, err = await asyncio.wait_for(process.communicate(), seconds + 10)
    except TimeoutError:
        raise RpcError(ROBOT_ERROR, "the microphone gave no sound (arecord hung)") from None
    finally:
        if process.returncode is None:
            process.kill()
            await process.wait()
    if process.returncode != 0:
        why = err.decode(errors="replace").strip() or f"status {process.returncode}"
        raise RpcError(ROBOT_ERROR, f"cannot record from the microphone: {why}{_no_sound_card()}")
    return out[: int(seconds * SAMPLE_RATE) * 2]


def _record_sounddevice(sounddevice, seconds: float, device) -> bytes:
    try:
        frames = sounddevice.rec(
            int(seconds * SAMPLE_RATE), samplerate=SAMPLE_RATE, channels=1, dtype="int16",
            device=device,
        )  # fmt: skip
        sounddevice.wait()
    except (sounddevice.PortAudioError, ValueError) as exc:
        raise RpcError(
            ROBOT_ERROR, f"cannot record from the microphone: {exc}{_no_sound_card()}"
        ) from None
    return frames.tobytes()


async def hear(
    phrases: tuple[str, ...],
    recording: int | None = None,
    record: Callable[[], Awaitable[bytes]] | None = None,
) -> dict:
    """What robots/hearing.py hears: in the file open as `recording` (read there, not here),
    else in what `record()` gives (16 kHz samples), recorded once the recogniser knows the
    phrases' words; ValueError for what the program gave wrong (a word it lacks: before
    anything is recorded)."""
    request = {"phrases": list(phrases), "recording": recording}
    process = await asyncio.create_subprocess_exec(
        *hearing_command(),
        stdin=asyncio.subprocess.PIPE, stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE, env=HEARING_ENV,
        pass_fds=() if recording is None else (recording,),
    )  # fmt: skip
    try:
        async with asyncio.timeout(HEARING_SECONDS):
            process.stdin.write(json.dumps(request).encode() + b"\n")
            answer = _answer(await process.stdout.readline())  # the words known, or why not
            if answer is not None and "ok" in answer:
                samples = await record() if record is not None else b""
                out, err = await process.communicate(samples)
                answer = _answer(out)
            else:
                _, err = await process.communicate()
    except TimeoutError:
        raise RpcError(
            ROBOT_ERROR, f"listen() gave up: hearing took more than {HEARING_SECONDS:g} s"
        ) from None
    finally:
        if process.returncode is None:
            process.kill()
            await process.wait()
    if answer is None:
        why = err.decode(errors="replace").strip().splitlines()
        log.warning("listen(): the recogniser ended with %s: %s", process.returncode, why[-1:])
        raise RpcError(
            ROBOT_ERROR,
            "listen() could not hear it: the recogniser ran out of memory or time"
            f" ({HEARING_MEMORY // 2**20} MB, {HEARING_SECONDS:g} s)",
        )
    if "error" in answer:
        raise ValueError(answer["error"])
    return answer


def _answer(line: bytes) -> dict | None:
    """A line of the recogniser's, or None where it ended without one."""
    try:
        return json.loads(line)
    except ValueError:
        return None


def hearing_command() -> list[str]:
    """The recogniser with its memory and CPU limits and a lower priority than the server's,
    set by util-linux's prlimit and coreutils' nice (no code between fork and exec in this
    process, whose other threads may hold locks)."""
    limits = [f"--as={HEARING_MEMORY}", f"--cpu={int(HEARING_SECONDS)}"]
    return [
        tool("prlimit"), *limits, "--", tool("nice"), "-n", "10",
        sys.executable, "-I", str(HEARING),
    ]  # fmt: skip


def _no_sound_card() -> str:
    return "" if Path("/dev/snd").exists() else " (this computer has no sound card)"
