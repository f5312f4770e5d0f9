"""The workbench's requests: save, save and run, and the robot panel beside the editor.

The workbench page itself is the program page (views.program_edit); without scripts its form
posts there as before. With scripts, its buttons and keys come here and stay on the page: a
save answers JSON, a run answers the console (which then streams the run over its websocket),
the panel answers the chosen robot's live view.

A save names the revision the editor started from; if someone saved another since, nothing
is overwritten: the answer is 409 with the difference, and the page asks what to do. While
the user types, the page keeps a draft here every few seconds (one per user and program);
the page offers it back when it is newer than what was saved.
"""

from __future__ import annotations

import difflib
import json

from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.core.exceptions import PermissionDenied
from django.db import transaction
from django.http import HttpRequest, HttpResponse, JsonResponse
from django.shortcuts import redirect, render
from django.utils import timezone
from django.utils.translation import gettext as _
from django.views.decorators.http import require_GET, require_POST

from programs import blocks_worker, debug_spec
from programs.access import EDIT, can, get_program_for_user
from programs.forms import EditProgramForm, free_name, too_large
from programs.models import MAX_SOURCE_BYTES, Draft, Program, Revision
from robotide.security import plain_number
from robots import sims
from robots.availability import robot_to_run_on
from robots.models import get_robot_for_user
from robots.runs import RunRefused, start_run
from robots.views import robot_state_context


class Conflict(Exception):
    """Someone saved the program since this editor opened it."""

    def __init__(self, program: Program, base: int, source: str) -> None:
        latest = program.revisions.first()
        self.latest = latest.number if latest else 0
        self.diff = "".join(
            difflib.unified_diff(
                (latest.source if latest else "").splitlines(keepends=True),
                source.splitlines(keepends=True),
                _("revision %(number)s (saved since you opened it)") % {"number": self.latest},
                _("your text"),
            )
        )
        super().__init__(f"revision {self.latest} was saved after revision {base}")


@login_required
@require_POST
def program_save(request: HttpRequest, program_id: int) -> JsonResponse:
    program = get_program_for_user(request.user, program_id)
    try:
        revision = _save(request, program)
    except Conflict as conflict:
        return _conflict(conflict)
    except ValueError as exc:
        return JsonResponse({"error": str(exc)}, status=400)
    return JsonResponse({"revision": revision, "saved": True})


@login_required
@require_POST
def program_start(request: HttpRequest, program_id: int) -> HttpResponse:
    """Save (when the user may) and run; the answer is the console for the new run."""
    program = get_program_for_user(request.user, program_id)
    try:
        debug = debug_spec_of(request)  # Debug: checked before anything is saved
        revision = _save(request, program) if can(request.user, EDIT, program) else None
        # No robot open to the user: why, not a 404 (robots.availability.NoRobotOpen).
        robot = robot_to_run_on(request.user, request.POST.get("robot", ""))
        run = start_run(program, robot, request.user, debug=debug)
    except Conflict as conflict:
        return _conflict(conflict)
    except (ValueError, RunRefused, PermissionDenied) as exc:
        return JsonResponse({"error": str(exc)}, status=400)
    # The page's console websocket, if open, already follows the run (robots.runs); this
    # console opens the run's own websocket, for a page whose console's is not open.
    response = render(request, "programs/_console.html", {"run": run})
    response["X-Run"] = str(run.pk)
    response["X-Robot"] = robot.name  # "My sim" (sims.MY_SIM) is a robot of its own now
    if revision is not None:
        response["X-Revision"] = str(revision)
    return response


def debug_spec_of(request: HttpRequest) -> dict | None:
    """Debug (action "debug"): the breakpoints and watches it starts with, from the field
    `debug` (JSON, programs.debug_spec); None for Run. ValueError if they are not right."""
    if request.POST.get("action") != "debug":
        return None
    text = request.POST.get("debug", "")
    if not text:
        return {"breakpoints": [], "watches": []}
    try:
        spec = json.loads(text)
    except (ValueError, RecursionError):
        raise ValueError(_("The debugger's breakpoints and watches are not JSON.")) from None
    if (why := debug_spec.check_spec(spec)) is not None:
        raise ValueError(_("The debugger's breakpoints and watches: %(why)s") % {"why": why})
    return spec


@login_required
@require_GET
def program_panel(request: HttpRequest, program_id: int) -> HttpResponse:
    """The chosen robot's live view for the side panel: camera, readings, what is shown."""
    get_program_for_user(request.user, program_id)
    name = request.GET.get("robot", "")
    if name == sims.MY_SIM:  # "My sim (new)": made when it first runs, not when looked at
        return render(request, "programs/_sim_to_make.html")
    robot = get_robot_for_user(request.user, name)
    sims.touch(robot)  # a personal sim watched is in use
    return render(request, "programs/_panel.html", robot_state_context(robot, request.user))


@login_required
@require_POST
def program_draft(request: HttpRequest, program_id: int) -> HttpResponse:
    """Keep the editor's text as this user's draft, or (``discard``) forget it."""
    program = get_program_for_user(request.user, program_id, EDIT)
    if request.POST.get("discard"):
        forget_draft(request.user, program)
        return HttpResponse(status=204)
    form = EditProgramForm(request.POST)
    if not form.is_valid():
        return JsonResponse({"error": "; ".join(_errors(form))}, status=400)
    base = request.POST.get("base_revision", "")
    Draft.objects.update_or_create(
        user=request.user,
        program=program,
        defaults={
            "source": form.cleaned_data["source"],
            "language": form.cleaned_data["language"],
            "base_revision": plain_number(base) or 0,
            "updated": timezone.now(),
        },
    )
    return HttpResponse(status=204)


def draft_to_offer(user, program: Program) -> Draft | None:
    """The user's draft of the program, if it holds anything the saved program does not."""
    draft = Draft.objects.filter(user=user, program=program).first()
    return draft if draft is not None and draft.newer_than_saved() else None


def forget_draft(user, program: Program) -> None:
    Draft.objects.filter(user=user, program=program).delete()


def _errors(form) -> list[str]:
    return [error for errors in form.errors.values() for error in errors]


@login_required
@require_POST
def blocks_python(request: HttpRequest, program_id: int) -> JsonResponse:
    """The Python a blocks text runs as, for the read-only pane beside the blocks: made in a
    worker process (programs.blocks_worker), from no more than a program may be."""
    get_program_for_user(request.user, program_id)
    source = request.POST.get("source", "")
    if len(source.encode()) > MAX_SOURCE_BYTES:
        return JsonResponse({"error": too_large()}, status=413)
    if not source.strip():
        return JsonResponse({"python": _("# No blocks yet: drag some from the toolbox.") + "\n"})
    try:
        python, blocks = blocks_worker.to_python_mapped(source)
        # blocks: the block each line is made for, to mark the one a run's error names
        return JsonResponse({"python": python, "blocks": blocks})
    except blocks_worker.BlocksBusy as exc:
        return JsonResponse({"error": str(exc)}, status=503)
    except ValueError as exc:  # a BlocksError: its message names the block
        return JsonResponse({"error": str(exc)}, status=422)


@login_required
@require_POST
def blocks_as_python(request: HttpRequest, program_id: int) -> HttpResponse:
    """A new Python program of the user's from the blocks as they are in the editor."""
    program = get_program_for_user(request.user, program_id)
    source = request.POST.get("source", program.source)
    try:
        if len(source.encode()) > MAX_SOURCE_BYTES:
            raise ValueError(too_large())
        code = blocks_worker.to_python(source)
    except ValueError as exc:
        messages.error(request, _("These blocks do not make a program yet: %(why)s") % {"why": exc})
        return redirect("program-edit", program.pk)
    name = free_name(request.user, _("%(name)s (Python)") % {"name": program.name})
    copy = Program.objects.create(owner=request.user, name=name, language="python")
    copy.save_source(code, request.user)
    messages.success(request, _("Copied as the Python program %(name)s.") % {"name": copy.name})
    return redirect("program-edit", copy.pk)


def _save(request: HttpRequest, program: Program) -> int:
    """Save the posted text as a new revision; its number. ValueError for a bad form."""
    if not can(request.user, EDIT, program):
        raise PermissionDenied(read_only())
    form = EditProgramForm(request.POST)
    if not form.is_valid():
        raise ValueError("; ".join(_errors(form)))
    return save_edit(request, program, form.cleaned_data).number


def read_only() -> str:
    return _("This program is shared with you read-only: save a copy.")


def save_edit(request: HttpRequest, program: Program, data: dict) -> Revision:
    """The editor's text as a new revision (Conflict if another was saved since the one it
    opened); the user's draft of it ends. One step for the workbench and the plain form."""
    with transaction.atomic():
        # Two saves at once: the second checks its base against the first's revision.
        Program.objects.select_for_update().filter(pk=program.pk).first()
        check_base(program, request.POST.get("base_revision", ""), data["source"])
        program.language = data["language"]
        revision = program.save_source(data["source"], request.user)
        forget_draft(request.user, program)
    return revision


def check_base(program: Program, base: str, source: str) -> None:
    """Conflict if another revision was saved since ``base`` (the one the editor opened) and
    this text would overwrite it; no base (an old page, the API) is no conflict."""
    latest, number = program.revisions.first(), plain_number(base)
    if number is not None and latest is not None and latest.number != number:
        if latest.source != source:
            raise Conflict(program, number, source)


def _conflict(conflict: Conflict) -> JsonResponse:
    return JsonResponse(
        {"conflict": True, "revision": conflict.latest, "diff": conflict.diff}, status=409
    )
