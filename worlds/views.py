"""The worlds' pages: the list (/worlds/), import, export (/worlds/<id>.json) and sharing.

The editor's pages (/worlds/new, /worlds/<id>/edit) are worlds.editor_views'.
"""

import json

from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.db import IntegrityError, transaction
from django.http import Http404, HttpRequest, HttpResponse
from django.shortcuts import get_object_or_404, redirect, render
from django.utils.http import content_disposition_header
from django.utils.translation import gettext as _
from django.views.decorators.http import require_POST

from worlds import documents
from worlds.access import OWN, get_world_for_user, worlds_for_user
from worlds.documents import DocumentError
from worlds.models import MAX_DOCUMENT_BYTES, World
from worlds.shares import ShareError, add_share, remove_share


@login_required
def world_list(request: HttpRequest) -> HttpResponse:
    visible = (
        worlds_for_user(request.user)
        .defer("document")  # up to 256 KB each: the list shows none
        .prefetch_related("shares")
        .order_by("owner__username", "name")
    )
    groups = set(request.user.groups.values_list("pk", flat=True))
    mine, shared, public = [], [], []
    for world in visible:
        if world.owner_id == request.user.pk:
            mine.append(world)
        elif everyones(world) and not shared_with(world, request.user, groups):
            public.append(world)
        else:  # with them, their classes, or (a teacher) their classes' worlds
            shared.append(world)
    builtin = [
        {"name": name, "title": documents.builtin_title(name)}
        for name in documents.builtin_worlds()
    ]
    context = {
        "mine": mine, "shared": shared, "public": public, "builtin": builtin,
        "max_kb": MAX_DOCUMENT_BYTES // 1024,
    }  # fmt: skip
    return render(request, "worlds/list.html", context)


def everyones(world: World) -> bool:
    return any(s.everyone for s in world.shares.all())


def shared_with(world: World, user, groups: set[int]) -> bool:
    """Shared with ``user`` or a class of theirs (``groups``), not only with everyone."""
    return any(s.user_id == user.pk or s.group_id in groups for s in world.shares.all())


def _json_download(document: dict, filename: str) -> HttpResponse:
    response = HttpResponse(
        json.dumps(document, indent=2, ensure_ascii=False), content_type="application/json"
    )
    response["Content-Disposition"] = content_disposition_header(True, filename)
    return response


@login_required
def world_export(request: HttpRequest, world_id: int) -> HttpResponse:
    """The document as a file (``?revision=N``: as saved then): what Import takes back."""
    world = get_world_for_user(request.user, world_id)
    document, suffix = world.document, ""
    if number := request.GET.get("revision", ""):
        revision = world.revisions.filter(number=int(number) if number.isdigit() else -1).first()
        if revision is None:
            raise Http404(_("No revision %(number)s of this world.") % {"number": number})
        document, suffix = revision.document, f"-r{revision.number}"
    return _json_download(document, f"{world.name}{suffix}.json")


@login_required
def builtin_export(request: HttpRequest, name: str) -> HttpResponse:
    document = documents.builtin_worlds().get(name)
    if document is None:
        raise Http404(_("No such world."))
    return _json_download(document, f"{name}.json")


@login_required
@require_POST
def world_import(request: HttpRequest) -> HttpResponse:
    """A world file (as exported) becomes a world of the user's: named as in it, or with -2
    after the name when they have one of that name (or a built-in world has it)."""
    upload = request.FILES.get("file")
    if upload is None:
        messages.error(request, _("Choose a world file (.json) to import."))
        return redirect("world-list")
    try:
        world = import_world(request.user, upload.read(MAX_DOCUMENT_BYTES + 1))
    except DocumentError as exc:
        where = f"{exc.path}: " if exc.path else ""
        messages.error(
            request,
            _("Nothing was imported from %(file)s: %(why)s")
            % {"file": upload.name, "why": where + str(exc)},
        )
        return redirect("world-list")
    messages.success(
        request, _("Imported %(file)s as %(name)s.") % {"file": upload.name, "name": world.name}
    )
    return redirect("world-list")


def import_world(user, data: bytes) -> World:
    if len(data) > MAX_DOCUMENT_BYTES:
        raise DocumentError(
            _("a world file is at most %(max)s KB") % {"max": MAX_DOCUMENT_BYTES // 1024},
            status=413,
        )
    try:
        document = json.loads(data.decode("utf-8-sig"))
    except (UnicodeDecodeError, ValueError) as exc:
        raise DocumentError(_("not a JSON file: %(why)s") % {"why": exc}) from None
    if not isinstance(document, dict):
        raise DocumentError(_("a world document is a JSON object"))
    for _attempt in range(3):  # another import of the same name may come between
        name = documents.free_name(user, document)
        normal = documents.validated(document, name)
        try:
            with transaction.atomic():
                world = World.objects.create(owner=user, name=name, title=normal["title"][:200])
                world.save_document(normal, user)
            return world
        except IntegrityError:
            continue
    raise DocumentError(_("You have a world named %(name)s already.") % {"name": repr(name)})


@login_required
def world_shares(request: HttpRequest, world_id: int) -> HttpResponse:
    """Its owner shares it with a user, a class or everyone, as programs are shared."""
    world = get_world_for_user(request.user, world_id, OWN)
    if request.method == "POST":
        target = request.POST.get("target", "").strip()
        kind, _sep, name = target.partition(":") if ":" in target else ("user", "", target)
        if target == "everyone":
            kind = "everyone"
        try:
            share = add_share(
                world, request.user, user=name.strip() if kind == "user" else "",
                group=name.strip() if kind == "group" else "", everyone=target == "everyone",
            )  # fmt: skip
        except ShareError as exc:
            messages.error(request, _("Not shared: %(why)s.") % {"why": exc})
        else:
            messages.success(request, _("Shared with %(target)s.") % {"target": share.target})
        return redirect("world-shares", world.pk)
    shares = world.shares.select_related("user", "group")
    return render(request, "worlds/shares.html", {"world": world, "shares": shares})


@login_required
@require_POST
def world_unshare(request: HttpRequest, world_id: int, share_id: int) -> HttpResponse:
    world = get_world_for_user(request.user, world_id, OWN)
    share = get_object_or_404(world.shares, pk=share_id)
    remove_share(world, share)
    messages.success(request, _("No longer shared with %(target)s.") % {"target": share.target})
    return redirect("world-shares", world.pk)


@login_required
def world_delete(request: HttpRequest, world_id: int) -> HttpResponse:
    world = get_world_for_user(request.user, world_id, OWN)
    if request.method == "POST":
        from worlds.resolve import reconfigure, robots_using

        using, name = robots_using(world), world.name
        with transaction.atomic():
            world.delete()
            transaction.on_commit(lambda: reconfigure(using, name))
        messages.success(request, _("Deleted %(name)s.") % {"name": name})
        return redirect("world-list")
    return render(request, "worlds/delete.html", {"world": world})
