"""A worker making blocks into Python (see programs.blocks_worker): one JSON request a line
on stdin, {"source", "language"}; one JSON answer a line on stdout, {"python", "blocks"} (the
source map: the id of the block each line of the Python is made for) or {"error"}, with
"retire": true when it will take no more (out of memory, or near its lifetime's CPU).

It runs within the address space prlimit gave it; before each program it sets its CPU cap to
what it has used plus the seconds a program may take, so a runaway program ends it by SIGXCPU.
It needs Django only for its translations, so it configures nothing else."""

import json
import os
import resource
import sys
from pathlib import Path

import django
from django.conf import settings
from django.utils import translation

PROGRAMS = Path(__file__).resolve().parent.parent


def main(seconds: int) -> None:
    answers = os.fdopen(os.dup(1), "wb")
    os.dup2(2, 1)  # whatever else writes to stdout cannot pass for an answer
    settings.configure(
        USE_I18N=True, LANGUAGE_CODE="en", LOCALE_PATHS=[PROGRAMS / "locale"], INSTALLED_APPS=[]
    )
    django.setup()
    from programs.blocks import BlocksError, to_python_mapped

    for line in sys.stdin.buffer:
        request = json.loads(line)
        _cap_cpu(seconds)
        try:
            with translation.override(request.get("language") or "en"):
                python, blocks = to_python_mapped(request["source"])
                answer = {"python": python, "blocks": blocks}
        except BlocksError as exc:
            answer = {"error": str(exc)}
        except MemoryError:  # the caller says so, in its user's language
            answer = {"out_of_memory": True}
        answer["retire"] = "out_of_memory" in answer or _spent(seconds)
        answers.write(json.dumps(answer).encode() + b"\n")
        answers.flush()
        if answer["retire"]:
            return


def _cap_cpu(seconds: int) -> None:
    """This process's CPU capped at what it has used plus `seconds` (within its lifetime's
    cap, set by prlimit): a program taking more ends it by SIGXCPU."""
    _, hard = resource.getrlimit(resource.RLIMIT_CPU)
    soft = _used() + seconds
    resource.setrlimit(
        resource.RLIMIT_CPU, (soft if hard == resource.RLIM_INFINITY else min(soft, hard), hard)
    )


def _spent(seconds: int) -> bool:
    """Whether its lifetime's CPU cap leaves less than one more program may take."""
    _, hard = resource.getrlimit(resource.RLIMIT_CPU)
    return hard != resource.RLIM_INFINITY and _used() + seconds > hard


def _used() -> int:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return int(usage.ru_utime + usage.ru_stime) + 1  # whole seconds, rounded up


if __name__ == "__main__":
    main(int(sys.argv[1]))
