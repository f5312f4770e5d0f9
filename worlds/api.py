"""The worlds API: /api/worlds, a sim's arena as a JSON document (rhal.simulator's format 1).

Stored worlds have integer ids; the built-in worlds (rhal.simulator.worlds.BUILTIN) are listed
with them as ``"builtin:NAME"``, read-only. Importing a world is posting its exported document.
"""

from datetime import datetime

from django.db import IntegrityError, transaction
from django.db.models import OuterRef, Subquery
from django.http import Http404
from django.utils.translation import gettext as _
from ninja import Field, Router, Schema
from ninja.errors import HttpError
from ninja.responses import Status
from pydantic import BaseModel, ConfigDict, model_validator

from programs.api import Error
from programs.shares_api import ShareTargetIn, ShareTargetOut
from worlds import documents
from worlds.access import OWN, get_world_for_user, worlds_for_user
from worlds.documents import DocumentError
from worlds.models import World, WorldRevision
from worlds.resolve import BUILTIN_PREFIX, reconfigure, robots_using, tell_robots
from worlds.shares import ShareError, add_share, remove_share

worlds_router = Router(tags=["worlds"])


def _doc(description: str, kind: str = "array"):
    # Checked by rhal.simulator.world (its messages say where and what), not by pydantic.
    return Field(None, description=description, json_schema_extra={"type": kind})


class WorldDocument(BaseModel):
    """A world document, format 1: x east, y north, metres, the origin at the arena's centre,
    angles in radians counter-clockwise from +x. At most 256 KB as JSON."""

    # A plain pydantic model: ninja's Schema reads declared fields only, and drops the rest.
    model_config = ConfigDict(extra="allow")

    @model_validator(mode="before")
    @classmethod
    def an_object(cls, data):
        if not isinstance(data, dict):
            raise ValueError(_("the body must be a JSON object"))
        return data

    format: object = _doc("1", "integer")
    name: object = _doc(
        "the stored world's name, made a slug (else its title's); what a sim's URL names it"
        " by: sim://?world=NAME",
        "string",
    )
    title: object = _doc("shown in lists", "string")
    size: object = _doc("the arena: {width, height}, 1 to 50 m each", "object")
    walls: object = _doc("inner walls: [{from: [x, y], to: [x, y], thickness}]")
    boxes: object = _doc("[{x, y, width, height, angle}] (centre; angle in radians)")
    landmarks: object = _doc("QR landmarks on walls: [{text, x, y, facing, size, height}]")
    lines: object = _doc("painted on the floor: [{points: [[x, y], ...], width, colour}]")
    zones: object = _doc("named floor areas: [{name, x, y, width, height, colour?}]")
    start: object = _doc("start poses, the first the world's: [{x, y, theta}]")
    robot: object = _doc("the world's robot: {radius, range, sonar, floor_sensor}", "object")

    def document(self) -> dict:
        return self.model_dump(exclude_unset=True)


class WorldSummary(Schema):
    id: int | str = Field(description='a stored world\'s number, or "builtin:NAME"')
    name: str = Field(description="what a sim's world setting names it by: sim://?world=NAME")
    title: str
    owner: str | None = Field(None, description="none for a built-in world")
    builtin: bool = False
    visibility: str = Field(
        description="private, shared (with users), class, everyone; builtin for a built-in"
    )
    revision: int | None = Field(None, description="its latest revision's number")
    created: datetime | None = None
    updated: datetime | None = None


class WorldOut(WorldSummary):
    document: dict = Field(description="the world document, as stored (normalised)")


class Invalid(Schema):
    detail: list[dict] | str = Field(
        description="a list of {type, loc, path, msg}: path is where in the document"
        ' (e.g. "walls[2].to"), msg what is wrong'
    )


class ShareIn(ShareTargetIn):
    """A world's share: a program's without "may edit" (only the owner changes a world)."""


class ShareOut(ShareTargetOut):
    pass


class RevisionOut(Schema):
    number: int
    author: str | None = None
    created: datetime

    @staticmethod
    def resolve_author(revision):
        return revision.author.username if revision.author_id else None


# -- what the schemas are made from -----------------------------------------------------------


def visibility(world: World) -> str:
    """The widest of its shares (the rows prefetched, or read now)."""
    shares = world.shares.all()
    if any(s.everyone for s in shares):
        return "everyone"
    if any(s.group_id for s in shares):
        return "class"
    return "shared" if shares else "private"


def summary_out(world: World, revision: int | None) -> dict:
    return {
        "id": world.pk, "name": world.name, "title": world.title,
        "owner": world.owner.username, "visibility": visibility(world), "revision": revision,
        "created": world.created, "updated": world.updated,
    }  # fmt: skip


def stored_out(world: World, revision: WorldRevision | None = None) -> dict:
    """The world with its document: as saved last, or as ``revision`` kept it."""
    if revision is None:
        latest = world.revisions.values_list("number", flat=True).first()
        return {**summary_out(world, latest), "document": world.document}
    return {**summary_out(world, revision.number), "document": revision.document}


def builtin_out(name: str, document: dict) -> dict:
    return {
        "id": BUILTIN_PREFIX + name, "name": name, "title": documents.builtin_title(name),
        "builtin": True, "visibility": "builtin", "document": document,
    }  # fmt: skip


def _builtin(world_id: str) -> str | None:
    """The built-in world's name an id such as "builtin:maze" names; 404 if none."""
    if not world_id.startswith(BUILTIN_PREFIX):
        return None
    name = world_id.removeprefix(BUILTIN_PREFIX)
    if name not in documents.builtin_worlds():
        raise Http404(_("No such world."))
    return name


def _stored(request, world_id: str, level=None) -> World:
    if not world_id.isdigit():
        raise Http404(_("No such world."))
    return get_world_for_user(request.user, int(world_id), *([level] if level else []))


def _invalid(exc: DocumentError):
    detail = exc.as_detail() if exc.status == 422 else str(exc)
    return Status(exc.status, {"detail": detail})


def _read_only():
    raise HttpError(403, _("Built-in worlds are read-only: to change one, save a copy of it."))


# -- the routes ---------------------------------------------------------------------------------


@worlds_router.get("", response=list[WorldSummary])
def list_worlds(request, builtin: bool = True):
    """The worlds you may see: yours first, then those shared with you or your classes (and
    your classes' worlds, for a teacher), then the built-in ones (unless ``builtin=false``)."""
    latest = WorldRevision.objects.filter(world=OuterRef("pk")).order_by("-number")
    visible = (
        worlds_for_user(request.user)
        .defer("document")  # up to 256 KB each: a list has no documents
        .annotate(latest=Subquery(latest.values("number")[:1]))
        .prefetch_related("shares")
    )
    mine = [w for w in visible if w.owner_id == request.user.pk]
    others = sorted(
        (w for w in visible if w.owner_id != request.user.pk),
        key=lambda w: (w.owner.username, w.name),
    )
    listed = [summary_out(w, w.latest) for w in mine + others]
    if builtin:
        listed += [builtin_out(n, d) for n, d in documents.builtin_worlds().items()]
    return listed


@worlds_router.post(
    "", response={201: WorldOut, 409: Error, 413: Error, 422: Invalid}, summary="Create a world"
)
def create_world(request, data: WorldDocument):
    """A new world of yours (an import: post an exported document). 422 names where the
    document is wrong (a wall outside the arena, a start pose overlapping a box...)."""
    document = data.document()
    try:
        name = documents.name_for(document)
        normal = documents.validated(document, name)
    except DocumentError as exc:
        return _invalid(exc)
    try:
        with transaction.atomic():
            world = World.objects.create(owner=request.user, name=name, title=normal["title"][:200])
            world.save_document(normal, request.user)
    except IntegrityError:
        return Status(409, {"detail": already_named(name)})
    return Status(201, stored_out(world))


def already_named(name: str) -> str:
    return _("You have a world named %(name)s already.") % {"name": repr(name)}


@worlds_router.get("/{world_id}", response=WorldOut)
def get_world(request, world_id: str, revision: int | None = None):
    """The world's document and what it is (``revision=N``: as it was saved then)."""
    if (name := _builtin(world_id)) is not None:
        if revision is not None:
            raise Http404(_("A built-in world has no revisions."))
        return builtin_out(name, documents.builtin_worlds()[name])
    world = _stored(request, world_id)
    if revision is None:
        return stored_out(world)
    kept = world.revisions.filter(number=revision).first()
    if kept is None:
        raise Http404(_("No revision %(number)s of this world.") % {"number": revision})
    return stored_out(world, kept)


@worlds_router.put(
    "/{world_id}", response={200: WorldOut, 409: Error, 413: Error, 422: Invalid},
    summary="Save a world",
)  # fmt: skip
def update_world(request, world_id: str, data: WorldDocument):
    """Its owner saves a new revision (the one before is kept). A new name in the document
    renames it. Sims in this world reopen in the new one (their next reset starts there)."""
    if _builtin(world_id) is not None:
        _read_only()
    world = _stored(request, world_id, OWN)
    old_name, document = world.name, data.document()
    try:
        name = documents.name_for(document) if document.get("name") else world.name
        normal = documents.validated(document, name)
    except DocumentError as exc:
        return _invalid(exc)
    try:
        with transaction.atomic():
            world.name, world.title = name, normal["title"][:200]
            world.save_document(normal, request.user)
            tell_robots(world, old_name)
    except IntegrityError:
        return Status(409, {"detail": already_named(name)})
    return Status(200, stored_out(world))


@worlds_router.delete("/{world_id}", response={204: None})
def delete_world(request, world_id: str):
    """Its owner deletes it; sims in it stop opening, saying their world is gone."""
    if _builtin(world_id) is not None:
        _read_only()
    world = _stored(request, world_id, OWN)
    using = robots_using(world)
    with transaction.atomic():
        world.delete()
        transaction.on_commit(lambda: reconfigure(using, world_id))
    return Status(204, None)


@worlds_router.get("/{int:world_id}/revisions", response=list[RevisionOut])
def list_revisions(request, world_id: int):
    world = get_world_for_user(request.user, world_id)
    return world.revisions.select_related("author")


@worlds_router.get("/{int:world_id}/shares", response=list[ShareOut])
def list_shares(request, world_id: int):
    world = get_world_for_user(request.user, world_id, OWN)
    return world.shares.select_related("user", "group")


@worlds_router.post("/{int:world_id}/shares", response={201: ShareOut})
def create_share(request, world_id: int, data: ShareIn):
    """Share it with one user, one class (``group``) or ``everyone``: as programs are."""
    world = get_world_for_user(request.user, world_id, OWN)
    try:
        share = add_share(world, request.user, **data.dict())
    except ShareError as exc:
        raise HttpError(422, str(exc)) from None
    return Status(201, share)


@worlds_router.delete("/{int:world_id}/shares/{int:share_id}", response={204: None})
def delete_share(request, world_id: int, share_id: int):
    world = get_world_for_user(request.user, world_id, OWN)
    share = world.shares.filter(pk=share_id).first()
    if share is None:
        raise HttpError(404, _("No such share."))
    remove_share(world, share)
    return Status(204, None)
