import difflib
import json

from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.core.exceptions import ValidationError
from django.http import HttpRequest, HttpResponse, StreamingHttpResponse
from django.shortcuts import get_object_or_404, redirect, render
from django.utils.http import url_has_allowed_host_and_scheme
from django.views.decorators.http import require_POST

from programs.access import get_program_for_user, get_run_for_user, programs_for_user, runs_for_user
from programs.forms import EditProgramForm, NewProgramForm, UploadForm, unique_name
from programs.languages import (
    availability,
    editor_mode_of_language,
    editor_modes,
    get_language,
)
from programs.models import AgentUnreachable, Program, Run, RunRefused, request_stop, start_run
from programs.runlog import plain_text, render_lines, tail
from robots.models import get_robot_for_user, robots_for_user


@login_required
def program_list(request: HttpRequest) -> HttpResponse:
    return render(
        request,
        "programs/list.html",
        {
            "programs": programs_for_user(request.user),
            "new_form": NewProgramForm(owner=request.user, auto_id="new_%s"),
            "upload_form": UploadForm(owner=request.user, auto_id="upload_%s"),
            "robots": robots_for_user(request.user),
        },
    )


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
    messages.success(request, f"Uploaded {program.name}.")
    return redirect("program-edit", program.pk)


def _list_with_errors(request, **forms) -> HttpResponse:
    context = {
        "programs": programs_for_user(request.user),
        "new_form": NewProgramForm(owner=request.user, auto_id="new_%s"),
        "upload_form": UploadForm(owner=request.user, auto_id="upload_%s"),
        "robots": robots_for_user(request.user),
        **forms,
    }
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


def _render_editor(request, program, form, status=200):
    context = {
        "program": program,
        "form": form,
        "language": program.lang,
        "editor_modes": editor_modes(),
        "editor_modes_json": json.dumps(editor_mode_of_language()),
        "robots": robots_for_user(request.user),
        "runs": runs_for_user(request.user).filter(program=program)[:10],
        "revision": program.revisions.first(),
    }
    return render(request, "programs/edit.html", context, status=status)


def _save_and_act(request, program: Program, form: EditProgramForm) -> HttpResponse:
    data = form.cleaned_data
    action = request.POST.get("action", "save")
    if action == "save_as":
        return _save_copy(request, program, form)
    program.language = data["language"]
    revision = program.save_source(data["source"], request.user)
    if action == "run":
        return _start(request, program, request.POST.get("robot", ""))
    messages.success(request, f"Saved (revision {revision.number}).")
    return redirect("program-edit", program.pk)


def _save_copy(request, program: Program, form: EditProgramForm) -> HttpResponse:
    """Save as: the edited text becomes a new program of the user's, the original stays."""
    data = form.cleaned_data
    try:
        name = unique_name(request.user, data["save_as"])
        if not name:
            raise ValidationError("Give the copy a name.")
    except ValidationError as exc:
        form.add_error("save_as", exc)
        return _render_editor(request, program, form, status=400)
    copy = Program.objects.create(owner=request.user, name=name, language=data["language"])
    copy.save_source(data["source"], request.user)
    messages.success(request, f"Saved a copy as {copy.name}.")
    return redirect("program-edit", copy.pk)


def _start(request, program: Program, robot_name: str) -> HttpResponse:
    robot = get_robot_for_user(request.user, robot_name)
    try:
        run = start_run(program, robot, request.user)
    except RunRefused as exc:
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
def program_delete(request: HttpRequest, program_id: int) -> HttpResponse:
    program = get_program_for_user(request.user, program_id)
    if request.method == "POST":
        name = program.name
        program.delete()
        messages.success(request, f"Deleted {name}.")
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
        restored = program.save_source(revision.source, request.user)
        messages.success(request, f"Restored revision {number} as revision {restored.number}.")
        return redirect("program-edit", program.pk)
    diff = difflib.unified_diff(
        revision.source.splitlines(),
        program.source.splitlines(),
        fromfile=f"revision {revision.number}",
        tofile="current",
        lineterm="",
    )
    return render(
        request,
        "programs/revision.html",
        {"program": program, "revision": revision, "diff": [_diff_line(d) for d in diff]},
    )


def _diff_line(line: str) -> tuple[str, str]:
    if line.startswith(("+++", "---")):
        return "file", line
    kind = {"+": "add", "-": "del", "@": "hunk"}.get(line[:1], "same")
    return kind, line


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
        "running": runs.filter(state__in=Run.ACTIVE),
        "recent": runs.exclude(state__in=Run.ACTIVE)[:50],
        "robot_filter": robot,
        "robots": robots_for_user(user),
    }


@login_required
def run_detail(request: HttpRequest, run_id: int) -> HttpResponse:
    run = get_run_for_user(request.user, run_id)
    lines, skipped, offset = tail(run.log_path)
    context = {"run": run, "log_html": render_lines(lines), "skipped": skipped, "offset": offset}
    return render(request, "runs/detail.html", context)


@login_required
def run_log(request: HttpRequest, run_id: int) -> HttpResponse:
    run = get_run_for_user(request.user, run_id)
    if not run.log_path.exists():
        return HttpResponse(b"", content_type="text/plain; charset=utf-8")
    response = StreamingHttpResponse(
        plain_text(run.log_path), content_type="text/plain; charset=utf-8"
    )
    response["Content-Disposition"] = f'attachment; filename="{run.log_filename}"'
    return response


@login_required
@require_POST
def run_stop(request: HttpRequest, run_id: int) -> HttpResponse:
    run = get_run_for_user(request.user, run_id)
    try:
        request_stop(run)
    except AgentUnreachable as exc:
        if request.htmx:
            return HttpResponse(str(exc), status=503)
        messages.error(request, str(exc))
    else:
        if request.htmx:
            return HttpResponse(status=204)
        messages.info(request, f"Stopping run {run.pk}.")
    next_url = request.POST.get("next", "")
    if url_has_allowed_host_and_scheme(next_url, allowed_hosts={request.get_host()}):
        return redirect(next_url)
    return redirect("run-detail", run.pk)


@login_required
def language_list(request: HttpRequest) -> HttpResponse:
    """Which languages this computer can run, and what to install for the others."""
    return render(request, "programs/languages.html", {"languages": availability()})
