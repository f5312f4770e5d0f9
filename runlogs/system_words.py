"""robotide's own words about a run (its log's ``[robotide] …`` lines, a run's reason) in the
reader's language.

They are written in English, when the run ends, by the supervisor (runbox, which has no Django)
or the agent, and stored so: the log file and the run's reason are data, which tools read
("[robotide] finished" ends benchmarks' and tests' waits) and which two readers in two
languages (a student in Portuguese, a teacher in English) both read. They are translated where
shown: the run's page, its live stream, its table row and its downloaded log, each in the
language of whoever asks. Each known wording is a pattern here; a part the wording embeds (a
reason inside "…: sending SIGTERM") is translated in turn, and text of other origin (an
operating system's error) is left as it is.
"""

import re

from django.utils.translation import gettext, gettext_noop, pgettext

PREFIX = "[robotide] "

# Wordings that are always the same (msgids, translated where shown).
FIXED = (
    gettext_noop("stopped by user"),
    gettext_noop("stopped by user before it started"),
    gettext_noop("emergency stop"),
    gettext_noop("robot agent shutting down"),
    gettext_noop("it no longer waited to start"),
    gettext_noop("internal error (see the server's log)"),
    gettext_noop("CPU time limit reached"),
    gettext_noop("file size limit reached"),
    gettext_noop("memory limit reached"),
    gettext_noop("its box ended before the run began"),
)

# (a stored wording, what it says in the reader's language): `reason` and `why` are wordings
# themselves, translated in turn; numbers and names are kept as they are. First match wins.
PATTERNS = [
    (r"(?P<state>finished|failed|stopped): (?P<reason>.+)", None),  # the run's last line
    (r"exit status (?P<code>-?\d+)", gettext_noop("exit status %(code)s")),
    (r"killed by (?P<signal>SIG\w+)", gettext_noop("killed by %(signal)s")),
    (
        r"(?P<reason>.+): sending (?P<signal>SIGTERM|SIGKILL)",
        gettext_noop("%(reason)s: sending %(signal)s"),
    ),
    (
        r"did not stop within (?P<seconds>[\d.]+) s: sending SIGKILL",
        gettext_noop("did not stop within %(seconds)s s: sending SIGKILL"),
    ),
    (r"could not start: (?P<why>.+)", gettext_noop("could not start: %(why)s")),
    (r"its box could not be made: (?P<why>.+)", gettext_noop("its box could not be made: %(why)s")),
    (
        r"its program could not start: (?P<why>.+)",
        gettext_noop("its program could not start: %(why)s"),
    ),
    (
        r"its cgroup could not be made: (?P<why>.+)",
        gettext_noop("its cgroup could not be made: %(why)s"),
    ),
    (
        r"The (?P<language>.+) interpreter is not installed on this robot computer",
        gettext_noop("The %(language)s interpreter is not installed on this robot computer"),
    ),
    (
        r"output size limit \((?P<size>[\d.]+) MB\) reached; further output was discarded",
        gettext_noop("output size limit (%(size)s MB) reached; further output was discarded"),
    ),
    (
        r"(?P<why>.+); further output was discarded",
        gettext_noop("%(why)s; further output was discarded"),
    ),
    (
        r"wall-clock time limit \((?P<seconds>[\d.]+) s\) reached",
        gettext_noop("wall-clock time limit (%(seconds)s s) reached"),
    ),
    (  # a check run's (robots.check_sims)
        r"time limit reached: (?P<seconds>[\d.]+) s of sim time",
        gettext_noop("time limit reached: %(seconds)s s of sim time"),
    ),
    (
        r"CPU time limit \((?P<seconds>[\d.]+) s\) reached",
        gettext_noop("CPU time limit (%(seconds)s s) reached"),
    ),
    (
        r"memory limit \((?P<size>\d+) MB\) reached: the kernel killed (?P<count>\d+) of its "
        r"processes",
        gettext_noop(
            "memory limit (%(size)s MB) reached: the kernel killed %(count)s of its processes"
        ),
    ),
    (
        r"memory limit reached: the kernel killed (?P<count>\d+) of its processes",
        gettext_noop("memory limit reached: the kernel killed %(count)s of its processes"),
    ),
    (
        r"memory limit \((?P<size>\d+) MB\) reached",
        gettext_noop("memory limit (%(size)s MB) reached"),
    ),
    (
        r"the memory limit of all runs together \((?P<size>\d+) MB\) reached: the kernel "
        r"killed (?P<count>\d+) of this run's processes",
        gettext_noop(
            "the memory limit of all runs together (%(size)s MB) reached: the kernel killed "
            "%(count)s of this run's processes"
        ),
    ),
    (
        r"process limit \((?P<count>\d+) processes\) reached",
        gettext_noop("process limit (%(count)s processes) reached"),
    ),
    (
        r"it reached its process limit \((?P<count>\d+) processes\)",
        gettext_noop("it reached its process limit (%(count)s processes)"),
    ),
    (
        r"it reached its open files limit \((?P<count>\d+)\)",
        gettext_noop("it reached its open files limit (%(count)s)"),
    ),
    (
        r"it came up to its memory limit \((?P<size>\d+) MB\)",
        gettext_noop("it came up to its memory limit (%(size)s MB)"),
    ),
    (
        r"it filled its folder \((?P<size>\d+) MB\)",
        gettext_noop("it filled its folder (%(size)s MB)"),
    ),
    (
        r"it reached its file size limit \((?P<size>\d+) MB a file\)",
        gettext_noop("it reached its file size limit (%(size)s MB a file)"),
    ),
    (
        r"the agent of robot '(?P<robot>[\w-]+)' is not taking commands",
        gettext_noop("the agent of robot '%(robot)s' is not taking commands"),
    ),
    (
        r"the robot's agent cannot be reached \((?P<error>\w+)\)",
        gettext_noop("the robot's agent cannot be reached (%(error)s)"),
    ),
    (
        r"its turn on the shared robot ended \((?P<seconds>[\d.]+) s\)",
        gettext_noop("its turn on the shared robot ended (%(seconds)s s)"),
    ),
    (  # runbox.timescale
        r"this sim runs at (?P<speed>[\d.]+)x real time, and its programs' clocks need "
        r"libfaketime to keep up \(as root: apt-get install libfaketime\); or set its speed to 1",
        gettext_noop(
            "this sim runs at %(speed)sx real time, and its programs' clocks need libfaketime"
            " to keep up (as root: apt-get install libfaketime); or set its speed to 1"
        ),
    ),
]
_COMPILED = [(re.compile(pattern), words) for pattern, words in PATTERNS]
_NESTED = ("reason", "why")


def translated(text: str) -> str:
    """A stored wording (a run's reason, a log line without its prefix) in the active
    language; text no pattern knows, as it is."""
    from runlogs.notes import quota_reason_words  # a log quota's reason: its own words

    if text in FIXED:
        return gettext(text)
    quota = quota_reason_words(text)
    if quota is not None:
        return quota
    for pattern, words in _COMPILED:
        found = pattern.fullmatch(text)
        if found is None:
            continue
        parts = found.groupdict()
        for name in _NESTED:
            if name in parts:
                parts[name] = translated(parts[name])
        if words is None:  # "<state>: <reason>"
            return f"{pgettext('run state', parts['state'])}: {parts['reason']}"
        return gettext(words) % parts
    return text


def line(text: str) -> str:
    """A ``[robotide] …`` log line in the active language; any other line as it is."""
    if not text.startswith(PREFIX):
        return text
    return PREFIX + translated(text[len(PREFIX) :])
