"""Sharing a world with a user, a class or everyone: programs.shares' targets, for worlds.

Only the owner (or an admin) shares; access is decided in worlds.access on every request, so
removing a share takes the world away at once (and from the sims in it: worlds.resolve).
"""

from django.db import transaction
from django.utils.translation import gettext as _

from programs.shares import ShareError, share_target
from worlds.models import World, WorldShare
from worlds.resolve import tell_robots

__all__ = ["ShareError", "add_share", "remove_share"]


def add_share(world: World, by, *, user: str = "", group: str = "", everyone: bool = False):
    """Share with exactly one of a user (by name), a class (by name) or everyone."""
    owned = _("a world is always shared with its owner")
    target = share_target(world.owner, owned, user=user, group=group, everyone=everyone)
    with transaction.atomic():
        share, _created = WorldShare.objects.get_or_create(
            world=world, **target, defaults={"created_by": by}
        )
        tell_robots(world)  # a sim that could not use it may now
    return share


def remove_share(world: World, share: WorldShare) -> None:
    with transaction.atomic():
        share.delete()
        tell_robots(world)  # a sim that used it may no longer
