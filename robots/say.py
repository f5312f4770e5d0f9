"""The "Say to the robot" box: a phrase typed for the robot's programs to hear with listen().

Three ways in, one rule: the robot page's and the workbench's box send it on the robot's
websocket (robots.consumers), the same box without scripts is a plain form POST (`robot_say`),
and scripts and tests use `POST /api/robots/{name}/hear` (robots.api). Whoever may drive the
robot may speak to it (as for driving by hand). The phrase goes to the robot's agent
(``robot.hear``), which gives it to the listen() waiting or keeps it briefly for the next
(robots.typed_speech).
"""

import json

from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.core.exceptions import PermissionDenied
from django.http import HttpRequest, HttpResponse
from django.shortcuts import render
from django.template.loader import render_to_string
from django.utils.translation import gettext as _
from django.views.decorators.http import require_http_methods

from robotide.redirects import back
from robots.bus import AgentUnavailable, ask_agent, ask_agent_sync, blocking
from robots.models import get_robot_for_user
from robots.typed_speech import KEEP_SECONDS, MAX_CHARS, MAX_WAITING


class SayRefused(Exception):
    """The phrase was not taken; the message, in the user's language, says why."""


def may_say(user, robot) -> bool:
    return robot.drivable_by(user)


def not_yours(robot) -> str:
    return _("Only %(who)s may speak to %(robot)s.") % {
        "who": robot.get_drive_by_display(),
        "robot": robot.name,
    }


def refusal(code: str, detail: str) -> str:
    """The agent's reason (robots.typed_speech.Refused.code) in the user's language."""
    reasons = {
        "empty": _("Type what the robot should hear."),
        "long": _("Say at most %(count)s characters at a time.") % {"count": MAX_CHARS},
        "nobody": _("No program is listening to the robot now."),
        "full": _("%(count)s phrases wait for a program to listen already: wait a moment.")
        % {"count": MAX_WAITING},
    }
    return reasons.get(code, detail)


async def say(robot, user, text: str, queue: bool = True) -> bool:
    """Say `text` to `robot` as `user` (who may: checked by the caller). True if a program's
    listen() was waiting and took it; False if it waits for the next listen(). SayRefused
    with the reason; AgentUnavailable if the robot's agent does not answer."""
    if not text.strip():  # no need to ask the agent
        raise SayRefused(refusal("empty", ""))
    reply = await ask_agent(
        robot.name, "robot.hear", text=text[: MAX_CHARS * 5], user=user.get_username(),
        queue=queue,
    )  # fmt: skip
    if "refused" in reply:
        raise SayRefused(refusal(reply["refused"], reply.get("detail", "")))
    return bool(reply["listening"])


say_sync = blocking(say)


def outcome(text: str, listening: bool) -> str:
    """What the box says once the robot's agent took the phrase."""
    if listening:
        return _("Said “%(text)s”: a program was listening.") % {"text": text}
    return _(
        "Said “%(text)s”: no program listens yet; the next listen() within %(seconds)s s hears it."
    ) % {"text": text, "seconds": f"{KEEP_SECONDS:g}"}


@login_required
@require_http_methods(["GET", "POST"])
def robot_say(request: HttpRequest, name: str) -> HttpResponse:
    """The box without scripts: a form POST, answered with a message on the page it came from;
    GET, the box on a page of its own (the robot's page, without scripts, reloads itself)."""
    robot = get_robot_for_user(request.user, name)
    if request.method == "GET":
        context = {"robot": robot, "may_drive": may_say(request.user, robot)}
        return render(request, "robots/say.html", {**context, "heard": _last_heard(robot)})
    if not may_say(request.user, robot):
        raise PermissionDenied(not_yours(robot))
    text = " ".join(request.POST.get("say", "").split())
    try:
        listening = say_sync(robot, request.user, text)
    except (SayRefused, AgentUnavailable) as exc:
        messages.error(request, str(exc))
    else:
        messages.info(request, outcome(text, listening))
    return back(request, "robot-detail", robot.name)


def _last_heard(robot) -> dict | None:
    try:
        return ask_agent_sync(robot.name, "robot.state", timeout=1.0).get("heard")
    except AgentUnavailable:
        return None


# -- on the robot's websocket (robots.consumers.RobotConsumer) -----------------------------


def parse_say(text: str | None) -> str | None:
    """The phrase of the box's message (htmx's ws-send: the form's fields as JSON, ``say``
    among them); None for any other message."""
    try:
        message = json.loads(text or "")
    except ValueError:
        return None
    said = message.get("say") if isinstance(message, dict) else None
    return " ".join(said.split()) if isinstance(said, str) else None


class SayOnSocket:
    """RobotConsumer's part: the box's phrases in, what listen() heard out (as HTML)."""

    async def say_typed(self, text: str) -> None:
        if not await self.still_allowed():
            return
        try:
            if not self.may_drive:
                raise SayRefused(not_yours(self.robot))
            listening = await say(self.robot, self.scope["user"], text)
        except (SayRefused, AgentUnavailable) as exc:
            await self.send(_say_status(str(exc), error=True))
            return
        await self.send(_say_status(outcome(text, listening)))

    async def robot_hearing(self, event):
        """A listen() began or ended, or heard something (HostServices._tell_hearing): what
        was heard is sent when it changed only (it is read out)."""
        if not await self.still_allowed():
            return
        last, part = event["last"], "listening"
        if last != getattr(self, "heard_sent", None):
            self.heard_sent, part = last, None
        await self.send(heard_note(last, event["listening"], oob=True, part=part))


def _say_status(text: str, error: bool = False) -> str:
    context = {"say_status": text, "say_error": error, "oob": True}
    return render_to_string("robots/_say_status.html", context)


def heard_note(last: dict | None, listening: bool, oob: bool = False, part=None) -> str:
    context = {"heard": last, "listening": listening, "oob": oob, "part": part}
    return render_to_string("robots/_heard.html", context)
