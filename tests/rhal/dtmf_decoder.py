"""An independent DTMF decoder: a Goertzel detector in numpy, sharing nothing with the driver."""

import math
import wave

import numpy as np

ROWS = (697, 770, 852, 941)
COLUMNS = (1209, 1336, 1477, 1633)
KEYPAD = ("123A", "456B", "789C", "*0#D")


def goertzel_power(samples: np.ndarray, rate: int, frequency: float) -> float:
    """Power of one frequency in ``samples`` by the Goertzel recurrence."""
    coeff = 2 * math.cos(2 * math.pi * frequency / rate)
    s1 = s2 = 0.0
    for x in samples.tolist():
        s1, s2 = x + coeff * s1 - s2, s1
    return s1 * s1 + s2 * s2 - coeff * s1 * s2


def detect_digit(tone: np.ndarray, rate: int) -> str:
    rows = [goertzel_power(tone, rate, f) for f in ROWS]
    columns = [goertzel_power(tone, rate, f) for f in COLUMNS]
    row, column = int(np.argmax(rows)), int(np.argmax(columns))
    # A real decoder rejects a tone whose pair is not clearly dominant; so do we.
    assert sorted(rows)[-2] < rows[row] / 20, rows
    assert sorted(columns)[-2] < columns[column] / 20, columns
    return KEYPAD[row][column]


def decode(samples: np.ndarray, rate: int) -> list[tuple[str, float, float]]:
    """(digit, tone ms, gap ms after it) for each tone burst; the last gap runs to the end."""
    frame = rate // 1000  # 1 ms frames: burst edges to within a millisecond or two
    frames = samples[: len(samples) // frame * frame].astype(float).reshape(-1, frame)
    rms = np.sqrt((frames**2).mean(axis=1))
    on = rms > 0.1 * rms.max()
    edges = np.flatnonzero(np.diff(np.concatenate([[0], on.astype(int), [0]])))
    starts, ends = edges[::2], edges[1::2]
    next_starts = np.append(starts[1:], len(on))
    return [
        (detect_digit(samples[s * frame : e * frame], rate), float(e - s), float(n - e))
        for s, e, n in zip(starts, ends, next_starts, strict=True)
    ]


def read_wav(path) -> tuple[np.ndarray, int]:
    with wave.open(str(path), "rb") as wav:
        assert (wav.getnchannels(), wav.getsampwidth()) == (1, 2)
        data = wav.readframes(wav.getnframes())
        return np.frombuffer(data, dtype="<i2"), wav.getframerate()
