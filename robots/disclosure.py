"""What of a robot's setup each viewer sees.

A real robot's settings and URL may hold device paths, hosts, and credentials. Its owner and
staff, who set them, see them (a password in the URL never: it is masked); everyone else who
may use the robot sees the kind of robot it is (its driver, ``pioneer://``) and no settings.
Used by the API (robots.api) and the robot's pages (robots.views).
"""

from urllib.parse import urlsplit, urlunsplit

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
