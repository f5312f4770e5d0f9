"""Checking an exercise: an attempt runs a revision of a student's program once per variant,
each on a fresh check sim (robots.check_sims), and judges each run's trace.

- ``start_attempt`` (a student's Check): refused (``CheckRefused``, its message says why, its
  ``status`` what the API answers) for a language the exercise does not take, a program not
  the student's, a check of theirs still queued or running (of any exercise), or when the
  server has too many check sims already. The attempt records the revision checked (the
  program's saved source: a draft not saved is not checked), its number, whether it is late,
  the exercise's version; its static checks (blocks) are judged at once; then one run per
  variant, through the agents, the queue and the fair shares as any run (a hidden variant's
  run is ``sealed``: its owner does not see it).
- When a run ends (``run_ended``, classroom.receivers; in whichever process marked it ended:
  the web tier's or an agent's, so nothing is kept in memory), its variant's checks are judged
  on its trace; once every variant is, the attempt is DONE: ``results`` one row a check and
  variant (static ones: variant None), ``score`` the points of the checks passed in every
  variant, ``passed`` all of them. A run that did not run its program (it could not start, it
  was stopped before) fails its variant's checks, the why saying so ("the program did not
  run: ..."): the attempt is DONE all the same. ERROR is for what went wrong on the server's
  side while judging (the why in ``error``).
- ``recheck(exercise)``: the counted attempts checked under an older version of the exercise
  are judged again: on their stored traces when what the runs were made of is the same (world,
  pose, speed, time limit: robots.check_sims.setup_of, kept on each check sim), else run again.
- ``counted_attempt``: the attempt that counts for a student (best or latest, among the first
  ``attempts_allowed`` attempts that were checked).
"""

from __future__ import annotations

import contextlib
import logging

from django.contrib.auth import get_user_model
from django.db import transaction
from django.utils import timezone, translation
from django.utils.translation import gettext as _

from classroom import checks as checks_module
from classroom.models import Attempt, AttemptRun, Exercise
from classroom.trace import Trace
from programs.models import Program, Revision
from rhal.simulator.world import World
from robots import check_sims
from runlogs.system_words import translated

log = logging.getLogger(__name__)

GOING = (Attempt.State.QUEUED, Attempt.State.RUNNING)


class CheckRefused(Exception):
    """A Check not made: ``message`` says why (in the asker's language), ``status`` is what the
    API answers (403 not theirs, 409 one going, 422 a language not taken, 429 the server full)."""

    def __init__(self, message: str, status: int = 409):
        super().__init__(message)
        self.message = message
        self.status = status


# -- a student's Check -------------------------------------------------------------------------


def start_attempt(exercise: Exercise, program: Program, user) -> Attempt:
    """A new attempt of ``user``'s at ``exercise`` with ``program`` (see the module's doc)."""
    if program.owner_id != user.pk:
        raise CheckRefused(_("only your own programs can be checked"), 403)
    refuse_language(exercise, program.language)
    world = world_of(exercise)
    with transaction.atomic():
        # One Check at a time per student: two tabs cannot both pass.
        get_user_model().objects.select_for_update().filter(pk=user.pk).first()
        if Attempt.objects.filter(student=user, state__in=GOING).exists():
            raise CheckRefused(
                _("a check of yours is still going: wait for its results, then check again"),
                409,
            )
        variants = exercise.variants if per_variant_checks(exercise) else []
        try:
            check_sims.room_for(len(variants))
        except check_sims.CheckSimsFull as exc:
            raise CheckRefused(str(exc), 429) from None
        revision = saved_revision(program, user)
        last = Attempt.objects.filter(exercise=exercise, student=user).order_by("-number")
        number = (last.values_list("number", flat=True).first() or 0) + 1
        now = timezone.now()
        attempt = Attempt.objects.create(
            exercise=exercise, student=user, program=program, revision=revision,
            language=program.language, source=revision.source, revision_number=revision.number,
            number=number, late=exercise.due is not None and now > exercise.due,
            exercise_version=exercise.version, max_score=exercise.max_score, created=now,
        )  # fmt: skip
        with in_language_of(user):
            attempt.results = static_results(exercise, attempt)
        if not variants:
            finish(attempt, exercise)
        else:
            attempt.save(update_fields=["results"])
            for index, variant in enumerate(variants):
                run_variant(attempt, exercise, index, variant, world)
    return attempt


def refuse_language(exercise: Exercise, language: str) -> None:
    allowed = exercise.languages or []
    if not allowed or language in allowed:
        return
    if exercise.blocks_only:
        raise CheckRefused(_("this exercise takes blocks programs only"), 422)
    from programs.languages import get_language

    names = []
    for name in allowed:
        try:
            names.append(str(get_language(name).label))
        except Exception:  # a language no longer installed: its name
            names.append(name)
    raise CheckRefused(
        _("this exercise takes programs in %(languages)s only") % {"languages": ", ".join(names)},
        422,
    )


def world_of(exercise: Exercise) -> World:
    """The exercise's world as checks judge in it; CheckRefused if it cannot be read."""
    try:
        return World.from_doc(exercise.world_document)
    except Exception as exc:
        log.error("exercise %s: its world cannot be read: %s", exercise.pk, exc)
        raise CheckRefused(
            _("this exercise's world cannot be used: ask your teacher to save it again"), 409
        ) from None


def saved_revision(program: Program, user) -> Revision:
    """The program's latest revision, as saved (a revision made if it has none of that)."""
    latest = program.revisions.first()
    if latest is not None and latest.source == program.source:
        return latest
    return program.save_source(program.source, user)


def per_variant_checks(exercise: Exercise) -> list[int]:
    return [i for i, check in enumerate(exercise.checks) if not checks_module.is_static(check)]


def run_variant(attempt: Attempt, exercise: Exercise, index: int, variant: dict, world) -> None:
    """Variant ``index``'s run of the attempt's revision, on a fresh check sim (sealed when
    the variant is hidden); its AttemptRun made or, run again, pointed at it."""
    student = attempt.student
    pose = check_sims.start_of(variant)
    robot = check_sims.make(
        student, exercise.world_document, pose, exercise.speed, exercise.time_limit_s
    )
    program = attempt.program
    hidden = bool(variant.get("hidden"))
    run = check_sims.start_run(
        robot, student, program=program,
        program_name=program.name if program is not None else exercise.title[:100],
        language=attempt.language, source=attempt.source, sealed=hidden,
    )  # fmt: skip
    AttemptRun.objects.update_or_create(
        attempt=attempt, variant=index,
        defaults={"hidden": hidden, "pose": pose, "run": run, "checked": False},
    )  # fmt: skip


@contextlib.contextmanager
def in_language_of(user):
    """The student's words: results are stored, and read later wherever they are shown."""
    from robotide.language import stored_language

    with translation.override(stored_language(user) or translation.get_language()):
        yield


# -- judging -----------------------------------------------------------------------------------


def static_results(exercise: Exercise, attempt: Attempt) -> list[dict]:
    rows = []
    for i, check in enumerate(exercise.checks):
        if checks_module.is_static(check):
            outcome = checks_module.evaluate_static(check, attempt.language, attempt.source, _)
            rows.append(_row(i, None, check, outcome.passed, outcome.why))
    return rows


def variant_results(exercise: Exercise, attempt_run: AttemptRun, world: World) -> list[dict]:
    """Every per-variant check judged on the run's trace (or failed, saying why not)."""
    run, index = attempt_run.run, attempt_run.variant
    doc = check_sims.read_trace(run) if run is not None else None
    trace, why_not = None, ""
    if doc is None:
        reason = (translated(run.reason) or run.get_state_display()) if run is not None else ""
        why_not = _("the program did not run: %(reason)s") % {"reason": reason or _("no run")}
    else:
        try:
            trace = Trace.from_dict(doc)
        except ValueError as exc:
            log.error("run %s: its trace cannot be read: %s", run.pk, exc)
            why_not = _("the run's recording could not be read")
    rows = []
    for i, check in enumerate(exercise.checks):
        if checks_module.is_static(check):
            continue
        if trace is None:
            passed, why = False, why_not
        else:
            outcome = checks_module.evaluate(check, trace, world, _)
            passed, why = outcome.passed, outcome.why
        if attempt_run.hidden:  # in words that do not give its pose away (classroom.checks)
            why = _("hidden variant %(number)s: %(why)s") % {"number": index + 1, "why": why}
        rows.append(_row(i, index, check, passed, why))
    return rows


def _row(check_index: int, variant, check: dict, passed: bool, why: str) -> dict:
    points = float(check.get("points", 1))
    return {"check": check_index, "variant": variant, "passed": bool(passed), "why": why,
            "points": points}  # fmt: skip


def finish(attempt: Attempt, exercise: Exercise) -> None:
    """Every variant judged: the score, passed, DONE (saved)."""
    rows = sorted(
        attempt.results, key=lambda r: (r["check"], -1 if r["variant"] is None else r["variant"])
    )
    score, checks = 0.0, exercise.checks
    for i, check in enumerate(checks):
        mine = [row for row in rows if row["check"] == i]
        if mine and all(row["passed"] for row in mine):
            score += float(check.get("points", 1))
    attempt.results = rows
    attempt.score = score
    attempt.max_score = exercise.max_score
    judged = {row["check"] for row in rows}  # a check with no row (no variant) did not pass
    attempt.passed = all(row["passed"] for row in rows) and judged == set(range(len(checks)))
    attempt.state = Attempt.State.DONE
    attempt.error = ""
    attempt.finished = timezone.now()
    attempt.save()


def run_ended(run_id: int) -> None:
    """A run ended (programs.run_ended): if it is an attempt's, its variant is judged."""
    found = AttemptRun.objects.filter(run_id=run_id, checked=False).values_list("pk", flat=True)
    for attempt_run_id in found:
        try:
            check_run(attempt_run_id)
        except Exception as exc:  # the attempt says so; the run's end goes on
            log.exception("attempt run %s (run %s) could not be checked", attempt_run_id, run_id)
            fail_attempt(attempt_run_id, exc)


def check_run(attempt_run_id: int) -> None:
    attempt_run = AttemptRun.objects.select_related(
        "run", "attempt__exercise", "attempt__student"
    ).get(pk=attempt_run_id)
    run = attempt_run.run
    if attempt_run.checked or (run is not None and run.ongoing):
        return
    attempt, exercise = attempt_run.attempt, attempt_run.attempt.exercise
    with in_language_of(attempt.student):  # judged outside the attempt's lock
        rows = variant_results(exercise, attempt_run, World.from_doc(exercise.world_document))
    with transaction.atomic():
        attempt = Attempt.objects.select_for_update().get(pk=attempt.pk)
        marked = AttemptRun.objects.filter(pk=attempt_run.pk, checked=False, run=run)
        if not marked.update(checked=True):
            return  # judged meanwhile (its run's end heard twice), or run again since
        variant = attempt_run.variant
        attempt.results = [r for r in attempt.results if r["variant"] != variant] + rows
        if attempt.state == Attempt.State.QUEUED:
            attempt.state = Attempt.State.RUNNING
        if attempt.runs.filter(checked=False).exists():
            attempt.save(update_fields=["results", "state"])
        else:
            finish(attempt, exercise)


def fail_attempt(attempt_run_id: int, exc: Exception) -> None:
    attempt_id = AttemptRun.objects.filter(pk=attempt_run_id).values_list("attempt", flat=True)
    Attempt.objects.filter(pk__in=list(attempt_id), state__in=GOING).update(
        state=Attempt.State.ERROR,
        error=_("the server could not check this run (%(why)s)") % {"why": type(exc).__name__},
        finished=timezone.now(),
    )


def run_started(run_id: int) -> None:
    """An agent took one of an attempt's runs: the attempt is running. (Every run's start
    asks: a read, no write unless it is an attempt's.)"""
    attempt_id = AttemptRun.objects.filter(run_id=run_id).values_list("attempt", flat=True)
    if attempt_id := attempt_id.first():
        Attempt.objects.filter(pk=attempt_id, state=Attempt.State.QUEUED).update(
            state=Attempt.State.RUNNING
        )


# -- the teacher changed the exercise ----------------------------------------------------------


def recheck(exercise: Exercise) -> list[Attempt]:
    """Every student's counted attempt checked under an older version, checked again: on its
    stored traces when only the checks changed, else run again. The attempts touched."""
    touched = []
    world = world_of(exercise)
    students = Attempt.objects.filter(exercise=exercise).values_list("student", flat=True)
    for student_id in sorted(set(students)):
        attempt = counted_attempt(exercise, student_id)
        if attempt is None or attempt.exercise_version >= exercise.version:
            continue
        if same_runs(attempt, exercise):
            rejudge(attempt, exercise, world)
        else:
            run_again(attempt, exercise, world)
        touched.append(attempt)
    return touched


def same_runs(attempt: Attempt, exercise: Exercise) -> bool:
    """Whether the attempt's runs were made of what the exercise would run now."""
    variants = exercise.variants if per_variant_checks(exercise) else []
    runs = {ar.variant: ar for ar in attempt.runs.select_related("run__robot")}
    if set(runs) != set(range(len(variants))):
        return False
    for index, variant in enumerate(variants):
        ar = runs[index]
        if ar.run is None or ar.hidden != bool(variant.get("hidden")):
            return False
        setup = check_sims.setup_of(
            exercise.world_document, variant, exercise.speed, exercise.time_limit_s
        )
        if check_sims.setup_stored(ar.run.robot) != setup:
            return False
    return True


def rejudge(attempt: Attempt, exercise: Exercise, world: World) -> None:
    with in_language_of(attempt.student):
        rows = static_results(exercise, attempt)
        for ar in attempt.runs.select_related("run"):
            rows += variant_results(exercise, ar, world)
    with transaction.atomic():
        attempt = Attempt.objects.select_for_update().get(pk=attempt.pk)
        attempt.results = rows
        attempt.exercise_version = exercise.version
        finish(attempt, exercise)


def run_again(attempt: Attempt, exercise: Exercise, world: World) -> None:
    """The attempt's revision run again on every variant as the exercise is now (a teacher's
    recheck: the check sims' cap is not asked, their runs wait their turn as any)."""
    variants = exercise.variants if per_variant_checks(exercise) else []
    with transaction.atomic():
        attempt = Attempt.objects.select_for_update().get(pk=attempt.pk)
        attempt.runs.filter(variant__gte=len(variants)).delete()
        with in_language_of(attempt.student):
            attempt.results = static_results(exercise, attempt)
        attempt.exercise_version = exercise.version
        attempt.score, attempt.passed, attempt.finished, attempt.error = 0.0, False, None, ""
        attempt.max_score = exercise.max_score
        if not variants:
            finish(attempt, exercise)
            return
        attempt.state = Attempt.State.QUEUED
        attempt.save()
        for index, variant in enumerate(variants):
            run_variant(attempt, exercise, index, variant, world)


# -- what counts ---------------------------------------------------------------------------------


def counted_attempt(exercise: Exercise, student) -> Attempt | None:
    """The attempt that counts for ``student`` (a user or their id): among their first
    ``attempts_allowed`` attempts that were checked (DONE; all when not set), the best (the
    highest score, the later of equals) or the latest, as the exercise says."""
    student_id = getattr(student, "pk", student)
    done = Attempt.objects.filter(
        exercise=exercise, student_id=student_id, state=Attempt.State.DONE
    ).order_by("number")
    if exercise.attempts_allowed:
        done = done[: exercise.attempts_allowed]
    attempts = list(done)
    if not attempts:
        return None
    if exercise.counts == Exercise.Counts.LATEST:
        return attempts[-1]
    return max(attempts, key=lambda a: (a.score, a.number))
