"""Reset: a simulated robot put back at its world's start pose (or at a pose given), stopped,
with a fresh odometer, battery and path; and the robot setting ``start_each_run``.

Three ways in, one rule: the Reset on the robot's page (a form: scripts or not) and on the
workbench's robot panel (htmx), and ``POST /api/robots/{name}/reset`` (robots.api), with a pose
``{"x": m, "y": m, "theta": rad}`` in the frame of ``sensors()["position"]`` or none. Whoever
may drive the robot may reset it. The robot's agent does it (``robot.reset``,
robots.start_pose, which says what a reset does to runs going on and to the next run).
"""

import math

from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.core.exceptions import PermissionDenied
from django.http import HttpRequest, HttpResponse
from django.shortcuts import render
from django.utils.translation import gettext as _
from django.utils.translation import pgettext
from django.views.decorators.http import require_POST

from rhal.registry import driver_class
from robotide.redirects import back
from robots.bus import AgentUnavailable, ask_agent, blocking
from robots.models import get_robot_for_user
from robots.sims import touch

SETTING = "start_each_run"


class ResetRefused(Exception):
    """Not reset; the message, in the user's language, says why. ``status``: the API's."""

    def __init__(self, message: str, status: int = 409):
        super().__init__(message)
        self.status = status


def may_reset(user, robot) -> bool:
    return robot.drivable_by(user)


def not_yours(robot) -> str:
    return _("Only %(who)s may reset %(robot)s.") % {
        "who": robot.get_drive_by_display(),
        "robot": robot.name,
    }


def refusal(reply: dict) -> ResetRefused:
    """The agent's refusal (robots.start_pose) in the user's language."""
    code, detail = reply.get("refused"), reply.get("detail", "")
    if code == "not_sim":
        return ResetRefused(_("Only simulated robots can be reset."))
    if code == "busy":
        said = _(
            "Run #%(run)s of %(user)s is going on the robot: it may be reset by its owner,"
            " staff, or once the run has ended."
        ) % {"run": reply.get("run"), "user": reply.get("user") or "?"}
        return ResetRefused(said)
    if code == "pose":  # the simulator's own plain words
        return ResetRefused(_("That pose cannot be used: %(why)s") % {"why": detail}, 422)
    return ResetRefused(detail or _("The robot was not reset."))


async def reset(robot, user, pose=None, override: bool = False) -> None:
    """Reset ``robot`` as ``user`` (who may drive it: checked by the caller), at ``pose``
    ((x, y, theta)) or the world's start pose. ``override``: the user is staff or its owner.
    ResetRefused with the reason; AgentUnavailable if its agent does not answer."""
    asked = {"by": user.get_username(), "override": override}
    if pose is not None:
        asked["pose"] = [float(value) for value in pose]
    reply = await ask_agent(robot.name, "robot.reset", **asked)
    if not reply.get("ok"):
        raise refusal(reply)


_reset_sync = blocking(reset)


def reset_sync(robot, user, pose=None) -> None:
    """``reset`` from a view: whether the user may override a run is read here."""
    touch(robot)  # a personal sim someone resets is in use (robots.sims: not idle)
    _reset_sync(robot, user, pose, override=robot.configurable_by(user))


def done(robot, pose) -> str:
    if pose is None:
        return _("%(robot)s is back at its start.") % {"robot": robot.name}
    x, y, theta = pose
    said = _("%(robot)s is at x %(x)s m, y %(y)s m, θ %(theta)s rad; the next run starts there.")
    return said % {"robot": robot.name, "x": f"{x:g}", "y": f"{y:g}", "theta": f"{theta:g}"}


def can_reset_driver(url: str) -> bool:
    """Whether a robot with this URL could be reset (its driver has a reset): for the setting."""
    try:
        return callable(getattr(driver_class(url), "reset", None))
    except Exception:  # no driver, or one that does not load here
        return False


def setting_row(robot) -> dict | None:
    """``start_each_run`` as the robot page's settings card shows it; None for a robot that
    cannot be reset."""
    if not can_reset_driver(robot.url):
        return None
    if SETTING in robot.settings:
        return {"value": robot.settings[SETTING] is True, "source": _("set here")}
    return {"value": False, "source": pgettext("source of a value", "default")}


def check_setting(settings: dict) -> None:
    """ValueError unless ``start_each_run``, if set, is true or false."""
    if SETTING in settings and not isinstance(settings[SETTING], bool):
        raise ValueError(_("%(name)s must be true or false") % {"name": SETTING})


# -- the page's form and the panel's button ------------------------------------------------


def pose_from(data) -> tuple[float, float, float] | None:
    """(x, y, theta) from a form's x, y and theta: all three or none; ValueError else."""
    given = [str(data.get(name, "")).strip().replace(",", ".") for name in ("x", "y", "theta")]
    if not any(given):
        return None
    try:
        pose = tuple(float(value) for value in given)
    except ValueError:
        raise ValueError(_("Give x, y and θ as numbers, all three or none.")) from None
    if not all(math.isfinite(value) for value in pose):
        raise ValueError(_("Give x, y and θ as numbers, all three or none."))
    return pose


@login_required
@require_POST
def robot_reset(request: HttpRequest, name: str) -> HttpResponse:
    """The Reset: a form POST answered with a message on the page it came from; with htmx, the
    outcome as a line of text for the button's status."""
    robot = get_robot_for_user(request.user, name)
    if not may_reset(request.user, robot):
        raise PermissionDenied(not_yours(robot))
    try:
        pose = pose_from(request.POST)
        reset_sync(robot, request.user, pose)
    except (ValueError, ResetRefused, AgentUnavailable) as exc:
        outcome = {"error": str(exc)}
    else:
        outcome = {"said": done(robot, pose)}
    if request.htmx:
        return render(request, "robots/_reset_status.html", outcome)
    if "error" in outcome:
        messages.error(request, outcome["error"])
    else:
        messages.success(request, outcome["said"])
    return back(request, "robot-detail", robot.name)
