"""The dtmf:// driver, checked at the wire: its WAV (or device stream) is decoded back to digits
by a Goertzel detector written here, independent of the driver's own tone code."""

import sys
import threading
import time
import types

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

import rhal
from rhal.dtmf import STATES, TABLES, DtmfRobot, motor_state
from rhal.registry import DRIVERS
from tests.rhal.dtmf_decoder import decode, read_wav
from tests.waiting import until


def digits_of(tones) -> list[str]:
    return [digit for digit, _, _ in tones]


def played(wav_path, digit: str, times: int = 1) -> bool:
    """``digit`` has played out whole ``times`` so far: the tones play in real time, so a
    test waits for them, not for a guess of how long they take on a busy machine."""
    if not wav_path.exists() or wav_path.stat().st_size <= 44:
        return False
    tones = decode(*read_wav(wav_path))
    return [d for d, tone_ms, _ in tones if tone_ms >= 35].count(digit) >= times


def runs(digits: list[str]) -> list[str]:
    """Consecutive repeats merged: D D 5 5 5 D -> D 5 D."""
    return [d for i, d in enumerate(digits) if i == 0 or digits[i - 1] != d]


@pytest.fixture
def wav_path(tmp_path):
    return tmp_path / "tones.wav"


@pytest.fixture
def dtmf(monkeypatch):
    """dtmf:// in the registry, whether or not it is registered there yet."""
    monkeypatch.setitem(DRIVERS, "dtmf", ("rhal.dtmf", "DtmfRobot"))


# -- the digit table -------------------------------------------------------------------------

# From the MT8870 datasheet: Q4..Q1 for each key.
DATASHEET = {"1": 0b0001, "4": 0b0100, "5": 0b0101, "6": 0b0110, "9": 0b1001, "0": 0b1010,
             "D": 0b0000}  # fmt: skip
# (digit, left wheel, right wheel) with Q1/Q2 = left fwd/back, Q3/Q4 = right fwd/back.
DOCUMENTED = {"stop": ("D", 0, 0), "forward": ("5", 1, 1), "back": ("0", -1, -1),
              "spin_left": ("6", -1, 1), "spin_right": ("9", 1, -1),
              "pivot_left": ("4", 0, 1), "pivot_right": ("1", 1, 0)}  # fmt: skip


def test_the_default_table_is_the_documented_one():
    assert TABLES["mt8870"] == {state: digit for state, (digit, _, _) in DOCUMENTED.items()}


@pytest.mark.parametrize("state", STATES)
def test_each_digit_sets_the_h_bridge_bits_of_its_state(state):
    digit, left, right = DOCUMENTED[state]
    code = DATASHEET[digit]
    q1, q2, q3, q4 = (code >> bit & 1 for bit in range(4))
    assert (q1 - q2, q3 - q4) == (left, right)
    assert not (q1 and q2) and not (q3 and q4), "both halves of an H-bridge on: a short"


@pytest.mark.parametrize(
    ("linear", "angular", "state"),
    [(0.5, 0.0, "forward"), (0.1, 0.0, "forward"), (-0.5, 0.0, "back"), (0.0, 2.0, "spin_left"),
     (0.0, -2.0, "spin_right"), (0.5, 2.0, "pivot_left"), (0.5, -2.0, "pivot_right"),
     (0.0, 0.0, "stop"), (0.04, 0.1, "stop"), (0.5, 0.6, "forward"), (0.5, 1.0, "pivot_left"),
     (0.1, 1.5, "spin_left"), (-0.5, 1.0, "back"), (-0.2, 1.5, "spin_left"),
     (-0.5, -0.6, "back"), (9.0, 0.0, "forward")],
)  # fmt: skip
def test_a_command_maps_to_the_nearest_state(linear, angular, state):
    assert motor_state(linear, angular, max_linear=0.5, max_angular=2.0) == state


def test_the_deadband_is_a_fraction_of_the_limits():
    assert motor_state(0.04, 0.0, 0.5, 2.0, deadband=0.1) == "stop"
    assert motor_state(0.04, 0.0, 0.5, 2.0, deadband=0.05) == "forward"
    assert motor_state(1e-9, 0.0, 0.5, 2.0, deadband=0.0) == "forward"


@settings(max_examples=500)
@given(
    st.floats(allow_nan=False, allow_infinity=False),
    st.floats(allow_nan=False, allow_infinity=False),
    st.floats(min_value=1e-6, max_value=1e6),
    st.floats(min_value=1e-6, max_value=1e6),
    st.floats(min_value=0.0, max_value=0.99),
)
def test_any_finite_command_is_one_of_the_seven_states(linear, angular, lin_max, ang_max, band):
    assert motor_state(linear, angular, lin_max, ang_max, band) in STATES


@settings(
    max_examples=40, deadline=None, suppress_health_check=[HealthCheck.function_scoped_fixture]
)
@given(
    st.floats(allow_nan=False, allow_infinity=False),
    st.floats(allow_nan=False, allow_infinity=False),
)
async def test_any_finite_drive_gives_a_state_and_its_digit(wav_path, linear, angular):  # fmt: skip
    async with DtmfRobot(wav=wav_path, tone_ms=1, gap_ms=0, stop_repeats=1) as bot:
        await bot.drive(linear, angular)
        readings = await bot.sensors()
    assert readings["motor_state"] in STATES
    assert readings["digit"] == TABLES["mt8870"][readings["motor_state"]]


# -- at the wire -----------------------------------------------------------------------------


async def test_a_drive_sequence_comes_out_as_its_digits(wav_path):
    async with DtmfRobot(wav=wav_path) as bot:
        await until(lambda: played(wav_path, "D", 3))  # the stop tones sent on opening
        await bot.drive(0.3, 0.0)
        await until(lambda: played(wav_path, "5"))
        await bot.drive(0.0, 1.5)
        readings = await bot.sensors()
        assert (readings["motor_state"], readings["digit"]) == ("spin_left", "6")
        assert readings["time"] > 0  # s since it opened
        await until(lambda: played(wav_path, "6"))
        await bot.stop()
    digits = digits_of(decode(*read_wav(wav_path)))
    assert runs(digits) == ["D", "5", "6", "D"]
    assert digits[:3] == digits[-3:] == ["D", "D", "D"]  # stop_repeats, on opening and at stop
    assert digits[3] == "5"


@pytest.mark.parametrize(("rate", "tone_ms", "gap_ms"), [(8000, 40, 40), (44100, 60, 30)])
async def test_tone_and_gap_lengths_are_as_configured(dtmf, wav_path, rate, tone_ms, gap_ms):
    url = f"dtmf://?wav={wav_path}&sample_rate={rate}&tone_ms={tone_ms}&gap_ms={gap_ms}"
    async with rhal.connect(url) as bot:
        await bot.drive(-0.5, 0.0)
        await until(lambda: played(wav_path, "0"))
    samples, wav_rate = read_wav(wav_path)
    tones = decode(samples, wav_rate)
    assert wav_rate == rate
    assert runs(digits_of(tones)) == ["D", "0", "D"] or runs(digits_of(tones)) == ["0", "D"]
    for digit, tone, gap in tones:
        assert tone == pytest.approx(tone_ms, abs=2), digit
        assert gap == pytest.approx(gap_ms, abs=2), digit
    assert len(samples) == len(tones) * round((tone_ms + gap_ms) * rate / 1000)


async def test_the_wav_is_readable_while_it_plays(wav_path):
    async with DtmfRobot(wav=wav_path) as bot:
        await bot.drive(0.0, -1.0)
        await until(lambda: played(wav_path, "9"))
        assert bot.is_open


async def test_close_sends_stop_and_is_idempotent(wav_path):
    bot = DtmfRobot(wav=wav_path)
    await bot.open()
    await bot.drive(0.5, 2.0)
    await until(lambda: played(wav_path, "4"))
    await bot.close()
    await bot.close()
    await bot.stop()  # a closed robot is already stopped
    digits = digits_of(decode(*read_wav(wav_path)))
    assert runs(digits)[-2:] == ["4", "D"]
    assert digits[-3:] == ["D", "D", "D"]
    assert not bot.is_open


async def test_a_custom_table_from_the_url(dtmf, wav_path):
    table = "forward:1,back:2,spin_left:3,spin_right:A,pivot_left:B,pivot_right:C,stop:*"
    async with rhal.connect(f"dtmf://?wav={wav_path}&table={table}") as bot:
        await bot.drive(0.0, -2.0)
        await until(lambda: played(wav_path, "A"))
        assert bot.capabilities()["dtmf"]["table"]["spin_right"] == "A"
    # A move made before the opening stop tone plays replaces it: the newest command wins.
    assert runs(digits_of(decode(*read_wav(wav_path)))) in (["*", "A", "*"], ["A", "*"])


async def test_it_reports_only_what_it_commanded(wav_path):
    async with DtmfRobot(wav=wav_path) as bot:
        assert set(bot.capabilities()["sensors"]) == {"motor_state", "digit", "time"}
        assert bot.capabilities()["camera"] is None
        assert await bot.sensor("motor_state") == "stop"
        for lacking in ("heading", "range"):
            with pytest.raises(
                rhal.NotSupportedError, match=f"dtmf robot has no sensor '{lacking}'"
            ):
                await bot.sensor(lacking)


# -- options ---------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("query", "message"),
    [
        ("tone_ms=-40", "tone_ms must be between 1 and 1000, got -40"),
        ("gap_ms=-1", "gap_ms must be between 0 and 1000"),
        ("tone_ms=long", "tone_ms must be a number"),
        ("table=morse", "unknown digit table 'morse'; use one of: mt8870"),
        ("table=forward:5,back:0", r"missing states \['stop', 'spin_left'"),
        ("table=forward:5,back:X,sideways:1", r"unknown states \['sideways'\].*not DTMF digits"),
        ("table=forward:5,back:5,spin_left:6,spin_right:9,pivot_left:4,pivot_right:1,stop:D",
         "two states share a digit"),
        ("sample_rate=4000", "sample_rate must be between 8000 and 192000"),
        ("amplitude=2", "amplitude must be between"),
        ("stop_repeats=0", "stop_repeats must be between 1 and 20"),
        ("device=hw&wav=x.wav", "either wav"),
        ("wav=", "wav needs a file path"),
    ],
)  # fmt: skip
def test_bad_options_are_clear_errors(dtmf, query, message):
    with pytest.raises(ValueError, match=message):
        rhal.connect(f"dtmf://?{query}")


async def test_an_unwritable_wav_is_a_connection_error(tmp_path):
    bot = DtmfRobot(wav=tmp_path / "missing" / "out.wav")
    with pytest.raises(rhal.RobotConnectionError, match="cannot open robot"):
        await bot.open()


# -- a sound device, through a stand-in for sounddevice ----------------------------------------


class FakeStream:
    """Plays nothing, but paces and keeps what it was given, as a PortAudio stream would."""

    fail_after: int | None = None

    def __init__(self, *, samplerate, channels, dtype, device, latency):
        assert (channels, dtype) == (1, "int16")
        self.rate, self.device = samplerate, device
        self.chunks: list[bytes] = []
        self.started = self.stopped = self.closed = False
        self.lock = threading.Lock()

    def start(self):
        self.started = True

    def write(self, data):
        with self.lock:
            if self.fail_after is not None and len(self.chunks) >= self.fail_after:
                raise FakeSounddevice.PortAudioError("Unanticipated host error: device unplugged")
            self.chunks.append(bytes(data))
        time.sleep(len(data) / 2 / self.rate)

    def stop(self):
        self.stopped = True

    def close(self):
        self.closed = True


class FakeSounddevice(types.ModuleType):
    class PortAudioError(Exception):
        pass

    def __init__(self):
        super().__init__("sounddevice")
        self.streams: list[FakeStream] = []

    def RawOutputStream(self, **kwargs):  # noqa: N802 - sounddevice's name
        stream = FakeStream(**kwargs)
        self.streams.append(stream)
        return stream


@pytest.fixture
def sounddevice(monkeypatch):
    fake = FakeSounddevice()
    monkeypatch.setitem(sys.modules, "sounddevice", fake)
    return fake


def digits_given(stream) -> list[str]:
    with stream.lock:
        samples = np.frombuffer(b"".join(stream.chunks), dtype="<i2")
    return digits_of(decode(samples, stream.rate)) if samples.size else []


async def test_a_device_plays_the_same_digits(sounddevice):
    async with DtmfRobot(device="hw:1,0") as bot:
        await bot.drive(0.5, -2.0)
        await until(lambda: "1" in digits_given(sounddevice.streams[0]))
    (stream,) = sounddevice.streams
    assert (stream.rate, stream.device, stream.stopped, stream.closed) == (
        44100,
        "hw:1,0",
        True,
        True,
    )
    samples = np.frombuffer(b"".join(stream.chunks), dtype="<i2")
    digits = digits_of(decode(samples, 44100))
    assert runs(digits) == ["D", "1", "D"] or runs(digits) == ["1", "D"]
    assert digits[-3:] == ["D", "D", "D"]


async def test_a_device_that_dies_is_reported_to_the_next_call(sounddevice, monkeypatch):
    monkeypatch.setattr(FakeStream, "fail_after", 2)
    bot = DtmfRobot(tone_ms=10, gap_ms=10)
    await bot.open()
    await bot.drive(0.5, 0.0)
    await until(lambda: output_lost(bot))  # its third block of tones fails
    with pytest.raises(rhal.RobotConnectionError, match="lost its audio output: .*unplugged"):
        await bot.drive(0.5, 0.0)
    with pytest.raises(rhal.RobotConnectionError, match="unplugged"):
        await bot.stop()  # an e-stop must learn that its stop could not be sent
    await bot.close()  # releasing a dead output still works
    assert sounddevice.streams[0].closed


async def output_lost(bot) -> bool:
    try:
        await bot.sensors()
    except rhal.RobotConnectionError:
        return True
    return False


async def test_without_sounddevice_a_device_robot_names_the_package(monkeypatch):
    monkeypatch.setitem(sys.modules, "sounddevice", None)  # import fails as if not installed
    bot = DtmfRobot()
    with pytest.raises(rhal.DriverUnavailableError, match="'sounddevice'.*dtmf://\\?wav=PATH"):
        await bot.open()
    assert not bot.is_open


async def test_without_numpy_it_says_what_to_install(monkeypatch, wav_path):
    monkeypatch.setitem(sys.modules, "rhal.dtmf_tones", None)
    with pytest.raises(rhal.DriverUnavailableError, match=r"needs numpy.*robotide\[dtmf\]"):
        await DtmfRobot(wav=wav_path).open()
