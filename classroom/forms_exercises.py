"""The exercise editor's form (templates/classroom/exercise_edit.html): an exercise document
(classroom.documents' shape) as fields a teacher fills in, and back.

The page posts plain fields: the exercise's own (``title``, ``world``, ``due``...), one row of
fields a start pose (``variants-<i>-x``, ``-y``, ``-theta_deg``, ``-hidden``) and one a check
(``checks-<i>-kind``, ``-points``, ``-message`` and its kind's fields). Rows are read in the
order of their numbers, which need not follow each other (the page's script adds and removes
rows). What cannot even be read (a number that is not one, a date that is not one) is an error
here, by the document's path; everything else is classroom.documents' to judge, whose errors
name paths too: each is shown beside the field of that path (``errors_by_field``).
"""

from __future__ import annotations

import math
import re
from dataclasses import dataclass, field
from datetime import datetime

from django.utils import timezone
from django.utils.translation import gettext as _
from django.utils.translation import gettext_lazy

#: The check kinds (classroom.checks) and the fields of each, in the order shown.
CHECK_KINDS: dict[str, dict] = {
    "reach_zone": {
        "label": gettext_lazy("Reach a zone"),
        "fields": ["zone", "within_s"],
        "help": gettext_lazy("The robot gets into the zone (the world's named area)."),
    },
    "zones_in_order": {
        "label": gettext_lazy("Visit zones in order"),
        "fields": ["zones", "within_s"],
        "help": gettext_lazy("The robot gets into each zone in turn, in this order."),
    },
    "no_contact": {
        "label": gettext_lazy("Never touch a wall or box"),
        "fields": [],
        "help": gettext_lazy("From start to end, the robot never touches a wall or a box."),
    },
    "stop_near_wall": {
        "label": gettext_lazy("Stop near a wall"),
        "fields": ["min_m", "max_m"],
        "help": gettext_lazy(
            "At the end the robot stands still, and the gap between its body and the nearest"
            " wall or box is in this band."
        ),
    },
    "ends_within": {
        "label": gettext_lazy("End on its own"),
        "fields": ["seconds"],
        "help": gettext_lazy(
            "The program ends by itself without an error (not stopped, not at the time limit)."
        ),
    },
    "output_matches": {
        "label": gettext_lazy("Print or say a text"),
        "fields": ["pattern", "flags"],
        "help": gettext_lazy("A line the program prints, or a text it says, matches the pattern."),
    },
    "uses_block": {
        "label": gettext_lazy("Use a block (blocks)"),
        "fields": ["block"],
        "help": gettext_lazy("The blocks program uses this block: checked on the program itself."),
    },
    "max_blocks": {
        "label": gettext_lazy("At most N blocks (blocks)"),
        "fields": ["count"],
        "help": gettext_lazy("The blocks program has at most this many blocks."),
    },
}

#: A check's fields: label, input type (number, text, zone, zones, flag, block), whether it
#: may be left empty, and a hint.
CHECK_FIELDS: dict[str, dict] = {
    "zone": {"label": gettext_lazy("Zone"), "type": "zone"},
    "zones": {
        "label": gettext_lazy("Zones, in order"),
        "type": "zones",
        "hint": gettext_lazy("names separated by commas"),
    },
    "within_s": {
        "label": gettext_lazy("within (s)"),
        "type": "number",
        "optional": True,
        "step": "0.1",
        "hint": gettext_lazy("empty: any time"),
    },
    "min_m": {"label": gettext_lazy("gap from (m)"), "type": "number", "step": "0.01"},
    "max_m": {"label": gettext_lazy("gap to (m)"), "type": "number", "step": "0.01"},
    "seconds": {"label": gettext_lazy("ends within (s)"), "type": "number", "step": "0.1"},
    "pattern": {
        "label": gettext_lazy("Pattern"),
        "type": "text",
        "hint": gettext_lazy("a Python regular expression, searched in each line printed or said"),
    },
    "flags": {"label": gettext_lazy("ignore case"), "type": "flag"},
    "block": {
        "label": gettext_lazy("Block"),
        "type": "block",
        "hint": gettext_lazy("loop, condition, or a block's type (controls_whileUntil)"),
    },
    "count": {"label": gettext_lazy("at most (blocks)"), "type": "number", "step": "1"},
}
BLOCK_SUGGESTIONS = [
    "loop", "condition", "controls_whileUntil", "controls_repeat_ext", "controls_for",
    "controls_forEach", "controls_if", "logic_compare", "math_arithmetic", "variables_set",
    "procedures_defnoreturn",
]  # fmt: skip

SCALARS = [
    "title", "class", "text", "world", "starter", "starter_language", "due", "attempts",
    "counts", "speed", "time_limit_s",
]  # fmt: skip
ROW = re.compile(r"^(variants|checks)-(\d+)-(\w+)$")


def number(text: str) -> float:
    """A number as typed: a comma for the decimal point too (pt-BR)."""
    value = float(text.strip().replace(",", "."))
    if not math.isfinite(value):
        raise ValueError(text)
    return value


def shown(value, places: int = 3) -> str:
    """A number as the form shows it: no trailing zeros, no -0."""
    if value is None or value == "":
        return ""
    if isinstance(value, bool) or not isinstance(value, int | float):
        return str(value)
    text = f"{round(float(value), places):.{places}f}".rstrip("0").rstrip(".")
    return "0" if text in ("-0", "") else text


def degrees(theta) -> str:
    return shown(math.degrees(theta), 2) if isinstance(theta, int | float) else ""


def plain(value: float) -> int | float:
    return int(value) if float(value).is_integer() else value


@dataclass
class Variant:
    x: str = ""
    y: str = ""
    theta_deg: str = ""
    rad: str = ""  # the stored radians the degrees were shown from (kept if unchanged)
    hidden: bool = False


@dataclass
class Check:
    kind: str = "reach_zone"
    points: str = "1"
    message: str = ""
    values: dict = field(default_factory=dict)  # field -> str (flags: bool)


@dataclass
class EditorState:
    """The form as filled in: strings as typed (so a refused one is shown as it was)."""

    scalars: dict = field(default_factory=dict)
    languages: list = field(default_factory=list)
    variants: list = field(default_factory=list)
    checks: list = field(default_factory=list)

    # -- from a document, from a POST ---------------------------------------------------------

    @classmethod
    def from_document(cls, doc: dict) -> EditorState:
        due = doc.get("due")
        if isinstance(due, str) and due:
            due = datetime.fromisoformat(due)
        if isinstance(due, datetime):
            due = timezone.localtime(due).strftime("%Y-%m-%dT%H:%M")
        scalars = {
            "title": doc.get("title") or "",
            "class": "" if doc.get("class") is None else str(doc["class"]),
            "text": doc.get("text") or "",
            "world": str(doc.get("world") or ""),
            "starter": doc.get("starter") or "",
            "starter_language": doc.get("starter_language") or "python",
            "due": due or "",
            "attempts": "" if doc.get("attempts") is None else str(doc["attempts"]),
            "counts": doc.get("counts") or "best",
            "speed": shown(doc.get("speed", 5)),
            "time_limit_s": shown(doc.get("time_limit_s", 60)),
        }
        variants = [
            Variant(
                x=shown(v.get("x")),
                y=shown(v.get("y")),
                theta_deg=degrees(v.get("theta")),
                rad=repr(v["theta"]) if isinstance(v.get("theta"), int | float) else "",
                hidden=bool(v.get("hidden")),
            )  # fmt: skip
            for v in doc.get("variants") or []
        ]
        checks = []
        for c in doc.get("checks") or []:
            values = {}
            for name in CHECK_FIELDS:
                if name not in c:
                    continue
                if name == "zones":
                    values[name] = ", ".join(str(z) for z in c[name] or [])
                elif name == "flags":
                    values[name] = "i" in (c[name] or "")
                else:
                    values[name] = shown(c[name]) if c[name] is not None else ""
            checks.append(
                Check(
                    kind=c.get("kind", ""),
                    points=shown(c.get("points", 1)),
                    message=c.get("message") or "",
                    values=values,
                )  # fmt: skip
            )
        return cls(scalars, list(doc.get("languages") or []), variants, checks)

    @classmethod
    def from_post(cls, post) -> EditorState:
        scalars = {name: post.get(name, "") for name in SCALARS}
        for name in ("text", "starter"):  # a browser's textarea sends CRLF
            scalars[name] = scalars[name].replace("\r\n", "\n")
        rows: dict[tuple[str, int], dict] = {}
        for key in post:
            if match := ROW.match(key):
                kind, index, name = match.groups()
                rows.setdefault((kind, int(index)), {})[name] = post.get(key, "")
        variants, checks = [], []
        for (kind, _index), row in sorted(rows.items()):
            if kind == "variants":
                variants.append(
                    Variant(
                        x=row.get("x", ""),
                        y=row.get("y", ""),
                        theta_deg=row.get("theta_deg", ""),
                        rad=row.get("rad", ""),
                        hidden="hidden" in row,
                    )  # fmt: skip
                )
            else:
                values = {name: row.get(name, "") for name in CHECK_FIELDS if name != "flags"}
                values["flags"] = "flags" in row
                checks.append(
                    Check(
                        kind=row.get("kind", ""),
                        points=row.get("points", ""),
                        message=row.get("message", ""),
                        values=values,
                    )  # fmt: skip
                )
        return cls(scalars, post.getlist("languages"), variants, checks)

    # -- to a document ------------------------------------------------------------------------

    def document(self) -> tuple[dict, dict[str, str]]:
        """The exercise document, and the paths of what could not be read (path -> why)."""
        errors: dict[str, str] = {}
        s = self.scalars

        def read(path: str, text: str, *, optional=False, integer=False):
            text = (text or "").strip()
            if not text:
                if not optional:
                    errors[path] = _("a number is needed here")
                return None
            try:
                value = number(text)
            except ValueError:
                errors[path] = _("%(text)s is not a number") % {"text": repr(text)}
                return None
            if integer:
                if not value.is_integer():
                    errors[path] = _("a whole number is needed here")
                    return None
                return int(value)
            return value

        world = s.get("world", "").strip()
        group = s.get("class", "").strip()
        doc: dict = {
            "title": s.get("title", "").strip(),
            "text": s.get("text", ""),
            "world": int(world) if world.isdigit() else world,
            "class": int(group) if group.isdigit() else None,
            "languages": [lang for lang in self.languages if lang],
            "starter": s.get("starter", ""),
            "starter_language": s.get("starter_language", "") or "python",
            "due": self._due(errors),
            "attempts": read("attempts", s.get("attempts", ""), optional=True, integer=True),
            "counts": s.get("counts", "") or "best",
            "speed": read("speed", s.get("speed", "")),
            "time_limit_s": read("time_limit_s", s.get("time_limit_s", "")),
        }
        if not doc["starter"].strip() and doc["languages"]:
            if doc["starter_language"] not in doc["languages"]:
                doc["starter_language"] = ""  # no starter: the first language allowed
        variants = []
        for i, v in enumerate(self.variants):
            at = f"variants[{i}]"
            theta = None
            if v.rad and v.theta_deg.strip() == degrees(_float(v.rad)):
                theta = _float(v.rad)  # unchanged: the stored radians, not a rounding of them
            else:
                deg = read(f"{at}.theta", v.theta_deg)
                theta = None if deg is None else round(math.radians(deg), 6)
            variants.append(
                {
                    "x": read(f"{at}.x", v.x),
                    "y": read(f"{at}.y", v.y),
                    "theta": theta,
                    "hidden": v.hidden,
                }  # fmt: skip
            )
        doc["variants"] = variants
        checks = []
        for i, c in enumerate(self.checks):
            at = f"checks[{i}]"
            points = read(f"{at}.points", c.points)
            check = {"kind": c.kind, "points": plain(points) if points is not None else None,
                     "message": c.message.strip()}  # fmt: skip
            for name in CHECK_KINDS.get(c.kind, {}).get("fields", []):
                spec, value = CHECK_FIELDS[name], c.values.get(name, "")
                if spec["type"] == "number":
                    read_value = read(f"{at}.{name}", value, optional=spec.get("optional", False),
                                      integer=name == "count")  # fmt: skip
                    if read_value is not None:
                        check[name] = plain(read_value) if name == "count" else read_value
                elif spec["type"] == "zones":
                    check[name] = [z.strip() for z in value.split(",") if z.strip()]
                elif spec["type"] == "flag":
                    if value:
                        check[name] = "i"
                else:
                    check[name] = value.strip()
            checks.append(check)
        doc["checks"] = checks
        return doc, errors

    def _due(self, errors: dict) -> str | None:
        text = (self.scalars.get("due") or "").strip()
        if not text:
            return None
        try:
            when = datetime.fromisoformat(text)
        except ValueError:
            errors["due"] = _("%(text)s is not a date and time") % {"text": repr(text)}
            return None
        if timezone.is_naive(when):
            when = timezone.make_aware(when)
        return when.isoformat()

    # -- rows, for the template ---------------------------------------------------------------

    def variant_rows(self, errors: ErrorMap) -> list[dict]:
        return [variant_row(i, v, errors) for i, v in enumerate(self.variants)]

    def check_rows(self, errors: ErrorMap) -> list[dict]:
        return [check_row(i, c, errors) for i, c in enumerate(self.checks)]


def _float(text: str) -> float | None:
    try:
        return float(text)
    except (TypeError, ValueError):
        return None


class ErrorMap:
    """Errors by document path, each given to the field that claims the longest part of its
    path ("checks[2].zones[1]" -> the field of "checks[2].zones"); what no field claims is
    ``left`` (shown at the top of the form)."""

    def __init__(self, errors: dict[str, str]):
        self.errors = dict(errors)
        self.claimed: set[str] = set()

    def __bool__(self) -> bool:
        return bool(self.errors)

    def claim(self, path: str, *, whole: bool = False) -> str:
        """The messages of ``path`` (and, ``whole``, of paths under it no other field takes:
        call it after those fields'), joined."""
        found = []
        for where, message in self.errors.items():
            if where in self.claimed:
                continue
            under = where.startswith((path + ".", path + "["))
            if where == path or (whole and under):
                found.append(message)
                self.claimed.add(where)
        return "; ".join(found)

    def left(self) -> list[tuple[str, str]]:
        return [(path, msg) for path, msg in self.errors.items() if path not in self.claimed]


def variant_row(i, v: Variant, errors: ErrorMap | None = None) -> dict:
    errors = errors or ErrorMap({})
    at = f"variants[{i}]"
    fields = {
        "x": errors.claim(f"{at}.x"),
        "y": errors.claim(f"{at}.y"),
        "theta": errors.claim(f"{at}.theta"),
        "hidden": errors.claim(f"{at}.hidden"),
    }
    return {"index": i, "number": i + 1 if isinstance(i, int) else "", "v": v, "errors": fields,
            "error": errors.claim(at, whole=True)}  # fmt: skip


def check_row(i, c: Check, errors: ErrorMap | None = None) -> dict:
    errors = errors or ErrorMap({})
    at = f"checks[{i}]"
    kinds_of: dict[str, list[str]] = {}
    for kind, spec in CHECK_KINDS.items():
        for name in spec["fields"]:
            kinds_of.setdefault(name, []).append(kind)
    fields = []
    for name, spec in CHECK_FIELDS.items():
        fields.append(
            {
                "key": name,
                "name": f"checks-{i}-{name}",
                "id": f"checks-{i}-{name}",
                "value": c.values.get(name, False if spec["type"] == "flag" else ""),
                "kinds": " ".join(kinds_of.get(name, [])),
                "shown": name in CHECK_KINDS.get(c.kind, {}).get("fields", []),
                "error": errors.claim(f"{at}.{name}", whole=True),
                **spec,
            }  # fmt: skip
        )
    return {
        "index": i, "number": i + 1 if isinstance(i, int) else "", "c": c, "fields": fields,
        "kinds": [(kind, spec["label"]) for kind, spec in CHECK_KINDS.items()],
        "helps": [(kind, spec["help"]) for kind, spec in CHECK_KINDS.items()],
        "known_kind": c.kind in CHECK_KINDS,
        "errors": {"kind": errors.claim(f"{at}.kind"), "points": errors.claim(f"{at}.points"),
                   "message": errors.claim(f"{at}.message")},
        "error": errors.claim(at, whole=True),
    }  # fmt: skip


def blank_document(world: str = "boxes", start: dict | None = None, group=None) -> dict:
    """A new exercise: one visible start pose (the world's first), no checks yet."""
    start = start or {"x": 0.0, "y": 0.0, "theta": math.pi / 2}
    return {
        "title": "", "text": "", "world": world, "class": group, "languages": [],
        "variants": [{"x": start["x"], "y": start["y"], "theta": start["theta"],
                      "hidden": False}],
        "checks": [], "starter": "", "starter_language": "python", "due": None,
        "attempts": None, "counts": "best", "speed": 5, "time_limit_s": 60,
    }  # fmt: skip
