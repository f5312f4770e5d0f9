"""Sharing a program with a user, a class or everyone, and saving a copy of one.

Only the owner (or an admin) shares; access itself is decided in programs/access.py, which
reads these rows on every request, so removing a share takes access away at once.
"""

from django.contrib.auth import get_user_model
from django.contrib.auth.models import Group
from django.db import transaction
from django.utils.translation import gettext as _

from programs.forms import free_name
from programs.models import Program, Share
from robotide import names


class ShareError(ValueError):
    """A share that cannot be made: no such user or class, or no target."""


def share_target(owner, owned: str, *, user: str = "", group: str = "", everyone: bool = False):
    """The one target a share names (a user or a class by name, or everyone), as the fields
    of a share row (programs' and worlds'); `owned` is the refusal of a share with `owner`."""
    if sum([bool(user), bool(group), bool(everyone)]) != 1:
        raise ShareError(_("share with one of: a user, a group, or everyone"))
    if why := names.problem(user) or names.problem(group):
        raise ShareError(why)
    if user:
        found = get_user_model().objects.filter(username=user).first()
        if found is None:
            raise ShareError(_("no user named %(name)s") % {"name": repr(user)})
        if found == owner:
            raise ShareError(owned)
        return {"user": found}
    if group:
        found = Group.objects.filter(name=group).first()
        if found is None:
            raise ShareError(_("no group named %(name)s") % {"name": repr(group)})
        return {"group": found}
    return {"everyone": True}


def add_share(
    program: Program, by, *, user: str = "", group: str = "", everyone: bool = False,
    can_edit: bool = False,
) -> Share:  # fmt: skip
    """Share with exactly one of a user (by name), a class (by name) or everyone; sharing
    again with the same target changes whether they may edit."""
    owned = _("a program is always shared with its owner")
    target = share_target(program.owner, owned, user=user, group=group, everyone=everyone)
    share, _created = Share.objects.update_or_create(
        program=program, **target, defaults={"can_edit": can_edit, "created_by": by}
    )
    return share


def copy_program(program: Program, user, name: str = "") -> Program:
    """Save as: a program of ``user``'s with the same source, saying where it came from."""
    with transaction.atomic():
        copy = Program.objects.create(
            owner=user,
            name=free_name(user, (name or program.name).strip() or program.name),
            language=program.language,
            origin=f"copied from {program.owner.username}'s {program.name!r}"[:300],
        )
        copy.save_source(program.source, user)
    return copy
