"""Emergency stops and resumes, from the web tier: who may, doing it, and the record of it.

Whoever may see a robot may press its emergency stop unless its owner chose otherwise
(``Robot.estop_by``); staff, its owner and whoever pressed it may resume (when others
pressed it too since it was last resumed: staff and its owner only). Every press and
resume is recorded (``RobotStop``: who, when, through what, the runs it ended), also when
the robot's agent could not be reached.

The record comes first. Presses and resumes of one robot are decided and recorded one at a
time, under a lock on the robot (``_one_at_a_time``): a press is in the records (and sent)
before its agent hears of it, so nobody may resume past a press still on its way. Messages
carry their record's id (ids grow in the records' order); the agent ignores a resume older
than the last press it heard, so a press recorded after it wins whichever message arrives
first. A press's reply (the runs it ended) is waited for after the lock is let go, then added
to its record.

Runs waiting at a press, or asked for during the stop, are held (robots.run_queue): a resume
lets the robot move but starts none of them, unless the one who resumes asks for it
(``start_held``); otherwise each starts when its owner starts it again (``start_again``). Once
a press or resume is committed, the robot's pages hear of it (its banner, live on the robot's
page and the workbench's panel: robots.consumers).
"""

import contextlib
import logging

from channels.layers import get_channel_layer
from django.core.exceptions import PermissionDenied
from django.db import transaction
from django.utils.translation import gettext as _
from django.utils.translation import gettext_lazy

from programs.models import Run
from robots import run_queue
from robots.bus import (
    AgentUnavailable,
    agent_reply_sync,
    blocking,
    request_agent_sync,
    tell_agent_sync,
)
from robots.models import Robot, RobotStop, robot_group

log = logging.getLogger(__name__)
WHO_RESUMES = gettext_lazy("staff, the robot's owner or whoever pressed it")  # the words everywhere


def press(user, robot: Robot, via: str) -> RobotStop:
    """The emergency stop; its record. AgentUnavailable (recorded) if the agent is away."""
    if not robot.stoppable_by(user):
        raise PermissionDenied(
            _("Only %(who)s may press %(robot)s's emergency stop.")
            % {"who": robot.get_estop_by_display(), "robot": robot.name}
        )
    with transaction.atomic():
        _one_at_a_time(robot)
        record = _record(robot, "estop", user, via)
        try:
            reply_to = request_agent_sync(
                robot.name, "robot.estop", by=user.get_username(), record=record.pk
            )
        except Exception as exc:  # the channel layer away: the press stands, recorded
            unsent = AgentUnavailable(str(exc))
        else:
            unsent = None
    _tell_pages(robot)
    try:
        if unsent is not None:
            raise unsent
        reply = agent_reply_sync(robot.name, reply_to)
    except AgentUnavailable as exc:
        _add_to(record, note=f"its agent was not reached: {exc}")
        raise
    _add_to(record, runs=_described(reply.get("runs", [])))
    return record


def may_resume(user, robot: Robot, pressed: RobotStop | None) -> bool:
    """Staff and the robot's owner; whoever pressed the stop while every press in force is
    theirs (pressing on top of a teacher's stop gives a student no say over it)."""
    if not user.is_authenticated:
        return False
    if robot.configurable_by(user):
        return True
    return (
        pressed is not None
        and pressed.user_id == user.pk
        and not RobotStop.pressed_by_others(robot.pk, user)
    )


def resume(user, robot: Robot, via: str, start_held: bool = False) -> int:
    """The robot may move again: how many runs were waiting, held. They stay held (each
    starts when started again) unless ``start_held``. Decided under the lock presses take,
    so a press recorded (even one whose agent has not answered yet) is seen. The agent is
    told once the resume is committed, with the record it follows: it ignores a resume older
    than the last press it heard (RobotAgent.resume_from), so a press recorded after this one
    keeps it stopped whichever message comes first."""
    with transaction.atomic():
        _one_at_a_time(robot)
        pressed = RobotStop.pressed(robot.pk)
        if not may_resume(user, robot, pressed):
            raise PermissionDenied(
                _("Only %(who)s may resume the emergency stop.") % {"who": WHO_RESUMES}
            )
        last = _record(robot, "resume", user, via) if pressed is not None else _last(robot)
        count = run_queue.held(robot)
    after = {"after": last.pk} if last is not None else {}
    with contextlib.suppress(Exception):  # the agent away: back, it finds it resumed
        tell_agent_sync(robot.name, "robot.resume", **after)
    _tell_pages(robot)
    if start_held and count:  # the one who resumes chose so: after the resume, in order
        _unhold_unless_pressed(robot, None)
    else:
        run_queue.queue_changed(robot)  # held runs' pages: they may be started again now
    return count


def start_again(user, robot: Robot, run: Run | None = None) -> int:
    """Held runs (all of the robot's, or ``run``) wait as any others, to start when the robot
    is free: how many. Not while its emergency stop is in force (decided under the lock
    presses take, so a press on its way is seen: its agent then holds them again)."""
    if run is not None and not run_queue.may_start_again(user, run):
        raise PermissionDenied(_("Only its owner, staff or the robot's owner start it again."))
    if run is None and not run_queue.may_manage(user, robot):
        raise PermissionDenied(_("Only staff and the robot's owner start every held run."))
    return _unhold_unless_pressed(robot, None if run is None else run.pk)


def _unhold_unless_pressed(robot: Robot, run_id: int | None) -> int:
    with transaction.atomic():
        _one_at_a_time(robot)
        if RobotStop.pressed(robot.pk) is not None:
            raise StillPressed(
                _("%(robot)s's emergency stop is in force: %(who)s may resume it first.")
                % {"robot": robot.name, "who": WHO_RESUMES}
            )
        return run_queue.unhold(robot, run_id)


class StillPressed(PermissionDenied):
    pass


def banner_context(user, robot: Robot) -> dict:
    """What the robot's stop banner (robots/_estop.html) says to ``user``: the stop in force,
    whether they may resume it, and how many runs it holds."""
    pressed = RobotStop.pressed(robot.pk)
    return {
        "robot": robot,
        "pressed": pressed,
        "may_resume": pressed is not None and may_resume(user, robot, pressed),
        "held_runs": run_queue.held(robot) if pressed is not None else 0,
        "who_resumes": WHO_RESUMES,
    }


def _tell_pages(robot: Robot) -> None:
    """A press or resume is committed: the robot's pages show it (robots.consumers)."""
    try:
        blocking(get_channel_layer().group_send)(robot_group(robot.name), {"type": "robot.stop"})
    except Exception:  # the channel layer away: the pages show it when loaded again
        log.exception("could not tell robot %s's pages of its stop", robot.name)


def recent(robot: Robot, count: int = 10) -> list[RobotStop]:
    return list(RobotStop.objects.filter(robot=robot)[:count])


def _one_at_a_time(robot: Robot) -> None:
    """Within a transaction: until it ends, no other press or resume of the robot is decided.
    PostgreSQL: the robot's row locked. SQLite: transactions begin IMMEDIATE (robotide.settings),
    taking the database's write lock, and select_for_update is a no-op there."""
    list(Robot.objects.select_for_update().filter(pk=robot.pk).values_list("pk", flat=True))


def _last(robot: Robot) -> RobotStop | None:
    return RobotStop.objects.filter(robot=robot).order_by("-pk").first()


def _record(robot, kind: str, user, via: str) -> RobotStop:
    return RobotStop.objects.create(
        robot=robot, kind=kind, user=user, username=user.get_username(), via=via
    )


def _add_to(record: RobotStop, runs=(), note: str = "") -> None:
    """What the agent answered (the runs it ended), or why it did not, added to a press's
    record once its reply came; only those fields, whatever else changed meanwhile."""
    record.runs, record.note = list(runs), note[:300]
    record.save(update_fields=["runs", "note"])


def _described(run_ids: list[int]) -> list[dict]:
    rows = Run.objects.filter(pk__in=run_ids).select_related("owner").order_by("pk")
    return [{"run": r.pk, "owner": r.owner.get_username(), "program": r.program_name} for r in rows]
