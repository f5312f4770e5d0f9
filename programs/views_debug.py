"""The page's debugger commands: POST /runs/ID/debug (programs/clients/PROTOCOL.md, "The
debugger"). The run's owner only; the command goes to the run's agent on its channel
(robots.debugger takes it), which tells the run's viewers what the debugger does."""

import json

from django.contrib.auth.decorators import login_required
from django.http import HttpRequest, JsonResponse
from django.utils.translation import gettext as _
from django.views.decorators.http import require_POST

from programs import debug_spec
from programs.access import get_run_for_user
from programs.models import Run
from robots.bus import tell_agent_sync

MAX_BODY_BYTES = 256 * 1024  # 200 breakpoints and 50 watches of 500 characters fit


@login_required
@require_POST
def run_debug(request: HttpRequest, run_id: int) -> JsonResponse:
    run = get_run_for_user(request.user, run_id)  # 404 for who may not see it
    if run.owner_id != request.user.pk:
        return _error(_("Only who started this run may debug it."), 403)
    if run.debug is None:
        return _error(_("This run is not under the debugger."), 409)
    if run.state not in Run.ONGOING:
        return _error(_("This run has ended."), 409)
    body, why = read_command(request)
    if why is not None:
        return _error(why, 400)
    try:
        tell_agent_sync(run.robot.name, "run.debug", run_id=run.pk, **body)
    except Exception as exc:  # ChannelFull, or the channel layer away
        why = _("the agent of robot %(robot)s cannot be reached (%(why)s)") % {
            "robot": repr(run.robot.name),
            "why": type(exc).__name__,
        }
        return _error(why, 503)
    return JsonResponse({"sent": True}, status=202)


def read_command(request: HttpRequest) -> tuple[dict, str | None]:
    """The command, and its breakpoints and watches if given, checked (programs.debug_spec):
    (body, None), or ({}, why not)."""
    if len(request.body) > MAX_BODY_BYTES:
        return {}, _("The request is too large.")
    try:
        body = json.loads(request.body)
    except (ValueError, RecursionError):
        return {}, _("The request is not JSON.")
    if not isinstance(body, dict) or set(body) - {"command", "breakpoints", "watches"}:
        return {}, _("The request must be an object with a command, and optionally breakpoints"
                     " and watches.")  # fmt: skip
    checks = {
        "command": debug_spec.check_command,
        "breakpoints": debug_spec.check_breakpoints,
        "watches": debug_spec.check_watches,
    }
    for name, check in checks.items():
        if (name in body or name == "command") and (why := check(body.get(name))) is not None:
            return {}, f"{name}: {why}"
    return body, None


def _error(why: str, status: int) -> JsonResponse:
    return JsonResponse({"error": why}, status=status)
