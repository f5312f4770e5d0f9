"""A teacher's exercise pages: their exercises, the editor (a form, or the document as JSON),
re-checking everyone after an edit, and a class's grid of students x exercises.

Only teachers (who teach a class, and staff: classroom.access.is_teacher) open them. An
exercise is fetched through classroom.access and changed only by who may
(``can_edit_exercise``: else 404, as if it were not there); what is saved is checked by
classroom.documents, whose errors name a path of the document ("checks[2].zone"): the form
shows each beside its field (classroom.forms_exercises).
"""

from __future__ import annotations

import json

from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.core.exceptions import PermissionDenied
from django.core.serializers.json import DjangoJSONEncoder
from django.db.models import Count, Q
from django.http import Http404, HttpRequest, HttpResponse
from django.shortcuts import redirect, render
from django.urls import reverse
from django.utils.translation import gettext as _
from django.utils.translation import ngettext
from django.views.decorators.http import require_POST

from classroom import access, documents
from classroom.checking import counted_attempt, recheck
from classroom.forms_exercises import (
    BLOCK_SUGGESTIONS,
    CHECK_FIELDS,
    CHECK_KINDS,
    Check,
    EditorState,
    ErrorMap,
    Variant,
    blank_document,
    check_row,
    variant_row,
)
from classroom.grades import grid
from classroom.models import Exercise
from programs.languages import LANGUAGES
from worlds.access import worlds_for_user
from worlds.documents import builtin_title, builtin_worlds

JSON_LIMIT = 512 * 1024  # bytes of an exercise document typed or pasted as JSON


def _teacher(request: HttpRequest) -> None:
    if not access.is_teacher(request.user):
        raise PermissionDenied(_("Only a class's teachers write exercises and see its grades."))


def _editable(request: HttpRequest, pk: int) -> Exercise:
    """The exercise, if this user may change it; 404 else (another teacher's is not there)."""
    _teacher(request)
    exercise = access.get_exercise_for_user(request.user, pk)
    if not access.can_edit_exercise(request.user, exercise):
        raise Http404(_("No such exercise."))
    return exercise


# -- the list -----------------------------------------------------------------------------------


@login_required
def exercise_list(request: HttpRequest) -> HttpResponse:
    _teacher(request)
    user = request.user
    taught = access.classes_for_teacher(user)
    exercises = (
        access.exercises_for_user(user)
        .filter(Q(owner=user) | Q(group__in=taught))
        .annotate(
            attempt_count=Count("attempts", distinct=True),
            passed_count=Count("attempts__student", filter=Q(attempts__passed=True), distinct=True),
            class_size=Count("group__user", distinct=True),
        )
        .order_by("group__name", "due", "title", "pk")
    )
    return render(
        request,
        "classroom/exercise_list.html",
        {"exercises": exercises, "classes": taught},
    )


# -- the editor ---------------------------------------------------------------------------------


def _world_choices(user, current: str) -> tuple[list, list]:
    builtin = [(name, builtin_title(name)) for name in builtin_worlds()]
    stored = [
        (str(w.pk), w.title or w.name, w.owner.username)
        for w in worlds_for_user(user).defer("document").order_by("owner__username", "name")
    ]
    known = {name for name, _title in builtin} | {pk for pk, *_rest in stored}
    if current and current not in known:  # no longer shared with this teacher: kept as it is
        stored.append((current, _("world %(id)s") % {"id": current}, ""))
    return builtin, stored


def _world_document(user, world: str, exercise: Exercise | None) -> dict | None:
    """The document of ``world`` as this user may read it (the map, the zones' names)."""
    if exercise is not None and str(exercise.world) == world and exercise.world_document:
        return exercise.world_document
    if world in builtin_worlds():
        return builtin_worlds()[world]
    if world.isdigit():
        found = worlds_for_user(user).filter(pk=int(world)).first()
        return found.document if found else None
    return None


def _class_choices(user, exercise: Exercise | None) -> list[tuple[str, str]]:
    classes = [(str(g.pk), g.name) for g in access.classes_for_teacher(user)]
    if exercise is not None and exercise.group_id and str(exercise.group_id) not in dict(classes):
        classes.append((str(exercise.group_id), exercise.group.name))
    return classes


def _editor(
    request: HttpRequest,
    state: EditorState,
    exercise: Exercise | None,
    errors: dict[str, str] | None = None,
    *,
    preview=None,
    show_preview: bool = False,
    status: int = 200,
) -> HttpResponse:
    user = request.user
    emap = ErrorMap(errors or {})
    world = state.scalars.get("world", "")
    world_doc = _world_document(user, world, exercise)
    builtin, stored = _world_choices(user, world)
    scalar_errors = {name: emap.claim(name, whole=name == "languages") for name in
                     ("title", "class", "text", "world", "languages", "starter",
                      "starter_language", "due", "attempts", "counts", "speed",
                      "time_limit_s")}  # fmt: skip
    variant_rows = state.variant_rows(emap)
    check_rows = state.check_rows(emap)
    scalar_errors["variants"] = emap.claim("variants", whole=True)
    scalar_errors["checks"] = emap.claim("checks", whole=True)
    context = {
        "exercise": exercise,
        "state": state,
        "s": state.scalars,
        "errors": scalar_errors,
        "error_count": len(emap.errors),
        "left_errors": emap.left(),
        "variant_rows": variant_rows,
        "check_rows": check_rows,
        "variant_template": variant_row("__i__", Variant(x="0", y="0", theta_deg="90")),
        "check_template": check_row("__i__", Check(kind="reach_zone")),
        "classes": _class_choices(user, exercise),
        "builtin_worlds": builtin,
        "stored_worlds": stored,
        "zones": [z.get("name") for z in (world_doc or {}).get("zones", [])],
        "block_suggestions": BLOCK_SUGGESTIONS,
        "languages": [(name, lang.label) for name, lang in LANGUAGES.items()],
        "preview": preview,
        "show_preview": show_preview,
        "stale": _stale_attempts(exercise),
        "editor": {
            "world": world_doc,
            "builtin": list(builtin_worlds()),
            "world_url": reverse("world-export", args=[0]),
            "builtin_url": reverse("world-builtin-export", args=["NAME"]),
            "kinds": {kind: spec["fields"] for kind, spec in CHECK_KINDS.items()},
        },
        "check_kinds": CHECK_KINDS,
        "check_fields": CHECK_FIELDS,
    }
    return render(request, "classroom/exercise_edit.html", context, status=status)


def _stale_attempts(exercise: Exercise | None) -> int:
    """How many students' counted attempts were checked under an older version of the
    exercise: what "Re-check everyone" checks again (classroom.checking.recheck)."""
    if exercise is None or exercise.pk is None:
        return 0
    old = exercise.attempts.filter(exercise_version__lt=exercise.version)
    students = set(old.values_list("student_id", flat=True))
    return sum(
        1
        for student in students
        if (counted := counted_attempt(exercise, student)) is not None
        and counted.exercise_version < exercise.version
    )


def _render_markdown(text: str):
    try:
        from classroom.markdown import render as markdown
    except ImportError:  # the student pages' helper not there yet: the text as it is
        return None
    return markdown(text)


@login_required
@require_POST
def text_preview(request: HttpRequest) -> HttpResponse:
    """The text as students will see it (htmx swaps it under the text; the form's Preview
    button does the same without scripts)."""
    _teacher(request)
    text = request.POST.get("text", "")
    return render(
        request,
        "classroom/exercise_preview.html",
        {"preview": _render_markdown(text), "text": text},  # fmt: skip
    )


@login_required
def exercise_new(request: HttpRequest) -> HttpResponse:
    _teacher(request)
    if request.method == "POST":
        return _submit(request, None)
    if request.GET.get("as") == "json":
        return _json_editor(request, None, _blank(request))
    return _editor(request, EditorState.from_document(_blank(request)), None)


def _blank(request) -> dict:
    """A new exercise: for the class named by ``?class=`` (from a class's page) if its
    teacher's, or the only class they teach; else a draft until they choose."""
    taught = access.classes_for_teacher(request.user)
    asked = request.GET.get("class", "")
    chosen = taught.filter(pk=int(asked)).first() if asked.isdigit() else None
    if chosen is None:
        classes = list(taught[:2])
        chosen = classes[0] if len(classes) == 1 else None
    world = "boxes"
    start = builtin_worlds()[world]["start"][0]
    return blank_document(world, start, chosen.pk if chosen else None)


@login_required
def exercise_edit(request: HttpRequest, pk: int) -> HttpResponse:
    exercise = _editable(request, pk)
    if request.method == "POST":
        return _submit(request, exercise)
    if request.GET.get("as") == "json":
        return _json_editor(request, exercise, documents.document(exercise, request.user))
    return _editor(request, EditorState.from_document(_document_of(exercise)), exercise)


def _submit(request: HttpRequest, exercise: Exercise | None) -> HttpResponse:
    if request.POST.get("mode") == "json":
        return _submit_json(request, exercise)
    state = EditorState.from_post(request.POST)
    action = request.POST.get("action", "save")
    # Without scripts, the rows' buttons post the form: the page comes back with the change.
    if action == "add-variant":
        state.variants.append(Variant(x="0", y="0", theta_deg="90"))
        return _editor(request, state, exercise)
    if action == "add-check":
        state.checks.append(Check(kind="reach_zone"))
        return _editor(request, state, exercise)
    if action.startswith(("remove-variant-", "remove-check-")):
        rows = state.variants if action.startswith("remove-variant-") else state.checks
        index = action.rsplit("-", 1)[1]
        if index.isdigit() and int(index) < len(rows):
            del rows[int(index)]
        return _editor(request, state, exercise)
    if action == "preview":
        preview = _render_markdown(state.scalars["text"])
        return _editor(request, state, exercise, preview=preview, show_preview=True)
    document, errors = state.document()
    if errors:
        return _editor(request, state, exercise, errors, status=422)
    saved, errors = _save(request.user, document, exercise)
    if errors:
        return _editor(request, state, exercise, errors, status=422)
    return _saved(request, saved, exercise)


def _saved(request, saved: Exercise, before: Exercise | None) -> HttpResponse:
    messages.success(request, _("Saved %(title)s.") % {"title": saved.title})
    return redirect("exercise-edit", saved.pk)


# -- as JSON --------------------------------------------------------------------------------------


def _json_editor(request, exercise, document: dict, errors=None, text=None, status=200):
    if text is None:
        text = json.dumps(document, indent=2, ensure_ascii=False, cls=DjangoJSONEncoder)
    context = {
        "exercise": exercise,
        "text": text,
        "errors": sorted((errors or {}).items()),
        "stale": _stale_attempts(exercise),
    }
    return render(request, "classroom/exercise_json.html", context, status=status)


def _submit_json(request: HttpRequest, exercise: Exercise | None) -> HttpResponse:
    text = request.POST.get("document", "")
    if len(text.encode()) > JSON_LIMIT:
        errors = {"": _("an exercise document is at most %(kb)s KB") % {"kb": JSON_LIMIT // 1024}}
        return _json_editor(request, exercise, {}, errors, text, status=413)
    try:
        document = json.loads(text)
    except ValueError as exc:
        errors = {"": _("not JSON: %(why)s") % {"why": exc}}
        return _json_editor(request, exercise, {}, errors, text, status=422)
    if not isinstance(document, dict):
        errors = {"": _("an exercise document is a JSON object")}
        return _json_editor(request, exercise, {}, errors, text, status=422)
    saved, errors = _save(request.user, document, exercise)
    if errors:
        return _json_editor(request, exercise, document, errors, text, status=422)
    return _saved(request, saved, exercise)


# -- re-check -------------------------------------------------------------------------------------


@login_required
@require_POST
def exercise_recheck(request: HttpRequest, pk: int) -> HttpResponse:
    exercise = _editable(request, pk)
    touched = recheck(exercise)
    count = len(touched) if touched is not None else 0
    messages.success(
        request,
        ngettext(
            "%(count)s attempt is being checked again.",
            "%(count)s attempts are being checked again.",
            count,
        )
        % {"count": count},
    )
    return redirect("exercise-edit", exercise.pk)


# -- the grid -------------------------------------------------------------------------------------


@login_required
def class_grid(request: HttpRequest, group_id: int) -> HttpResponse:
    _teacher(request)
    group = access.get_class_for_teacher(request.user, group_id)
    table = grid(group)
    passed = [sum(1 for _student, cells in table.rows() if cells[i].passed)
              for i in range(len(table.exercises))]  # fmt: skip
    context = {
        "group": group, "grid": table, "passed": passed, "student_count": len(table.students),
        "csv_url": f"/api/classes/{group.pk}/grades.csv",
    }  # fmt: skip
    return render(request, "classroom/grid.html", context)


# -- classroom.documents (the api helper's) ---------------------------------------------------


def _document_of(exercise: Exercise) -> dict:
    """Everything its teacher wrote, hidden variants' poses included (the form's)."""
    return documents.stored_document(exercise)


def _save(user, document: dict, exercise: Exercise | None):
    """(the saved exercise, None) or (None, {path: why})."""
    try:
        return documents.save(document, user, exercise), None
    except documents.ExerciseError as exc:
        return None, {exc.path or "": str(exc)}
