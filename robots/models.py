from django.db import models
from django.http import Http404
from django.utils import timezone

# Robot settings a staff member may set; anything else in `settings` is passed to the driver.
SPEED_SETTINGS = ("max_linear", "max_angular")


class Robot(models.Model):
    """A robot this appliance controls; its agent owns the hardware behind `url`."""

    name = models.SlugField(max_length=50, unique=True)
    url = models.CharField(
        max_length=500, help_text="Driver URL, e.g. sim:// or pioneer:///dev/ttyUSB0"
    )
    settings = models.JSONField(default=dict, blank=True)
    description = models.CharField(max_length=200, blank=True)
    created = models.DateTimeField(default=timezone.now)
    last_seen = models.DateTimeField(null=True, blank=True, editable=False)

    class Meta:
        ordering = ["name"]

    def __str__(self) -> str:
        return self.name

    @property
    def agent_channel(self) -> str:
        return agent_channel(self.name)

    @property
    def group(self) -> str:
        return robot_group(self.name)

    def driver_options(self) -> dict:
        """Options for rhal.connect(): the robot's settings minus the run limits."""
        return {k: v for k, v in self.settings.items() if k != "limits"}

    def run_limits(self, defaults: dict) -> dict:
        return {**defaults, **self.settings.get("limits", {})}


def agent_channel(name: str) -> str:
    return f"agent.{name}"


def robot_group(name: str) -> str:
    return f"robot-{name}"


def get_robot_for_user(user, name: str) -> Robot:
    """Every signed-in user may use every robot (group restrictions come with the lab roles)."""
    if not user.is_authenticated:
        raise Http404("No such robot.")
    try:
        return Robot.objects.get(name=name)
    except Robot.DoesNotExist:
        raise Http404(f"No robot named {name!r}.") from None
