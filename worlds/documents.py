"""A world document checked before it is stored: its size, rhal.simulator's validation (the
path and plain words of what is wrong), and the name the stored row goes by."""

import json
import re

from django.utils.text import slugify
from django.utils.translation import gettext as _
from django.utils.translation import gettext_noop

from worlds.models import MAX_DOCUMENT_BYTES


class DocumentError(ValueError):
    """A document that cannot be stored: ``path`` in it (e.g. ``"walls[2].to"``, "" for the
    whole), what is wrong, and the HTTP status that says it (413 too large, 422 invalid)."""

    kind = "world"  # the error's "type" in the API (classroom's exercises say "exercise")

    def __init__(self, message: str, path: str = "", status: int = 422):
        super().__init__(message)
        self.path = path
        self.status = status

    def as_detail(self) -> list[dict]:
        """As the API's other validation errors are (pydantic's list), with the path too."""
        return [
            {"type": self.kind, "loc": ["body", *path_parts(self.path)], "path": self.path,
             "msg": str(self)}
        ]  # fmt: skip


def path_parts(path: str) -> list:
    """``"walls[2].to"`` -> ``["walls", 2, "to"]``."""
    return [int(p) if p.isdigit() else p for p in re.findall(r"[^.\[\]]+", path)]


def builtin_worlds() -> dict[str, dict]:
    """The built-in worlds' documents by name (rhal.simulator.worlds.BUILTIN)."""
    from rhal.simulator.worlds import BUILTIN

    return BUILTIN


#: The built-in worlds' titles (rhal.simulator.worlds, in English there): shown translated.
BUILTIN_TITLES = (
    gettext_noop("Two boxes"),
    gettext_noop("Empty square"),
    gettext_noop("Maze"),
    gettext_noop("Line track"),
    gettext_noop("Rooms with doorways"),
)


def builtin_title(name: str) -> str:
    """A built-in world's title in the reader's language (its own, if not one of ours)."""
    title = builtin_worlds()[name].get("title") or name
    return _(title) if title in BUILTIN_TITLES else title


def document_size(document) -> int:
    return len(json.dumps(document, separators=(",", ":"), ensure_ascii=False).encode())


def validated(document, name: str = "", title: str | None = None) -> dict:
    """The document as stored: checked and normalised by rhal.simulator.world, named ``name``
    (the row's) and titled ``title`` (its own, else its name); DocumentError if it cannot be."""
    from rhal.simulator.world import World, WorldError

    if not isinstance(document, dict):
        raise DocumentError(_("a world document is a JSON object"))
    size = document_size(document)
    if size > MAX_DOCUMENT_BYTES:
        raise DocumentError(
            _("a world document is at most %(max)s KB; this one is %(size)s KB")
            % {"max": MAX_DOCUMENT_BYTES // 1024, "size": -(-size // 1024)},
            status=413,
        )
    try:
        normal = World.from_doc(document).to_doc()
    except WorldError as exc:
        raise DocumentError(str(exc), exc.path) from None
    except (TypeError, ValueError, KeyError, AttributeError) as exc:  # a check it missed
        raise DocumentError(_("not a world document: %(why)s") % {"why": exc}) from None
    if name:
        normal["name"] = name
    if title is not None:
        normal["title"] = title
    normal["title"] = normal.get("title") or normal.get("name", "")
    return normal


def base_name(document) -> str:
    """The name a stored world takes from its document: its name (else its title) as a slug,
    never only digits (a sim's URL would read it as an id)."""
    given = document.get("name") if isinstance(document, dict) else None
    title = document.get("title") if isinstance(document, dict) else None
    name = slugify(given if isinstance(given, str) else "")[:50].strip("-_")
    if not name:
        name = slugify(title if isinstance(title, str) else "")[:50].strip("-_") or "world"
    return f"world-{name}"[:50] if name.isdigit() else name


def name_for(document) -> str:
    """base_name, or DocumentError for a built-in world's name (a sim's URL names that one)."""
    name = base_name(document)
    if name in builtin_worlds():
        raise DocumentError(
            _("%(name)s is the name of a built-in world: give yours another") % {"name": name},
            "name",
        )
    return name


def free_name(owner, document) -> str:
    """base_name, or with -2, -3... after it: a name none of ``owner``'s worlds has, nor a
    built-in one (an import of a world someone exported)."""
    from worlds.models import World

    base = base_name(document)
    taken = set(
        World.objects.filter(owner=owner, name__startswith=base).values_list("name", flat=True)
    )
    taken |= set(builtin_worlds())
    name, n = base, 1
    while name in taken:
        n += 1
        name = f"{base[: 50 - len(str(n)) - 1]}-{n}"
    return name
