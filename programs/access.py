"""The one place that decides who may see and use a program or a run.

Views, API endpoints and consumers fetch objects only through these helpers, so pages, the API
and websockets answer alike, and an unshared program is gone from all of them at once.

Who sees what:
- a program: its owner; whoever it is shared with (a user, a class they belong to, everyone);
  the teachers of a class its owner belongs to; admins (superusers);
- to edit it: its owner, whoever a share says may edit it, admins;
- to delete, rename or share it: its owner and admins;
- a run: who started it, the teachers of that person's classes, admins; a *sealed* run (a
  hidden variant's run of an exercise's check, classroom.checking): not who started it, only
  the teachers of their classes and staff (its log, its robot's world: the hidden pose).
"""

from django.core.exceptions import PermissionDenied
from django.db.models import Q, QuerySet
from django.http import Http404
from django.utils.translation import gettext as _

from programs.models import Program, Run

# How long a websocket's read of its viewer's access stands: what it is sent after that waits
# for a fresh read (a class's teacher replaced, a share taken back, a robot's classes changed).
ACCESS_STANDS_SECONDS = 2.0

READ, EDIT, OWN = "read", "edit", "own"


def taught_groups(user) -> QuerySet:
    from django.contrib.auth.models import Group

    return Group.objects.filter(teachers__user=user)


def programs_for_user(user, level: str = READ) -> QuerySet:
    """The programs ``user`` may see (``READ``), change (``EDIT``) or own (``OWN``)."""
    if not user.is_authenticated:
        return Program.objects.none()
    qs = Program.objects.select_related("owner")
    if user.is_superuser:
        return qs
    if level == OWN:
        return qs.filter(owner=user)
    groups = user.groups.all()
    if level == EDIT:
        shared = (
            Q(shares__user=user, shares__can_edit=True)
            | Q(shares__group__in=groups, shares__can_edit=True)
            | Q(shares__everyone=True, shares__can_edit=True)
        )
        return qs.filter(Q(owner=user) | shared).distinct()
    shared = Q(shares__user=user) | Q(shares__group__in=groups) | Q(shares__everyone=True)
    taught = Q(owner__groups__in=taught_groups(user))
    return qs.filter(Q(owner=user) | shared | taught).distinct()


def runs_for_user(user) -> QuerySet:
    if not user.is_authenticated:
        return Run.objects.none()
    qs = Run.objects.select_related("robot", "owner")
    if user.is_superuser:
        return qs
    mine = Q(owner=user, sealed=False)
    if user.is_staff:  # staff see sealed runs; their own others as before
        mine |= Q(sealed=True)
    taught = Q(owner__groups__in=taught_groups(user)) & ~Q(owner=user, sealed=True)
    return qs.filter(mine | taught).distinct()


def get_program_for_user(user, pk, level: str = READ) -> Program:
    """The program: 404 if ``user`` may not see it, 403 if they see it but may not do
    ``level`` to it (a read-only share, a teacher's view of a student's program)."""
    try:
        # Its owner may do anything to it: one plain query first, the common case (the
        # query of everything a student may see takes twice as long, and more under load).
        if (program := _owned(Program.objects.select_related("owner"), user, pk)) is not None:
            return program
        program = programs_for_user(user).get(pk=pk)
    except (Program.DoesNotExist, ValueError, TypeError):
        raise Http404(_("No such program.")) from None
    if level != READ and not can(user, level, program):
        if level == EDIT:
            raise PermissionDenied(_("You may read this program but not change it."))
        raise PermissionDenied(_("You may read this program but not delete or share it."))
    return program


def can(user, level: str, program: Program) -> bool:
    return programs_for_user(user, level).filter(pk=program.pk).exists()


def get_run_for_user(user, pk) -> Run:
    try:
        # Who started it sees it (not sealed): one plain query first, as for a program.
        runs = Run.objects.select_related("robot", "owner").filter(sealed=False)
        if (run := _owned(runs, user, pk)) is not None:
            return run
        return runs_for_user(user).get(pk=pk)
    except (Run.DoesNotExist, ValueError, TypeError):
        raise Http404(_("No such run.")) from None


def _owned(objects: QuerySet, user, pk):
    """The object numbered ``pk`` if ``user`` owns it, else None (and for admins, whose
    query of everything is as plain)."""
    if not user.is_authenticated or user.is_superuser:
        return None
    return objects.filter(pk=pk, owner=user).first()
