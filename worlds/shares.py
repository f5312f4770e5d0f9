"""Sharing a world with a user, a class or everyone: programs.shares' targets, for worlds.

Only the owner (or an admin) shares; access is decided in worlds.access on every request, so
removing a share takes the world away at once (and from the sims in it: worlds.resolve).
"""

from django.contrib.auth import get_user_model
from django.contrib.auth.models import Group
from django.db import transaction
from django.utils.translation import gettext as _

from programs.shares import ShareError
from robotide import names
from worlds.models import World, WorldShare
from worlds.resolve import tell_robots

__all__ = ["ShareError", "add_share", "remove_share"]


def add_share(world: World, by, *, user: str = "", group: str = "", everyone: bool = False):
    """Share with exactly one of a user (by name), a class (by name) or everyone."""
    if sum([bool(user), bool(group), bool(everyone)]) != 1:
        raise ShareError(_("share with one of: a user, a group, or everyone"))
    if why := names.problem(user) or names.problem(group):
        raise ShareError(why)
    target = {"everyone": True}
    if user:
        found = get_user_model().objects.filter(username=user).first()
        if found is None:
            raise ShareError(_("no user named %(name)s") % {"name": repr(user)})
        if found == world.owner:
            raise ShareError(_("a world is always shared with its owner"))
        target = {"user": found}
    elif group:
        found = Group.objects.filter(name=group).first()
        if found is None:
            raise ShareError(_("no group named %(name)s") % {"name": repr(group)})
        target = {"group": found}
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
