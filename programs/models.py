from functools import partial
from pathlib import Path

from django.conf import settings
from django.db import models, transaction
from django.dispatch import Signal
from django.utils import timezone
from django.utils.text import slugify
from django.utils.translation import gettext, gettext_noop, pgettext_lazy
from django.utils.translation import gettext_lazy as _

from programs.languages import get_language, language_choices

MAX_SOURCE_BYTES = 512 * 1024

#: A run ended (finished, failed, stopped, lost, cancelled while queued), sent once the change
#: is committed, in whichever process marked it (the web tier, or the robot's agent: in fleet
#: mode another process than the web server's): ``run_id``. Receivers keep no state in memory
#: (classroom.receivers checks an attempt's run on its trace).
run_ended = Signal()
#: An agent took a run to start it (Run.claim): ``run_id``, sent once committed.
run_started = Signal()


def _send_after_commit(signal: Signal, run_ids) -> None:
    for run_id in run_ids:
        transaction.on_commit(partial(signal.send_robust, sender=Run, run_id=run_id))


class Program(models.Model):
    owner = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        on_delete=models.CASCADE,
        related_name="programs",
        verbose_name=_("owner"),
    )
    name = models.CharField(_("name"), max_length=100)
    language = models.CharField(_("language"), max_length=20, choices=language_choices)
    source = models.TextField(_("source"), blank=True)
    created = models.DateTimeField(_("created"), default=timezone.now)
    updated = models.DateTimeField(_("updated"), default=timezone.now)
    #: Where it came from, when not written here: "copied from …", "pushed from …", "imported".
    origin = models.CharField(_("origin"), max_length=300, blank=True)

    class Meta:
        verbose_name = _("program")
        verbose_name_plural = _("programs")
        ordering = ["name"]
        constraints = [
            models.UniqueConstraint(fields=["owner", "name"], name="unique_program_name")
        ]

    def __str__(self) -> str:
        return self.name

    @property
    def lang(self):
        return get_language(self.language)

    @property
    def filename(self) -> str:
        return program_filename(self.name, self.language)

    def save_source(self, source: str, author) -> "Revision":
        """Save new text; every save keeps a revision, even an unchanged one is not duplicated."""
        with transaction.atomic():
            self.source = source
            self.updated = timezone.now()
            self.save()
            latest = self.revisions.first()
            if latest is not None and latest.source == source:
                return latest
            number = (latest.number + 1) if latest else 1
            return Revision.objects.create(
                program=self, number=number, source=source, author=author
            )


class Draft(models.Model):
    """What a user typed and has not saved yet, kept by the editor every few seconds: one per
    user and program, apart from the revisions, gone when they save or discard it."""

    user = models.ForeignKey(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, verbose_name=_("user")
    )
    program = models.ForeignKey(
        Program, on_delete=models.CASCADE, related_name="drafts", verbose_name=_("program")
    )
    source = models.TextField(_("source"), blank=True)
    language = models.CharField(_("language"), max_length=20)
    # What the editor started from.
    base_revision = models.PositiveIntegerField(_("base revision"), default=0)
    updated = models.DateTimeField(_("updated"), default=timezone.now)

    class Meta:
        verbose_name = _("draft")
        verbose_name_plural = _("drafts")
        constraints = [
            models.UniqueConstraint(fields=["user", "program"], name="one_draft_per_user")
        ]

    def newer_than_saved(self) -> bool:
        """Worth offering: it differs from the program as saved now."""
        program = self.program
        return self.source != program.source or self.language != program.language


class Revision(models.Model):
    program = models.ForeignKey(
        Program, on_delete=models.CASCADE, related_name="revisions", verbose_name=_("program")
    )
    number = models.PositiveIntegerField(_("number"))
    source = models.TextField(_("source"), blank=True)
    author = models.ForeignKey(
        settings.AUTH_USER_MODEL, on_delete=models.SET_NULL, null=True, verbose_name=_("author")
    )
    created = models.DateTimeField(_("created"), default=timezone.now)

    class Meta:
        verbose_name = _("revision")
        verbose_name_plural = _("revisions")
        ordering = ["-number"]
        constraints = [
            models.UniqueConstraint(fields=["program", "number"], name="unique_revision_number")
        ]

    def __str__(self) -> str:
        return f"{self.program} r{self.number}"


class Run(models.Model):
    class State(models.TextChoices):
        # The values are machine codes (the API, the pages' CSS); the labels are for people.
        QUEUED = "queued", pgettext_lazy("run state", "queued")
        STARTING = "starting", pgettext_lazy("run state", "starting")
        RUNNING = "running", pgettext_lazy("run state", "running")
        FINISHED = "finished", pgettext_lazy("run state", "finished")
        FAILED = "failed", pgettext_lazy("run state", "failed")
        STOPPED = "stopped", pgettext_lazy("run state", "stopped")
        LOST = "lost", pgettext_lazy("run state", "lost")

    # Handed to an agent, which supervises it: lost if that agent goes away.
    ACTIVE = (State.STARTING, State.RUNNING)
    # Not ended: active, or waiting its turn on a busy robot (robots.run_queue). A queued run
    # never started, so an agent that goes away leaves it queued, not lost.
    ONGOING = (State.QUEUED, *ACTIVE)
    #: A queued run an emergency stop held (waiting then, or asked for during the stop): it
    #: stays in line, not started, until its owner starts it again (robots.stops.start_again),
    #: also once the stop is resumed; whatever made someone press it may still be there.
    HELD = "held after an emergency stop"
    #: What HELD said before (rows queued then): read as held too.
    HELD_BEFORE = "the queue is held after an emergency stop; staff or the robot's owner resume it"

    program = models.ForeignKey(
        Program,
        on_delete=models.SET_NULL,
        null=True,
        related_name="runs",
        verbose_name=_("program"),
    )
    # What ran, kept even if the program is edited or deleted later.
    program_name = models.CharField(_("program name"), max_length=100)
    language = models.CharField(_("language"), max_length=20)
    source = models.TextField(_("source"), blank=True)
    args = models.JSONField(_("arguments"), default=list, blank=True)
    # A robot with a history of runs is not deleted with it: runs belong to their users.
    robot = models.ForeignKey(
        "robots.Robot", on_delete=models.PROTECT, related_name="runs", verbose_name=_("robot")
    )
    owner = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        on_delete=models.CASCADE,
        related_name="runs",
        verbose_name=_("owner"),
    )
    state = models.CharField(
        _("state"), max_length=10, choices=State.choices, default=State.STARTING
    )
    exit_code = models.IntegerField(_("exit code"), null=True, blank=True)
    reason = models.CharField(
        _("reason"), max_length=200, blank=True, help_text=_("How the run ended")
    )
    created = models.DateTimeField(_("created"), default=timezone.now)
    started = models.DateTimeField(_("started"), null=True, blank=True)
    ended = models.DateTimeField(_("ended"), null=True, blank=True)
    pid = models.IntegerField("PID", null=True, blank=True, editable=False)
    #: While queued: its place in its robot's queue, lowest first (ties: the older first).
    queue_position = models.PositiveIntegerField(
        _("queue position"), null=True, blank=True, editable=False
    )
    # Its log's storage (runlogs): the bytes it takes on disk, counted against its owner's
    # quota (while it runs, what it may grow to), how it is stored once ended, and when and
    # why it was pruned (the run itself is kept).
    log_bytes = models.BigIntegerField(_("log size (bytes)"), default=0, editable=False)
    log_storage = models.CharField(
        _("log storage"),
        max_length=8,
        blank=True,
        editable=False,
        help_text=_("gzip, or plain (as written: it did not compress); empty until settled"),
    )
    log_pruned_at = models.DateTimeField(_("log pruned"), null=True, blank=True, editable=False)
    log_pruned_reason = models.CharField(
        _("why its log was pruned"), max_length=200, blank=True, editable=False
    )
    #: A hidden variant's run of an exercise's check (classroom.checking): its page, log and
    #: robot are not shown to its owner, only to their teachers and staff (programs.access).
    sealed = models.BooleanField(_("sealed"), default=False, editable=False)
    # A run under the debugger (programs/clients/PROTOCOL.md, "The debugger"): the breakpoints
    # and watches it starts with, {"breakpoints": [{"line": n, "condition": text or null}],
    # "watches": [text]}; null for a plain run. Kept in the row so that an agent that takes the
    # run from the database (untaken_runs) starts it under the debugger too.
    debug = models.JSONField(_("debugger"), null=True, blank=True, editable=False)

    class Meta:
        verbose_name = _("run")
        verbose_name_plural = _("runs")
        ordering = ["-created"]
        indexes = [models.Index(fields=["state"]), models.Index(fields=["robot", "state"])]

    def __str__(self) -> str:
        return gettext("run %(id)s of %(program)s on %(robot)s") % {
            "id": self.pk,
            "program": self.program_name,
            "robot": self.robot_id,
        }

    @property
    def active(self) -> bool:
        return self.state in self.ACTIVE

    @property
    def queued(self) -> bool:
        return self.state == self.State.QUEUED

    @property
    def held(self) -> bool:
        """Queued, held by an emergency stop: it starts only when started again."""
        return self.queued and self.reason in (self.HELD, self.HELD_BEFORE)

    @property
    def ongoing(self) -> bool:
        """Not ended yet: queued, starting or running (it may be stopped or cancelled)."""
        return self.state in self.ONGOING

    @property
    def queue_rank(self) -> int | None:
        """Its place in line, 1 for the next to start; None when not queued."""
        if not self.queued or self.queue_position is None:
            return None
        ahead = models.Q(queue_position__lt=self.queue_position) | models.Q(
            queue_position=self.queue_position, pk__lt=self.pk
        )
        return Run.queue_of(self.robot_id).filter(ahead).count() + 1

    @property
    def queue_place(self) -> str:
        """Its place as the pages say it: "2nd in line"."""
        rank = self.queue_rank
        return in_line(rank) if rank else ""

    @property
    def directory(self) -> Path:
        return self.log_path_of(self.pk).parent

    @property
    def log_path(self) -> Path:
        return self.log_path_of(self.pk)

    @staticmethod
    def log_path_of(run_id: int) -> Path:
        """Where run ``run_id`` logs, known without reading it (programs.watch_pass)."""
        return settings.RUNS_DIR / str(run_id) / "output.log"

    @property
    def duration(self):
        if self.started is None:
            return None
        return (self.ended or timezone.now()) - self.started

    @property
    def reason_note(self) -> str:
        """How the run ended, unless the exit code shown beside it says it all."""
        return "" if self.reason == f"exit status {self.exit_code}" else self.reason_shown

    @property
    def reason_shown(self) -> str:
        """How the run ended, for people: stored in English (data, like its log), the fixed
        wordings shown in the reader's language."""
        return gettext(self.reason) if self.reason in FIXED_REASONS else self.reason

    @property
    def program_file(self) -> str:
        """The name its program ran under (the file its tracebacks name)."""
        return program_filename(self.program_name, self.language)

    @property
    def log_filename(self) -> str:
        return f"{slugify(self.program_name) or 'program'}-run{self.pk}.log"

    @classmethod
    def create_for(
        cls, program: Program, robot, user, args=(), source: str | None = None, sealed=False,
        debug: dict | None = None,
    ) -> "Run":
        """``source``: what runs, if not the program as saved (a checked revision's)."""
        return cls.objects.create(
            program=program,
            program_name=program.name,
            language=program.language,
            source=program.source if source is None else source,
            args=list(args),
            robot=robot,
            owner=user,
            sealed=sealed,
            debug=debug,
        )

    def start_message(self) -> dict:
        """What the agent needs to start it (as start_run hands it over), from the row."""
        filename = self.program_file
        return {
            "run_id": self.pk,
            "language": self.language,
            "source": self.source,
            "filename": filename,
            "args": [str(a) for a in self.args],
            "user": self.owner.get_username(),
            **({"debug": self.debug} if self.debug is not None else {}),
        }

    # -- a robot's queue (robots.run_queue decides; these are its atomic steps) ---------------

    @classmethod
    def queue_of(cls, robot_id: int) -> models.QuerySet:
        """The runs waiting on that robot, the next to start first."""
        return cls.objects.filter(robot_id=robot_id, state=cls.State.QUEUED).order_by(
            "queue_position", "pk"
        )

    @classmethod
    def enqueue(cls, run_id: int, reason: str = "") -> int | None:
        """A run not yet started waits at the end of its robot's queue: its rank, or None
        if it no longer waits to start (stopped or failed meanwhile)."""
        with transaction.atomic():
            run = cls.objects.filter(pk=run_id).only("robot_id").first()
            if run is None:
                return None
            last = cls.queue_of(run.robot_id).aggregate(last=models.Max("queue_position"))
            position = (last["last"] or 0) + 1
            queued = cls.objects.filter(
                pk=run_id, state=cls.State.STARTING, pid__isnull=True
            ).update(state=cls.State.QUEUED, queue_position=position, reason=reason)
            if not queued:
                return None
            return cls.queue_of(run.robot_id).count()

    @classmethod
    def unqueue(cls, run_id: int) -> bool:
        """Its turn: queued -> starting (the agent then claims it); False if it was cancelled."""
        return (
            cls.objects.filter(pk=run_id, state=cls.State.QUEUED).update(
                state=cls.State.STARTING, queue_position=None, reason="", pid=None
            )
            == 1
        )

    @classmethod
    def cancel_queued(cls, run_id: int, reason: str = "cancelled while queued") -> bool:
        """Stop a run that waits its turn; False if it no longer waits (it started)."""
        now = timezone.now()
        cancelled = (
            cls.objects.filter(pk=run_id, state=cls.State.QUEUED).update(
                state=cls.State.STOPPED, queue_position=None, reason=reason, ended=now
            )
            == 1
        )
        if cancelled:
            _send_after_commit(run_ended, [run_id])
        return cancelled

    @classmethod
    def move_in_queue(cls, run_id: int, rank: int) -> int | None:
        """Put a queued run at ``rank`` (1-based, clamped) of its robot's queue, the others
        keeping their order: its rank then, or None if it no longer waits."""
        with transaction.atomic():
            run = cls.objects.filter(pk=run_id, state=cls.State.QUEUED).first()
            if run is None:
                return None
            order = list(
                cls.queue_of(run.robot_id).select_for_update().values_list("pk", flat=True)
            )
            order.remove(run_id)
            rank = max(1, min(rank, len(order) + 1))
            order.insert(rank - 1, run_id)
            for position, pk in enumerate(order, 1):
                cls.objects.filter(pk=pk, state=cls.State.QUEUED).update(queue_position=position)
            return rank

    # -- state changes made by the robot agent ------------------------------------------------

    @classmethod
    def claim(cls, run_id: int, running_pid: int | None = None) -> bool:
        """The agent takes a run that waits to start; False if it no longer waits. With its
        program's pid (the program under way), marked running in the same write."""
        waiting = cls.objects.filter(pk=run_id, state=cls.State.STARTING, pid__isnull=True)
        if running_pid is None:
            taken = waiting.update(pid=0) == 1
        else:
            running = {"state": cls.State.RUNNING, "pid": running_pid, "started": timezone.now()}
            taken = waiting.update(**running) == 1
        if taken:
            _send_after_commit(run_started, [run_id])
        return taken

    @classmethod
    def mark_ended(cls, run_id: int, state: str, exit_code: int | None, reason: str) -> None:
        now = timezone.now()
        # A run already marked lost stays lost: its end was never seen.
        cls.objects.filter(pk=run_id).exclude(state=cls.State.LOST).update(
            state=state, exit_code=exit_code, reason=reason[:200], ended=now
        )
        cls.objects.filter(pk=run_id, started__isnull=True).update(started=now)
        _send_after_commit(run_ended, [run_id])

    @staticmethod
    def tell_ended(run_ids) -> None:
        """``run_ended`` for runs marked ended by an update of their own (robots.presence)."""
        _send_after_commit(run_ended, run_ids)

    @classmethod
    def mark_lost(cls, robot_name: str) -> list[int]:
        """Runs a dead agent left unfinished: nothing is supervising them any more.
        Queued runs are not among them: they never started, and wait for the agent again;
        nor runs no agent has taken yet (asked of a robot whose agent is only starting:
        their run.start waits for it; the presence watch fails one nobody takes)."""
        active = cls.objects.filter(robot__name=robot_name, state__in=cls.ACTIVE)
        untaken = models.Q(state=cls.State.STARTING, pid__isnull=True)
        lost = list(active.exclude(untaken).values_list("pk", flat=True))
        cls.objects.filter(pk__in=lost).update(
            state=cls.State.LOST,
            reason="its robot agent stopped while it ran",
            ended=timezone.now(),
        )
        _send_after_commit(run_ended, lost)
        return lost


def ordinal(n: int) -> str:
    """1st, 2nd, 3rd, 4th, 11th, 21st... (in Portuguese 1º, 2º: the suffixes are translated)."""
    suffix = "th" if 10 <= n % 100 <= 20 else {1: "st", 2: "nd", 3: "rd"}.get(n % 10, "th")
    return f"{n}{ORDINAL_SUFFIXES[suffix]}"


ORDINAL_SUFFIXES = {
    "st": pgettext_lazy("ordinal suffix, as in 1st", "st"),
    "nd": pgettext_lazy("ordinal suffix, as in 2nd", "nd"),
    "rd": pgettext_lazy("ordinal suffix, as in 3rd", "rd"),
    "th": pgettext_lazy("ordinal suffix, as in 4th", "th"),
}


def in_line(rank: int) -> str:
    """A queued run's place: "2nd in line"."""
    return gettext("%(place)s in line") % {"place": ordinal(rank)}


#: Reasons a run ended that are always the same words: kept in English in the database and
#: translated where shown (Run.reason_note).
FIXED_REASONS = (
    gettext_noop("the queue is held after an emergency stop; staff or the robot's owner resume it"),
    gettext_noop("held after an emergency stop"),
    gettext_noop("cancelled while queued"),
    gettext_noop("its robot agent stopped while it ran"),
)


class Share(models.Model):
    """A program shared with one user, one group (a class), or everyone (the gallery)."""

    program = models.ForeignKey(
        Program, on_delete=models.CASCADE, related_name="shares", verbose_name=_("program")
    )
    user = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        null=True,
        blank=True,
        on_delete=models.CASCADE,
        related_name="shared_with_me",
        verbose_name=_("user"),
    )
    group = models.ForeignKey(
        "auth.Group",
        null=True,
        blank=True,
        on_delete=models.CASCADE,
        related_name="shares",
        verbose_name=_("class"),
    )
    everyone = models.BooleanField(_("everyone"), default=False)
    can_edit = models.BooleanField(_("may edit"), default=False)
    created_by = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        null=True,
        on_delete=models.SET_NULL,
        related_name="+",
        verbose_name=_("created by"),
    )
    created = models.DateTimeField(_("created"), default=timezone.now)

    class Meta:
        verbose_name = _("share")
        verbose_name_plural = _("shares")
        ordering = ["created"]
        constraints = [
            models.CheckConstraint(
                name="share_has_one_target",
                condition=(
                    models.Q(user__isnull=False, group__isnull=True, everyone=False)
                    | models.Q(user__isnull=True, group__isnull=False, everyone=False)
                    | models.Q(user__isnull=True, group__isnull=True, everyone=True)
                ),
            ),
            models.UniqueConstraint(
                fields=["program", "user"], condition=models.Q(user__isnull=False),
                name="one_share_per_user",
            ),
            models.UniqueConstraint(
                fields=["program", "group"], condition=models.Q(group__isnull=False),
                name="one_share_per_group",
            ),
            models.UniqueConstraint(
                fields=["program"], condition=models.Q(everyone=True),
                name="one_share_with_everyone",
            ),
        ]  # fmt: skip

    def __str__(self) -> str:
        return f"{self.program} -> {self.target}"

    @property
    def target(self) -> str:
        if self.everyone:
            return gettext("everyone")
        if self.group_id:
            return gettext("group %(name)s") % {"name": self.group.name}
        return gettext("user %(name)s") % {"name": self.user.username}


#: Names of the Robot API clients' modules: a program saved under one of them would be found
#: by its own ``import robot`` (Python and Lua look beside the program first).
CLIENT_MODULES = ("robot",)


def program_filename(name: str, language: str) -> str:
    """The file a program runs as: its name, made safe, never a client module's."""
    stem = slugify(name) or "program"
    if stem in CLIENT_MODULES:
        stem += "-program"
    return stem + get_language(language).extension
