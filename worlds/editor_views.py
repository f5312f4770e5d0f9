"""The world editor's pages (templates/worlds/editor.html, robotide/static/robotide/
world_editor.js).

The page carries the document; the script draws and edits it and saves it through the worlds
API, which validates it. A world its reader may not change, and a built-in one, is shown to
read, with "Copy to edit": the copy is saved as a new world of the reader's.
"""

import math

from django.contrib.auth.decorators import login_required
from django.http import Http404
from django.shortcuts import render
from django.urls import reverse
from django.utils.translation import gettext as _

from worlds.access import OWN, get_world_for_user, worlds_for_user
from worlds.documents import builtin_title, builtin_worlds

BLANK_SIZE = 4.0  # m: a new world's arena, as the built-in ones


def blank_document() -> dict:
    return {
        "format": 1,
        "name": "",
        "title": "",
        "size": {"width": BLANK_SIZE, "height": BLANK_SIZE},
        "walls": [],
        "boxes": [],
        "landmarks": [],
        "lines": [],
        "zones": [],
        "start": [{"x": 0.0, "y": 0.0, "theta": round(math.pi / 2, 4)}],
    }


def editor(request, document: dict, *, world_id=None, builtin="", can_edit: bool, heading: str):
    data = {
        "world": document,
        "id": world_id,
        "builtin": builtin,  # its name: a sim in it is made by that name
        "can_edit": can_edit,
        "api": "/api/worlds",
        "edit_url": reverse("world-edit", args=[0]),
    }
    return render(request, "worlds/editor.html", {"editor": data, "heading": heading,
                                                   "can_edit": can_edit})  # fmt: skip


@login_required
def world_new(request):
    return editor(request, blank_document(), can_edit=True, heading=_("New world"))


@login_required
def world_edit(request, world_id: int):
    world = get_world_for_user(request.user, world_id)
    can_edit = worlds_for_user(request.user, OWN).filter(pk=world.pk).exists()
    document = {**world.document, "name": world.name, "title": world.title or world.name}
    return editor(request, document, world_id=world.pk, can_edit=can_edit,
                  heading=world.title or world.name)  # fmt: skip


@login_required
def world_builtin(request, name: str):
    if name not in builtin_worlds():
        raise Http404(_("No such world."))
    title = builtin_title(name)  # in the reader's language, and so its copy's
    document = {**builtin_worlds()[name], "title": title}
    return editor(request, document, builtin=name, can_edit=False, heading=title)
