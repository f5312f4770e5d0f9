"""What someone types into a robot's "Say to the robot" box, as its programs' listen() hears it.

The sim robot has no microphone (its driver's ``hearing`` is "typed"): its listen() waits for a
typed phrase. A robot with a microphone hears typed phrases too: whichever comes first, a phrase
typed or the words of its recording (robots.host_services).

A phrase typed while a listen() waits goes to it. Otherwise it waits for the next listen(), but
briefly (KEEP_SECONDS: a program started later must not hear what was said to another long
ago) and at most MAX_WAITING of them per robot: typing faster than programs listen is refused
with a reason, never queued without end.
"""

import asyncio
import string
import time
from collections import deque
from dataclasses import dataclass

MAX_CHARS = 200  # a phrase, not a speech
MAX_WAITING = 4  # phrases waiting for a listen() per robot
KEEP_SECONDS = 10.0  # how long a phrase nobody listened to waits for the next listen()
# Stripped from a word's ends: "Move!" is the command "move" (a recogniser hears no commas).
_PUNCTUATION = string.punctuation.replace("'", "") + "¡¿…“”‘’«»"


class Refused(ValueError):
    """The phrase was not taken: `code` says why (the web tier says it in the user's language:
    robots.say), the message in English."""

    def __init__(self, code: str, message: str):
        super().__init__(message)
        self.code = code


@dataclass(frozen=True)
class Phrase:
    text: str  # as typed, stripped
    user: str  # who typed it
    at: float  # monotonic seconds


class TypedSpeech:
    """One robot's typed phrases: those waiting, and the listen() waiting for one, if any."""

    def __init__(self, clock=time.monotonic):
        self.clock = clock
        self.waiting: deque[Phrase] = deque()
        self.listener: asyncio.Future | None = None

    @property
    def listening(self) -> bool:
        return self.listener is not None and not self.listener.done()

    def say(self, text: str, user: str, queue: bool = True) -> bool:
        """Hand `text` to the listen() waiting (True) or keep it for the next one (False).
        Refused: an empty or long text; with `queue` false, nobody listening now; too many
        waiting already."""
        text = " ".join(text.split()) if isinstance(text, str) else ""
        if not text:
            raise Refused("empty", "say what the robot should hear: the text is empty")
        if len(text) > MAX_CHARS:
            raise Refused("long", f"say at most {MAX_CHARS} characters at a time")
        phrase = Phrase(text, user, self.clock())
        if self.listening:
            self.listener.set_result(phrase)
            return True
        if not queue:
            raise Refused("nobody", "no program is listening to the robot now")
        self._forget_old()
        if len(self.waiting) >= MAX_WAITING:
            raise Refused(
                "full", f"{MAX_WAITING} phrases wait for a program to listen already: wait"
            )
        self.waiting.append(phrase)
        return False

    def take(self) -> Phrase | None:
        """The oldest phrase still waiting for a listen(), if any."""
        self._forget_old()
        return self.waiting.popleft() if self.waiting else None

    async def wait(self, seconds: float | None) -> Phrase | None:
        """A phrase waiting, or the next one typed within `seconds` (None: until cancelled)."""
        phrase = self.take()
        if phrase is not None:
            return phrase
        if self.listening:  # listen() calls take turns (HostServices): never two at once
            raise RuntimeError("two listen() calls wait for typed phrases at once")
        self.listener = future = asyncio.get_running_loop().create_future()
        try:
            await asyncio.wait({future}, timeout=seconds)  # the future itself is never cancelled
        except asyncio.CancelledError:
            if future.done():  # typed just as this listen() gave up: the next one hears it
                self.waiting.appendleft(future.result())
            else:
                future.cancel()
            raise
        finally:
            self.listener = None
        if future.done():
            return future.result()
        future.cancel()
        return None

    def _forget_old(self) -> None:
        now = self.clock()
        while self.waiting and now - self.waiting[0].at > KEEP_SECONDS:
            self.waiting.popleft()


def normalise(text: str) -> str:
    """Lower case, single-spaced, without punctuation around words: as a recogniser says it."""
    words = (word.strip(_PUNCTUATION) for word in text.lower().split())
    return " ".join(word for word in words if word)


def heard(phrase: Phrase, phrases: tuple[str, ...]) -> dict:
    """What listen() answers for a typed phrase: with `phrases`, the one of them that comes
    first in what was typed ("move please" is "move"), or "" for none of them."""
    text = normalise(phrase.text)
    if phrases:
        text = first_of(text.split(), phrases)
    return {"text": text, "words": text.split(), "typed": True}


def first_of(words: list[str], phrases: tuple[str, ...]) -> str:
    found = []
    for phrase in phrases:
        wanted = phrase.split()
        for start in range(len(words) - len(wanted) + 1):
            if words[start : start + len(wanted)] == wanted:
                found.append((start, -len(wanted), phrase))
                break
    return min(found)[2] if found else ""
