"""A student's side of exercises: the list, an exercise, its Check from the workbench, an
attempt's checklist and replays, and "Try on the real robot".

Nothing here shows a hidden variant's pose to who may not change the exercise
(classroom.access.sees_hidden): the exercise's drawing has the visible starts only and says
how many are hidden, a hidden variant's replay is a 404 to its student, its run is not linked.
"""

from __future__ import annotations

import json
import logging

from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.core.exceptions import PermissionDenied
from django.db import IntegrityError, transaction
from django.http import Http404, HttpRequest, HttpResponse, JsonResponse
from django.shortcuts import redirect, render
from django.urls import reverse
from django.utils import timezone
from django.utils.translation import gettext as _
from django.views.decorators.http import require_GET, require_POST

from classroom import markdown
from classroom.access import (
    attempts_for_user,
    can_edit_exercise,
    exercises_for_user,
    get_attempt_for_user,
    get_exercise_for_user,
    sees_hidden,
)
from classroom.checking import CheckRefused, counted_attempt, start_attempt
from classroom.documents import visible_checks
from classroom.models import Attempt, AttemptRun, Exercise, Work
from classroom.templatetags.classroom_student import check_words, variant_name
from programs.access import EDIT, READ, can
from programs.forms import EditProgramForm, free_name
from programs.languages import get_language
from programs.models import Program
from robots.models import Robot, robots_for_user
from robots.runs import RunRefused, start_run
from worlds.documents import BUILTIN_TITLES

log = logging.getLogger(__name__)

#: A replay draws at most this many poses (a trace keeps up to 100,000): every nth is kept,
#: and the last.
REPLAY_POSES = 20_000
ONGOING = (Attempt.State.QUEUED, Attempt.State.RUNNING)


# -- the list -----------------------------------------------------------------------------


@login_required
@require_GET
def exercise_list(request: HttpRequest) -> HttpResponse:
    """The exercises of the user's classes (and, a teacher's, those they set): when due, the
    score that counts, attempts used of those that count."""
    user = request.user
    now = timezone.now()
    exercises = exercises_for_user(user).order_by("due", "title", "pk")
    mine = attempts_for_user(user).filter(student=user)
    used: dict[int, int] = {}
    for exercise_id in mine.values_list("exercise_id", flat=True):
        used[exercise_id] = used.get(exercise_id, 0) + 1
    works = {w.exercise_id: w for w in Work.objects.filter(student=user, exercise__in=exercises)}
    rows = [
        {
            "exercise": exercise,
            "counted": counted_attempt(exercise, user) if used.get(exercise.pk) else None,
            "used": used.get(exercise.pk, 0),
            "past_due": exercise.due is not None and exercise.due < now,
            "work": works.get(exercise.pk),
            "can_edit": can_edit_exercise(user, exercise),
        }
        for exercise in exercises
    ]
    return render(request, "classroom/student_exercises.html", {"rows": rows})


# -- one exercise ---------------------------------------------------------------------------


@login_required
@require_GET
def exercise_detail(request: HttpRequest, pk: int) -> HttpResponse:
    exercise = get_exercise_for_user(request.user, pk)
    user = request.user
    visible = [(i, v) for i, v in enumerate(exercise.variants) if not v.get("hidden")]
    hidden = len(exercise.variants) - len(visible)
    drawing = drawn_world(exercise)
    if (title := drawing["world"].get("title")) in BUILTIN_TITLES:  # in the reader's language
        drawing["world"]["title"] = _(title)
    drawing["starts"] = [
        {"x": v["x"], "y": v["y"], "theta": v["theta"], "label": str(i + 1)} for i, v in visible
    ]
    context = {
        "exercise": exercise,
        "text": markdown.render(exercise.text),
        "drawing": drawing,
        "visible_count": len(visible),
        "hidden_count": hidden,
        "checks": [
            {"words": check_words(check), "points": check.get("points", 1)}
            for check in visible_checks(exercise, user)
        ],
        "languages": languages_in_words(exercise),
        "work": own_work(exercise, user),
        "attempts": attempts_for_user(user).filter(exercise=exercise, student=user),
        "past_due": exercise.due is not None and exercise.due < timezone.now(),
        "can_edit": can_edit_exercise(user, exercise),
    }
    return render(request, "classroom/student_exercise.html", context)


def own_work(exercise: Exercise, user) -> Work | None:
    """The user's program for the exercise, if they started it (and it is still there)."""
    return Work.objects.filter(exercise=exercise, student=user).select_related("program").first()


def languages_in_words(exercise: Exercise) -> str:
    if not exercise.languages:
        return _("any language")
    if exercise.blocks_only:
        return _("blocks only")
    return ", ".join(str(get_language(name).label) for name in exercise.languages)


def starter_language(exercise: Exercise) -> str:
    if exercise.starter_language and (
        not exercise.languages or exercise.starter_language in exercise.languages
    ):
        return exercise.starter_language
    return exercise.languages[0] if exercise.languages else "python"


@login_required
@require_POST
def exercise_start(request: HttpRequest, pk: int) -> HttpResponse:
    """The user's program for the exercise, made from its starter (once), opened."""
    exercise = get_exercise_for_user(request.user, pk)
    work = own_work(exercise, request.user)
    if work is None:
        try:
            with transaction.atomic():
                name = free_name(request.user, exercise.title[:90] or _("exercise"))
                program = Program.objects.create(
                    owner=request.user, name=name, language=starter_language(exercise),
                    origin=_("exercise: %(title)s") % {"title": exercise.title[:250]},
                )  # fmt: skip
                program.save_source(exercise.starter, request.user)
                work = Work.objects.create(exercise=exercise, student=request.user, program=program)
        except IntegrityError:  # a second Start at the same moment: the first one's
            work = own_work(exercise, request.user)
            if work is None:
                raise
    return redirect("program-edit", work.program_id)


# -- Check, from the workbench --------------------------------------------------------------


@login_required
@require_POST
def exercise_check(request: HttpRequest, pk: int) -> HttpResponse:
    """Check the user's program for the exercise. From the workbench's script (saved just
    before): the checklist, which follows the attempt. From the plain form (scripts off): the
    editor's text saved first, then back to the program."""
    exercise = get_exercise_for_user(request.user, pk)
    work = own_work(exercise, request.user)
    scripted = request.headers.get("X-Requested-With") == "fetch"
    if work is None:
        why = _("Start the exercise first: it makes your program.")
        if scripted:
            return JsonResponse({"error": why}, status=400)
        messages.error(request, why)
        return redirect("student-exercise", exercise.pk)
    program = work.program
    if not scripted and "source" in request.POST:
        if (refused := _save_plain(request, program)) is not None:
            messages.error(request, refused)
            return redirect("program-edit", program.pk)
    try:
        attempt = start_attempt(exercise, program, request.user)
    except CheckRefused as exc:
        if scripted:
            return JsonResponse({"error": str(exc)}, status=getattr(exc, "status", 400))
        messages.error(request, str(exc))
        return redirect("program-edit", program.pk)
    if scripted:
        response = render(request, "classroom/_checklist.html", checklist_context(attempt, request))
        response["X-Attempt"] = str(attempt.pk)
        return response
    messages.success(request, _("Checking attempt %(number)s…") % {"number": attempt.number})
    return redirect("program-edit", program.pk)


def _save_plain(request: HttpRequest, program: Program) -> str | None:
    """The plain editor form's text as a revision (as its Save does); why not, or None."""
    from programs.workbench import Conflict, save_edit

    if not can(request.user, EDIT, program):
        return _("You may read this program but not change it.")
    form = EditProgramForm(request.POST)
    if not form.is_valid():
        return "; ".join(e for errors in form.errors.values() for e in errors)
    try:
        save_edit(request, program, form.cleaned_data)
    except Conflict as conflict:
        return _(
            "Not checked: revision %(number)s was saved after you opened the program; open it"
            " again."
        ) % {"number": conflict.latest}
    return None


# -- an attempt -----------------------------------------------------------------------------


def hidden_variants(attempt: Attempt) -> set[int]:
    """The attempt's hidden variants: hidden when it ran, or hidden now."""
    hidden = {run.variant for run in attempt.runs.all() if run.hidden}
    hidden |= {i for i, v in enumerate(attempt.exercise.variants) if v.get("hidden")}
    return hidden


def _without_prefix(why: str, variant, hidden: bool) -> str:
    """A hidden variant's why without the "hidden variant N: " it was stored with (its row is
    named so already), as written in English or in the student's language."""
    if not hidden or variant is None:
        return why
    number = {"number": int(variant) + 1}
    for prefix in (
        _("hidden variant %(number)s: ") % number,
        f"hidden variant {number['number']}: ",
    ):
        if why.startswith(prefix):
            return why[len(prefix) :]
    return why


def checklist_context(attempt: Attempt, request: HttpRequest) -> dict:
    """✔/✗ per check and variant, with why and the teacher's message where it failed."""
    exercise = attempt.exercise
    hidden = hidden_variants(attempt)
    rows = []
    results = attempt.results or []
    for index, check in enumerate(exercise.checks):
        mine = [r for r in results if r.get("check") == index]
        entries = [
            {
                "variant": r.get("variant"),
                "name": variant_name(r.get("variant"), r.get("variant") in hidden),
                "hidden": r.get("variant") in hidden,
                "passed": bool(r.get("passed")),
                "why": _without_prefix(
                    r.get("why", ""), r.get("variant"), r.get("variant") in hidden
                ),
            }
            for r in sorted(mine, key=lambda r: (r.get("variant") is not None, r.get("variant")))
        ]
        passed = all(e["passed"] for e in entries) if entries else None
        rows.append(
            {
                "index": index,
                "words": check_words(check),
                "points": check.get("points", 1),
                "message": check.get("message", "") if passed is False else "",
                "passed": passed,
                "entries": entries,
            }
        )
    ongoing = attempt.state in ONGOING
    progress = []
    if ongoing:  # each variant's run as it goes: its state only, never where it started
        for attempt_run in attempt.runs.select_related("run").all():
            run = attempt_run.run
            progress.append(
                {
                    "name": variant_name(attempt_run.variant, attempt_run.variant in hidden),
                    "state": run.state if run is not None else "queued",
                    "state_shown": run.get_state_display() if run is not None else _("waiting"),
                    "checked": attempt_run.checked,
                }
            )
    return {
        "attempt": attempt,
        "exercise": exercise,
        "rows": rows,
        "ongoing": ongoing,
        "progress": progress,
        "poll_url": reverse("attempt-checklist", args=[attempt.pk]) if ongoing else "",
    }


@login_required
@require_GET
def attempt_detail(request: HttpRequest, pk: int) -> HttpResponse:
    attempt = get_attempt_for_user(request.user, pk)
    return render(request, "classroom/attempt.html", attempt_context(attempt, request))


@login_required
@require_GET
def attempt_body(request: HttpRequest, pk: int) -> HttpResponse:
    """The attempt page's changing part (polled while the attempt runs)."""
    attempt = get_attempt_for_user(request.user, pk)
    return render(request, "classroom/attempt_body.html", attempt_context(attempt, request))


@login_required
@require_GET
def attempt_checklist(request: HttpRequest, pk: int) -> HttpResponse:
    """The workbench's checklist (polled while the attempt runs)."""
    attempt = get_attempt_for_user(request.user, pk)
    return render(request, "classroom/_checklist.html", checklist_context(attempt, request))


def attempt_context(attempt: Attempt, request: HttpRequest) -> dict:
    user = request.user
    exercise = attempt.exercise
    shows_hidden = sees_hidden(user, exercise)
    hidden = hidden_variants(attempt)
    runs = []
    for attempt_run in attempt.runs.select_related("run").all():
        is_hidden = attempt_run.variant in hidden
        if is_hidden and not shows_hidden:
            runs.append({"variant": attempt_run.variant, "hidden": True, "shown": False,
                         "name": variant_name(attempt_run.variant, True)})  # fmt: skip
            continue
        run = attempt_run.run
        runs.append(
            {
                "variant": attempt_run.variant,
                "hidden": is_hidden,
                "shown": True,
                "name": variant_name(attempt_run.variant, is_hidden),
                "run": run,
                "replay": run is not None and not run.ongoing and attempt_run.checked,
                "replay_url": reverse("attempt-replay", args=[attempt.pk, attempt_run.variant]),
            }
        )
    checklist = checklist_context(attempt, request)
    return {
        **checklist,
        # the page polls its whole body (replays come when it is done), not the checklist
        "poll_url": "",
        "body_poll_url": reverse("attempt-body", args=[attempt.pk]) if checklist["ongoing"] else "",
        "runs": runs,
        "robots": robots_to_try(attempt, user),
        "is_student": attempt.student_id == user.pk,
        "work_program": attempt.program
        if attempt.program_id and can(user, READ, attempt.program)
        else None,
    }


# -- a replay -------------------------------------------------------------------------------


def drawn_world(exercise: Exercise) -> dict:
    """The exercise's world as the page draws it, without its own start poses (a teacher may
    have put a hidden variant there): {"world", "robot"}."""
    from rhal.simulator.world import World, WorldError

    document = exercise.world_document or {}
    try:
        normal = World.from_doc(document).to_doc()
    except (WorldError, ValueError, TypeError, KeyError):
        log.warning("exercise %s: its world document does not load", exercise.pk, exc_info=True)
        normal = dict(document)
    robot = normal.pop("robot", None) or {"radius": 0.15}
    normal["start"] = []
    return {"world": normal, "robot": robot}


@login_required
@require_GET
def attempt_replay(request: HttpRequest, pk: int, variant: int) -> JsonResponse:
    """A variant's run as recorded (its trace) and the world it ran in, for the replay.
    A hidden variant's is a 404 to who may not see hidden poses (its student)."""
    attempt = get_attempt_for_user(request.user, pk)
    attempt_run = (
        AttemptRun.objects.filter(attempt=attempt, variant=variant).select_related("run").first()
    )
    if attempt_run is None:
        raise Http404(_("No such variant."))
    if variant in hidden_variants(attempt) and not sees_hidden(request.user, attempt.exercise):
        raise Http404(_("No such variant."))
    run = attempt_run.run
    trace = _trace(run)
    if trace is None:
        return JsonResponse({"error": _("This run has no recording (yet).")}, status=404)
    poses = trace.get("poses") or []
    if len(poses) > REPLAY_POSES:
        step = -(-len(poses) // REPLAY_POSES)
        poses = poses[::step] + ([poses[-1]] if (len(poses) - 1) % step else [])
    answer = {
        **drawn_world(attempt.exercise),
        "variant": variant,
        "name": variant_name(variant, attempt_run.variant in hidden_variants(attempt)),
        "run": run.pk,
        "speed": trace.get("speed"),
        "radius": trace.get("radius"),
        "start": trace.get("start"),
        "poses": [[round(float(v), 4) for v in pose[:4]] for pose in poses],
        "contacts": [[round(float(v), 4) for v in c[:3]] for c in trace.get("contacts") or []],
        "said": trace.get("said") or [],
        "output": trace.get("output") or [],
        "end": trace.get("end") or {},
        "truncated": bool(trace.get("truncated")),
    }
    response = JsonResponse(answer)
    response["Cache-Control"] = "private, max-age=3600"  # a trace does not change
    return response


def _trace(run) -> dict | None:
    if run is None:
        return None
    path = run.directory / "trace.json"
    try:
        trace = json.loads(path.read_text())
    except (OSError, ValueError):
        return None
    return trace if isinstance(trace, dict) else None


# -- from sim to robot ----------------------------------------------------------------------


def robots_to_try(attempt: Attempt, user) -> list[Robot]:
    """The real robots of the exercise's class the attempt's student may run programs on;
    none unless the attempt passed and it is theirs."""
    exercise = attempt.exercise
    if not attempt.passed or attempt.student_id != user.pk or exercise.group_id is None:
        return []
    candidates = (
        robots_for_user(user)
        .filter(groups=exercise.group_id, personal=False, checking=False)
        .exclude(url__istartswith="sim:")
        .order_by("name")
    )
    return [robot for robot in candidates if robot.drivable_by(user)]


@login_required
@require_POST
def attempt_try(request: HttpRequest, pk: int) -> HttpResponse:
    """The revision the attempt checked, queued on a real robot of the class (as any run:
    its queue, its lease); then its run's page."""
    attempt = get_attempt_for_user(request.user, pk)
    robots = robots_to_try(attempt, request.user)
    chosen = request.POST.get("robot", "")
    robot = next((r for r in robots if r.name == chosen), robots[0] if len(robots) == 1 else None)
    if robot is None or attempt.program_id is None:
        if not robots:
            why = _("Only a passed attempt of yours runs on a robot of its class.")
        elif attempt.program_id is None:
            why = _("The program of this attempt was deleted.")
        else:
            why = _("Choose a robot.")
        messages.error(request, why)
        return redirect("attempt-detail", attempt.pk)
    program = attempt.program
    if program.language != attempt.language:
        messages.error(request, _("The program's language changed since this attempt."))
        return redirect("attempt-detail", attempt.pk)
    # The run is of the checked revision, whatever the program holds now.
    source = attempt.revision.source if attempt.revision_id else attempt.source
    try:
        run = start_run(program, robot, request.user, source=source)
    except (RunRefused, PermissionDenied) as exc:
        messages.error(request, str(exc))
        return redirect("attempt-detail", attempt.pk)
    return redirect("run-detail", run.pk)
