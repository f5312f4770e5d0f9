"""DTMF tone synthesis for the ``dtmf://`` driver.

Kept apart from :mod:`rhal.dtmf` so numpy is imported only when a DTMF robot is opened: the
appliance's other robots never pay for it.
"""

from __future__ import annotations

import numpy as np

#: Keypad digit -> (row Hz, column Hz), ITU-T Q.23.
FREQUENCIES: dict[str, tuple[int, int]] = {
    digit: (row, column)
    for row, keys in zip((697, 770, 852, 941), ("123A", "456B", "789C", "*0#D"), strict=True)
    for column, digit in zip((1209, 1336, 1477, 1633), keys, strict=True)
}

# A tone cut off mid-wave clicks, and the click's broadband energy can upset the decoder's
# guard timing; a 1 ms raised-cosine edge removes it without shortening the tone noticeably.
RAMP_SECONDS = 0.001


def tone_block(digit: str, rate: int, tone: float, gap: float, amplitude: float) -> bytes:
    """One tone of ``tone`` seconds then ``gap`` seconds of silence, as 16-bit mono PCM.

    ``amplitude`` (0..1 of full scale) is the peak of the two summed sine waves, each at half.
    """
    low, high = FREQUENCIES[digit]
    t = np.arange(round(tone * rate)) / rate
    wave = np.sin(2 * np.pi * low * t) + np.sin(2 * np.pi * high * t)
    ramp = min(round(RAMP_SECONDS * rate), len(t) // 2)
    if ramp:
        edge = 0.5 - 0.5 * np.cos(np.pi * np.arange(ramp) / ramp)
        wave[:ramp] *= edge
        wave[-ramp:] *= edge[::-1]
    pcm = np.round(wave * (amplitude / 2) * 32767).astype("<i2")
    silence = np.zeros(round(gap * rate), dtype="<i2")
    return np.concatenate([pcm, silence]).tobytes()
