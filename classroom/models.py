"""Classes, exercises, attempts: a teacher's classroom without the admin site.

A *class* is an auth Group, as before (robots' and worlds' classes, LDAP/OpenID Connect
groups): its teachers are its robotide.ClassTeacher rows, its students its members. A class
made on the classroom page (or `POST /api/classes`) also gets a ``Classroom`` row for what
only such classes have (a join code). An *exercise* is a document (``Exercise.document()``
is the API's shape) checked against the trace of a run on a fresh sim per variant; an
*attempt* is one Check of one revision of a student's program.
"""

from __future__ import annotations

import secrets

from django.conf import settings
from django.db import models
from django.utils import timezone
from django.utils.translation import gettext_lazy as _

#: Join codes: no 0/O, 1/I/L, read aloud and typed from a board.
JOIN_ALPHABET = "ABCDEFGHJKMNPQRSTUVWXYZ23456789"
JOIN_LENGTH = 8


def new_join_code() -> str:
    return "".join(secrets.choice(JOIN_ALPHABET) for _ in range(JOIN_LENGTH))


class Classroom(models.Model):
    """What a class made in the classroom has beside its Group: a join code students type at
    sign-up (null: joining by code is off)."""

    group = models.OneToOneField(
        "auth.Group", on_delete=models.CASCADE, related_name="classroom", verbose_name=_("class")
    )
    join_code = models.CharField(_("join code"), max_length=16, null=True, blank=True, unique=True)
    created_by = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        on_delete=models.SET_NULL,
        null=True,
        blank=True,
        related_name="+",
        verbose_name=_("created by"),
    )
    created = models.DateTimeField(_("created"), default=timezone.now)

    class Meta:
        verbose_name = _("classroom")
        verbose_name_plural = _("classrooms")

    def __str__(self) -> str:
        return str(self.group)


class OneTimePassword(models.Model):
    """The account's password was made by a teacher (printed on a sheet): its user must
    choose their own at the next sign-in before anything else."""

    user = models.OneToOneField(
        settings.AUTH_USER_MODEL,
        on_delete=models.CASCADE,
        related_name="one_time_password",
        verbose_name=_("user"),
    )
    issued_by = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        on_delete=models.SET_NULL,
        null=True,
        blank=True,
        related_name="+",
        verbose_name=_("issued by"),
    )
    created = models.DateTimeField(_("created"), default=timezone.now)

    class Meta:
        verbose_name = _("one-time password")
        verbose_name_plural = _("one-time passwords")


class Exercise(models.Model):
    class Counts(models.TextChoices):
        BEST = "best", _("the best attempt")
        LATEST = "latest", _("the latest attempt")

    owner = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        on_delete=models.CASCADE,
        related_name="exercises",
        verbose_name=_("author"),
    )
    # None: a draft only its author (and staff) see
    group = models.ForeignKey(
        "auth.Group",
        on_delete=models.SET_NULL,
        null=True,
        blank=True,
        related_name="exercises",
        verbose_name=_("class"),
    )
    title = models.CharField(_("title"), max_length=200)
    text = models.TextField(_("text"), blank=True)  # Markdown, sanitised when shown
    # The world as written (a built-in's name or a stored world's id), and the document it
    # named when the exercise was saved: checks and check sims use the document.
    world = models.CharField(_("world"), max_length=100)
    world_document = models.JSONField(_("world document"), default=dict)
    languages = models.JSONField(_("languages"), default=list, blank=True)  # []: any
    variants = models.JSONField(_("variants"), default=list)  # [{"x","y","theta","hidden"}]
    checks = models.JSONField(_("checks"), default=list)
    starter = models.TextField(_("starter program"), blank=True)
    starter_language = models.CharField(_("starter's language"), max_length=20, blank=True)
    due = models.DateTimeField(_("due"), null=True, blank=True)
    attempts_allowed = models.PositiveIntegerField(_("attempts that count"), null=True, blank=True)
    counts = models.CharField(
        _("counts"), max_length=10, choices=Counts.choices, default=Counts.BEST
    )
    speed = models.FloatField(_("speed"), default=5.0)  # the check sims' clock, x real time
    time_limit_s = models.FloatField(_("time limit (s)"), default=60.0)  # a variant's run, sim s
    # Bumped when what decides a result changes (world, variants, checks, limit): attempts
    # checked under an older version are re-checked.
    version = models.PositiveIntegerField(_("version"), default=1)
    created = models.DateTimeField(_("created"), default=timezone.now)
    updated = models.DateTimeField(_("updated"), default=timezone.now)

    class Meta:
        verbose_name = _("exercise")
        verbose_name_plural = _("exercises")
        ordering = ["due", "title", "pk"]

    def __str__(self) -> str:
        return self.title

    @property
    def blocks_only(self) -> bool:
        return self.languages == ["blocks"]

    @property
    def max_score(self) -> float:
        """Points of all checks, every variant counted once (a check passes in all or not)."""
        return float(sum(check.get("points", 1) for check in self.checks))


class Work(models.Model):
    """A student's program for an exercise (made from its starter when they start it)."""

    exercise = models.ForeignKey(
        Exercise, on_delete=models.CASCADE, related_name="works", verbose_name=_("exercise")
    )
    student = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        on_delete=models.CASCADE,
        related_name="exercise_works",
        verbose_name=_("student"),
    )
    program = models.ForeignKey(
        "programs.Program",
        on_delete=models.CASCADE,
        related_name="exercise_works",
        verbose_name=_("program"),
    )
    created = models.DateTimeField(_("created"), default=timezone.now)

    class Meta:
        verbose_name = _("exercise work")
        verbose_name_plural = _("exercise works")
        constraints = [
            models.UniqueConstraint(fields=["exercise", "student"], name="one_work_a_student")
        ]


class Attempt(models.Model):
    class State(models.TextChoices):
        QUEUED = "queued", _("queued")  # its runs asked, none started
        RUNNING = "running", _("running")
        DONE = "done", _("done")  # every variant ran and was checked
        ERROR = "error", _("error")  # could not be checked (why: in ``error``)

    exercise = models.ForeignKey(
        Exercise, on_delete=models.CASCADE, related_name="attempts", verbose_name=_("exercise")
    )
    student = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        on_delete=models.CASCADE,
        related_name="attempts",
        verbose_name=_("student"),
    )
    program = models.ForeignKey(
        "programs.Program",
        on_delete=models.SET_NULL,
        null=True,
        related_name="attempts",
        verbose_name=_("program"),
    )
    revision = models.ForeignKey(
        "programs.Revision",
        on_delete=models.SET_NULL,
        null=True,
        related_name="attempts",
        verbose_name=_("revision"),
    )
    # What was checked, kept when the program or revision is deleted
    language = models.CharField(_("language"), max_length=20)
    source = models.TextField(_("source"), blank=True)
    revision_number = models.PositiveIntegerField(_("revision number"), default=0)
    number = models.PositiveIntegerField(_("number"))  # the student's nth on this exercise
    state = models.CharField(_("state"), max_length=10, choices=State.choices, default=State.QUEUED)
    error = models.CharField(_("error"), max_length=500, blank=True)
    score = models.FloatField(_("score"), default=0.0)
    max_score = models.FloatField(_("maximum score"), default=0.0)
    passed = models.BooleanField(_("passed"), default=False)
    # [{"check": i, "variant": j, "passed": bool, "why": str, "points": float}]
    results = models.JSONField(_("results"), default=list, blank=True)
    exercise_version = models.PositiveIntegerField(_("exercise version"), default=1)
    late = models.BooleanField(_("late"), default=False)
    created = models.DateTimeField(_("created"), default=timezone.now)
    finished = models.DateTimeField(_("finished"), null=True, blank=True)

    class Meta:
        verbose_name = _("attempt")
        verbose_name_plural = _("attempts")
        ordering = ["-created", "-pk"]
        constraints = [
            models.UniqueConstraint(
                fields=["exercise", "student", "number"], name="one_attempt_number"
            )
        ]

    def __str__(self) -> str:
        return f"{self.exercise} #{self.number} ({self.student})"


class AttemptRun(models.Model):
    """One variant's run of an attempt (its trace: ``trace.json`` in the run's directory)."""

    attempt = models.ForeignKey(
        Attempt, on_delete=models.CASCADE, related_name="runs", verbose_name=_("attempt")
    )
    variant = models.PositiveIntegerField(_("variant"))  # index into exercise.variants
    hidden = models.BooleanField(_("hidden"), default=False)
    pose = models.JSONField(_("start pose"), default=dict)  # {"x","y","theta"} as run
    run = models.ForeignKey(
        "programs.Run",
        on_delete=models.SET_NULL,
        null=True,
        related_name="attempt_runs",
        verbose_name=_("run"),
    )
    checked = models.BooleanField(_("checked"), default=False)

    class Meta:
        verbose_name = _("attempt run")
        verbose_name_plural = _("attempt runs")
        ordering = ["variant"]
        constraints = [
            models.UniqueConstraint(fields=["attempt", "variant"], name="one_run_a_variant")
        ]
