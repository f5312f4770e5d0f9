"""Why someone has no robot to run programs on, and what to ask for.

A robot of some classes is open to those classes (robots.models.robots_for_user): a student
whose classes have none sees no robot at all, though robots exist. Every place that lists the
robots or starts a run says so in these words, rather than "No robots yet." or a bare 404.
"""

from django.http import Http404
from django.utils.translation import gettext as _

from robots.models import Robot, get_robot_for_user, robots_for_user
from robots.runs import RunRefused


class NoRobotOpen(RunRefused):
    """A run asked of someone to whom no robot is open: its message says why."""


def no_robot_reason(user, visible=None) -> str:
    """'' when ``user`` may use some robot; else why none is open to them and what to do.
    ``visible``: robots_for_user(user), if the caller has it already."""
    if robots_for_user(user).exists() if visible is None else bool(visible):
        return ""
    if not Robot.objects.exists():
        if user.is_staff:
            return _(
                "There are no robots yet. Add one in the administration (Robots, then Add"
                " robot; sim:// is a simulated robot)."
            )
        return _("There are no robots yet. Ask your teacher to add one.")
    if user.is_staff:
        return _(
            "No robot is open to you: robots belong to classes, and you teach none of"
            " theirs. Add your class to a robot in the administration (Robots)."
        )
    return _(
        "No robot is open to you yet: robots belong to classes, and none of your classes has"
        " one. Ask your teacher to add a robot to your class."
    )


def robot_to_run_on(user, name: str) -> Robot:
    """The robot named, as get_robot_for_user; NoRobotOpen saying why when no robot at all is
    open to ``user`` (a 404 would say nothing of it)."""
    try:
        return get_robot_for_user(user, name)
    except Http404:
        if reason := no_robot_reason(user):
            raise NoRobotOpen(reason) from None
        raise
