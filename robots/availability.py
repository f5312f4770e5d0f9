"""Why someone has no robot to run programs on, and what to ask for.

A robot of some classes is open to those classes (robots.models.robots_for_user): a student
whose classes have none sees no robot at all, though robots exist. Every place that lists the
robots or starts a run says so in these words, rather than "No robots yet." or a bare 404.
"""

from django.db.models import Case, Q, Value, When
from django.http import Http404
from django.utils.translation import gettext as _

from robots import sims
from robots.models import Robot, get_robot_for_user, robots_for_user
from robots.runs import RunRefused


class NoRobotOpen(RunRefused):
    """A run asked of someone to whom no robot is open: its message says why."""


def no_robot_reason(user, visible=None) -> str:
    """'' when ``user`` may use some robot; else why none is open to them and what to do
    (a student: run on a sim of their own, where personal sims are on). ``visible``:
    robots_for_user(user), if the caller has it already."""
    if robots_for_user(user).exists() if visible is None else bool(visible):
        return ""
    sim = sims.offered(user) and not user.is_staff
    if not Robot.objects.filter(personal=False).exists():
        if user.is_staff:
            return _(
                "There are no robots yet. Add one in the administration (Robots, then Add"
                " robot; sim:// is a simulated robot)."
            )
        if sim:
            return _(
                "There are no robots yet. Ask your teacher to add one, or run on a simulated"
                " robot of your own (My sim on the workbench; POST /api/sims)."
            )
        return _("There are no robots yet. Ask your teacher to add one.")
    if user.is_staff:
        return _(
            "No robot is open to you: robots belong to classes, and you teach none of"
            " theirs. Add your class to a robot in the administration (Robots)."
        )
    if sim:
        return _(
            "No robot is open to you yet: robots belong to classes, and none of your classes"
            " has one. Ask your teacher to add a robot to your class, or run on a simulated"
            " robot of your own (My sim on the workbench; POST /api/sims)."
        )
    return _(
        "No robot is open to you yet: robots belong to classes, and none of your classes has"
        " one. Ask your teacher to add a robot to your class."
    )


def run_choices(user) -> dict:
    """What a page that starts runs offers ``user``: ``robots`` to run on (not others'
    personal sims: only their owners run on them; the user's own last), ``offer_sim`` (a
    "My sim (new)" choice: they have no sim and may make one), ``no_robot`` (why Run is
    disabled, if it is) and ``sim_note`` (no robot is open to them but a sim of their own)."""
    robots = list(
        robots_for_user(user)
        .filter(Q(personal=False) | Q(owner=user.pk))
        .order_by(Case(When(personal=True, then=Value(1)), default=Value(0)), "name")
    )
    offer = sims.offered(user) and not any(robot.personal for robot in robots)
    reason = no_robot_reason(user, robots)
    return {
        "robots": robots,
        "offer_sim": offer,
        "my_sim": sims.MY_SIM,
        "no_robot": "" if offer else reason,
        "sim_note": reason if offer else "",
    }


def robot_to_run_on(user, name: str) -> Robot:
    """The robot named, as get_robot_for_user; NoRobotOpen saying why when no robot at all is
    open to ``user`` (a 404 would say nothing of it). ``sims.MY_SIM``: the user's own sim,
    made if they have none (sims.SimRefused past a cap)."""
    if name == sims.MY_SIM:
        return sims.my_sim(user)
    try:
        return get_robot_for_user(user, name)
    except Http404:
        if reason := no_robot_reason(user):
            raise NoRobotOpen(reason) from None
        raise
