"""An exercise as a JSON document (the API's shape) and back: checked, normalised, stored.

```
{"id", "title", "text", "world": "boxes" | <stored world id>, "class": <group id> | null,
 "languages": [...], "variants": [{"x", "y", "theta", "hidden"}], "checks": [...],
 "starter", "starter_language", "due", "attempts", "counts", "speed", "time_limit_s",
 "version", "owner", "created", "updated"}
```

What is wrong is an ExerciseError whose path says where (``variants[1].x``, ``checks[2].zone``)
and whose message says what, in the reader's language; the API answers it as 422, as the
worlds API does. The world is resolved as the exercise's author may use it (worlds.resolve)
and its document kept with the exercise (``world_document``): a later change of the stored
world does not change what an exercise checks until the exercise is saved again. Variants are
checked as a world's start poses are (rhal.simulator.world: inside the arena, clear of walls
and boxes for the robot's radius); checks by classroom.checks.validate_checks.

A student reads hidden variants as ``{"hidden": true}``: their index, never their pose.
"""

from __future__ import annotations

import math
import re
from datetime import datetime

from django.db import transaction
from django.utils import timezone
from django.utils.dateparse import parse_datetime
from django.utils.translation import gettext as _

from classroom.access import can_edit_exercise, can_set_for_class, sees_hidden
from classroom.models import Exercise
from programs.languages import LANGUAGES
from worlds.documents import DocumentError

MAX_TITLE = 200
MAX_TEXT = 20_000
MAX_STARTER = 100_000
MAX_VARIANTS = 10
MAX_CHECKS = 30
MAX_ATTEMPTS = 1000
SPEEDS = (1.0, 10.0)
TIME_LIMITS = (1.0, 600.0)  # a variant's run, sim seconds
DEFAULTS = {
    "text": "", "class": None, "languages": [], "variants": [], "checks": [], "starter": "",
    "starter_language": "", "due": None, "attempts": None, "counts": Exercise.Counts.BEST.value,
    "speed": 5.0, "time_limit_s": 60.0,
}  # fmt: skip
#: What a document read back (GET) has beside what a teacher writes: ignored when posted.
READ_ONLY = {"id", "version", "owner", "created", "updated"}
KNOWN = set(DEFAULTS) | {"title", "world", "variants"} | READ_ONLY
#: What decides a result: a change of one bumps the version (attempts then re-checked).
DECISIVE = ("world_document", "variants", "checks", "time_limit_s", "speed")


class ExerciseError(DocumentError):
    """An exercise document that cannot be saved: where (``path``, "" for the whole), what is
    wrong, and the HTTP status that says it (as a world document's error, worlds.documents)."""

    kind = "exercise"


# -- reading a document ------------------------------------------------------------------------


def _kind(value) -> str:
    if value is None:
        return _("nothing")
    if isinstance(value, bool):
        return _("true/false")
    if isinstance(value, int | float):
        return _("a number")
    if isinstance(value, str):
        return _("a text")
    if isinstance(value, list):
        return _("a list")
    if isinstance(value, dict):
        return _("an object")
    return type(value).__name__


def _text(value, path: str, what: str, longest: int, required: bool = False) -> str:
    if not isinstance(value, str):
        raise ExerciseError(
            _("%(what)s must be a text, not %(kind)s") % {"what": what, "kind": _kind(value)},
            path,
        )
    if required and not value.strip():
        raise ExerciseError(_("%(what)s is empty") % {"what": what}, path)
    if len(value) > longest:
        raise ExerciseError(
            _("%(what)s is at most %(max)s characters; this one has %(count)s")
            % {"what": what, "max": longest, "count": len(value)},
            path,
        )
    return value


def _number(value, path: str, what: str, low=-math.inf, high=math.inf) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float):
        raise ExerciseError(
            _("%(what)s must be a number, not %(kind)s") % {"what": what, "kind": _kind(value)},
            path,
        )
    number = float(value)
    if not math.isfinite(number):
        raise ExerciseError(_("%(what)s must be a finite number") % {"what": what}, path)
    if not low <= number <= high:
        raise ExerciseError(
            _("%(what)s must be %(low)s to %(high)s, not %(value)s")
            % {"what": what, "low": f"{low:g}", "high": f"{high:g}", "value": f"{number:g}"},
            path,
        )
    return number


def _list(value, path: str, what: str, longest: int) -> list:
    if not isinstance(value, list):
        raise ExerciseError(
            _("%(what)s must be a list, not %(kind)s") % {"what": what, "kind": _kind(value)},
            path,
        )
    if len(value) > longest:
        raise ExerciseError(
            _("at most %(max)s %(what)s; this list has %(count)s")
            % {"max": longest, "what": what, "count": len(value)},
            path,
        )
    return value


def resolve_world(value, owner) -> tuple[str, dict]:
    """The world a document names, as ``owner`` may use it: (the setting as stored — a
    built-in's name or a stored world's id —, its normalised document)."""
    from rhal.simulator.world import World as SimWorld
    from worlds.documents import builtin_worlds
    from worlds.resolve import WorldUnavailable, find_world

    if isinstance(value, bool) or not isinstance(value, str | int) or value in ("", None):
        raise ExerciseError(
            _("the world is a built-in world's name or a stored world's id, not %(kind)s")
            % {"kind": _kind(value)},
            "world",
        )
    try:
        found = find_world(value, owner)
    except WorldUnavailable:
        raise ExerciseError(
            _(
                "no world %(world)s that the exercise's author may use: name a built-in world,"
                " or a stored world of theirs or shared with them (its id)"
            )
            % {"world": repr(value)},
            "world",
        ) from None
    if isinstance(found, str):
        return found, SimWorld.from_doc(builtin_worlds()[found]).to_doc()
    return str(found.pk), found.document


def sim_world(document: dict):
    from rhal.simulator.world import World as SimWorld

    return SimWorld.from_doc(document)


def _variants(value, world_document: dict) -> list[dict]:
    """Each variant a start pose the world accepts (rhal.simulator.world's own checks), the
    first of the world's start poses if none is given."""
    from rhal.simulator.world import WorldError

    if value is None or value == []:
        x, y, theta = sim_world(world_document).start_pose
        return [{"x": x, "y": y, "theta": theta, "hidden": False}]
    _list(value, "variants", _("variants"), MAX_VARIANTS)
    variants = []
    for index, variant in enumerate(value):
        path = f"variants[{index}]"
        number = index + 1
        if not isinstance(variant, dict):
            raise ExerciseError(
                _("variant %(n)s must be an object {x, y, theta, hidden}, not %(kind)s")
                % {"n": number, "kind": _kind(variant)},
                path,
            )
        unknown = sorted(set(variant) - {"x", "y", "theta", "hidden"})
        if unknown:
            raise ExerciseError(
                _("unknown key %(key)s (known: hidden, theta, x, y)") % {"key": repr(unknown[0])},
                f"{path}.{unknown[0]}",
            )
        hidden = variant.get("hidden", False)
        if not isinstance(hidden, bool):
            raise ExerciseError(
                _("hidden is true or false, not %(kind)s") % {"kind": _kind(hidden)},
                f"{path}.hidden",
            )
        what = _("variant %(n)s's %(coordinate)s")
        pose = {
            key: _number(
                variant.get(key, 0.0 if key == "theta" else None),
                f"{path}.{key}",
                what % {"n": number, "coordinate": key},
            )
            for key in ("x", "y", "theta")
        }
        variants.append({**pose, "hidden": hidden})
    if all(v["hidden"] for v in variants):
        raise ExerciseError(
            _("at least one variant must be visible: students need a start pose to try from"),
            "variants",
        )
    # A world whose start poses are the variants: rhal's checks of a start pose are ours.
    poses = [{"x": v["x"], "y": v["y"], "theta": v["theta"]} for v in variants]
    try:
        sim_world({**world_document, "start": poses})
    except WorldError as exc:
        path = re.sub(r"^start(?=\[|$)", "variants", exc.path or "variants")
        message = re.sub(r"\bstart poses?\b", _("variant"), str(exc))
        raise ExerciseError(message, path) from None
    return variants


def _checks(value, world_document: dict) -> list[dict]:
    _list(value, "checks", _("checks"), MAX_CHECKS)
    if not value:
        return []
    from classroom.checks import CheckError, validate_checks

    try:
        return validate_checks(value, sim_world(world_document), _)
    except CheckError as exc:
        path = getattr(exc, "path", "") or "checks"
        if not path.startswith("checks"):
            path = f"checks{path}" if path.startswith("[") else f"checks.{path}"
        raise ExerciseError(getattr(exc, "message", None) or str(exc), path) from None


def _languages(value) -> list[str]:
    _list(value, "languages", _("languages"), len(LANGUAGES))
    chosen = []
    for index, name in enumerate(value):
        if name not in LANGUAGES:
            raise ExerciseError(
                _("unknown language %(name)s; known languages: %(known)s")
                % {"name": repr(name), "known": ", ".join(LANGUAGES)},
                f"languages[{index}]",
            )
        if name not in chosen:
            chosen.append(name)
    return chosen


def _due(value) -> datetime | None:
    if value is None or value == "":
        return None
    if isinstance(value, datetime):
        moment = value
    else:
        moment = parse_datetime(value) if isinstance(value, str) else None
        if moment is None:
            raise ExerciseError(
                _("the due date is an ISO 8601 date and time (2026-12-01T18:00:00Z), or null"),
                "due",
            )
    if timezone.is_naive(moment):
        moment = timezone.make_aware(moment)
    return moment


def _attempts(value) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= MAX_ATTEMPTS:
        raise ExerciseError(
            _("attempts is how many checked attempts count: 1 to %(max)s, or null (all)")
            % {"max": MAX_ATTEMPTS},
            "attempts",
        )
    return value


def _class(value, user, current: Exercise | None) -> int | None:
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, int):
        raise ExerciseError(
            _("class is a class's number, or null (a draft), not %(kind)s")
            % {"kind": _kind(value)},
            "class",
        )
    # Its author keeps its class when no longer teaching it (a class handed to a colleague).
    if current is not None and current.group_id == value and can_edit_exercise(user, current):
        return value
    if not can_set_for_class(user, value):
        raise ExerciseError(
            _("no class %(id)s that you teach: set exercises only for your classes")
            % {"id": value},
            "class",
        )
    return value


def validated(document, user, exercise: Exercise | None = None) -> dict:
    """The Exercise's fields a document gives (``exercise``: the one it changes, whose
    values stand for keys the document leaves out); ExerciseError if it cannot be saved."""
    if not isinstance(document, dict):
        raise ExerciseError(_("an exercise document is a JSON object"))
    unknown = sorted(set(document) - KNOWN)
    if unknown:
        raise ExerciseError(
            _("unknown key %(key)s (known: %(known)s)")
            % {"key": repr(unknown[0]), "known": ", ".join(sorted(KNOWN - READ_ONLY))},
            unknown[0],
        )
    base = stored_document(exercise) if exercise is not None else {**DEFAULTS}
    doc = {**base, **{k: v for k, v in document.items() if k not in READ_ONLY}}
    if "title" not in doc:
        raise ExerciseError(_("an exercise needs a title"), "title")
    if "world" not in doc:
        raise ExerciseError(
            _("an exercise needs a world: a built-in world's name or a stored world's id"),
            "world",
        )
    owner = exercise.owner if exercise is not None else user
    world, world_document = resolve_world(doc["world"], owner)
    languages = _languages(doc["languages"])
    starter = _text(doc["starter"], "starter", _("the starter program"), MAX_STARTER)
    starter_language = doc["starter_language"] or ""
    if not isinstance(starter_language, str):
        raise ExerciseError(_("the starter's language is a language's name"), "starter_language")
    if not starter_language:
        starter_language = languages[0] if languages else "python"
    if starter_language not in LANGUAGES:
        raise ExerciseError(
            _("unknown language %(name)s; known languages: %(known)s")
            % {"name": repr(starter_language), "known": ", ".join(LANGUAGES)},
            "starter_language",
        )
    if languages and starter_language not in languages:
        raise ExerciseError(
            _("the starter is in %(language)s, which this exercise does not take")
            % {"language": starter_language},
            "starter_language",
        )
    counts = doc["counts"]
    if counts not in Exercise.Counts.values:
        raise ExerciseError(_('counts is "best" or "latest"'), "counts")
    return {
        "title": _text(doc["title"], "title", _("the title"), MAX_TITLE, required=True).strip(),
        "text": _text(doc["text"], "text", _("the text"), MAX_TEXT),
        "world": world,
        "world_document": world_document,
        "group_id": _class(doc["class"], user, exercise),
        "languages": languages,
        "variants": _variants(doc["variants"], world_document),
        "checks": _checks(doc["checks"], world_document),
        "starter": starter,
        "starter_language": starter_language,
        "due": _due(doc["due"]),
        "attempts_allowed": _attempts(doc["attempts"]),
        "counts": counts,
        "speed": _number(doc["speed"], "speed", _("speed"), *SPEEDS),
        "time_limit_s": _number(doc["time_limit_s"], "time_limit_s", _("the time limit"),
                                *TIME_LIMITS),
    }  # fmt: skip


def save(document, user, exercise: Exercise | None = None) -> Exercise:
    """A new exercise of ``user``'s, or ``exercise`` changed, from a document; its version
    bumped when what decides a result changed. ExerciseError if it cannot be saved."""
    fields = validated(document, user, exercise)
    with transaction.atomic():
        if exercise is None:
            return Exercise.objects.create(owner=user, **fields)
        exercise = Exercise.objects.select_for_update().get(pk=exercise.pk)
        if any(getattr(exercise, name) != fields[name] for name in DECISIVE):
            exercise.version += 1
        for name, value in fields.items():
            setattr(exercise, name, value)
        exercise.updated = timezone.now()
        exercise.save()
    return exercise


# -- writing one -------------------------------------------------------------------------------


def world_out(exercise: Exercise):
    """The world as written: a built-in's name, or a stored world's id (a number)."""
    return int(exercise.world) if exercise.world.isdigit() else exercise.world


def stored_document(exercise: Exercise) -> dict:
    """Everything a teacher wrote, hidden poses included: what a PUT's missing keys keep."""
    return {
        "title": exercise.title, "text": exercise.text, "world": world_out(exercise),
        "class": exercise.group_id, "languages": list(exercise.languages),
        "variants": [dict(v) for v in exercise.variants],
        "checks": [dict(c) for c in exercise.checks], "starter": exercise.starter,
        "starter_language": exercise.starter_language,
        "due": exercise.due, "attempts": exercise.attempts_allowed, "counts": exercise.counts,
        "speed": exercise.speed, "time_limit_s": exercise.time_limit_s,
    }  # fmt: skip


def visible_variants(exercise: Exercise, user) -> list[dict]:
    """The variants as ``user`` may read them: a hidden one's pose only for who may change
    the exercise; for anyone else ``{"hidden": true}`` in its place."""
    if sees_hidden(user, exercise):
        return [dict(v) for v in exercise.variants]
    return [
        {"hidden": True} if v.get("hidden") else {**v, "hidden": False} for v in exercise.variants
    ]


#: What a student does not read of a check: an output pattern is often the answer itself (the
#: landmark's name); the teacher's message says what to print instead.
SECRET_KEYS = {"output_matches": ("pattern", "flags")}


def visible_checks(exercise: Exercise, user) -> list[dict]:
    """The checks as ``user`` may read them: whole for who may change the exercise, without
    their secrets (SECRET_KEYS) for anyone else."""
    if sees_hidden(user, exercise):
        return [dict(c) for c in exercise.checks]
    return [
        {k: v for k, v in c.items() if k not in SECRET_KEYS.get(c.get("kind"), ())}
        for c in exercise.checks
    ]


def document(exercise: Exercise, user) -> dict:
    """The exercise's document as ``user`` may read it (hidden poses stripped for students)."""
    return {
        "id": exercise.pk,
        **stored_document(exercise),
        "variants": visible_variants(exercise, user),
        "checks": visible_checks(exercise, user),
        "version": exercise.version,
        "owner": exercise.owner.username,
        "created": exercise.created,
        "updated": exercise.updated,
    }
