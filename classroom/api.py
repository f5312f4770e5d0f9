"""The classroom API: classes and their students (/api/classes), exercises (/api/exercises),
checks of a student's program and their attempts (/api/attempts).

Everything is fetched through classroom.access (404 for what the caller may not see). A
student reads an exercise's hidden variants as ``{"hidden": true}``, never their pose, and an
attempt's hidden variants' runs not at all.
"""

from datetime import datetime

from django.core.exceptions import PermissionDenied
from django.http import HttpResponse
from django.utils.http import content_disposition_header
from django.utils.translation import gettext as _
from ninja import Field, Query, Router, Schema
from ninja.responses import Status
from pydantic import BaseModel, ConfigDict, model_validator

from classroom import checking, documents, grades
from classroom.access import (
    attempts_for_user,
    can_edit_exercise,
    classes_for_teacher,
    exercises_for_user,
    get_attempt_for_user,
    get_class_for_teacher,
    get_exercise_for_user,
    is_teacher,
    sees_hidden,
)
from classroom.accounts import MAX_STUDENTS, AccountsError, Entry, create_class, create_students
from classroom.checking import CheckRefused, start_attempt
from classroom.documents import ExerciseError
from classroom.models import Attempt, Classroom, Exercise
from programs.access import get_program_for_user
from programs.api import Error
from robotide.schemas import Body

classes_router = Router(tags=["classes"])
exercises_router = Router(tags=["exercises"])
attempts_router = Router(tags=["exercises"])


# -- classes -------------------------------------------------------------------------------------


class StudentIn(Schema):
    username: str = Field(min_length=1, max_length=30)
    name: str = Field("", max_length=150, description="the full name")


StudentsField = Field(
    [],
    max_length=MAX_STUDENTS,
    description="each a name (its account made: username the name as a slug) or an existing"
    " account's username (it joins, no new password), or {username, name}",
)


class ClassIn(Body):
    name: str = Field(min_length=1, max_length=150)
    students: list[str | StudentIn] = StudentsField


class StudentsIn(Body):
    students: list[str | StudentIn] = StudentsField


class NewAccountOut(Schema):
    username: str
    name: str = Field(description="the full name")
    password: str | None = Field(
        description="a new account's one-time password (to change at its first sign-in):"
        " shown here once, never again; null for an account that existed"
    )
    created: bool


class MemberOut(Schema):
    username: str
    name: str


class ClassSummary(Schema):
    id: int
    name: str
    join_code: str | None = Field(description="what students type at sign-up; null: none")
    teachers: list[str]
    students: int = Field(description="how many")


class ClassOut(ClassSummary):
    students: list[MemberOut]


class ClassCreated(Schema):
    id: int
    name: str
    join_code: str | None
    students: list[NewAccountOut]


class StudentsAdded(Schema):
    students: list[NewAccountOut]


class Invalid(Schema):
    detail: list[dict] | str = Field(
        description="a list of {type, loc, path, msg}: path is where in the body"
        ' (e.g. "students[2]", "variants[1].x"), msg what is wrong'
    )


def _entries(students) -> list:
    return [
        Entry(username=s.username.strip(), name=s.name.strip()) if isinstance(s, StudentIn) else s
        for s in students
    ]


def _accounts_invalid(exc: AccountsError, key: str = "students"):
    path = key if exc.index is None or key != "students" else f"students[{exc.index}]"
    loc = ["body", key] + ([exc.index] if exc.index is not None and key == "students" else [])
    return Status(
        422, {"detail": [{"type": "accounts", "loc": loc, "path": path, "msg": str(exc)}]}
    )


def _members(group) -> list:
    teachers = group.teachers.values_list("user_id", flat=True)
    return list(group.user_set.exclude(pk__in=teachers).order_by("username"))


def _join_code(group) -> str | None:
    try:
        return group.classroom.join_code
    except Classroom.DoesNotExist:
        return None


def _class_summary(group) -> dict:
    teachers = group.teachers.select_related("user").order_by("user__username")
    return {
        "id": group.pk,
        "name": group.name,
        "join_code": _join_code(group),
        "teachers": [t.user.username for t in teachers],
        "students": len(_members(group)),
    }


def _accounts_out(made) -> list[dict]:
    return [
        {"username": a.username, "name": a.full_name, "password": a.password,
         "created": a.created}
        for a in made
    ]  # fmt: skip


@classes_router.get("", response=list[ClassSummary])
def list_classes(request):
    """The classes you teach (staff: every class)."""
    return [_class_summary(group) for group in classes_for_teacher(request.user)]


@classes_router.post("", response={201: ClassCreated, 422: Invalid}, summary="Create a class")
def create_class_(request, data: ClassIn):
    """A class you teach, with the students' accounts that do not exist yet: each new one's
    one-time password is in this answer, and only here (print it, hand it out). Teachers
    (who teach a class already) and staff only: a class's teacher reads its students'
    programs, and anyone could otherwise make a class of their classmates."""
    if not is_teacher(request.user):
        raise PermissionDenied(_("Only teachers and staff make classes."))
    try:
        group = create_class(data.name, request.user)
    except AccountsError as exc:
        return _accounts_invalid(exc, "name")
    try:
        made = create_students(group, _entries(data.students), request.user)
    except AccountsError as exc:
        group.delete()  # all or nothing: the class goes with its list
        return _accounts_invalid(exc)
    return Status(
        201,
        {"id": group.pk, "name": group.name, "join_code": _join_code(group),
         "students": _accounts_out(made)},
    )  # fmt: skip


@classes_router.get("/{int:group_id}", response=ClassOut)
def get_class(request, group_id: int):
    group = get_class_for_teacher(request.user, group_id)
    members = [{"username": u.username, "name": u.get_full_name()} for u in _members(group)]
    return {**_class_summary(group), "students": members}


@classes_router.post(
    "/{int:group_id}/students", response={200: StudentsAdded, 422: Invalid},
    summary="Add students",
)  # fmt: skip
def add_students(request, group_id: int, data: StudentsIn):
    """Names become accounts in the class (their one-time passwords in this answer, once);
    existing usernames join it."""
    group = get_class_for_teacher(request.user, group_id)
    try:
        made = create_students(group, _entries(data.students), request.user)
    except AccountsError as exc:
        return _accounts_invalid(exc)
    return Status(200, {"students": _accounts_out(made)})


CSV_RESPONSE = {
    "description": "one row a student: username, name, then each exercise's score",
    "content": {"text/csv": {"schema": {"type": "string"}}},
}


@classes_router.get("/{int:group_id}/grades.csv", openapi_extra={"responses": {200: CSV_RESPONSE}})
def grades_csv(request, group_id: int):
    """The class's grid as CSV, for a gradebook or LMS (the counted attempt's score)."""
    group = get_class_for_teacher(request.user, group_id)
    response = HttpResponse(grades.grades_csv(group), content_type="text/csv; charset=utf-8")
    response["Content-Disposition"] = content_disposition_header(True, grades.csv_filename(group))
    return response


# -- exercises ---------------------------------------------------------------------------------


def _doc(description: str, kind: str | list[str]):
    # Checked by classroom.documents (its errors name the field), not by pydantic.
    return Field(None, description=description, json_schema_extra={"type": kind})


class ExerciseIn(BaseModel):
    """An exercise document. On PUT, keys left out keep their values; id, version, owner,
    created and updated are read back, never written."""

    model_config = ConfigDict(extra="allow")

    @model_validator(mode="before")
    @classmethod
    def an_object(cls, data):
        if not isinstance(data, dict):
            raise ValueError(_("the body must be a JSON object"))
        return data

    title: object = _doc("1 to 200 characters", "string")
    text: object = _doc("Markdown, at most 20,000 characters", "string")
    world: object = _doc("a built-in world's name, or a stored world's id", ["string", "integer"])
    class_: object = Field(
        None,
        alias="class",
        description="the class it is set for (one you teach), or null: a draft",
        json_schema_extra={"type": ["integer", "null"]},
    )
    languages: object = _doc('allowed: [] any, ["blocks"] blocks only', "array")
    variants: object = _doc(
        "start poses, at most 10: [{x, y, theta, hidden}] (metres, radians)", "array"
    )
    checks: object = _doc("at most 30: [{kind, points, message, ...}]", "array")
    starter: object = _doc("the program a student starts from", "string")
    starter_language: object = _doc("its language", "string")
    due: object = _doc("ISO 8601, or null", ["string", "null"])
    attempts: object = _doc("how many checked attempts count (null: all)", ["integer", "null"])
    counts: object = _doc('"best" or "latest"', "string")
    speed: object = _doc("the check sims' clock, 1 to 10 x real time", "number")
    time_limit_s: object = _doc("a variant's run, sim seconds (1 to 600)", "number")

    def document(self) -> dict:
        return self.model_dump(exclude_unset=True, by_alias=True)


class ExerciseOut(Schema):
    id: int
    title: str
    text: str
    world: str | int
    class_: int | None = Field(alias="class")
    languages: list[str]
    variants: list[dict] = Field(
        description='[{x, y, theta, hidden}]; a student reads a hidden one as {"hidden": true}'
    )
    checks: list[dict]
    starter: str
    starter_language: str
    due: datetime | None
    attempts: int | None
    counts: str
    speed: float
    time_limit_s: float
    version: int
    owner: str
    created: datetime
    updated: datetime


def _invalid(exc: ExerciseError):
    detail = exc.as_detail() if exc.status == 422 else str(exc)
    return Status(exc.status, {"detail": detail})


@exercises_router.get("", response=list[ExerciseOut], by_alias=True)
def list_exercises(request, group: int | None = Query(None, alias="class")):
    """Yours, your classes' (teacher) and those set for your classes (student); ``class=N``:
    one class's."""
    exercises = exercises_for_user(request.user)
    if group is not None:
        exercises = exercises.filter(group_id=group)
    return [documents.document(e, request.user) for e in exercises.order_by("due", "title", "pk")]


@exercises_router.post(
    "", response={201: ExerciseOut, 413: Error, 422: Invalid}, by_alias=True,
    summary="Create an exercise",
)  # fmt: skip
def create_exercise(request, data: ExerciseIn):
    """An exercise of yours: a draft (``class`` null) or set for a class you teach. 422 names
    where the document is wrong (a variant in a wall, a check's unknown zone...)."""
    try:
        exercise = documents.save(data.document(), request.user)
    except ExerciseError as exc:
        return _invalid(exc)
    return Status(201, documents.document(exercise, request.user))


@exercises_router.get("/{int:exercise_id}", response=ExerciseOut, by_alias=True)
def get_exercise(request, exercise_id: int):
    exercise = get_exercise_for_user(request.user, exercise_id)
    return documents.document(exercise, request.user)


def _editable(request, exercise_id: int) -> Exercise:
    exercise = get_exercise_for_user(request.user, exercise_id)
    if not can_edit_exercise(request.user, exercise):
        raise PermissionDenied(_("Only its author and its class's teachers change an exercise."))
    return exercise


@exercises_router.put(
    "/{int:exercise_id}", response={200: ExerciseOut, 413: Error, 422: Invalid}, by_alias=True,
    summary="Save an exercise",
)  # fmt: skip
def update_exercise(request, exercise_id: int, data: ExerciseIn):
    """Its author or its class's teachers change it; ``version`` goes up when its world,
    variants, checks, speed or time limit change (attempts checked before: ``recheck``)."""
    exercise = _editable(request, exercise_id)
    try:
        exercise = documents.save(data.document(), request.user, exercise)
    except ExerciseError as exc:
        return _invalid(exc)
    return Status(200, documents.document(exercise, request.user))


@exercises_router.delete("/{int:exercise_id}", response={204: None})
def delete_exercise(request, exercise_id: int):
    """Its author or its class's teachers delete it, with its attempts."""
    _editable(request, exercise_id).delete()
    return Status(204, None)


class RecheckOut(Schema):
    attempts: int = Field(description="how many counted attempts are checked again")


@exercises_router.post("/{int:exercise_id}/recheck", response=RecheckOut)
def recheck(request, exercise_id: int):
    """Every student's counted attempt checked under an older version is checked again."""
    exercise = _editable(request, exercise_id)
    return {"attempts": len(checking.recheck(exercise))}


# -- attempts ----------------------------------------------------------------------------------


#: What a refused Check answers (classroom.checking.CheckRefused.status).
CHECK_REFUSALS = (403, 409, 422, 429)


class CheckIn(Body):
    program: int = Field(description="your program's id: its latest saved revision is checked")


class AttemptRunOut(Schema):
    variant: int
    hidden: bool
    run: int | None = Field(description="the run's id; null for a student's hidden variant")
    checked: bool


class AttemptOut(Schema):
    id: int
    exercise: int
    student: str
    number: int = Field(description="the student's nth attempt at this exercise")
    state: str = Field(description="queued, running, done, error")
    score: float
    max_score: float
    passed: bool
    late: bool
    program: int | None
    revision: int = Field(description="the program's revision number checked")
    exercise_version: int
    created: datetime
    finished: datetime | None
    results: list[dict] = Field(
        description="[{check, variant, passed, why, points}] (variant null: a static check)"
    )
    error: str
    runs: list[AttemptRunOut]


def attempt_out(attempt: Attempt, user) -> dict:
    """An attempt as ``user`` may read it: a student does not get a hidden variant's run."""
    teacher = sees_hidden(user, attempt.exercise)
    return {
        "id": attempt.pk, "exercise": attempt.exercise_id,
        "student": attempt.student.username, "number": attempt.number,
        "state": attempt.state, "score": attempt.score, "max_score": attempt.max_score,
        "passed": attempt.passed, "late": attempt.late, "program": attempt.program_id,
        "revision": attempt.revision_number, "exercise_version": attempt.exercise_version,
        "created": attempt.created, "finished": attempt.finished,
        "results": [dict(r) for r in attempt.results], "error": attempt.error,
        "runs": [
            {"variant": r.variant, "hidden": r.hidden,
             "run": r.run_id if teacher or not r.hidden else None, "checked": r.checked}
            for r in attempt.runs.all()
        ],
    }  # fmt: skip


@exercises_router.post(
    "/{int:exercise_id}/check",
    # 422's detail: a refusal's words, or pydantic's list for a body that is not {program}
    response={202: AttemptOut, **dict.fromkeys(CHECK_REFUSALS, Error), 422: Invalid},
    summary="Check a program",
)
def check(request, exercise_id: int, data: CheckIn):
    """Your program's latest revision runs on a fresh sim once per variant (hidden ones too)
    and is checked: 202 with the attempt, whose results come at ``GET /api/attempts/{id}``.
    403: the program is not yours; 409: a check of yours is still running; 422: a language
    this exercise does not take; 429: the server checks as many as it can at once."""
    exercise = get_exercise_for_user(request.user, exercise_id)
    program = get_program_for_user(request.user, data.program)
    try:
        attempt = start_attempt(exercise, program, request.user)
    except CheckRefused as exc:
        status = exc.status if exc.status in CHECK_REFUSALS else 409
        return Status(status, {"detail": exc.message})
    return Status(202, attempt_out(attempt, request.user))


@exercises_router.get("/{int:exercise_id}/attempts", response=list[AttemptOut])
def list_attempts(request, exercise_id: int, student: str | None = None):
    """A teacher: every student's (``student=USERNAME``: one's); a student: their own."""
    exercise = get_exercise_for_user(request.user, exercise_id)
    attempts = attempts_for_user(request.user).filter(exercise=exercise)
    if student is not None:
        attempts = attempts.filter(student__username=student)
    attempts = attempts.select_related("exercise", "student").prefetch_related("runs")
    return [attempt_out(a, request.user) for a in attempts.order_by("-created", "-pk")]


@attempts_router.get("/{int:attempt_id}", response=AttemptOut)
def get_attempt(request, attempt_id: int):
    attempt = get_attempt_for_user(request.user, attempt_id)
    return attempt_out(attempt, request.user)
