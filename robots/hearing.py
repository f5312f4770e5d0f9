"""listen()'s recogniser, in a process of its own (numpy, pocketsphinx and the standard
library; no Django): robots.host_services starts one per call, with limits.

Recognition is C code that holds the interpreter for as long as the recording takes to hear
(47 s for a minute of noise), and a recording is decoded and resampled in memory (a 32 MB
file at a high rate came to gigabytes): in the server, either stopped every robot and page
it serves. Here they cost this process only.

    python robots/hearing.py
    stdin:  {"phrases": [...], "recording": FD} on one line: the recording is read from
            descriptor FD (a WAV file, or another kind ffmpeg reads); with "recording": null,
            16 kHz mono 16-bit samples follow, once the phrases' words are known (the
            microphone is not listened to for a word the model lacks)
    stdout: {"ok": true} once the phrases' words are known, then {"text": ..., "words":
            [...]}; or {"error": "why"} (what the program gave was wrong), one line each
"""

import io
import json
import re
import shutil
import subprocess
import sys
import wave

SAMPLE_RATE = 16000  # what the model was trained on
MAX_AUDIO_SECONDS = 60.0
MAX_AUDIO_BYTES = 32 * 1024 * 1024  # checked by the server before: a file grown since is cut
MAX_RATE = 192000  # a WAV file's samples per second: more is no recording of speech


class Refused(ValueError):
    """What the program gave cannot be heard; the message says why."""


def main() -> int:
    request = json.loads(sys.stdin.buffer.readline())
    phrases = tuple(request.get("phrases") or ())
    try:
        decoder = load()
        check(decoder, phrases)
        say({"ok": True})
        if request.get("recording") is not None:
            with open(request["recording"], "rb") as recording:
                pcm = audio_to_pcm(recording.read(MAX_AUDIO_BYTES + 1))
        else:
            pcm = sys.stdin.buffer.read()
        say(recognise(decoder, pcm, phrases))
    except Refused as exc:
        say({"error": str(exc)})
    return 0


def say(answer: dict) -> None:
    sys.stdout.write(json.dumps(answer) + "\n")
    sys.stdout.flush()


def load():
    from pocketsphinx import Decoder

    return Decoder(samprate=SAMPLE_RATE, loglevel="FATAL")


def check(decoder, phrases: tuple[str, ...]) -> None:
    for phrase in phrases:
        for word in phrase.split():
            if decoder.lookup_word(word) is None:
                raise Refused(f"listen() does not know the word {word!r}")


def recognise(decoder, pcm: bytes, phrases: tuple[str, ...]) -> dict:
    """{"text": what was said, "words": its words}; with ``phrases``, the text is the one of
    them heard, or "" when none was. Batch (cepstral mean over the whole utterance)."""
    if phrases:
        grammar = f"#JSGF V1.0;\ngrammar words;\npublic <words> = {' | '.join(phrases)};\n"
        decoder.add_jsgf_string("words", grammar)
        decoder.activate_search("words")
    decoder.start_utt()
    if pcm:
        decoder.process_raw(pcm, full_utt=True)
    decoder.end_utt()
    hypothesis = decoder.hyp()
    text = " ".join(hypothesis.hypstr.split()) if hypothesis else ""
    words = [
        re.sub(r"\(\d+\)$", "", segment.word)  # "the(2)": a second pronunciation
        for segment in decoder.seg() or ()
        if not segment.word.startswith(("<", "["))  # silence, noise
    ]
    if phrases and text not in phrases:  # it got part of the way into one: no command
        return {"text": "", "words": []}
    return {"text": text, "words": words}


def audio_to_pcm(data: bytes) -> bytes:
    """A recording as the recogniser hears it: 16 kHz, mono, 16-bit little-endian samples.
    PCM WAV files are read with the standard library; anything else ffmpeg can read (another
    kind of WAV, MP3, Ogg...) goes through ffmpeg when it is installed."""
    try:
        samples, rate = read_wav(data)
    except (wave.Error, EOFError) as exc:
        ffmpeg = shutil.which("ffmpeg")
        if ffmpeg is None:
            raise Refused(
                f"wav is not a PCM WAV file ({exc}); ffmpeg, which reads other kinds, is not"
                " installed"
            ) from None
        return ffmpeg_pcm(ffmpeg, data)
    return resample(samples, rate)


def read_wav(data: bytes):
    """(mono samples as floats, sample rate) of a PCM WAV file; its length and rate are
    checked from its header, before its samples are read."""
    import numpy as np

    with wave.open(io.BytesIO(data)) as recording:
        width, channels = recording.getsampwidth(), recording.getnchannels()
        rate, count = recording.getframerate(), recording.getnframes()
        if not 0 < rate <= MAX_RATE:
            raise Refused(f"wav has {rate} samples a second: at most {MAX_RATE}")
        if count > MAX_AUDIO_SECONDS * rate:
            raise Refused(f"wav is longer than {MAX_AUDIO_SECONDS:g} s")
        frames = recording.readframes(count)
    if width == 1:  # 8-bit WAV is unsigned
        samples = np.frombuffer(frames, np.uint8).astype(np.float64) - 128.0
        samples *= 256.0
    elif width == 3:
        raw = np.frombuffer(frames, np.uint8).reshape(-1, 3)
        samples = raw[:, 0] | raw[:, 1].astype(np.int32) << 8 | raw[:, 2].astype(np.int32) << 16
        samples = np.where(samples >= 1 << 23, samples - (1 << 24), samples) / 256.0
    elif width in (2, 4):
        samples = np.frombuffer(frames, f"<i{width}").astype(np.float64)
        samples /= 1 << (8 * (width - 2))
    else:
        raise wave.Error(f"{8 * width}-bit samples")
    samples = samples[: len(samples) // channels * channels].reshape(-1, channels).mean(axis=1)
    return samples, rate


def resample(samples, rate: int) -> bytes:
    """To 16 kHz by Fourier interpolation: band-limited, so nothing above 8 kHz folds back
    into what the recogniser hears."""
    import numpy as np

    if rate != SAMPLE_RATE and len(samples):
        count = max(1, round(len(samples) * SAMPLE_RATE / rate))
        spectrum = np.fft.rfft(samples)
        bins = count // 2 + 1
        if len(spectrum) >= bins:
            spectrum = spectrum[:bins]
        else:
            spectrum = np.pad(spectrum, (0, bins - len(spectrum)))
        samples = np.fft.irfft(spectrum, count) * (count / len(samples))
    return np.clip(np.round(samples), -32768, 32767).astype("<i2").tobytes()


def ffmpeg_pcm(ffmpeg: str, data: bytes) -> bytes:
    done = subprocess.run(
        [ffmpeg, "-nostdin", "-loglevel", "error", "-threads", "1", "-i", "pipe:0",
         "-t", str(MAX_AUDIO_SECONDS), "-ac", "1", "-ar", str(SAMPLE_RATE), "-f", "s16le",
         "pipe:1"],
        input=data, capture_output=True, timeout=60,
    )  # fmt: skip
    if done.returncode != 0:
        message = done.stderr.decode(errors="replace").strip().splitlines()
        raise Refused(f"wav is not a recording ffmpeg can read: {message[-1] if message else ''}")
    return done.stdout


if __name__ == "__main__":
    sys.exit(main())
