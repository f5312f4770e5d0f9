import shlex

from django.conf import settings as django_settings
from django.db import models
from django.http import Http404
from django.utils import timezone
from django.utils.translation import gettext, gettext_noop
from django.utils.translation import gettext_lazy as _

from robotide import names
from robots.isolation_words import isolation_shown

# Settings for the runs on a robot; anything else in its `settings` goes to its driver.
RUN_SETTINGS = (
    "limits", "isolation", "network", "tmp_mb", "loopback_ports", "allow_networks", "camera",
    "speech", "queue_turn_seconds", "runs_at_once", "start_each_run", "check",
)  # fmt: skip


WHO = [
    ("everyone", _("everyone who may see it")),
    ("teachers", _("the teachers of its classes, its owner and staff")),
    ("owner", _("its owner and staff")),
]


#: Descriptions robotide gives the robots it makes (robotide.cli's sims): stored in English,
#: translated where shown (Robot.description_shown).
DESCRIPTIONS = (gettext_noop("Simulated robot"),)


class Robot(models.Model):
    """A robot this appliance controls; its agent owns the hardware behind `url`."""

    name = models.SlugField(_("name"), max_length=50, unique=True)
    url = models.CharField(
        "URL", max_length=500, help_text=_("Driver URL, e.g. sim:// or pioneer:///dev/ttyUSB0")
    )
    settings = models.JSONField(_("settings"), default=dict, blank=True)
    description = models.CharField(_("description"), max_length=200, blank=True)
    created = models.DateTimeField(_("created"), default=timezone.now)
    last_seen = models.DateTimeField(
        _("last seen"),
        null=True,
        blank=True,
        editable=False,
        help_text=_("Its agent's last heartbeat"),
    )
    agent_host = models.CharField(
        _("agent host"),
        max_length=200,
        blank=True,
        editable=False,
        help_text=_("Where its agent runs"),
    )
    agent_started = models.DateTimeField(_("agent started"), null=True, blank=True, editable=False)
    isolation = models.CharField(
        _("isolation"),
        max_length=1000,  # runbox.isolation.InForce.describe: a rootless box says a lot
        blank=True,
        editable=False,
        help_text=_("What its agent gives each run"),
    )
    isolation_runs_at_once = models.PositiveSmallIntegerField(
        _("runs at once (isolation)"),
        null=True,
        blank=True,
        editable=False,
        help_text=_("How many runs its agent's isolation allows at once; empty: no limit"),
    )
    groups = models.ManyToManyField(
        "auth.Group",
        blank=True,
        related_name="robots",
        verbose_name=_("classes"),
        help_text=_("Only these classes (and their teachers) may use it; none: everyone"),
    )
    owner = models.ForeignKey(
        django_settings.AUTH_USER_MODEL,
        null=True,
        blank=True,
        on_delete=models.SET_NULL,
        related_name="robots",
        verbose_name=_("owner"),
        help_text=_("Who looks after it: with staff, configures its buttons"),
    )

    gateway_seeded = models.BooleanField(
        _("gateway seeded"),
        default=False,
        editable=False,
        help_text=_("Its default gateway endpoints were made"),
    )
    # Who may move it, among those who may see it (its classes). Safety first: everyone who
    # sees a robot may stop it unless its owner says otherwise.
    drive_by = models.CharField(
        _("who may drive it"), max_length=10, choices=WHO, default="everyone",
        help_text=_("Who may drive it, with programs or by hand"),
    )  # fmt: skip
    estop_by = models.CharField(
        _("who may stop it"), max_length=10, choices=WHO, default="everyone",
        help_text=_("Who may press its emergency stop"),
    )  # fmt: skip
    # A personal sim (robots.sims): a user's own simulated robot. Its owner, staff and the
    # teachers of its owner's classes see, drive and stop it, whatever the fields above say;
    # only its owner runs programs on it (no queue). An idle one is removed ("reaped"): its
    # row stays while runs name it (their logs are kept), out of every list and agent.
    personal = models.BooleanField(
        _("personal sim"), default=False, editable=False,
        help_text=_("A user's own simulated robot: only they, their teachers and staff see it"),
    )  # fmt: skip
    twin_of = models.CharField(
        _("twin of"), max_length=50, blank=True, editable=False,
        help_text=_("The robot whose speeds and sensors it copies"),
    )  # fmt: skip
    used = models.DateTimeField(
        _("last used"), null=True, blank=True, editable=False,
        help_text=_("A personal sim: made, chosen, reset or run on"),
    )  # fmt: skip
    reaped = models.DateTimeField(
        _("removed"), null=True, blank=True, editable=False,
        help_text=_("A personal sim removed (idle, or by its owner); kept for its runs"),
    )  # fmt: skip
    # A check sim (robots.check_sims): a personal sim made for one variant's run of an
    # exercise's Check, in the exercise's world at the variant's start pose; out of every list
    # and cap of personal sims, seen by staff and the owner's teachers only (never its owner:
    # a hidden variant's pose), removed once its run ended and its trace was saved.
    checking = models.BooleanField(
        _("check sim"), default=False, editable=False,
        help_text=_("A sim made for one run of an exercise's check, removed after it"),
    )  # fmt: skip

    class Meta:
        verbose_name = _("robot")
        verbose_name_plural = _("robots")
        ordering = ["name"]

    def __str__(self) -> str:
        return self.name

    @property
    def description_shown(self) -> str:
        """Its description in the reader's language when it is one robotide wrote (the sim's
        "Simulated robot", made by `robotide up`); one a person wrote, as written."""
        return gettext(self.description) if self.description in DESCRIPTIONS else self.description

    @property
    def isolation_shown(self) -> str:
        """How its programs are boxed, in the reader's language (stored as runbox says it)."""
        return isolation_shown(self.isolation)

    @property
    def online(self) -> bool:
        """Its agent sent a heartbeat within AGENT_OFFLINE_AFTER seconds."""
        if self.last_seen is None:
            return False
        age = (timezone.now() - self.last_seen).total_seconds()
        return age < django_settings.AGENT_OFFLINE_AFTER

    def configurable_by(self, user) -> bool:
        """Staff, and who looks after it (not a check sim's owner: it is not theirs to see)."""
        owner = self.owner_id is not None and self.owner_id == user.pk and not self.checking
        return user.is_staff or owner

    def drivable_by(self, user) -> bool:
        """Run programs on it and drive it by hand (seeing it is checked apart)."""
        return self._allows(self.drive_by, user)

    def stoppable_by(self, user) -> bool:
        """Press its emergency stop."""
        return self._allows(self.estop_by, user)

    def runs_programs_of(self, user) -> bool:
        """Whose programs may run on it, among those who may drive it: a personal sim's
        owner's alone (nobody queues for it)."""
        return not self.personal or self.owner_id == user.pk

    def _allows(self, who: str, user) -> bool:
        if not user.is_authenticated:
            return False
        if self.personal:  # its owner, staff, the teachers of its owner's classes
            return self.configurable_by(user) or taught_by(self.owner_id, user)
        if who == "everyone" or self.configurable_by(user):
            return True
        if who == "teachers":
            return self.groups.filter(teachers__user=user).exists()
        return False

    def driver_options(self) -> dict:
        """Options for rhal.connect(): the robot's settings but those for its runs."""
        return {k: v for k, v in self.settings.items() if k not in RUN_SETTINGS}

    def run_limits(self, defaults: dict) -> dict:
        return {**defaults, **self.settings.get("limits", {})}

    def run_isolation(self, defaults: dict) -> dict:
        return {**defaults, **{k: v for k, v in self.settings.items() if k in defaults}}


class RobotStop(models.Model):
    """An emergency stop pressed, or a robot let move again after one: who, when, what ran."""

    robot = models.ForeignKey(
        Robot, on_delete=models.CASCADE, related_name="stops", verbose_name=_("robot")
    )
    kind = models.CharField(_("kind"), max_length=10, choices=[
        ("estop", _("emergency stop")), ("resume", _("resumed"))])  # fmt: skip
    user = models.ForeignKey(
        django_settings.AUTH_USER_MODEL,
        null=True,
        on_delete=models.SET_NULL,
        related_name="+",
        verbose_name=_("user"),
    )
    username = models.CharField(_("user name"), max_length=150, help_text=_("As it was then"))
    at = models.DateTimeField(_("at"), default=timezone.now)
    via = models.CharField(_("via"), max_length=20, help_text=_("the robot's page, the API..."))
    # The runs it ended: [{"run": id, "owner": name, "program": name}].
    runs = models.JSONField(_("runs"), default=list, blank=True)
    note = models.CharField(
        _("note"), max_length=300, blank=True, help_text=_("e.g. its agent unreachable")
    )

    class Meta:
        verbose_name = _("emergency stop")
        verbose_name_plural = _("emergency stops")
        ordering = ["-at", "-pk"]

    def __str__(self) -> str:
        return gettext("%(kind)s of %(robot)s by %(user)s at %(at)s") % {
            "kind": self.get_kind_display(),
            "robot": self.robot,
            "user": self.username,
            "at": f"{self.at:%c}",
        }

    @property
    def via_shown(self) -> str:
        """Where it was pressed, for people: stored in English, shown translated."""
        return gettext(self.via) if self.via in VIAS else self.via

    @classmethod
    def pressed(cls, robot_id: int) -> "RobotStop | None":
        """The robot's emergency stop in force (pressed and not resumed since), if any."""
        last = cls.objects.filter(robot_id=robot_id).first()
        return last if last is not None and last.kind == "estop" else None

    @classmethod
    def pressed_by_others(cls, robot_id: int, user) -> bool:
        """Whether someone else pressed the robot's stop since it was last resumed."""
        presses = cls.objects.filter(robot_id=robot_id, kind="estop")
        resumed = cls.objects.filter(robot_id=robot_id, kind="resume").first()
        if resumed is not None:
            presses = presses.filter(pk__gt=resumed.pk)
        return presses.exclude(user_id=user.pk).exists()


#: Where a stop or resume came from (RobotStop.via): stored in English, shown translated.
VIAS = (
    gettext_noop("the robot's page"),
    gettext_noop("the workbench"),
    gettext_noop("the API"),
)


class RobotButton(models.Model):
    """A manual command on the robot's page: one click runs a program with arguments."""

    robot = models.ForeignKey(
        Robot, on_delete=models.CASCADE, related_name="buttons", verbose_name=_("robot")
    )
    label = models.CharField(_("label"), max_length=40)
    program = models.ForeignKey(
        "programs.Program", on_delete=models.CASCADE, related_name="+", verbose_name=_("program")
    )
    args = models.JSONField(_("arguments"), default=list, blank=True)
    position = models.PositiveSmallIntegerField(_("position"), default=0)

    class Meta:
        verbose_name = _("button")
        verbose_name_plural = _("buttons")
        ordering = ["position", "label"]
        constraints = [
            models.UniqueConstraint(fields=["robot", "label"], name="unique_button_label")
        ]

    def __str__(self) -> str:
        return f"{self.robot.name}: {self.label}"

    @property
    def arguments(self) -> str:
        """The arguments as they would be typed: ``dock 'bay two'``."""
        return shlex.join(self.args)


class GatewayEndpoint(models.Model):
    """One more endpoint of a MAVLink robot's router: a ground station, programs, a radio."""

    ROLES = [
        ("", _("added")),
        ("gcs", _("ground stations")),
        ("programs", _("programs on this robot")),
    ]

    robot = models.ForeignKey(
        Robot, on_delete=models.CASCADE, related_name="endpoints", verbose_name=_("robot")
    )
    type = models.CharField(
        _("type"), max_length=10, choices=[(t, t) for t in ("udp", "tcp", "serial")]
    )
    mode = models.CharField(
        _("mode"),
        max_length=10,
        blank=True,
        choices=[("server", _("server (listens)")), ("client", _("client"))],
    )
    address = models.CharField(
        _("address"), max_length=200, blank=True, help_text=_("HOST:PORT (UDP, TCP)")
    )
    device = models.CharField(
        _("device"), max_length=200, blank=True, help_text=_("serial device path")
    )
    baud = models.PositiveIntegerField(_("baud"), null=True, blank=True)
    read_only = models.BooleanField(
        _("read only"), default=False, help_text=_("Receives everything; what it sends is dropped")
    )
    allow = models.JSONField(
        _("allow"),
        null=True,
        blank=True,
        help_text=_("Only these message ids pass (JSON list); empty: all"),
    )
    block = models.JSONField(
        _("block"), default=list, blank=True, help_text=_("These message ids never pass")
    )
    control = models.CharField(
        _("control"), max_length=10, default="always",
        choices=[("always", _("always")), ("lease", _("while no program holds the robot")),
                 ("never", _("never: telemetry and reads only"))],
        help_text=_("May what it sends command the vehicle (arm, modes, setpoints...)"),
    )  # fmt: skip
    role = models.CharField(_("role"), max_length=10, blank=True, choices=ROLES, editable=False)
    created = models.DateTimeField(_("created"), default=timezone.now, editable=False)

    class Meta:
        verbose_name = _("MAVLink gateway endpoint")
        verbose_name_plural = _("MAVLink gateway endpoints")
        ordering = ["robot", "id"]

    def __str__(self) -> str:
        from gateway.specs import describe

        try:
            return f"{self.robot.name}: {describe(self.spec())}"
        except (KeyError, ValueError):
            return gettext("%(robot)s: endpoint %(id)s") % {"robot": self.robot.name, "id": self.pk}

    def spec(self) -> dict:
        """As gateway.specs describes endpoints."""
        spec = {"type": self.type, "read_only": self.read_only, "allow": self.allow}
        spec["block"], spec["control"] = self.block or [], self.control
        if self.type == "serial":
            spec.update(device=self.device, baud=self.baud)
        else:
            spec.update(mode=self.mode, address=self.address)
        return spec

    def set_spec(self, spec: dict) -> None:
        """From a spec gateway.specs.check has cleaned."""
        self.type = spec["type"]
        self.mode, self.address = spec.get("mode", ""), spec.get("address", "")
        self.device, self.baud = spec.get("device", ""), spec.get("baud")
        self.read_only, self.allow, self.block = spec["read_only"], spec["allow"], spec["block"]
        self.control = spec.get("control", "always")


class SerialBridge(models.Model):
    """A serial device of the robot shared over TCP, raw or RFC 2217 (gateway.serial_bridge)."""

    robot = models.ForeignKey(
        Robot, on_delete=models.CASCADE, related_name="bridges", verbose_name=_("robot")
    )
    device = models.CharField(
        _("device"),
        max_length=200,
        blank=True,
        help_text=_("Serial device path; empty: the robot's own"),
    )
    baud = models.PositiveIntegerField(_("baud"), default=9600)
    address = models.CharField(
        _("address"), max_length=200, help_text=_("HOST:PORT the bridge listens on")
    )
    protocol = models.CharField(
        _("protocol"),
        max_length=10,
        default="raw",
        choices=[("raw", _("raw bytes")), ("rfc2217", "RFC 2217")],
    )
    when_busy = models.CharField(
        _("when busy"),
        max_length=10,
        default="read_only",
        choices=[("read_only", _("watch read-only")), ("refuse", _("refuse"))],
        help_text=_("A client that comes while a program drives the robot"),
    )
    created = models.DateTimeField(_("created"), default=timezone.now, editable=False)

    class Meta:
        verbose_name = _("serial bridge")
        verbose_name_plural = _("serial bridges")
        ordering = ["robot", "id"]

    def __str__(self) -> str:
        return gettext("%(robot)s: %(device)s on %(address)s") % {
            "robot": self.robot.name,
            "device": self.device or gettext("its serial port"),
            "address": self.address,
        }


def agent_channel(name: str) -> str:
    return f"{django_settings.CHANNEL_NAMESPACE}agent.{name}"


def manager_channel() -> str:
    """Where `robotide agent` hears of robots added (robots.bus.robot_added)."""
    return f"{django_settings.CHANNEL_NAMESPACE}agents.manager"


def robot_group(name: str) -> str:
    return f"robot-{name}"


def taught_by(student_id: int | None, user) -> bool:
    """Whether ``user`` teaches a class of the user numbered ``student_id``."""
    from django.contrib.auth.models import Group

    return Group.objects.filter(user=student_id, teachers__user=user).exists()


def robots_for_user(user, reaped: bool = False):
    """The robots ``user`` may use: those of no class in particular, those of their classes
    (as a member or a teacher), those they own, and all of them for admins. Personal sims:
    to their owners, staff and the teachers of their owners' classes only. Removed sims
    (``reaped``) are left out unless asked for; check sims always (get_robot_for_user finds
    one for those who may see it)."""
    if not user.is_authenticated:
        return Robot.objects.none()
    robots = Robot.objects.filter(checking=False)
    robots = robots if reaped else robots.filter(reaped__isnull=True)
    if user.is_superuser:
        return robots
    Q = models.Q
    classes = Q(groups__user=user) | Q(groups__teachers__user=user)
    shared = Q(personal=False) & (Q(groups__isnull=True) | classes)
    # who looks after it sees it, whatever its classes (a personal sim: its owner)
    seen = shared | Q(owner=user)
    if user.is_staff:
        seen |= Q(personal=True)
    else:  # a student's sim, to the teachers of the student's classes
        seen |= Q(personal=True, owner__groups__teachers__user=user)
    return robots.filter(seen).distinct()


def check_sims_for_user(user):
    """The check sims (robots.check_sims) ``user`` may see: staff's, and those of the students
    of the classes they teach; never their owner's (a hidden variant's world and pose)."""
    sims = Robot.objects.filter(checking=True)
    if not user.is_authenticated:
        return sims.none()
    if user.is_staff or user.is_superuser:
        return sims
    return sims.filter(owner__groups__teachers__user=user).exclude(owner=user).distinct()


def get_robot_for_user(user, name: str) -> Robot:
    try:
        if names.problem(name):  # none is named so, and PostgreSQL cannot look for NUL
            raise Robot.DoesNotExist
        found = robots_for_user(user).filter(name=name).first()
        if found is None:  # out of every list: found by name by whoever may see it
            found = check_sims_for_user(user).filter(name=name, reaped__isnull=True).first()
        if found is None:
            raise Robot.DoesNotExist
        return found
    except Robot.DoesNotExist:
        removed = robots_for_user(user, reaped=True).filter(name=name, reaped__isnull=False)
        if not names.problem(name) and removed.exists():
            raise Http404(
                gettext(
                    "The simulated robot %(name)s was removed (unused for a while, or deleted"
                    " by its owner); its runs and their logs are kept."
                )
                % {"name": name}
            ) from None
        raise Http404(gettext("No robot named %(name)s.") % {"name": repr(name)}) from None
