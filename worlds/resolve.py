"""A sim's world setting, resolved for its driver by the robot's agent.

A ``sim://`` robot names its world in its settings (``"world": ...``) or its URL
(``sim://?world=...``; the settings win, as rhal.connect merges them). The value is:
- a built-in world's name (``maze``, also ``builtin:maze``): passed to the driver as it is;
- a world document itself (a dict: a check sim's, the exercise's world as saved with it);
- a stored world's id (``12``) or name (``my-maze``): the driver gets its document
  (``world=<dict>``), the one saved last. By name, the robot owner's own world of that name,
  else the only one of that name they may see.
Whose worlds a robot may use: its owner's (what its owner may see, worlds.access); a robot
without an owner (the lab's shared sim), the worlds shared with everyone.

robots.agent imports this module; this module imports nothing of robots.agent.
"""

import logging
from urllib.parse import urlsplit

from django.db import transaction
from django.utils.translation import gettext as _

from rhal.errors import RobotConnectionError
from rhal.registry import parse_query_options
from worlds.access import public_worlds, worlds_for_user
from worlds.documents import builtin_worlds
from worlds.models import World

log = logging.getLogger(__name__)

BUILTIN_PREFIX = "builtin:"
#: Where a sim whose world cannot be used is built (never opened: it says why instead).
FALLBACK_WORLD = "boxes"


class WorldUnavailable(RobotConnectionError):
    """The robot's world is unknown, or not one its owner may use: the robot does not open."""


def world_setting(robot):
    """The robot's world setting as written (an int, a name), or None (a sim's default, or not
    a sim)."""
    parts = urlsplit(robot.url)
    if parts.scheme.lower() != "sim":
        return None
    if "world" in robot.settings:
        return robot.settings["world"]
    return parse_query_options(parts.query).get("world")


def builtin_name(value) -> str | None:
    """The built-in world ``value`` names, if it names one."""
    if not isinstance(value, str):
        return None
    name = value.removeprefix(BUILTIN_PREFIX)
    return name if name in builtin_worlds() else None


def usable_worlds(user):
    """The stored worlds a robot of ``user``'s (None: a robot without owner) may be in."""
    return worlds_for_user(user) if user is not None else public_worlds()


def find_world(value, user) -> str | World:
    """The world a setting names, for a robot owned by ``user``: a built-in's name, or the
    stored world; WorldUnavailable saying why not."""
    if (name := builtin_name(value)) is not None:
        return name
    worlds = usable_worlds(user)
    if isinstance(value, int) or (isinstance(value, str) and value.isdigit()):
        found = worlds.filter(pk=int(value)).first()
    elif isinstance(value, str) and value and not value.startswith(BUILTIN_PREFIX):
        found = worlds.filter(owner=user).filter(name=value).first() if user else None
        if found is None:
            named = list(worlds.filter(name=value)[:2])
            if len(named) > 1:
                raise WorldUnavailable(
                    _("several worlds named %(name)s may be used here: give the world's id")
                    % {"name": repr(value)}
                )
            found = named[0] if named else None
    else:
        found = None
    if found is None:
        why = _(
            "no world %(world)s that this robot's owner may use: name a built-in world, or a"
            " stored world of theirs or shared with them (its id or name)"
        )
        raise WorldUnavailable(why % {"world": repr(value)})
    return found


def world_option(robot) -> dict:
    """The robot's driver options (Robot.driver_options) with its stored world's document in
    place of its id or name; WorldUnavailable if it has none it may use."""
    options = robot.driver_options()
    value = world_setting(robot)
    if value is None:
        return options
    if isinstance(value, dict):  # a document itself (a check sim's: robots.check_sims)
        return {**options, "world": value}
    found = find_world(value, robot.owner)
    options["world"] = found if isinstance(found, str) else found.document
    return options


def driver_options(robot) -> tuple[dict, WorldUnavailable | None]:
    """What the agent builds the robot's driver with, and why it must not open it (its world
    unavailable), or None. Not opened, the robot's page says why; it is reconfigured when a
    world it names is saved, shared or unshared."""
    try:
        return world_option(robot), None
    except WorldUnavailable as exc:
        return {**robot.driver_options(), "world": FALLBACK_WORLD}, exc


def options_to_check(robot) -> dict:
    """The driver options an edit of a robot's URL or settings is checked with (by building
    its driver): a stored world it names, by id or name, in place of its id or name, whoever
    owns that world; WorldUnavailable if none has that id or name. Whether the robot's owner
    may use it is the agent's to say, on the robot's page (driver_options)."""
    options = robot.driver_options()
    value = world_setting(robot)
    if value is None:
        return options
    if (name := builtin_name(value)) is not None:
        return {**options, "world": name}
    if isinstance(value, dict):
        return {**options, "world": value}
    if isinstance(value, int) or (isinstance(value, str) and value.isdigit()):
        found = World.objects.filter(pk=int(value)).first()
    else:
        found = World.objects.filter(name=value).first() if isinstance(value, str) else None
    if found is None:
        raise WorldUnavailable(
            _("no world %(world)s (a built-in world's name, or the id or name of a stored world)")
            % {"world": repr(value)}
        )
    return {**options, "world": found.document}


# -- telling the robots in a world that it changed ------------------------------------------


def names_world(value, world: World, names: tuple[str, ...]) -> bool:
    """Whether a setting names ``world`` by id or by one of ``names``."""
    if isinstance(value, int) or (isinstance(value, str) and value.isdigit()):
        return int(value) == world.pk
    return isinstance(value, str) and value in names


def robots_using(world: World, *names: str) -> list[str]:
    """The sims whose world is ``world`` (or names it by id or by ``names``, its names old
    and new: one that could not open may now, one that opened may no longer)."""
    from robots.models import Robot

    names = (world.name, *names)
    using = []
    for robot in Robot.objects.filter(url__istartswith="sim:").select_related("owner"):
        value = world_setting(robot)
        if value is None or builtin_name(value) is not None:
            continue
        try:
            found = find_world(value, robot.owner)
        except WorldUnavailable:
            found = None
        if (found is not None and found.pk == world.pk) or names_world(value, world, names):
            using.append(robot.name)
    return using


def tell_robots(world: World, *names: str) -> None:
    """Once the change is committed, the sims in ``world`` reopen in it as it is now."""
    transaction.on_commit(lambda: reconfigure(robots_using(world, *names), world.name))


def reconfigure(robot_names: list[str], why: str) -> None:
    from robots.bus import reconfigure_sync

    for robot_name in robot_names:
        try:
            reconfigure_sync(robot_name)
        except Exception:  # one robot's bus trouble must not fail the save
            log.exception("world %s: could not tell robot %s", why, robot_name)
