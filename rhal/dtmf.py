"""The paper's low-cost robot, for ``dtmf://`` URLs: motor commands as DTMF tones.

The computer's audio output feeds an MT8870 tone decoder on the robot; its four output bits
Q1..Q4 drive two H-bridges (Q1/Q2 left motor forward/back, Q3/Q4 right motor forward/back).
So the robot has seven motor states, one DTMF digit each (see ``docs/robots/dtmf.md``).

Options, also accepted in the URL query (``dtmf://?wav=/tmp/out.wav&tone_ms=50``):
``wav`` (record to this WAV file instead of playing), ``device`` (sounddevice name or index,
default the system's output), ``sample_rate`` (Hz; default 8000 for a WAV, 44100 for a device),
``tone_ms`` / ``gap_ms`` (default 40 / 40), ``amplitude`` (0..1 of full scale, default 0.5),
``table`` ("mt8870", or ``state:digit`` pairs such as ``forward:5,back:0,...``), ``deadband``
(fraction of the speed limits below which drive() means stop, default 0.1), ``stop_repeats``
(default 3), ``max_linear``, ``max_angular``; from code also ``clock`` (for the ``time`` reading).

The decoder latches its last digit, so a lost tone leaves the motors as they were: while
moving, the current digit is repeated (tone, gap, tone, ...) by a background task, which lets a
watchdog on the robot stop the motors when the tones stop, and lets one missed tone be
corrected by the next; stopping sends the stop digit ``stop_repeats`` times and goes quiet.
"""

from __future__ import annotations

import asyncio
import math
import numbers
import os
import time
import wave
from collections.abc import Callable, Mapping
from typing import Any

from rhal.base import Robot
from rhal.errors import DriverUnavailableError, RobotConnectionError

#: Each motor state as (left, right) wheel direction: +1 forward, -1 back, 0 off.
WHEELS: dict[str, tuple[int, int]] = {
    "stop": (0, 0),
    "forward": (1, 1),
    "back": (-1, -1),
    "spin_left": (-1, 1),
    "spin_right": (1, -1),
    "pivot_left": (0, 1),  # about the still left wheel
    "pivot_right": (1, 0),
}
STATES = tuple(WHEELS)

#: The MT8870's 4-bit output (Q4..Q1) for each DTMF key.
MT8870_CODE: dict[str, int] = {
    **{str(n): n for n in range(1, 10)},
    **{"0": 0b1010, "*": 0b1011, "#": 0b1100},
    **{"A": 0b1101, "B": 0b1110, "C": 0b1111, "D": 0b0000},
}
DIGITS = tuple(MT8870_CODE)

#: Direction of each moving state in the plane (linear, angular), both scaled to the limits,
#: in degrees counter-clockwise from straight ahead.
DIRECTIONS: dict[str, float] = {
    "forward": 0.0,
    "pivot_left": 45.0,
    "spin_left": 90.0,
    "back": 180.0,
    "spin_right": -90.0,
    "pivot_right": -45.0,
}


def wiring_code(left: int, right: int) -> int:
    """The Q4..Q1 bits that put the wheels in these directions (Q1 is the least bit)."""
    return (left > 0) | (left < 0) << 1 | (right > 0) << 2 | (right < 0) << 3


def _table_for_wiring() -> dict[str, str]:
    # Derived, not typed in, so the table cannot drift from the wiring it claims to match.
    by_code = {code: digit for digit, code in MT8870_CODE.items()}
    return {state: by_code[wiring_code(*wheels)] for state, wheels in WHEELS.items()}


#: Named digit tables; the default matches the wiring in the module docstring.
TABLES: dict[str, dict[str, str]] = {"mt8870": _table_for_wiring()}


def parse_table(table: str | Mapping[str, str]) -> dict[str, str]:
    """A table name, ``"forward:5,back:0,..."`` or a mapping -> {state: digit} for all states."""
    if isinstance(table, str):
        if table in TABLES:
            return dict(TABLES[table])
        if ":" not in table:
            raise ValueError(
                f"unknown digit table {table!r}; use one of: {', '.join(TABLES)}, "
                "or state:digit pairs such as 'forward:5,back:0,...'"
            )
        pairs = [item.split(":", 1) for item in table.split(",") if item.strip()]
        if any(len(pair) != 2 for pair in pairs):
            raise ValueError(f"digit table {table!r}: each item must be state:digit")
        table = dict(pairs)
    mapping = {str(s).strip().lower(): str(d).strip().upper() for s, d in table.items()}
    problems = []
    if unknown := sorted(set(mapping) - set(STATES)):
        problems.append(f"unknown states {unknown}")
    if missing := [state for state in STATES if state not in mapping]:
        problems.append(f"missing states {missing}")
    if bad := sorted({d for d in mapping.values() if d not in MT8870_CODE}):
        problems.append(f"not DTMF digits {bad}")
    if len(set(mapping.values())) != len(mapping):
        problems.append("two states share a digit")
    if problems:
        raise ValueError(
            f"bad digit table: {'; '.join(problems)}; states are {', '.join(STATES)}, "
            f"digits are {''.join(DIGITS)}"
        )
    return {state: mapping[state] for state in STATES}


def motor_state(
    linear: float, angular: float, max_linear: float, max_angular: float, deadband: float = 0.1
) -> str:
    """The motor state nearest to a drive command.

    Both speeds are scaled to the robot's limits (-1..1). Below ``deadband`` on both it is
    "stop"; otherwise the state whose direction in the (linear, angular) plane is nearest wins,
    so boundaries fall half way: forward within 22.5 degrees of straight ahead, pivots from
    22.5 to 67.5, spins from 67.5 to 135, back beyond 135. The motors have no speed control,
    so any command past the deadband moves at full speed.
    """
    scaled_linear = max(-1.0, min(1.0, linear / max_linear))
    scaled_angular = max(-1.0, min(1.0, angular / max_angular))
    if max(abs(scaled_linear), abs(scaled_angular)) < deadband or not (
        scaled_linear or scaled_angular
    ):
        return "stop"
    heading = math.degrees(math.atan2(scaled_angular, scaled_linear))
    return min(DIRECTIONS, key=lambda state: abs((heading - DIRECTIONS[state] + 180) % 360 - 180))


class DtmfRobot(Robot):
    kind = "dtmf"
    option_help = {
        **Robot.option_help,
        "wav": "record the tones to this WAV file instead of playing them",
        "device": "sound device name or index (blank: the system's output)",
        "sample_rate": "Hz (blank: 8000 for a WAV, 44100 for a device)",
        "tone_ms": "length of each tone, ms",
        "gap_ms": "silence between tones, ms",
        "amplitude": "tone level, 0..1 of full scale",
        "table": "digit table: mt8870, or state:digit pairs (forward:2,back:8,...)",
        "deadband": "fraction of the speed limits below which drive() means stop",
        "stop_repeats": "times the stop digit is sent on each stop",
    }

    def __init__(
        self,
        url: str = "dtmf://",
        *,
        wav: str | os.PathLike[str] | None = None,
        device: str | int | None = None,
        sample_rate: int | None = None,
        tone_ms: float = 40,
        gap_ms: float = 40,
        amplitude: float = 0.5,
        table: str | Mapping[str, str] = "mt8870",
        deadband: float = 0.1,
        stop_repeats: int = 3,
        clock: Callable[[], float] = time.monotonic,
        **limits: Any,
    ) -> None:
        super().__init__(url, **limits)
        if wav is not None and device is not None:
            raise ValueError("give either wav (a file) or device (a sound device), not both")
        if wav is not None and not os.fspath(wav):
            raise ValueError("wav needs a file path")
        self.wav = wav
        self.device = device
        if sample_rate is None:  # telephone rate keeps files small; cards all do 44.1 kHz
            sample_rate = 8000 if wav else 44100
        self.sample_rate = _integer("sample_rate", sample_rate, 8000, 192000)
        self.tone_ms = _number("tone_ms", tone_ms, 1, 1000)
        self.gap_ms = _number("gap_ms", gap_ms, 0, 1000)
        self.amplitude = _number("amplitude", amplitude, 0.001, 1)
        self.table = parse_table(table)
        self.deadband = _number("deadband", deadband, 0, 0.99)
        self.stop_repeats = _integer("stop_repeats", stop_repeats, 1, 20)
        self._clock = clock
        self._opened_at = clock()
        self._state = "stop"
        self._stops_left = 0
        self._player: asyncio.Task[None] | None = None
        self._failure: BaseException | None = None
        self._sink: _WavSink | _DeviceSink | None = None

    def capabilities(self) -> dict[str, Any]:
        return {
            **super().capabilities(),
            # The robot answers nothing back; the page shows how its tones are made instead.
            "dtmf": {
                "table": dict(self.table),
                "tone_ms": self.tone_ms,
                "gap_ms": self.gap_ms,
                "sample_rate": self.sample_rate,
                "output": f"wav:{os.fspath(self.wav)}" if self.wav else "device",
            },
        }

    # -- hooks -----------------------------------------------------------------------------

    async def _open(self) -> None:
        try:
            from rhal.dtmf_tones import tone_block
        except ImportError as exc:
            raise DriverUnavailableError(
                f"the dtmf:// driver needs numpy to make its tones ({exc}); "
                "install it with: pip install 'robotide[dtmf]'"
            ) from exc
        tone, gap = self.tone_ms / 1000, self.gap_ms / 1000
        self._blocks = {
            digit: tone_block(digit, self.sample_rate, tone, gap, self.amplitude)
            for digit in self.table.values()
        }
        if self.wav:
            self._sink = await _WavSink.open(self.wav, self.sample_rate)
        else:
            self._sink = await _DeviceSink.open(self.device, self.sample_rate)
        self._failure = None
        self._opened_at = self._clock()
        # The decoder may still hold a digit latched from before (or from power-up noise).
        self._command("stop")

    async def _close(self) -> None:
        player, self._player = self._player, None
        if player is not None:
            block = (self.tone_ms + self.gap_ms) / 1000
            # The stop tones must be out before the output closes; a hung device must not
            # hang close() for ever, so give up (cancelling the player) after a while.
            try:
                await asyncio.wait_for(player, timeout=(self.stop_repeats + 2) * block + 5)
            except TimeoutError:
                pass
        sink, self._sink = self._sink, None
        if sink is not None:
            await sink.close()

    async def _drive(self, linear: float, angular: float) -> None:
        self._check_link()
        self._command(
            motor_state(linear, angular, self.max_linear, self.max_angular, self.deadband)
        )

    async def _stop(self) -> None:
        if self._failure is not None and not self._is_open:
            return  # closing a dead output only releases it; stop() and drive() said it died
        self._check_link()
        self._command("stop")

    async def _read_sensors(self) -> dict[str, Any]:
        self._check_link()
        return {
            "motor_state": self._state,
            "digit": self.table[self._state],
            "time": self._clock() - self._opened_at,
        }

    def _sensor_specs(self) -> dict[str, dict[str, Any]]:
        # Nothing is measured: these are what the driver last commanded.
        return {
            "motor_state": {"unit": "", "values": list(STATES), "commanded": True},
            "digit": {"unit": "", "values": list(self.table.values()), "commanded": True},
            "time": {"unit": "s"},
        }

    # -- tone player -----------------------------------------------------------------------

    def _command(self, state: str) -> None:
        """Make ``state`` the one played from the next tone on; start the player if idle."""
        self._state = state
        # Every stop is sent afresh (an e-stop must not be skipped because we think the
        # robot is already stopped); a move cancels stop tones still to come.
        self._stops_left = self.stop_repeats if state == "stop" else 0
        if self._player is None or self._player.done():
            self._player = asyncio.create_task(self._play(), name=f"dtmf tones {self.url}")

    async def _play(self) -> None:
        # A tone is never cut short for a new command: a truncated tone could fall under the
        # decoder's guard time and be lost, so changes take effect at the next tone.
        assert self._sink is not None
        try:
            while True:
                if self._stops_left:
                    self._stops_left -= 1
                    digit = self.table["stop"]
                elif self._state == "stop":
                    return
                else:
                    digit = self.table[self._state]
                await self._sink.write(self._blocks[digit])
        except Exception as exc:  # the output died; the next call reports it
            self._failure = exc

    def _check_link(self) -> None:
        if self._failure is not None:
            raise RobotConnectionError(
                f"robot {self.url!r} lost its audio output: {self._failure}"
            ) from self._failure


class _WavSink:
    """16-bit mono WAV, written block by block in real time as if played, header kept valid.

    Blocks are small (a few KB) but go through a thread anyway: an SD card on a Raspberry Pi
    can stall a write for far longer than the event loop may wait.
    """

    def __init__(self, file: Any, rate: int) -> None:
        self._file = file
        self._wav = wave.open(file, "wb")
        self._wav.setnchannels(1)
        self._wav.setsampwidth(2)
        self._wav.setframerate(rate)
        self._rate = rate
        self._due = 0.0

    @classmethod
    async def open(cls, path: str | os.PathLike[str], rate: int) -> _WavSink:
        file = await asyncio.to_thread(open, path, "wb")
        return cls(file, rate)

    async def write(self, data: bytes) -> None:
        loop = asyncio.get_running_loop()
        # Pace like a sound card: the next block starts when this one has "played". After an
        # idle spell the clock restarts, so the recording holds no silence for idle time.
        start = max(self._due, loop.time())
        self._due = start + len(data) / 2 / self._rate
        await asyncio.to_thread(self._write, data)
        await asyncio.sleep(self._due - loop.time())

    def _write(self, data: bytes) -> None:
        self._wav.writeframes(data)  # also patches the header's lengths
        self._file.flush()  # so a reader sees every tone as soon as it "plays"

    async def close(self) -> None:
        def close() -> None:
            self._wav.close()
            self._file.close()

        await asyncio.to_thread(close)


class _DeviceSink:
    """A sound device through sounddevice (PortAudio, which uses ALSA on Linux)."""

    def __init__(self, sd: Any, stream: Any) -> None:
        self._sd = sd
        self._stream = stream

    @classmethod
    async def open(cls, device: str | int | None, rate: int) -> _DeviceSink:
        try:
            import sounddevice as sd
        except (ImportError, OSError) as exc:  # OSError: PortAudio's shared library is missing
            raise DriverUnavailableError(
                f"the dtmf:// driver needs the 'sounddevice' package and PortAudio to play on "
                f"a sound device ({exc}); install them (pip install sounddevice, apt install "
                "libportaudio2) or record to a file with dtmf://?wav=PATH"
            ) from exc

        def start() -> Any:
            stream = sd.RawOutputStream(
                samplerate=rate, channels=1, dtype="int16", device=device, latency="low"
            )
            stream.start()
            return stream

        try:
            stream = await asyncio.to_thread(start)
        except (sd.PortAudioError, ValueError) as exc:  # no such device, rate refused, ...
            raise RobotConnectionError(f"cannot open sound device {device!r}: {exc}") from exc
        return cls(sd, stream)

    async def write(self, data: bytes) -> None:
        # A blocking write returns once the device has room, which paces the player.
        await asyncio.to_thread(self._stream.write, data)

    async def close(self) -> None:
        def close() -> None:
            try:
                self._stream.stop()  # plays out what is queued: the stop tones
                self._stream.close()
            except self._sd.PortAudioError:
                pass  # the device is gone; there is nothing left to release

        await asyncio.to_thread(close)


def _number(name: str, value: object, low: float, high: float) -> float:
    # bool is an int subclass, but tone_ms=True is a mistake, not a length.
    if isinstance(value, bool) or not isinstance(value, numbers.Real):
        raise ValueError(f"{name} must be a number, got {value!r}")
    result = float(value)
    if not low <= result <= high:  # also rejects nan
        raise ValueError(f"{name} must be between {low:g} and {high:g}, got {value!r}")
    return result


def _integer(name: str, value: object, low: int, high: int) -> int:
    if isinstance(value, bool) or not isinstance(value, numbers.Integral):
        raise ValueError(f"{name} must be a whole number, got {value!r}")
    if not low <= value <= high:
        raise ValueError(f"{name} must be between {low} and {high}, got {value!r}")
    return int(value)
