"""The lab's API: program shares, copies, and classes (groups) with their members."""

from datetime import datetime

from django.contrib.auth import get_user_model
from django.contrib.auth.models import Group
from django.db import IntegrityError
from django.utils.translation import gettext as _
from ninja import Field, Router, Schema
from ninja.errors import HttpError
from ninja.responses import Status
from pydantic import StrictBool

from programs.access import OWN, get_program_for_user
from programs.api import Error, ProgramOut, _program_out
from programs.shares import ShareError, add_share, copy_program
from robotide.names import Name
from robotide.schemas import Body

shares_router = Router(tags=["sharing"])
groups_router = Router(tags=["groups"])


class ShareTargetIn(Body):
    """Whom a share is with (programs.shares.share_target): programs' and worlds'."""

    user: Name = ""
    group: Name = ""
    everyone: StrictBool = False


class ShareTargetOut(Schema):
    id: int
    user: str | None = None
    group: str | None = None
    everyone: bool
    created: datetime

    @staticmethod
    def resolve_user(share):
        return share.user.username if share.user_id else None

    @staticmethod
    def resolve_group(share):
        return share.group.name if share.group_id else None


class ShareIn(ShareTargetIn):
    can_edit: StrictBool = False


class ShareOut(ShareTargetOut):
    can_edit: bool


class CopyIn(Body):
    name: Name = Field("", max_length=100)


@shares_router.get("/{int:program_id}/shares", response=list[ShareOut])
def list_shares(request, program_id: int):
    program = get_program_for_user(request.user, program_id, OWN)
    return program.shares.select_related("user", "group")


@shares_router.post("/{int:program_id}/shares", response={201: ShareOut})
def create_share(request, program_id: int, data: ShareIn):
    program = get_program_for_user(request.user, program_id, OWN)
    try:
        share = add_share(program, request.user, **data.dict())
    except ShareError as exc:  # as ninja's own validation errors: 422
        raise HttpError(422, str(exc)) from None
    return Status(201, share)


@shares_router.delete("/{int:program_id}/shares/{int:share_id}", response={204: None})
def delete_share(request, program_id: int, share_id: int):
    program = get_program_for_user(request.user, program_id, OWN)
    deleted, _rows = program.shares.filter(pk=share_id).delete()
    if not deleted:
        raise HttpError(404, _("No such share."))
    return Status(204, None)


@shares_router.post("/{int:program_id}/copy", response={201: ProgramOut})
def copy(request, program_id: int, data: CopyIn):
    program = get_program_for_user(request.user, program_id)
    return Status(201, _program_out(copy_program(program, request.user, data.name)))


# -- classes ------------------------------------------------------------------------------


class GroupIn(Body):
    name: Name = Field(pattern=r"^[\w.@+-]{1,150}$")


class GroupOut(Schema):
    name: str
    members: list[str]
    teachers: list[str]

    @staticmethod
    def resolve_members(group):
        return sorted(group.user_set.values_list("username", flat=True))

    @staticmethod
    def resolve_teachers(group):
        return sorted(group.teachers.values_list("user__username", flat=True))


class MemberIn(Body):
    user: Name
    teacher: StrictBool = False


def _staff(request) -> None:
    if not request.user.is_staff:
        raise HttpError(403, _("Only staff manage classes."))


@groups_router.get("", response=list[GroupOut])
def list_groups(request):
    """Staff see every class; others the classes they are in."""
    groups = Group.objects.all() if request.user.is_staff else request.user.groups.all()
    return groups.order_by("name")


@groups_router.post("", response={201: GroupOut, 409: Error})
def create_group(request, data: GroupIn):
    _staff(request)
    try:
        group = Group.objects.create(name=data.name)
    except IntegrityError:
        detail = _("A group named %(name)s exists already.") % {"name": repr(data.name)}
        return Status(409, {"detail": detail})
    return Status(201, group)


@groups_router.post("/{name}/members", response=GroupOut)
def add_member(request, name: Name, data: MemberIn):
    """Add a student, or with ``"teacher": true`` a teacher, to the class."""
    from robotide.models import ClassTeacher

    _staff(request)
    group = Group.objects.filter(name=name).first()
    if group is None:
        raise HttpError(404, _("No group named %(name)s.") % {"name": repr(name)})
    user = get_user_model().objects.filter(username=data.user).first()
    if user is None:
        raise HttpError(422, _("no user named %(name)s") % {"name": repr(data.user)})
    if data.teacher:
        ClassTeacher.objects.get_or_create(group=group, user=user)
    else:
        user.groups.add(group)
    return group
