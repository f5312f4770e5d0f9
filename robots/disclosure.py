"""What of a robot's setup each viewer sees.

A real robot's settings and URL may hold device paths, hosts, and credentials. Its owner and
staff, who set them, see them (a password in the URL never: it is masked); everyone else who
may use the robot sees the kind of robot it is (its driver, ``pioneer://``) and no settings.
The same for how its programs are boxed (Robot.isolation): an administrator's line, with the
machine's cgroup paths and names in it, for its owner and staff; one plain sentence for others.
Used by the API (robots.api) and the robot's pages (robots.views).
"""

from urllib.parse import urlsplit, urlunsplit

from django.utils.translation import gettext as _

from robots.isolation_words import is_box, isolation_shown
from robots.models import Robot

MASK = "***"


def sees_setup(user, robot: Robot) -> bool:
    return user.is_authenticated and robot.configurable_by(user)


def settings_shown(user, robot: Robot) -> dict:
    """Its settings for its owner and staff; {} for anyone else."""
    return robot.settings if sees_setup(user, robot) else {}


def url_shown(user, robot: Robot) -> str:
    """Its URL without the password for its owner and staff; its driver alone for others."""
    if sees_setup(user, robot):
        return without_password(robot.url)
    return f"{urlsplit(robot.url).scheme}://"


def without_password(url: str) -> str:
    """``url`` with the password of its user part, if any, masked."""
    parts = urlsplit(url)
    if parts.password is None:
        return url
    host = parts.netloc.rpartition("@")[2]
    return urlunsplit(parts._replace(netloc=f"{parts.username or ''}:{MASK}@{host}"))


def isolation_line(user, robot: Robot) -> str:
    """How its programs are boxed, in the reader's language: runbox's whole line for its owner
    and staff, one plain sentence for others."""
    if not robot.isolation:
        return _("Programs run: (agent not started yet)")
    if sees_setup(user, robot):
        return _("Programs run: %(isolation)s") % {"isolation": isolation_shown(robot.isolation)}
    return plain_isolation(robot)


def plain_isolation(robot: Robot) -> str:
    if is_box(robot.isolation):
        return _("Programs run in a sandbox: each apart from the others and from the server.")
    # runbox's reason may name the machine's paths: its owner and staff read it.
    return _("Programs cannot run on this robot now: its owner or staff can see why.")


def isolation_api(user, robot: Robot) -> str:
    """Robot.isolation as runbox wrote it for its owner and staff; the plain sentence else."""
    if sees_setup(user, robot) or not robot.isolation:
        return robot.isolation
    return plain_isolation(robot)
