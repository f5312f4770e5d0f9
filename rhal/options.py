"""The typed options each driver takes, read off its constructor.

A driver's keyword-only parameters are its options; their annotations give the type and their
defaults the default, so the signature stays the one source of truth. A driver documents them
in ``option_help`` (name -> text) and may restrict text options in ``option_choices``.
Parameters only code can pass (a clock, a callable) are not options.

    >>> [o.name for o in driver_options("sim://")]
    ['arena', 'max_linear', 'max_angular']
"""

from __future__ import annotations

import inspect
import types
import typing
from dataclasses import dataclass
from typing import Any
from urllib.parse import urlencode, urlsplit

from rhal.base import Robot
from rhal.registry import driver_class, parse_query_options

#: The kinds of value an option can hold, as a form shows them.
KINDS = (bool, int, float, str)


@dataclass(frozen=True)
class Option:
    name: str
    kind: type  # one of KINDS
    default: Any  # None: not set, the driver decides (e.g. "no WAV file")
    help: str = ""
    choices: tuple[str, ...] = ()
    #: A text option that may also be a number (a sound device's name or index).
    numeric_text: bool = False

    def parse(self, text: str) -> Any:
        """The value a text (form field, URL query) stands for, or None when blank."""
        text = text.strip()
        if not text:
            return None
        if self.kind is str and not self.numeric_text:
            return text
        return parse_query_options(urlencode({"v": text}))["v"]


def driver_options(url: str) -> list[Option]:
    """Every option of the driver for ``url``, its own first, then the speed limits."""
    cls = driver_class(url)
    found = _options_of(cls.__init__, cls)
    limits = _options_of(Robot.__init__, Robot)
    return found + [o for o in limits if o.name not in {f.name for f in found}]


def url_options(url: str) -> dict[str, Any]:
    """Options given in the URL's query string."""
    return parse_query_options(urlsplit(url).query)


def _options_of(function: Any, cls: type) -> list[Option]:
    hints = typing.get_type_hints(function)
    options = []
    for param in inspect.signature(function).parameters.values():
        if param.kind is not inspect.Parameter.KEYWORD_ONLY:
            continue
        kind, numeric_text = _kind(hints.get(param.name, Any))
        if kind is None:
            continue
        default = None if param.default is inspect.Parameter.empty else param.default
        options.append(
            Option(
                name=param.name,
                kind=kind,
                default=default,
                help=getattr(cls, "option_help", {}).get(param.name, ""),
                choices=tuple(getattr(cls, "option_choices", {}).get(param.name, ())),
                numeric_text=numeric_text,
            )
        )
    return options


def _kind(annotation: Any) -> tuple[type | None, bool]:
    """(the form kind for an annotation, whether a text may also be a number)."""
    members = set(typing.get_args(annotation)) if _is_union(annotation) else {annotation}
    members.discard(type(None))
    if members <= {bool}:
        return bool, False
    if members <= {int}:
        return int, False
    if members <= {int, float}:
        return float, False
    if str in members:  # str | PathLike, str | Mapping: entered as text
        return str, bool(members & {int, float})
    return None, False  # callables and other things only code can pass


def _is_union(annotation: Any) -> bool:
    return typing.get_origin(annotation) in (typing.Union, types.UnionType)
