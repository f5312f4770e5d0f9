"""Emergency stops and resumes, from the web tier: who may, doing it, and the record of it.

Whoever may see a robot may press its emergency stop unless its owner chose otherwise
(``Robot.estop_by``); staff, its owner and whoever pressed it may resume (when others
pressed it too since it was last resumed: staff and its owner only). Every press and
resume is recorded (``RobotStop``: who, when, through what, the runs it ended), also when
the robot's agent could not be reached.
"""

import contextlib

from django.core.exceptions import PermissionDenied
from django.utils.translation import gettext as _

from programs.models import Run
from robots import run_queue
from robots.bus import AgentUnavailable, ask_agent_sync, tell_agent_sync
from robots.models import Robot, RobotStop


def press(user, robot: Robot, via: str) -> RobotStop:
    """The emergency stop; its record. AgentUnavailable (recorded) if the agent is away."""
    if not robot.stoppable_by(user):
        raise PermissionDenied(
            _("Only %(who)s may press %(robot)s's emergency stop.")
            % {"who": robot.get_estop_by_display(), "robot": robot.name}
        )
    try:
        reply = ask_agent_sync(robot.name, "robot.estop", by=user.get_username())
    except AgentUnavailable as exc:
        _record(robot, "estop", user, via, note=f"its agent was not reached: {exc}")
        raise
    return _record(robot, "estop", user, via, runs=_described(reply.get("runs", [])))


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


def resume(user, robot: Robot, via: str) -> int:
    """The robot may move again and its queue moves: how many runs were waiting, held."""
    pressed = RobotStop.pressed(robot.pk)
    if not may_resume(user, robot, pressed):
        raise PermissionDenied(
            _("Only staff, the robot's owner or whoever pressed its emergency stop resume it.")
        )
    if pressed is not None:
        _record(robot, "resume", user, via)
    count = run_queue.unhold(robot)
    with contextlib.suppress(Exception):  # the agent away: back, it finds it resumed
        tell_agent_sync(robot.name, "robot.resume")
    return count


def recent(robot: Robot, count: int = 10) -> list[RobotStop]:
    return list(RobotStop.objects.filter(robot=robot)[:count])


def _record(robot, kind: str, user, via: str, runs=(), note: str = "") -> RobotStop:
    return RobotStop.objects.create(
        robot=robot, kind=kind, user=user, username=user.get_username(), via=via,
        runs=list(runs), note=note[:300],
    )  # fmt: skip


def _described(run_ids: list[int]) -> list[dict]:
    rows = Run.objects.filter(pk__in=run_ids).select_related("owner").order_by("pk")
    return [{"run": r.pk, "owner": r.owner.get_username(), "program": r.program_name} for r in rows]
