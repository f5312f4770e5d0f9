"""What a name may not hold, checked in one place for the API's schemas and the pages' forms.

Names (of programs, robots, classes, tokens, buttons; the user or class a program is shared
with) go into file names, zip members, exports, e-mail subjects, logs, terminals and pages.
Refused in them: control characters (Unicode Cc: NUL, which PostgreSQL cannot store, line
breaks, escapes a terminal obeys...), the line and paragraph separators, surrogates (not
text: PostgreSQL refuses them too), and the marks that reorder text (bidi overrides and
isolates), which make a name read otherwise than it is ("txt.exe" shown as "exe.txt").
"""

import unicodedata
from typing import Annotated

from django.core.exceptions import ValidationError
from django.utils.translation import gettext as _
from pydantic import BeforeValidator

# Arabic letter mark, LRM, RLM; LRE, RLE, PDF, LRO, RLO; LRI, RLI, FSI, PDI.
BIDI_CONTROLS = frozenset(
    "\u061c\u200e\u200f\u202a\u202b\u202c\u202d\u202e\u2066\u2067\u2068\u2069"
)
REFUSED_CATEGORIES = frozenset({"Cc", "Cs", "Zl", "Zp"})


def refused(char: str) -> bool:
    return char in BIDI_CONTROLS or unicodedata.category(char) in REFUSED_CATEGORIES


def problem(name: str) -> str | None:
    """Why ``name`` may not be a name (its first refused character, where), or None."""
    for position, char in enumerate(name, 1):
        if refused(char):
            return _(
                "a name may not hold control or text-direction characters:"
                " U+%(code)04X at character %(position)s"
            ) % {"code": ord(char), "position": position}
    return None


def check(name: str) -> str:
    """``name``, or ValueError saying what is wrong with it (pydantic makes that a 422).
    Anything but a string passes, for the schema's type check to refuse."""
    if isinstance(name, str) and (why := problem(name)) is not None:
        raise ValueError(why)
    return name


def validate(name: str) -> None:
    """For a Django form field's validators: ValidationError saying what is wrong."""
    if (why := problem(name)) is not None:
        raise ValidationError(why, code="name_characters")


def cleaned(name: str) -> str:
    """``name`` without the characters a name may not hold: for names made from what a user
    did not type as a name (an uploaded file's, a zip member's)."""
    return "".join(char for char in name if not refused(char))


#: A name in an API schema (a body's field, a path or query parameter): refused with a 422
#: saying which character, before a pattern the field may have says only that it differs.
Name = Annotated[str, BeforeValidator(check)]
