"""Check sims: a fresh sim for each variant's run of an exercise's Check (classroom.checking).

A check sim is a personal sim (robots.sims) of the student's with ``checking`` set. Its world
is the exercise's document as saved with the exercise (a dict as its world setting:
worlds.resolve), whose only start pose is the variant's (each run starts there:
``start_each_run``); its clock runs at the exercise's speed; its runs have a wall-clock limit
of the exercise's time limit at that speed, and some slack for the program's start. Its agent
records the run's trace (robots.agent: ``trace.json`` in the run's folder) and stops the
program when the exercise's time limit of sim time is up.

It is out of every list (the robots list, "My sims", the workbench's choices, the API's
robots) and of the personal sims' caps; its robot page, live pose and world are for staff and
the teachers of its owner's classes (robots.models.check_sims_for_user), never its owner: a
hidden variant's pose is in it. At most CHECK_SIMS_MAX are live at once on the server; a Check
that would need more is refused (``CheckSimsFull``). Its agent removes it once its run ended
and the trace was saved (``remove_after_run``); one whose run ended another way (failed before
an agent took it, its agent gone) goes at the reaper's next look (robots.sims). The row stays,
``reaped``, while its run names it: the run and its trace are kept.
"""

from __future__ import annotations

import hashlib
import json
import logging
import math
import os

from django.conf import settings
from django.db import IntegrityError, transaction
from django.utils import timezone
from django.utils.translation import gettext as _

from programs.models import Run
from robots import sims
from robots.bus import begin_soon, send_to_agent
from robots.models import Robot
from robots.runs import RunRefused

log = logging.getLogger(__name__)

# Wall s a check run may take beyond its sim time limit at the sim's speed: its program's
# start (an interpreter, the Robot API's sign-in) and a machine busy with 25 others.
WALL_SLACK_SECONDS = 20.0
DESCRIPTION = sims.DESCRIPTION


class CheckSimsFull(RunRefused):
    """The server has CHECK_SIMS_MAX check sims already: its message says to try again."""


def live():
    """The check sims not removed, of everyone."""
    return Robot.objects.filter(checking=True, reaped__isnull=True)


def room_for(count: int) -> None:
    """CheckSimsFull unless ``count`` more check sims fit under CHECK_SIMS_MAX now."""
    now = live().count()
    if now + count > settings.CHECK_SIMS_MAX:
        raise CheckSimsFull(
            _(
                "the server is checking many programs right now (%(count)s checks' sims of"
                " %(limit)s at most): try again in a minute"
            )
            % {"count": now, "limit": settings.CHECK_SIMS_MAX}
        )


def setup_of(world: dict, pose: dict, speed: float, time_limit_s: float) -> str:
    """What decides a variant's run, as a short digest: a run made for the same setup need not
    run again when only an exercise's checks changed (classroom.checking.recheck)."""
    start = start_of(pose)
    made = json.dumps([world, start, float(speed), float(time_limit_s)], sort_keys=True)
    return hashlib.sha256(made.encode()).hexdigest()[:32]


def start_of(pose: dict) -> dict:
    return {"x": float(pose["x"]), "y": float(pose["y"]), "theta": float(pose["theta"])}


def check_settings(world: dict, pose: dict, speed: float, time_limit_s: float) -> dict:
    """The robot settings of a check sim (its driver's: world, speed; its runs': the rest)."""
    start = start_of(pose)
    wall = math.ceil(float(time_limit_s) / float(speed) + WALL_SLACK_SECONDS)
    return {
        "world": {**world, "start": [start]},
        "speed": float(speed),
        "start_each_run": True,
        "limits": {"wall_seconds": wall},
        "check": {
            "time_limit_s": float(time_limit_s),
            "setup": setup_of(world, start, speed, time_limit_s),
        },
    }


def time_limit_of(robot_settings: dict) -> float | None:
    """A check sim's time limit of sim time (its agent stops the run then), or None."""
    check = robot_settings.get("check")
    if not isinstance(check, dict):
        return None
    value = check.get("time_limit_s")
    return float(value) if isinstance(value, int | float) and value > 0 else None


def setup_stored(robot: Robot | None) -> str:
    check = robot.settings.get("check") if robot is not None else None
    return check.get("setup", "") if isinstance(check, dict) else ""


def name_base(user) -> str:
    return "check-" + sims.name_base(user).removeprefix("sim-")


def make(user, world: dict, pose: dict, speed: float, time_limit_s: float) -> Robot:
    """A new check sim of ``user``'s (in the caller's transaction; its agent starts once that
    is committed: ``start_run``)."""
    options = check_settings(world, pose, speed, time_limit_s)
    base = name_base(user)
    for _attempt in range(5):  # two Checks at once may pick the same free name
        taken = set(
            Robot.objects.filter(name__startswith=f"{base}-").values_list("name", flat=True)
        )
        number = 1
        while f"{base}-{number}" in taken:
            number += 1
        try:
            with transaction.atomic():
                return Robot.objects.create(
                    name=f"{base}-{number}"[:50], url="sim://", settings=options,
                    description=DESCRIPTION, owner=user, personal=True, checking=True,
                    used=timezone.now(),
                )  # fmt: skip
        except IntegrityError:
            continue
    raise RunRefused(_("Could not find a free name for a check's sim: try again."))


def start_run(robot: Robot, user, *, program, program_name: str, language: str, source: str,
              sealed: bool) -> Run:  # fmt: skip
    """The run of ``source`` on check sim ``robot`` (in the caller's transaction). Once that
    is committed, its agent starts and takes it (robots.agent: runs asked before it listened),
    and is sent its run.start too. Not attached to the owner's workbench consoles: a sealed
    run's output is not theirs to read."""
    run = Run.objects.create(
        program=program, program_name=program_name, language=language, source=source,
        robot=robot, owner=user, sealed=sealed,
    )  # fmt: skip
    name, message = robot.name, {**run.start_message(), "user": user.get_username()}
    transaction.on_commit(lambda: _begin(name, message))
    return run


def _begin(name: str, message: dict) -> None:
    sims.announce(name)
    begin_soon(_send_start, name, message)


async def _send_start(name: str, message: dict) -> None:
    try:
        await send_to_agent(name, "run.start", **message)
    except Exception:  # its agent takes it from the database when it starts
        log.warning("check sim %s: run.start not sent", name, exc_info=True)


def remove_after_run(name: str) -> bool:
    """Its run ended and its trace is saved: the check sim is removed (its agent is to stop);
    False if it is not a check sim, has a run going or waiting, or is removed already."""
    robot = Robot.objects.filter(name=name, checking=True, reaped__isnull=True).first()
    if robot is None or Run.objects.filter(robot=robot, state__in=Run.ONGOING).exists():
        return False
    return sims.remove(robot)


# -- what a check run did: its trace (the agent records it) -----------------------------------

OUTPUT_CAP = 256 * 1024  # bytes of a run's output kept in its trace; beyond, "truncated"
TRACE_FILE = "trace.json"
TIME_LIMIT_REASON = "time limit reached: %g s of sim time"  # a run's reason (stored in English)
WALL_LIMIT_REASON = "wall-clock time limit"  # what runbox.watch says, as the reason begins


class TraceRecorder:
    """One check run's trace, as its agent records it: the sim driver's (``start_trace`` once
    the robot stands at the start pose, ``take_trace`` at the end or at the time limit), the
    program's output lines at the sim's time, and how the run ended (classroom.trace reads
    it). Plain Python: nothing here waits.

    Its time 0, and its time limit's, is when the program first signs in on the Robot API
    (``signed_in``), not its launch: its interpreter's start (its box, its imports) takes
    real time, which a sim faster than real time multiplies, and a busy server more of it.
    The robot stands still until then (no drive without signing in), so the recording begun
    at the launch is begun afresh there, and the lines printed before get time 0. A program
    that never signs in (one that only prints) keeps the launch as its time 0: its time limit
    counts from there."""

    def __init__(self, driver, time_limit_s: float | None):
        self.driver = driver
        self.time_limit_s = time_limit_s
        self.started = False  # recording, from the launch at first
        self.signed = False  # from its program's first sign-in on the Robot API (signed_in)
        self.taken: dict | None = None
        self.end_t = 0.0
        self.output: list[list] = []
        self.output_bytes = 0
        self.truncated = False
        self.time_limit = False  # stopped at the time limit (sim time, or the wall clock's)

    @staticmethod
    def possible(driver) -> bool:
        return callable(getattr(driver, "start_trace", None))

    def start(self) -> None:
        """Its program is about to be launched (the robot at its start pose)."""
        self.driver.start_trace()
        self.started = True

    def signed_in(self) -> None:
        """Its program signed in on the Robot API: the first time, the trace and its time
        limit begin again now (the robot has not moved: nothing drives it without signing
        in); the output so far is at time 0."""
        if not self.started or self.signed or self.taken is not None:
            return
        self.signed = True
        self.driver.start_trace()
        for line in self.output:
            line[0] = 0.0

    def now(self) -> float:
        return self.driver.trace_time()

    def left(self) -> float | None:
        """Sim seconds left before the time limit (None: no limit, or not recording)."""
        if self.time_limit_s is None or not self.started or self.taken is not None:
            return None
        return self.time_limit_s - self.now()

    def lines(self, lines: list, skipped: int) -> None:
        """A batch of the program's output (runbox.supervisor's live lines)."""
        if not self.started or self.taken is not None:
            return
        if skipped:  # not sent live under a flood: the log has them, the trace does not
            self.truncated = True
        at = round(self.now(), 6)
        for _offset, tag, text in lines:
            if tag not in ("o", "e"):  # the box's own words ("s") are not the program's
                continue
            size = len(text.encode()) + 1
            if self.output_bytes + size > OUTPUT_CAP:
                self.truncated = True
                continue
            self.output.append([at, text])
            self.output_bytes += size

    def take(self) -> None:
        """The recording ends now (the run ended, or its time is up)."""
        if self.started and self.taken is None:
            self.end_t = self.now()
            self.taken = self.driver.take_trace()

    def document(self, state: str, exit_code: int | None, reason: str) -> dict | None:
        """The trace as saved (None: the program never started)."""
        self.take()
        if self.taken is None:
            return None
        time_limit = self.time_limit or reason.startswith(WALL_LIMIT_REASON)
        end = {
            "t": round(self.end_t, 6),
            "state": state if state in ("finished", "failed", "stopped") else "failed",
            "exit_code": exit_code,
            "reason": reason,
            "time_limit": time_limit,
        }
        truncated = bool(self.taken.get("truncated")) or self.truncated
        return {**self.taken, "output": self.output, "end": end, "truncated": truncated}


def save_trace(directory, doc: dict) -> None:
    """``trace.json`` in the run's folder, whole or not at all (written aside, then renamed)."""
    directory.mkdir(parents=True, exist_ok=True)
    aside = directory / f".{TRACE_FILE}.{os.getpid()}"
    aside.write_text(json.dumps(doc, separators=(",", ":"), ensure_ascii=False))
    os.replace(aside, directory / TRACE_FILE)


def read_trace(run: Run) -> dict | None:
    """A run's saved trace, or None (it never ran, or its trace could not be read)."""
    try:
        return json.loads((run.directory / TRACE_FILE).read_text())
    except (OSError, ValueError):
        return None
