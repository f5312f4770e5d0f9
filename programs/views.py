import difflib
import json

from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.core.exceptions import PermissionDenied, ValidationError
from django.db.models import Exists, OuterRef
from django.http import HttpRequest, HttpResponse
from django.shortcuts import get_object_or_404, redirect, render
from django.utils.http import content_disposition_header
from django.utils.translation import gettext as _
from django.utils.translation import ngettext
from django.views.decorators.http import require_POST

from programs import archive, outbound, workbench
from programs.access import (
    EDIT,
    OWN,
    can,
    get_program_for_user,
    get_run_for_user,
    programs_for_user,
    runs_for_user,
)
from programs.forms import EditProgramForm, NewProgramForm, UploadForm, unique_name
from programs.languages import (
    LANGUAGES,
    availability,
    editor_mode_of_language,
    editor_modes,
    get_language,
)
from programs.models import Program, Run, Share
from programs.run_page import robot_panel_context, run_page_context
from programs.runlog import download
from programs.shares import ShareError, add_share
from robotide.redirects import back
from robots import run_queue
from robots.availability import robot_to_run_on, run_choices
from robots.models import robots_for_user
from robots.runs import AgentUnreachable, RunRefused, request_stop, start_run


@login_required
def program_list(request: HttpRequest) -> HttpResponse:
    return render(request, "programs/list.html", _list_context(request))


def _list_context(request) -> dict:
    visible = programs_for_user(request.user)
    gallery = Share.objects.filter(program=OuterRef("pk"), everyone=True)
    return {
        "programs": visible.filter(owner=request.user),
        # Shared with them, their classes' programs for a teacher, everything for admins.
        "others": visible.exclude(owner=request.user)
        .annotate(in_gallery=Exists(gallery))
        .order_by("owner__username", "name"),
        "new_form": NewProgramForm(owner=request.user, auto_id="new_%s"),
        "upload_form": UploadForm(owner=request.user, auto_id="upload_%s"),
        # robots, offer_sim, no_robot (why Run is disabled, if it is), sim_note
        **run_choices(request.user),
    }


@login_required
@require_POST
def program_create(request: HttpRequest) -> HttpResponse:
    form = NewProgramForm(request.POST, owner=request.user, auto_id="new_%s")
    if not form.is_valid():
        return _list_with_errors(request, new_form=form)
    language = get_language(form.cleaned_data["language"])
    program = Program.objects.create(
        owner=request.user, name=form.cleaned_data["name"], language=language.name
    )
    program.save_source(language.template, request.user)
    return redirect("program-edit", program.pk)


@login_required
@require_POST
def program_upload(request: HttpRequest) -> HttpResponse:
    form = UploadForm(request.POST, request.FILES, owner=request.user, auto_id="upload_%s")
    if not form.is_valid():
        return _list_with_errors(request, upload_form=form)
    data = form.cleaned_data
    program = Program.objects.create(
        owner=request.user, name=data["name"], language=data["language"]
    )
    program.save_source(data["source"], request.user)
    messages.success(request, _("Uploaded %(name)s.") % {"name": program.name})
    return redirect("program-edit", program.pk)


def _list_with_errors(request, **forms) -> HttpResponse:
    context = {**_list_context(request), **forms}
    return render(request, "programs/list.html", context, status=400)


@login_required
def program_edit(request: HttpRequest, program_id: int) -> HttpResponse:
    program = get_program_for_user(request.user, program_id)
    form = EditProgramForm(initial={"source": program.source, "language": program.language})
    if request.method == "POST":
        form = EditProgramForm(request.POST)
        if form.is_valid():
            return _save_and_act(request, program, form)
    return _render_editor(request, program, form, status=400 if form.errors else 200)


def _render_editor(request, program, form, status=200, conflict=None):
    context = {
        "conflict": conflict,
        "blocks": program.language == "blocks",
        "program": program,
        "form": form,
        "language": program.lang,
        "editor_modes": editor_modes(),
        "editor_modes_json": json.dumps(editor_mode_of_language()),
        # The languages with a debugger: the Debug button follows the language chosen.
        "debuggable_json": json.dumps([n for n, lang in LANGUAGES.items() if lang.debuggable]),
        **run_choices(request.user),  # robots, offer_sim, no_robot, sim_note
        "runs": runs_for_user(request.user).filter(program=program)[:10],
        "revision": program.revisions.first(),
        "can_edit": can(request.user, EDIT, program),
        "is_owner": can(request.user, OWN, program),
        "shares": program.shares.select_related("user", "group"),
    }
    if draft := workbench.draft_to_offer(request.user, program):
        context["draft"] = draft
        context["draft_data"] = {"source": draft.source, "language": draft.language}
    response = render(request, "programs/edit.html", context, status=status)
    if context["blocks"]:
        # Blockly injects its stylesheet as a <style> element: allowed on this page only,
        # and for styles only (scripts stay our own files).
        response._csp_update = {"style-src": ["'unsafe-inline'"]}
    return response


@login_required
@require_POST
def program_share(request: HttpRequest, program_id: int) -> HttpResponse:
    """The owner shares the program with a user, a class or everyone."""
    program = get_program_for_user(request.user, program_id, OWN)
    target = request.POST.get("target", "").strip()
    kind, _sep, name = target.partition(":") if ":" in target else ("user", "", target)
    if target == "everyone":
        kind = "everyone"
    try:
        share = add_share(
            program, request.user, user=name.strip() if kind == "user" else "",
            group=name.strip() if kind == "group" else "", everyone=kind == "everyone",
            can_edit=request.POST.get("can_edit") == "on",
        )  # fmt: skip
    except ShareError as exc:
        messages.error(request, _("Not shared: %(why)s.") % {"why": exc})
    else:
        messages.success(request, _("Shared with %(target)s.") % {"target": share.target})
    return redirect("program-edit", program.pk)


@login_required
@require_POST
def program_unshare(request: HttpRequest, program_id: int, share_id: int) -> HttpResponse:
    program = get_program_for_user(request.user, program_id, OWN)
    share = get_object_or_404(program.shares, pk=share_id)
    share.delete()
    messages.success(request, _("No longer shared with %(target)s.") % {"target": share.target})
    return redirect("program-edit", program.pk)


def _save_and_act(request, program: Program, form: EditProgramForm) -> HttpResponse:
    data = form.cleaned_data
    action = request.POST.get("action", "save")
    if action == "save_as":
        return _save_copy(request, program, form)
    if not can(request.user, EDIT, program):
        if action == "run":  # a read-only program runs as it is
            return _start(request, program, request.POST.get("robot", ""))
        raise PermissionDenied(workbench.read_only())
    try:
        revision = workbench.save_edit(request, program, data)
    except workbench.Conflict as conflict:
        form.add_error(
            None,
            _(
                "Not saved: revision %(number)s was saved after you opened this program, and"
                " nothing was overwritten. What differs is below; Save again to save yours over it."
            )
            % {"number": conflict.latest},
        )
        return _render_editor(request, program, form, status=409, conflict=conflict)
    if action == "run":
        return _start(request, program, request.POST.get("robot", ""))
    messages.success(request, _("Saved (revision %(number)s).") % {"number": revision.number})
    return redirect("program-edit", program.pk)


def _save_copy(request, program: Program, form: EditProgramForm) -> HttpResponse:
    """Save as: the edited text becomes a new program of the user's, the original stays."""
    data = form.cleaned_data
    try:
        name = unique_name(request.user, data["save_as"])
        if not name:
            raise ValidationError(_("Give the copy a name."))
    except ValidationError as exc:
        form.add_error("save_as", exc)
        return _render_editor(request, program, form, status=400)
    copy = Program.objects.create(owner=request.user, name=name, language=data["language"])
    copy.save_source(data["source"], request.user)
    messages.success(request, _("Saved a copy as %(name)s.") % {"name": copy.name})
    return redirect("program-edit", copy.pk)


def _start(request, program: Program, robot_name: str) -> HttpResponse:
    try:
        # No robot open to the user at all: the editor says why (robots.availability).
        robot = robot_to_run_on(request.user, robot_name)
        run = start_run(program, robot, request.user)
    except (RunRefused, PermissionDenied) as exc:
        messages.error(request, str(exc))
        return redirect("program-edit", program.pk)
    return redirect("run-detail", run.pk)


@login_required
@require_POST
def program_run(request: HttpRequest, program_id: int) -> HttpResponse:
    program = get_program_for_user(request.user, program_id)
    return _start(request, program, request.POST.get("robot", ""))


@login_required
def program_download(request: HttpRequest, program_id: int) -> HttpResponse:
    program = get_program_for_user(request.user, program_id)
    response = HttpResponse(program.source, content_type="text/plain; charset=utf-8")
    response["Content-Disposition"] = f'attachment; filename="{program.filename}"'
    return response


@login_required
def program_export(request: HttpRequest) -> HttpResponse:
    """All of the user's own programs as a zip (what staff may see of others' is not theirs)."""
    data = archive.export_zip(Program.objects.filter(owner=request.user))
    response = HttpResponse(data, content_type="application/zip")
    filename = archive.export_filename(request.user)
    response["Content-Disposition"] = content_disposition_header(True, filename)
    return response


@login_required
@require_POST
def program_import(request: HttpRequest) -> HttpResponse:
    upload = request.FILES.get("file")
    if upload is None:
        messages.error(request, _("Choose a zip file to import."))
        return redirect("program-list")
    replace = request.POST.get("replace", "") in ("true", "on", "1")
    try:
        report = archive.import_zip(
            upload.read(), request.user, filename=upload.name, replace=replace
        )
    except archive.ArchiveError as exc:
        messages.error(
            request,
            _("Nothing was imported from %(file)s: %(why)s") % {"file": upload.name, "why": exc},
        )
        return redirect("program-list")
    messages.success(
        request,
        _("Imported %(file)s: %(summary)s.") % {"file": upload.name, "summary": report.summary()},
    )
    if report.skipped:
        shown = "; ".join(f"{s.file} ({s.why})" for s in report.skipped[:10])
        more = len(report.skipped) - 10
        if more > 0:
            text = ngettext(
                "Skipped %(files)s and %(more)s more.", "Skipped %(files)s and %(more)s more.", more
            )
        else:
            text = _("Skipped %(files)s.")
        messages.warning(request, text % {"files": shown, "more": more})
    return redirect("program-list")


@login_required
def program_delete(request: HttpRequest, program_id: int) -> HttpResponse:
    program = get_program_for_user(request.user, program_id, OWN)
    if request.method == "POST":
        name = program.name
        program.delete()
        messages.success(request, _("Deleted %(name)s.") % {"name": name})
        return redirect("program-list")
    return render(request, "programs/delete.html", {"program": program})


@login_required
def revision_list(request: HttpRequest, program_id: int) -> HttpResponse:
    program = get_program_for_user(request.user, program_id)
    return render(
        request,
        "programs/revisions.html",
        {"program": program, "revisions": program.revisions.select_related("author")},
    )


@login_required
def revision_detail(request: HttpRequest, program_id: int, number: int) -> HttpResponse:
    program = get_program_for_user(request.user, program_id)
    revision = get_object_or_404(program.revisions, number=number)
    if request.method == "POST":
        get_program_for_user(request.user, program_id, EDIT)
        restored = program.save_source(revision.source, request.user)
        messages.success(
            request,
            _("Restored revision %(old)s as revision %(new)s.")
            % {"old": number, "new": restored.number},
        )
        return redirect("program-edit", program.pk)
    diff = difflib.unified_diff(
        revision.source.splitlines(),
        program.source.splitlines(),
        fromfile=_("revision %(number)s") % {"number": revision.number},
        tofile=_("current"),
        lineterm="",
    )
    return render(
        request,
        "programs/revision.html",
        {
            "program": program,
            "revision": revision,
            "diff": [_diff_line(d) for d in diff],
            "current": revision.number == program.revisions.latest("number").number,
            "can_edit": can(request.user, EDIT, program),
        },
    )


def _diff_line(line: str) -> tuple[str, str]:
    if line.startswith(("+++", "---")):
        return "file", line
    kind = {"+": "add", "-": "del", "@": "hunk"}.get(line[:1], "same")
    return kind, line


@login_required
@require_POST
def program_email(request: HttpRequest, program_id: int) -> HttpResponse:
    program = get_program_for_user(request.user, program_id)
    try:
        to = outbound.email_program(
            program, request.POST.get("to", ""), user=request.user, site=outbound.site_of(request)
        )
    except outbound.OutboundError as exc:
        messages.error(request, str(exc))
    else:
        messages.success(request, _("Sent %(name)s to %(to)s.") % {"name": program.name, "to": to})
    return redirect("program-edit", program.pk)


@login_required
@require_POST
def program_push(request: HttpRequest, program_id: int) -> HttpResponse:
    program = get_program_for_user(request.user, program_id)
    try:
        arrived = outbound.push_program(
            program,
            request.POST.get("url", ""),
            request.POST.get("token", ""),
            user=request.user,
            site=outbound.site_of(request),
        )
    except outbound.OutboundError as exc:
        messages.error(request, str(exc))
    else:
        messages.success(
            request,
            _("Pushed %(name)s to %(url)s: it is %(there)s of %(owner)s there.")
            % {
                "name": program.name,
                "url": arrived["url"],
                "there": repr(arrived["name"]),
                "owner": arrived["owner"] or _("the account"),
            },
        )
    return redirect("program-edit", program.pk)


# -- runs ---------------------------------------------------------------------------------


@login_required
def run_list(request: HttpRequest) -> HttpResponse:
    robot = request.GET.get("robot") or None
    return render(request, "runs/list.html", run_tables_context(request.user, robot))


def run_tables_context(user, robot: str | None) -> dict:
    runs = runs_for_user(user)
    if robot:
        runs = runs.filter(robot__name=robot)
    return {
        # Those waiting in a robot's queue too: they have not ended, and may be cancelled.
        "running": runs.filter(state__in=Run.ONGOING),
        "recent": runs.exclude(state__in=Run.ONGOING)[:50],
        "robot_filter": robot,
        "robots": robots_for_user(user),
    }


@login_required
def run_detail(request: HttpRequest, run_id: int) -> HttpResponse:
    run = get_run_for_user(request.user, run_id)
    return render(request, "runs/detail.html", run_page_context(request, run))


@login_required
def run_robot(request: HttpRequest, run_id: int) -> HttpResponse:
    """The robot beside a run's output, fetched by its page once shown; nothing (204) once the
    run is over or for a viewer who may not see the robot."""
    context = robot_panel_context(request, get_run_for_user(request.user, run_id))
    if context is None:
        return HttpResponse(status=204)
    return render(request, "programs/_panel.html", context)


@login_required
def run_log(request: HttpRequest, run_id: int) -> HttpResponse:
    run = get_run_for_user(request.user, run_id)
    response = download(run)
    if response.status_code == 200:
        response["Content-Disposition"] = f'attachment; filename="{run.log_filename}"'
    return response


@login_required
@require_POST
def run_stop(request: HttpRequest, run_id: int) -> HttpResponse:
    """Stop a run; a queued one is cancelled (also by those who manage its robot's queue)."""
    run = run_queue.get_run_to_manage(request.user, run_id)
    queued = run.queued
    try:
        request_stop(run)
    except AgentUnreachable as exc:
        if request.htmx:
            return HttpResponse(str(exc), status=503)
        messages.error(request, str(exc))
    else:
        if request.htmx:
            return HttpResponse(status=204)
        cancelled = queued and run.state == Run.State.STOPPED
        said = _("Cancelled run %(id)s.") if cancelled else _("Stopping run %(id)s.")
        messages.info(request, said % {"id": run.pk})
    return back(request, "run-detail", run.pk)


@login_required
def language_list(request: HttpRequest) -> HttpResponse:
    """Which languages this computer can run, and what to install for the others."""
    return render(request, "programs/languages.html", {"languages": availability()})
