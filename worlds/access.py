"""Who may see and change a stored world: as for programs (programs.access), with the same
notions of sharing.

- see it: its owner; whoever it is shared with (a user, a class they belong to, everyone);
  the teachers of a class its owner belongs to; admins;
- change, rename, share or delete it: its owner and admins.

Built-in worlds (rhal.simulator.worlds.BUILTIN) are everyone's to see and nobody's to change.
"""

from django.core.exceptions import PermissionDenied
from django.db.models import Q, QuerySet
from django.http import Http404
from django.utils.translation import gettext as _

from programs.access import OWN, READ, taught_groups
from worlds.models import World

__all__ = ["OWN", "READ", "get_world_for_user", "worlds_for_user"]


def worlds_for_user(user, level: str = READ) -> QuerySet:
    """The worlds ``user`` may see (``READ``) or own (``OWN``)."""
    if user is None or not user.is_authenticated:
        return World.objects.none()
    qs = World.objects.select_related("owner")
    if user.is_superuser:
        return qs
    if level == OWN:
        return qs.filter(owner=user)
    shared = (
        Q(shares__user=user) | Q(shares__group__in=user.groups.all()) | Q(shares__everyone=True)
    )
    taught = Q(owner__groups__in=taught_groups(user))
    return qs.filter(Q(owner=user) | shared | taught).distinct()


def public_worlds() -> QuerySet:
    """The worlds shared with everyone: what a robot without an owner may use."""
    return World.objects.filter(shares__everyone=True).select_related("owner").distinct()


def get_world_for_user(user, pk, level: str = READ) -> World:
    """The world: 404 if ``user`` may not see it, 403 if they see it but may not change it."""
    try:
        world = worlds_for_user(user).get(pk=pk)
    except (World.DoesNotExist, ValueError, TypeError):
        raise Http404(_("No such world.")) from None
    if level != READ and not worlds_for_user(user, level).filter(pk=world.pk).exists():
        raise PermissionDenied(_("You may see this world but not change it."))
    return world
