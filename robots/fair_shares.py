"""Fair shares of the machine: how many runs one user, and one robot, have going at once.

A user has at most ``RUNS_PER_USER`` runs going on all robots together (staff:
``RUNS_PER_STAFF``; 0: no limit), and a robot runs at most its ``settings.runs_at_once``
programs, whoever's, and never more than its agent's isolation allows at once (a rootless box
without a run-wide cgroup: one). The runs of exercises' checks (runs on check sims,
robots.check_sims) go at most ``CHECK_RUNS_AT_ONCE`` at once on the whole server, whoever's,
and neither count towards nor wait for their owner's ``RUNS_PER_USER`` (a student has one
Check going at most; its variants' runs go together).
A run beyond a limit waits ``queued`` in its robot's queue (robots.run_queue) with the reason
in its ``reason``, shown on its page, the robot's page and in the API; when a run ends, the
agents holding runs that waited for it look again.

The decision is the database's, so that it holds with several agents (fleet mode: one process
a robot) and web workers at once: a run is *admitted* in one transaction that locks its
owner's row (and its robot's, for the robot's limit), counts what is going, and marks the run
admitted (``started`` set) before the lock is let go; two agents cannot both start a user's
third run. A check run's admission locks every live check sim's row too (in the order of their
ids, before its own robot's), so that the server-wide count holds. SQLite serialises such
transactions anyway (IMMEDIATE).
"""

from __future__ import annotations

import enum
import re
from dataclasses import dataclass

from django.conf import settings
from django.contrib.auth import get_user_model
from django.db import models, transaction
from django.utils import timezone
from django.utils.translation import gettext as _
from django.utils.translation import ngettext

from programs.models import Run
from robots.models import Robot

#: Every reason a run waits for a share begins so (a run waiting for the robot has none).
WAITING = "waiting: "


class Admission(enum.Enum):
    ADMITTED = "admitted"  # it may start now
    QUEUED = "queued"  # it was starting; it waits in its robot's queue now
    WAITS = "waits"  # it was queued; it waits on (its reason says for what, now)
    GONE = "gone"  # it no longer waits to start: stopped, failed or taken meanwhile


@dataclass(frozen=True)
class Decision:
    outcome: Admission
    reason: str = ""  # why it waits (QUEUED, WAITS)
    rank: int | None = None  # its place in line (QUEUED)
    changed: bool = False  # its reason is not what it was (WAITS)

    @property
    def robot_full(self) -> bool:
        """It waits for the robot's limit: no other run of the robot may start now either."""
        return self.reason.startswith(ROBOT_FULL)


def user_limit(user) -> int | None:
    """Runs ``user`` may have going at once on all robots; None: no limit."""
    staff = user.is_staff or user.is_superuser
    limit = settings.RUNS_PER_STAFF if staff else settings.RUNS_PER_USER
    return limit or None


def robot_setting(robot_settings: dict) -> int | None:
    """A robot's ``runs_at_once``: a whole number, 0 or none for no limit; ValueError else."""
    value = robot_settings.get("runs_at_once")
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int) or value < 0:
        raise ValueError(
            _("runs_at_once must be a whole number of runs, 0 or more (0: no limit), not %(v)s")
            % {"v": repr(value)}
        )
    return value or None


def robot_limit(robot: Robot, box_cap: int | None = None) -> int | None:
    """Runs ``robot`` has going at once: the lower of its setting and what its agent's
    isolation allows (``box_cap``, else as its agent last said); None: no limit."""
    try:
        setting = robot_setting(robot.settings)
    except ValueError:  # refused when saved; a row edited by hand: no limit of its own
        setting = None
    if box_cap is None:
        box_cap = robot.isolation_runs_at_once
    caps = [cap for cap in (setting, box_cap) if cap]
    return min(caps) if caps else None


def going() -> models.Q:
    """Runs that take a share: running, or admitted and on their way (an agent's claim or
    an admission marks it); not those asked and not decided on yet, nor those queued."""
    taken = models.Q(state=Run.State.RUNNING) | models.Q(pid__isnull=False)
    # state IN (...) first: the state index finds the few runs not ended among many.
    return models.Q(state__in=Run.ACTIVE) & (taken | models.Q(started__isnull=False))


def is_share_wait(reason: str) -> bool:
    return reason.startswith(WAITING)


USER_WAIT = f"{WAITING}you already have"


def user_reason(count: int, limit: int) -> str:
    # Stored in English, as run reasons are (data, like the run's log).
    runs = "run" if count == 1 else "runs"
    return f"{USER_WAIT} {count} {runs} going (your limit is {limit})"


ROBOT_FULL = f"{WAITING}the robot runs at most "


def robot_reason(limit: int) -> str:
    programs = "program" if limit == 1 else "programs"
    return f"{ROBOT_FULL}{limit} {programs} at once"


def admit(run_id: int, box_cap: int | None = None) -> Decision:
    """Decide whether run ``run_id`` may start now, for its first start (it is ``starting``,
    untaken) or from its robot's queue (``queued``). ``box_cap``: what the deciding agent's
    isolation allows at once."""
    with transaction.atomic():
        # The owner's row, then the robot's, always in this order (no deadlock between two
        # admissions): each locked alone, not the run's row with it.
        users = get_user_model().objects.select_for_update(of=("self",))
        owner = users.filter(runs__pk=run_id).first()
        checking = Robot.objects.filter(runs__pk=run_id, checking=True).exists()
        if checking:  # the server's count of check runs: every check sim's row, in order
            lock = Robot.objects.select_for_update(of=("self",)).filter(checking=True)
            list(lock.filter(reaped__isnull=True).order_by("pk").values_list("pk", flat=True))
        robot = Robot.objects.select_for_update(of=("self",)).filter(runs__pk=run_id).first()
        run = Run.objects.filter(pk=run_id).first()  # as it is now, under the locks
        if owner is None or robot is None or run is None:
            return Decision(Admission.GONE)
        queued = run.state == Run.State.QUEUED
        if not queued and not (run.state == Run.State.STARTING and run.pid is None):
            return Decision(Admission.GONE)
        if not queued and run.started is not None:
            return Decision(Admission.ADMITTED)  # admitted already: its claim decides the rest
        # A check run is paced by the server's count alone: its student has one Check going
        # at most (classroom.checking), and its variants' runs go together, not in turns.
        per_user = None if checking else user_limit(owner)
        reason = _over_limit(run, per_user, robot_limit(robot, box_cap))
        if reason is None and checking:
            reason = _over_check_limit(run)
        if reason is None:
            return Decision(_admitted(run, queued))
        if queued:
            Run.objects.filter(pk=run_id, state=Run.State.QUEUED).update(reason=reason)
            return Decision(Admission.WAITS, reason, changed=reason != run.reason)
        rank = Run.enqueue(run_id, reason)
        if rank is None:
            return Decision(Admission.GONE)
        return Decision(Admission.QUEUED, reason, rank)


def _over_limit(run: Run, per_user: int | None, per_robot: int | None) -> str | None:
    """Why ``run`` may not start now, or None."""
    if per_user is None and per_robot is None:
        return None
    # A user's own runs, not their checks' (counted apart: _over_check_limit)
    mine = models.Q(owner_id=run.owner_id, robot__checking=False)
    robots = models.Q(robot_id=run.robot_id)
    counts = (
        Run.objects.filter(going() & (mine | robots))
        .exclude(pk=run.pk)
        .aggregate(user=models.Count("pk", filter=mine), robot=models.Count("pk", filter=robots))
    )
    if per_user is not None and counts["user"] >= per_user:
        return user_reason(counts["user"], per_user)
    if per_robot is not None and counts["robot"] >= per_robot:
        return robot_reason(per_robot)
    return None


def _over_check_limit(run: Run) -> str | None:
    """Why check run ``run`` may not start now (the server's CHECK_RUNS_AT_ONCE), or None."""
    limit = settings.CHECK_RUNS_AT_ONCE
    going_now = Run.objects.filter(going(), robot__checking=True).exclude(pk=run.pk).count()
    return check_reason(limit) if going_now >= limit else None


def _admitted(run: Run, queued: bool) -> Admission:
    now = timezone.now()
    if queued:  # Run.unqueue's step, admitted in the same write
        changed = Run.objects.filter(pk=run.pk, state=Run.State.QUEUED).update(
            state=Run.State.STARTING, queue_position=None, reason="", pid=None, started=now
        )
    else:
        changed = Run.objects.filter(
            pk=run.pk, state=Run.State.STARTING, pid__isnull=True, started__isnull=True
        ).update(started=now)
    return Admission.ADMITTED if changed else Admission.GONE


CHECKS_FULL = f"{WAITING}the server runs at most "


def check_reason(limit: int) -> str:
    runs = "check run" if limit == 1 else "check runs"
    return f"{CHECKS_FULL}{limit} {runs} at once"


def reason_shown(reason: str, mine: bool) -> str:
    """A share wait's reason (stored in English, like the run's log) in the reader's language,
    said to the run's owner (``mine``) or, for staff and the robot's owner, about them."""
    if found := _USER_WAIT_STORED.fullmatch(reason):
        count, limit = int(found[1]), int(found[2])
        if mine:
            words = ngettext(
                "waiting: you already have %(count)s run going (your limit is %(limit)s)",
                "waiting: you already have %(count)s runs going (your limit is %(limit)s)",
                count,
            )
        else:
            words = ngettext(
                "waiting: its owner already has %(count)s run going (their limit is %(limit)s)",
                "waiting: its owner already has %(count)s runs going (their limit is %(limit)s)",
                count,
            )
        return words % {"count": count, "limit": limit}
    if found := _ROBOT_FULL_STORED.fullmatch(reason):
        limit = int(found[1])
        return ngettext(
            "waiting: the robot runs at most %(limit)s program at once",
            "waiting: the robot runs at most %(limit)s programs at once",
            limit,
        ) % {"limit": limit}
    if found := _CHECKS_FULL_STORED.fullmatch(reason):
        limit = int(found[1])
        return ngettext(
            "waiting: the server checks at most %(limit)s run at once, everyone's",
            "waiting: the server checks at most %(limit)s runs at once, everyone's",
            limit,
        ) % {"limit": limit}
    return reason


# What user_reason and robot_reason store, read back by reason_shown.
_USER_WAIT_STORED = re.compile(re.escape(USER_WAIT) + r" (\d+) runs? going \(your limit is (\d+)\)")
_ROBOT_FULL_STORED = re.compile(re.escape(ROBOT_FULL) + r"(\d+) programs? at once")
_CHECKS_FULL_STORED = re.compile(re.escape(CHECKS_FULL) + r"(\d+) check runs? at once")


def robots_to_look_again(run_id: int) -> list[str]:
    """A run ended: the robots other than its own whose queues hold runs of its owner waiting
    for a share (their agents look again; its own agent does anyway)."""
    ids = Run.objects.filter(pk=run_id).values_list("owner_id", "robot_id", "robot__checking")
    ids = ids.first()
    if ids is None:
        return []
    waiting = Run.objects.filter(
        owner_id=ids[0], state=Run.State.QUEUED, reason__startswith=WAITING
    ).exclude(robot_id=ids[1])
    robots = set(waiting.values_list("robot__name", flat=True))
    if ids[2]:  # a check run: the first check runs waiting for the server's count (the others
        # look again within run_queue.SHARES_LOOK; told all, every agent would ask at once)
        checks = Run.objects.filter(state=Run.State.QUEUED, reason__startswith=CHECKS_FULL)
        first = checks.order_by("pk").values_list("robot__name", flat=True)
        robots.update(first[: settings.CHECK_RUNS_AT_ONCE])
    return sorted(robots)


@dataclass(frozen=True)
class InForce:
    """What the robot's page and the API say is in force, for one viewer."""

    runs_per_user: int | None  # the viewer's own limit, on all robots
    yours_going: int
    runs_at_once: int | None  # the robot's, whoever's runs
    robot_going: int

    def as_dict(self) -> dict:
        return {
            "runs_per_user": self.runs_per_user,
            "yours_going": self.yours_going,
            "runs_at_once": self.runs_at_once,
            "robot_going": self.robot_going,
        }

    @property
    def user_words(self) -> str:
        if self.runs_per_user is None:
            return _("You may have any number of runs going at once.")
        return ngettext(
            "You may have %(limit)s run going at once, on all robots; more wait in line.",
            "You may have %(limit)s runs going at once, on all robots; more wait in line.",
            self.runs_per_user,
        ) % {"limit": self.runs_per_user}

    @property
    def robot_words(self) -> str:
        if self.runs_at_once is None:
            return _("This robot runs any number of programs at once.")
        return ngettext(
            "This robot runs at most %(limit)s program at once, whoever's.",
            "This robot runs at most %(limit)s programs at once, whoever's.",
            self.runs_at_once,
        ) % {"limit": self.runs_at_once}


def in_force(user, robot: Robot) -> InForce:
    runs = Run.objects.filter(going())
    mine = runs.filter(owner_id=user.pk).count() if user.is_authenticated else 0
    per_user = user_limit(user) if user.is_authenticated else None
    return InForce(per_user, mine, robot_limit(robot), runs.filter(robot=robot).count())


def in_force_of(user, robot: Robot) -> InForce:
    """``in_force``, asked once for a robot row however many fields of an answer read it."""
    found = getattr(robot, "_shares_in_force", None)
    if found is None or found[0] != user.pk:
        found = robot._shares_in_force = (user.pk, in_force(user, robot))
    return found[1]
