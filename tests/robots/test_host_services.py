"""The host services (say, snapshot, scan_barcode, listen) through a real agent's Robot API
socket on the sim robot: speech written to WAV files by espeak-ng, barcodes the tests draw,
the sim's landmarks, speech recognised from recordings espeak-ng made, and the paper's
"I'm home" and "say move and the robot moves" examples run as programs."""

import asyncio
import base64
import io
import json
import os
import re
import subprocess
import sys
import time
import wave
from pathlib import Path

import numpy as np
import pytest
from django.conf import settings
from PIL import Image, ImageDraw

import rhal
from programs.languages import CLIENTS_DIR, LANGUAGES
from robots import hearing, host_services
from robots.host_services import HostServices
from robots.models import Robot
from runbox import launcher
from tests.robot_api_server import admit

sys.path.insert(0, str(CLIENTS_DIR / "python"))
import robot as robot_client  # noqa: E402  (the client programs get on their path)

EXAMPLES = CLIENTS_DIR.parent / "examples"
TOKEN = "good-token"
RUN = 7
# The robot's speech and camera settings are read from its row at each call.
pytestmark = pytest.mark.django_db(transaction=True)


@pytest.fixture
async def agent(agent):
    # The registration RobotApi makes: its methods and the host's, on one socket.
    agent.api.methods.update(HostServices(agent).methods)
    admit(agent, TOKEN, RUN)
    return agent


class Bot:
    """The Python client, called from a thread so the server on this loop can answer."""

    def __init__(self, client):
        self.client = client

    async def call(self, method, *params):
        return await asyncio.to_thread(self.client.call, method, *params)

    async def error(self, method, *params) -> robot_client.RobotError:
        with pytest.raises(robot_client.RobotError) as caught:
            await self.call(method, *params)
        return caught.value


@pytest.fixture
async def bot(agent):
    client = await asyncio.to_thread(robot_client.Robot, agent.server.url, TOKEN)
    yield Bot(client)
    client.close()


@pytest.fixture
def workdir():
    """The run's folder, where its program would be (/home/robot in the sandbox)."""
    folder = settings.RUNS_DIR / str(RUN) / "work"
    folder.mkdir(parents=True)
    return folder


def speak_to_wav(path: Path, text: str) -> Path:
    subprocess.run(["espeak-ng", "-v", "en-us", "-w", str(path), text], check=True)
    return path


def wav_samples(path: Path) -> tuple[np.ndarray, int]:
    with wave.open(str(path)) as recording:
        frames = recording.readframes(recording.getnframes())
        return np.frombuffer(frames, "<i2").astype(float), recording.getframerate()


async def run_python(agent, program: Path, cwd: Path, *args, timeout=60) -> tuple[int, str, str]:
    """A program as the launcher starts it (without limits or sandbox), to its end."""
    python = LANGUAGES["python"]
    env = launcher.environment(python, cwd, {"ROBOT_API": agent.server.url, "ROBOT_TOKEN": TOKEN})
    process = await asyncio.create_subprocess_exec(
        *python.command(str(program)), *args,
        env=env, cwd=cwd, stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    try:
        out, err = await asyncio.wait_for(process.communicate(), timeout)
    finally:
        if process.returncode is None:
            process.kill()
            await process.wait()
    return process.returncode, out.decode(), err.decode()


# -- barcodes and the camera ------------------------------------------------------------------

# EAN-13, drawn bar by bar: the left half's digits in odd (L) or even (G) parity, chosen by
# the first digit; the right half's in R; guards 101, 01010, 101.
L_CODES = ["0001101", "0011001", "0010011", "0111101", "0100011",
           "0110001", "0101111", "0111011", "0110111", "0001011"]  # fmt: skip
R_CODES = ["".join("1" if bit == "0" else "0" for bit in code) for code in L_CODES]
G_CODES = [code[::-1] for code in R_CODES]
PARITY = ["LLLLLL", "LLGLGG", "LLGGLG", "LLGGGL", "LGLLGG",
          "LGGLLG", "LGGGLL", "LGLGLG", "LGLGGL", "LGGLGL"]  # fmt: skip


def ean13_modules(digits: str) -> str:
    first, left, right = int(digits[0]), digits[1:7], digits[7:]
    bits = "101"
    for parity, digit in zip(PARITY[first], left, strict=True):
        bits += (L_CODES if parity == "L" else G_CODES)[int(digit)]
    bits += "01010" + "".join(R_CODES[int(digit)] for digit in right) + "101"
    return bits


def draw_ean13(digits: str, module=3, height=120, at=(60, 80), size=(480, 320)) -> bytes:
    """A photo-like frame with the barcode on a label: grey background, JPEG."""
    image = Image.new("RGB", size, (120, 130, 125))
    draw = ImageDraw.Draw(image)
    bits = ean13_modules(digits)
    x0, y0 = at
    quiet = 10 * module
    draw.rectangle((x0 - quiet, y0 - 20, x0 + len(bits) * module + quiet, y0 + height + 20),
                   fill="white")  # fmt: skip
    for i, bit in enumerate(bits):
        if bit == "1":
            draw.rectangle((x0 + i * module, y0, x0 + (i + 1) * module - 1, y0 + height), "black")
    buffer = io.BytesIO()
    image.save(buffer, "JPEG", quality=90)
    return buffer.getvalue()


class BlindRobot(rhal.Robot):
    """A robot without a camera."""

    kind = "blind"

    async def _drive(self, linear, angular):
        pass

    async def _read_sensors(self):
        return {}

    def _sensor_specs(self):
        return {}


class PictureRobot(BlindRobot):
    """A robot whose camera sees the picture given."""

    kind = "picture"

    def __init__(self, picture: bytes):
        super().__init__("picture://")
        self.picture = picture

    def _camera_spec(self):
        return {"width": 0, "height": 0, "format": "jpeg"}

    async def _camera_jpeg(self):
        return self.picture


async def look_at(agent, picture: bytes) -> None:
    await agent.driver.close()
    agent.driver = PictureRobot(picture)
    await agent.driver.open()


async def test_scan_barcode_reads_the_papers_home_barcode_drawn_here(agent, bot):
    # The paper's example 2 looks for 7891219026195: an EAN-13 on a label, in the camera's frame.
    assert ean13_modules("7891219026195").count("") - 1 == 95
    await look_at(agent, draw_ean13("7891219026195"))
    (code,) = await bot.call("scan_barcode")
    assert code["text"] == "7891219026195" and code["format"] == "EAN13"
    xs = [x for x, _ in code["position"]]
    ys = [y for _, y in code["position"]]
    assert 55 <= min(xs) and max(xs) <= 60 + 95 * 3 + 5  # on the bars drawn
    assert 80 <= min(ys) <= max(ys) <= 200


async def test_scan_barcode_finds_nothing_in_a_frame_without_codes(agent, bot):
    buffer = io.BytesIO()
    Image.new("RGB", (320, 240), (90, 120, 90)).save(buffer, "JPEG")
    await look_at(agent, buffer.getvalue())
    assert await bot.call("scan_barcode") == []


async def test_the_sim_robot_sees_the_kitchen_code_ahead_from_the_start(bot):
    (code,) = await bot.call("scan_barcode")
    assert code["text"] == "kitchen" and code["format"] == "QRCode"
    assert all(0 <= x < 640 and 0 <= y < 480 for x, y in code["position"])


async def test_snapshot_is_the_sim_robots_front_camera_as_base64_jpeg(bot):
    frame = await bot.call("snapshot")
    jpeg = base64.b64decode(frame["jpeg"])
    image = Image.open(io.BytesIO(jpeg))
    assert image.format == "JPEG" and image.size == (640, 480)
    assert (frame["width"], frame["height"]) == (640, 480)


async def test_snapshot_is_jpeg_whatever_the_camera_gave(agent, bot):
    buffer = io.BytesIO()
    Image.new("RGB", (200, 100), (10, 200, 30)).save(buffer, "PNG")
    await look_at(agent, buffer.getvalue())
    frame = await bot.call("snapshot")
    image = Image.open(io.BytesIO(base64.b64decode(frame["jpeg"])))
    assert image.format == "JPEG" and image.size == (200, 100) == (frame["width"], frame["height"])
    assert image.convert("RGB").getpixel((100, 50))[1] > 180  # the camera's green picture


async def test_the_camera_device_in_the_robots_setting_comes_first(bot):
    # ffmpeg's test source stands in for a V4L2 camera: the same path through ffmpeg.
    camera = {"device": "lavfi:testsrc", "width": 320, "height": 240}
    await Robot.objects.acreate(name="sim", url="sim://", settings={"camera": camera})
    frame = await bot.call("snapshot")
    assert (frame["width"], frame["height"]) == (320, 240)  # not the sim's 640 x 480 front view
    assert Image.open(io.BytesIO(base64.b64decode(frame["jpeg"]))).format == "JPEG"
    assert await bot.call("scan_barcode") == []
    camera["device"] = "/dev/no-such-camera"
    await Robot.objects.filter(name="sim").aupdate(settings={"camera": camera})
    error = await bot.error("snapshot")
    assert error.code == -32000 and "/dev/no-such-camera" in str(error)
    await Robot.objects.filter(name="sim").aupdate(settings={"camera": {"fps": "many"}})
    error = await bot.error("snapshot")
    assert error.code == -32000 and "camera setting is wrong" in str(error)


async def test_a_robot_without_a_camera_says_so(agent, bot):
    agent.driver = BlindRobot("blind://")
    await agent.driver.open()
    for method in ("snapshot", "scan_barcode"):
        error = await bot.error(method)
        assert error.code == -32000 and "blind robot has no camera" in str(error)
    assert (await bot.error("snapshot", 1)).code == -32602


# -- say -------------------------------------------------------------------------------------


async def test_say_writes_speech_to_the_wav_file_the_setting_names(agent, bot, tmp_path):
    said = tmp_path / "said.wav"
    await Robot.objects.acreate(name="sim", url="sim://", settings={"speech": {"wav": str(said)}})
    short = await bot.call("say", "Hello")
    assert short["spoken"] is True and short["wav"] == str(said)
    samples, rate = wav_samples(said)
    assert np.sqrt(np.mean(samples**2)) > 500  # speech, not silence
    assert short["seconds"] == pytest.approx(len(samples) / rate, abs=0.01)
    assert agent.shows["said"]["value"] == "Hello" and agent.shows["said"]["run"] == RUN
    sentence = "I'm home. The kitchen is to my left and the lab is behind me."
    long = await bot.call("say", sentence)
    assert long["spoken"] and long["seconds"] > 3 * short["seconds"]
    assert len(wav_samples(said)[0]) / rate == pytest.approx(long["seconds"], abs=0.01)
    assert agent.shows["said"]["value"] == sentence


async def test_voice_and_speed_come_from_the_setting(bot, tmp_path):
    said = tmp_path / "said.wav"
    speech = {"wav": str(said), "voice": "en", "speed": 100}
    robot = await Robot.objects.acreate(name="sim", url="sim://", settings={"speech": speech})
    slow = await bot.call("say", "one two three four")
    robot.settings["speech"]["speed"] = 300
    await robot.asave()
    fast = await bot.call("say", "one two three four")  # read again at each call
    assert fast["seconds"] < slow["seconds"] / 2


async def test_say_without_a_sound_device_still_shows_the_text(agent, bot):
    result = await bot.call("say", "Nobody hears me")  # the robot has no speech setting
    assert agent.shows["said"]["value"] == "Nobody hears me"
    if not Path("/dev/snd").exists():
        assert result["spoken"] is False
        assert "no sound" in result["reason"] and "no sound card" in result["reason"]
        assert "shown on the robot's page" in result["reason"]


async def test_say_without_espeak_ng_is_a_reason_not_a_crash(agent, bot, monkeypatch, tmp_path):
    monkeypatch.setenv("PATH", str(tmp_path))
    result = await bot.call("say", "hello")
    assert result["spoken"] is False and "espeak-ng is not installed" in result["reason"]
    assert agent.shows["said"]["value"] == "hello"


async def test_say_refuses_what_is_not_a_short_text(bot):
    for params in ([""], ["  "], [42], [None], ["x" * 501], []):
        assert (await bot.error("say", *params)).code == -32602, params


async def test_a_wrong_speech_setting_is_a_clear_error(bot):
    await Robot.objects.acreate(name="sim", url="sim://", settings={"speech": {"speed": "fast"}})
    error = await bot.error("say", "hello")
    assert error.code == -32000
    assert "speech setting is wrong: speed must be a whole number from 80 to 450" in str(error)


@pytest.mark.parametrize(
    "speech, words",
    [
        ([], "must be an object"),
        ({"volume": 3}, "unknown speech setting(s) volume"),
        ({"voice": "-w /etc/x"}, "voice must be an espeak-ng voice name"),
        ({"device": "-x"}, "device must be a sound device's name"),
        ({"wav": "said.wav"}, "wav must be the absolute path"),
        ({"pitch": 100}, "pitch must be a whole number from 0 to 99"),
    ],
)
def test_speech_settings_are_checked(speech, words):
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
        host_services.check_speech_settings(speech)
    good = {"voice": "en-us", "speed": 160, "pitch": 50, "amplitude": 100, "device": "default",
            "wav": "/tmp/said.wav", "microphone": 2}  # fmt: skip
    assert host_services.check_speech_settings(good) == good


async def test_utterances_take_turns_in_order_and_the_queue_is_bounded(agent, monkeypatch):
    services = agent.api.methods["say"].__self__
    speaking, done = [], asyncio.Event()

    async def speak(text, speech):
        speaking.append(text)
        assert len(speaking) == len(spoken) + 1  # nobody else is speaking
        await done.wait()
        spoken.append(text)
        return {"spoken": True, "seconds": 1.0}

    spoken = []
    monkeypatch.setattr(host_services, "speak", speak)
    monkeypatch.setattr(host_services, "MAX_SAY_WAITING", 2)
    clients = [
        await asyncio.to_thread(robot_client.Robot, agent.server.url, TOKEN) for _ in range(4)
    ]

    async def until(condition):
        for _ in range(500):
            if condition():
                return
            await asyncio.sleep(0.01)
        pytest.fail("the server never got there")

    try:
        calls = [asyncio.create_task(asyncio.to_thread(clients[0].say, "number 0"))]
        await until(lambda: speaking == ["number 0"])
        for n in (1, 2):  # these wait their turn, in the order they came
            calls.append(asyncio.create_task(asyncio.to_thread(clients[n].say, f"number {n}")))
            await until(lambda n=n: services._waiting == n)
        with pytest.raises(robot_client.RobotError, match="things to say already: wait"):
            await asyncio.to_thread(clients[3].say, "number 3")  # no room left in the queue
        done.set()
        results = await asyncio.gather(*calls)
    finally:
        for client in clients:
            client.close()
    assert results == [{"spoken": True, "seconds": 1.0}] * 3
    assert spoken == ["number 0", "number 1", "number 2"]


# -- listen ----------------------------------------------------------------------------------

COMMANDS = ["move", "stop", "turn left", "turn right"]

LISTENER = f"""\
import json, sys
import robot

bot = robot.Robot()
for wav in sys.argv[1:]:
    print(json.dumps(bot.listen(wav=wav, words={COMMANDS!r})))
"""


async def test_listen_recognises_commands_espeak_ng_said(agent, workdir):
    for text in ("move", "stop", "turn left"):
        speak_to_wav(workdir / f"{text.replace(' ', '_')}.wav", text)
    program = workdir / "listener.py"
    program.write_text(LISTENER)
    # As the program names them: in its folder, and in the sandbox's view of it.
    files = ["move.wav", "/home/robot/stop.wav", str(workdir / "turn_left.wav")]
    status, out, err = await run_python(agent, program, workdir, *files)
    assert status == 0, err
    heard = [json.loads(line) for line in out.splitlines()]
    assert heard == [
        {"text": "move", "words": ["move"]},
        {"text": "stop", "words": ["stop"]},
        {"text": "turn left", "words": ["turn", "left"]},
    ]


async def test_listen_without_words_hears_whatever_was_said(bot, workdir):
    speak_to_wav(workdir / "hello.wav", "hello, how are you today")
    heard = await bot.call("listen", None, "hello.wav")
    assert isinstance(heard["text"], str) and heard["text"]
    assert heard["words"] == heard["text"].split()


async def test_listen_reads_other_rates_channels_and_kinds_of_wav(bot, workdir):
    samples, rate = wav_samples(speak_to_wav(workdir / "move.wav", "move"))
    at_48k = np.interp(np.arange(0, len(samples), rate / 48000), np.arange(len(samples)), samples)
    with wave.open(str(workdir / "stereo.wav"), "wb") as stereo:
        stereo.setnchannels(2)
        stereo.setsampwidth(2)
        stereo.setframerate(48000)
        stereo.writeframes(np.repeat(at_48k, 2).astype("<i2").tobytes())
    # Floating-point samples: the standard library cannot read them, ffmpeg does.
    to_float = ["-i", str(workdir / "move.wav"), "-c:a", "pcm_f32le", str(workdir / "float.wav")]
    subprocess.run(["ffmpeg", "-loglevel", "error", *to_float], check=True)
    for name in ("stereo.wav", "float.wav"):
        heard = await bot.call("listen", 5, name, COMMANDS)
        assert heard == {"text": "move", "words": ["move"]}, name
    (workdir / "noise.wav").write_bytes(b"RIFF but not really")
    error = await bot.error("listen", 5, "noise.wav", COMMANDS)
    assert error.code == -32602 and "not a recording ffmpeg can read" in str(error)


async def test_listen_hears_nothing_in_silence(bot, workdir):
    with wave.open(str(workdir / "silence.wav"), "wb") as silence:
        silence.setnchannels(1)
        silence.setsampwidth(2)
        silence.setframerate(16000)
        silence.writeframes(bytes(32000))
    heard = await bot.call("listen", 5, "silence.wav", COMMANDS)
    assert heard["text"] in ["", *COMMANDS] and isinstance(heard["words"], list)


async def test_listen_reads_nothing_outside_the_programs_folder(bot, workdir, tmp_path):
    secret = tmp_path / "secret.wav"
    speak_to_wav(secret, "move")
    (workdir / "link.wav").symlink_to(secret)
    (workdir / "sub").mkdir()
    for path, words in [
        (str(secret), "in the program's folder"),
        ("/etc/passwd", "in the program's folder"),
        ("../../secret.wav", "in the program's folder"),
        ("sub/../../../secret.wav", "in the program's folder"),
        ("link.wav", "in the program's folder"),
        ("nothing.wav", "no file nothing.wav"),
        ("sub", "is not a file"),
        ("", "name of a file"),
        (3, "name of a file"),
    ]:
        error = await bot.error("listen", 5, path, ["move"])
        assert error.code == -32602 and words in str(error), (path, str(error))


async def test_the_microphone_is_heard_once_the_recogniser_knows_the_words(workdir):
    """One recogniser process a call: it knows the words before the microphone is listened
    to (a word it lacks: nothing is recorded), then hears what was recorded."""
    recorded = []

    async def microphone() -> bytes:  # what record() gives: 16 kHz mono samples
        recorded.append("move")
        said = speak_to_wav(workdir / "move.wav", "move").read_bytes()
        return hearing.resample(*hearing.read_wav(said))

    with pytest.raises(ValueError, match="does not know the word 'xyzzyq'"):
        await host_services.hear(("move", "xyzzyq"), record=microphone)
    assert recorded == []
    heard = await host_services.hear(("move", "stop"), record=microphone)
    assert heard == {"text": "move", "words": ["move"]} and recorded == ["move"]


async def test_listen_refuses_unknown_words_and_odd_params(bot, workdir):
    speak_to_wav(workdir / "move.wav", "move")
    for params, words in [
        ((5, "move.wav", ["move", "xyzzyq"]), "does not know the word 'xyzzyq'"),
        ((5, "move.wav", []), "list of 1 to 100"),
        ((5, "move.wav", ["<move>"]), "is not a word"),
        ((5, "move.wav", [7]), "a word or a short phrase"),
        ((0, "move.wav"), "seconds must be"),
        ((31, "move.wav"), "seconds must be"),
        (("5", "move.wav"), "seconds must be"),
    ]:
        error = await bot.error("listen", *params)
        assert error.code == -32602 and words in str(error), (params, str(error))


def write_wav(path: Path, samples: bytes, rate: int, width: int = 2) -> None:
    with wave.open(str(path), "wb") as recording:
        recording.setnchannels(1)
        recording.setsampwidth(width)
        recording.setframerate(rate)
        recording.writeframes(samples)


async def test_hearing_a_long_recording_does_not_hold_up_the_server(agent, bot, workdir):
    """pocketsphinx holds the interpreter while it hears a recording (47 s for a minute of
    noise): in the server, every robot, page and stop waited that long. The loop that
    serves them must keep its pace while a program's noise is heard."""
    noise = np.random.default_rng(1).integers(-12000, 12000, 6 * 16000, dtype="<i2")
    write_wav(workdir / "noise.wav", noise.tobytes(), 16000)
    gaps, hearing = [], asyncio.ensure_future(bot.call("listen", None, "noise.wav"))
    before = time.monotonic()
    while not hearing.done():
        await asyncio.sleep(0.01)
        now = time.monotonic()
        gaps.append(now - before)
        before = now
    heard = await hearing
    assert isinstance(heard["text"], str)
    assert max(gaps) < 0.5, f"the loop stood still for {max(gaps):.2f} s"


HEARD = str(host_services.HEARING).encode()


def hearing_processes() -> list[int]:
    """This process's children running the recogniser (robots/hearing.py), once it is the
    interpreter (past the tools that set its limits)."""
    found = []
    for pid in filter(str.isdigit, os.listdir("/proc")):
        try:
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().split(b"\0")
            ppid = int(Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[1])
        except (OSError, IndexError, ValueError):
            continue
        if ppid == os.getpid() and argv[0] == sys.executable.encode() and argv[-2:-1] == [HEARD]:
            found.append(int(pid))
    return found


async def test_the_recogniser_hears_within_its_memory_cpu_and_priority(agent, bot, workdir):
    """Its process has the address space, CPU seconds and niceness host_services names
    (1 GB, 120 s, 10 below the server), set before it runs anything."""
    noise = np.random.default_rng(2).integers(-12000, 12000, 6 * 16000, dtype="<i2")
    write_wav(workdir / "noise.wav", noise.tobytes(), 16000)
    hearing = asyncio.ensure_future(bot.call("listen", None, "noise.wav"))
    deadline = time.monotonic() + 10
    while not (found := hearing_processes()) and not hearing.done():
        assert time.monotonic() < deadline, "no recogniser process seen"
        await asyncio.sleep(0.01)
    assert found, "the recording was heard before its process was seen"
    limits = Path(f"/proc/{found[0]}/limits").read_text()
    stat = Path(f"/proc/{found[0]}/stat").read_text().rsplit(")", 1)[1].split()
    await hearing
    assert re.search(rf"Max address space\s+{host_services.HEARING_MEMORY}\s", limits), limits
    assert re.search(r"Max cpu time\s+120\s+120\s", limits), limits
    assert int(stat[16]) == os.getpriority(os.PRIO_PROCESS, 0) + 10  # its nice value


async def test_large_recordings_at_once_stay_out_of_the_servers_memory(agent, workdir):
    """A program's threads each asking to hear a 32 MB recording at a high rate: decoded and
    resampled in the server, they made it hold gigabytes (the kernel killed it). Each is
    refused by what its header says, and the robot hears one at a time, 4 waiting."""
    write_wav(workdir / "big.wav", bytes(32 * 2**20 - 64), 600_000, width=1)
    clients = [
        await asyncio.to_thread(robot_client.Robot, agent.server.url, TOKEN) for _ in range(7)
    ]
    before, peak, errors = rss(), 0, []

    async def ask(client):
        try:
            await asyncio.to_thread(client.call, "listen", None, "big.wav")
        except robot_client.RobotError as exc:
            errors.append(exc)

    asking = asyncio.ensure_future(asyncio.gather(*(ask(c) for c in clients)))
    while not asking.done():
        peak = max(peak, rss())
        await asyncio.sleep(0.02)
    for client in clients:
        client.close()
    assert (peak - before) < 100 * 2**20, f"the server grew by {(peak - before) >> 20} MB"
    assert len(errors) == 7, errors
    refused = [e for e in errors if e.code == -32602 and "600000 samples a second" in str(e)]
    busy = [e for e in errors if e.code == -32000 and "hearing" in str(e)]
    assert len(refused) + len(busy) == 7 and len(refused) >= 5, [str(e) for e in errors]


def rss() -> int:
    """This process's resident memory (the agent serves from it)."""
    for line in open("/proc/self/status"):
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) * 1024
    raise AssertionError("no VmRSS")


@pytest.mark.skipif(Path("/dev/snd").exists(), reason="this computer has a sound card")
async def test_listen_to_a_microphone_that_is_not_there_is_a_clear_error(agent, bot):
    agent.driver.hearing = "microphone"  # the sim has none: it hears typed phrases only
    error = await bot.error("listen", 1, None, ["move"])
    assert error.code == -32000
    assert "microphone" in str(error) and "no sound card" in str(error)


# -- the paper's examples --------------------------------------------------------------------


class FastClock:
    """Simulated time running `factor` times faster than the wall clock."""

    def __init__(self, factor: float):
        self.factor, self.origin = factor, time.monotonic()

    def __call__(self) -> float:
        return (time.monotonic() - self.origin) * self.factor


async def test_im_home_wanders_until_it_sees_home_and_says_so(agent, workdir, tmp_path):
    said = tmp_path / "said.wav"
    await Robot.objects.acreate(name="sim", url="sim://", settings={"speech": {"wav": str(said)}})
    await agent.driver.close()
    agent.driver = rhal.connect("sim://", max_linear=0.5, clock=FastClock(4))
    await agent.driver.open()
    status, out, err = await run_python(agent, EXAMPLES / "im_home.py", workdir, timeout=50)
    assert status == 0, err
    assert out.splitlines()[-1] == "I'm home" and "I see: kitchen" in out
    assert agent.shows["said"]["value"] == "I'm home"
    assert agent.shows["landmark"]["value"] == "home"
    assert np.sqrt(np.mean(wav_samples(said)[0] ** 2)) > 500
    after = await agent.driver.sensors()
    assert after["velocity"] == {"linear": 0.0, "angular": 0.0}
    in_view = host_services.read_barcodes(await agent.driver.front_camera_jpeg())
    assert "home" in [code["text"] for code in in_view]


async def test_say_move_and_the_robot_moves(agent, workdir):
    for command in ("move", "left", "stop"):
        speak_to_wav(workdir / f"{command}.wav", command)
    start = await agent.driver.sensors()
    recordings = ["move.wav", "left.wav", "move.wav", "stop.wav"]
    status, out, err = await run_python(agent, EXAMPLES / "voice_move.py", workdir, *recordings)
    assert status == 0, err
    assert out.splitlines() == ["heard: move", "heard: left", "heard: move", "heard: stop"]
    after = await agent.driver.sensors()
    assert after["velocity"] == {"linear": 0.0, "angular": 0.0}
    moved = (after["position"]["x"] - start["position"]["x"], after["position"]["y"])
    assert moved[0] < -0.1 and moved[1] > 0.1  # ahead (north), then west after the turn
    assert 240 < after["heading"] < 300
    said = agent.shows["said"]["value"]
    assert said.startswith("The range is ") and said.endswith(" metres")
