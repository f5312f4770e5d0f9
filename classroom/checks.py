"""An exercise's checks: data (JSON, like worlds) and the plain functions that judge a run.

A check is ``{"kind", "points": 1, "message": ""}`` plus the parameters of its kind; each
kind is one entry of ``KINDS`` (its parameters, and the function that judges), as MakeCode's
Teacher Tool keeps its catalogue. ``validate_checks`` refuses what cannot be judged, with the
place (``checks[2].zone``), and gives the checks back with their defaults filled in.

Per-variant checks judge a run's trace (classroom.trace) in the exercise's world
(``evaluate``); static ones judge a blocks program's source (``evaluate_static``, see
classroom.blocks_checks). An ``Outcome``'s ``why`` is in plain words a student understands:
times, distances to walls, zone names, counts; never a coordinate, a heading or a pose (a
hidden variant's result must not give its start away). ``_`` is the translator: the
classroom passes Django's gettext; this module imports no Django.
"""

from __future__ import annotations

import math
import re
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import regex  # matches that give up in time (the standard `re` cannot)

from classroom import blocks_checks
from classroom.trace import Trace
from rhal.simulator.world import World

Translate = Callable[[str], str]
MAX_CHECKS = 50
MAX_POINTS = 1000.0
MAX_SECONDS = 24 * 3600.0
MAX_METRES = 100.0
MAX_MESSAGE = 2000
MAX_PATTERN = 500
MAX_ZONES_IN_ORDER = 20
MAX_MATCHED_CHARS = 2000  # of each output line: a pattern is searched in this much
MATCH_SECONDS = 2.0  # an output check's matches together, at most
BLOCK_TYPE = re.compile(r"[A-Za-z_][A-Za-z0-9_]{0,99}")


def _same(text: str) -> str:
    return text


class CheckError(ValueError):
    """A check that cannot be judged: ``path`` says where (``checks[2].zone``), the message
    what and why."""

    def __init__(self, path: str, message: str) -> None:
        super().__init__(f"{path}: {message}" if path else message)
        self.path = path
        self.message = message


@dataclass(frozen=True)
class Outcome:
    passed: bool
    why: str


@dataclass(frozen=True)
class Param:
    name: str
    kind: str  # zone | zones | seconds | metres | text | pattern_flags | block | count
    required: bool = True
    default: Any = None


@dataclass(frozen=True)
class Kind:
    name: str
    params: tuple[Param, ...]
    static: bool = False


KINDS: dict[str, Kind] = {
    kind.name: kind
    for kind in (
        Kind(
            "reach_zone",
            (Param("zone", "zone"), Param("within_s", "seconds", required=False)),
        ),
        Kind(
            "zones_in_order",
            (Param("zones", "zones"), Param("within_s", "seconds", required=False)),
        ),
        Kind("no_contact", ()),
        Kind("stop_near_wall", (Param("min_m", "metres"), Param("max_m", "metres"))),
        Kind("ends_within", (Param("seconds", "seconds"),)),
        Kind(
            "output_matches",
            (Param("pattern", "pattern"), Param("flags", "flags", required=False, default="")),
        ),
        Kind("uses_block", (Param("block", "block"),), static=True),
        Kind("max_blocks", (Param("count", "count"),), static=True),
    )
}
STATIC_KINDS = frozenset(name for name, kind in KINDS.items() if kind.static)
COMMON = ("kind", "points", "message")


def is_static(check: dict) -> bool:
    """Whether a check judges the program's source (once) rather than each variant's run."""
    return check.get("kind") in STATIC_KINDS


# -- validating ------------------------------------------------------------------------------


def validate_checks(checks: Any, world: World, _: Translate = _same) -> list[dict]:
    """The checks with their defaults filled in; CheckError at the first that cannot be
    judged in ``world``."""
    if not isinstance(checks, list):
        raise CheckError("checks", _("the checks are a list"))
    if len(checks) > MAX_CHECKS:
        raise CheckError(
            "checks", _("an exercise has at most %(count)s checks") % {"count": MAX_CHECKS}
        )
    return [_validate(check, f"checks[{i}]", world, _) for i, check in enumerate(checks)]


def _validate(check: Any, path: str, world: World, _: Translate) -> dict:
    if not isinstance(check, dict):
        raise CheckError(path, _("a check is an object with a kind"))
    name = check.get("kind")
    kind = KINDS.get(name) if isinstance(name, str) else None
    if kind is None:
        raise CheckError(
            f"{path}.kind",
            _("unknown kind of check %(kind)s; the kinds are: %(kinds)s")
            % {"kind": _quoted(name), "kinds": ", ".join(KINDS)},
        )
    allowed = set(COMMON) | {param.name for param in kind.params}
    for key in check:
        if key not in allowed:
            raise CheckError(
                f"{path}.{key}",
                _("a %(kind)s check has no %(key)s; it takes: %(keys)s")
                % {"kind": kind.name, "key": _quoted(key), "keys": ", ".join(sorted(allowed))},
            )
    out: dict[str, Any] = {"kind": kind.name}
    points = check.get("points", 1)
    if not _is_number(points) or not 0 <= points <= MAX_POINTS:
        raise CheckError(
            f"{path}.points",
            _("points are a number from 0 to %(max)s") % {"max": f"{MAX_POINTS:g}"},
        )
    out["points"] = points
    message = check.get("message", "")
    if message is None:
        message = ""
    if not isinstance(message, str) or len(message) > MAX_MESSAGE:
        raise CheckError(
            f"{path}.message",
            _("the message is a text of at most %(count)s characters") % {"count": MAX_MESSAGE},
        )
    out["message"] = message
    for param in kind.params:
        where = f"{path}.{param.name}"
        value = check.get(param.name)
        if value is None:
            if param.required:
                raise CheckError(
                    where,
                    _("a %(kind)s check needs %(key)s") % {"kind": kind.name, "key": param.name},
                )
            out[param.name] = param.default
            continue
        out[param.name] = VALIDATORS[param.kind](value, where, world, _)
    if kind.name == "stop_near_wall" and out["min_m"] > out["max_m"]:
        raise CheckError(
            f"{path}.min_m",
            _("min_m (%(min)s m) is more than max_m (%(max)s m)")
            % {"min": f"{out['min_m']:g}", "max": f"{out['max_m']:g}"},
        )
    return out


def _is_number(value: Any) -> bool:
    return isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)


def _quoted(value: Any) -> str:
    return f'"{value}"' if isinstance(value, str) else repr(value)[:40]


def _zone_names(world: World) -> list[str]:
    return [zone.name for zone in world.zones]


def _zone(value: Any, where: str, world: World, _: Translate) -> str:
    names = _zone_names(world)
    if not isinstance(value, str) or value not in names:
        if not names:
            raise CheckError(
                where,
                _("there is no zone %(zone)s: this world has no zones") % {"zone": _quoted(value)},
            )
        raise CheckError(
            where,
            _("there is no zone %(zone)s in this world; its zones are: %(zones)s")
            % {"zone": _quoted(value), "zones": ", ".join(names)},
        )
    return value


def _zones(value: Any, where: str, world: World, _: Translate) -> list[str]:
    if not isinstance(value, list) or not 2 <= len(value) <= MAX_ZONES_IN_ORDER:
        raise CheckError(
            where,
            _("a list of %(low)s to %(high)s zone names is needed")
            % {"low": 2, "high": MAX_ZONES_IN_ORDER},
        )
    return [_zone(name, f"{where}[{i}]", world, _) for i, name in enumerate(value)]


def _seconds(value: Any, where: str, world: World, _: Translate) -> float:
    if not _is_number(value) or not 0 < value <= MAX_SECONDS:
        raise CheckError(
            where,
            _("a number of seconds above 0 and at most %(max)s is needed")
            % {"max": f"{MAX_SECONDS:g}"},
        )
    return value


def _metres(value: Any, where: str, world: World, _: Translate) -> float:
    if not _is_number(value) or not 0 <= value <= MAX_METRES:
        raise CheckError(
            where,
            _("a distance in metres from 0 to %(max)s is needed") % {"max": f"{MAX_METRES:g}"},
        )
    return value


def _pattern(value: Any, where: str, world: World, _: Translate) -> str:
    if not isinstance(value, str) or not value or len(value) > MAX_PATTERN:
        raise CheckError(
            where,
            _("a pattern (a Python regular expression) of 1 to %(max)s characters is needed")
            % {"max": MAX_PATTERN},
        )
    try:
        regex.compile(value)
    except regex.error as exc:
        raise CheckError(
            where, _("the pattern is not a valid regular expression: %(why)s") % {"why": exc}
        ) from None
    return value


def _flags(value: Any, where: str, world: World, _: Translate) -> str:
    if value not in ("", "i"):
        raise CheckError(where, _('flags are "" or "i" (ignore case)'))
    return value


def _block(value: Any, where: str, world: World, _: Translate) -> str:
    if not isinstance(value, str) or not BLOCK_TYPE.fullmatch(value):
        raise CheckError(
            where,
            _('a block type (such as controls_whileUntil), "loop" or "condition" is needed'),
        )
    return value


def _count(value: Any, where: str, world: World, _: Translate) -> int:
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 10_000:
        raise CheckError(where, _("a whole number of blocks from 1 to 10000 is needed"))
    return value


VALIDATORS: dict[str, Callable[[Any, str, World, Translate], Any]] = {
    "zone": _zone,
    "zones": _zones,
    "seconds": _seconds,
    "metres": _metres,
    "pattern": _pattern,
    "flags": _flags,
    "block": _block,
    "count": _count,
}


# -- judging ---------------------------------------------------------------------------------


def evaluate(check: dict, trace: Trace, world: World, _: Translate = _same) -> Outcome:
    """Whether the run whose trace this is passes ``check`` (a validated one) in ``world``."""
    kind = check.get("kind") if isinstance(check, dict) else None
    if kind in STATIC_KINDS:
        raise ValueError(f"a {kind} check judges the program's source: evaluate_static")
    try:  # as saved, it was valid; a world changed since may have lost its zone
        check = _validate(check, "", world, _)
    except CheckError as exc:
        return _unjudged(exc, _)
    return JUDGES[check["kind"]](check, trace, world, _)


def _unjudged(exc: CheckError, _: Translate) -> Outcome:
    return Outcome(
        False, _("this check cannot be judged as it is written: %(why)s") % {"why": exc.message}
    )


def evaluate_static(check: dict, language: str, source: str, _: Translate = _same) -> Outcome:
    """Whether a program (its language and source) passes a static check (uses_block,
    max_blocks); a program that is not a blocks program does not, and the why says so."""
    kind = check.get("kind") if isinstance(check, dict) else None
    if kind not in STATIC_KINDS:
        raise ValueError(f"a {kind} check judges a run's trace: evaluate")
    try:
        check = _validate(check, "", None, _)  # type: ignore[arg-type] # no zones in these
    except CheckError as exc:
        return _unjudged(exc, _)
    if language != "blocks":
        return Outcome(
            False,
            _("this check needs a blocks program; this program is in %(language)s")
            % {"language": blocks_checks.language_name(language)},
        )
    try:
        blocks = blocks_checks.blocks_of(source)
    except ValueError:
        return Outcome(False, _("the blocks program could not be read"))
    if kind == "uses_block":
        return Outcome(*blocks_checks.uses_block(check["block"], blocks, _))
    return Outcome(*blocks_checks.max_blocks(int(check["count"]), blocks, _))


def _s(seconds: float) -> str:
    return f"{seconds:.1f}"


def _late(seconds: float, limit: float) -> str:
    """Seconds past a limit, with the decimals it takes not to read as within it."""
    for digits in (1, 2, 3):
        shown = f"{seconds:.{digits}f}"
        if float(shown) > limit:
            return shown
    return f"{seconds:.3f}"


def _m(metres: float) -> str:
    return f"{metres:.2f}"


def _reach_zone(check: dict, trace: Trace, world: World, _: Translate) -> Outcome:
    name = check["zone"]
    zone = _world_zone(world, name)
    within = check.get("within_s")
    if zone is None:
        return Outcome(False, _("the world has no zone %(zone)s") % {"zone": _quoted(name)})
    when = trace.first_time_in((zone.x, zone.y, zone.width, zone.height))
    if when is None:
        return Outcome(
            False,
            _("it never reached the %(zone)s zone (the run lasted %(seconds)s s)")
            % {"zone": name, "seconds": _s(trace.end_time)},
        )
    if within is not None and when > within:
        return Outcome(
            False,
            _("it reached the %(zone)s zone after %(seconds)s s; the exercise wants it there "
              "within %(within)s s")
            % {"zone": name, "seconds": _late(when, within), "within": f"{within:g}"},
        )  # fmt: skip
    return Outcome(
        True,
        _("it reached the %(zone)s zone after %(seconds)s s") % {"zone": name, "seconds": _s(when)},
    )


def _zones_in_order(check: dict, trace: Trace, world: World, _: Translate) -> Outcome:
    names = check["zones"]
    within = check.get("within_s")
    when = 0.0
    for index, name in enumerate(names):
        zone = _world_zone(world, name)
        if zone is None:
            return Outcome(False, _("the world has no zone %(zone)s") % {"zone": _quoted(name)})
        reached = trace.first_time_in((zone.x, zone.y, zone.width, zone.height), after=when)
        if reached is None:
            if index == 0:
                return Outcome(
                    False,
                    _("it never reached the %(zone)s zone, the first of the zones to visit")
                    % {"zone": name},
                )
            return Outcome(
                False,
                _(
                    "it reached the %(before)s zone after %(seconds)s s, but never the "
                    "%(zone)s zone after it"
                )
                % {"before": names[index - 1], "seconds": _s(when), "zone": name},
            )
        when = reached
    order = ", ".join(names)
    if within is not None and when > within:
        return Outcome(
            False,
            _("it visited %(zones)s in that order, but only after %(seconds)s s; the exercise "
              "wants it done within %(within)s s")
            % {"zones": order, "seconds": _late(when, within), "within": f"{within:g}"},
        )  # fmt: skip
    return Outcome(
        True,
        _("it visited %(zones)s in that order, the last after %(seconds)s s")
        % {"zones": order, "seconds": _s(when)},
    )


def _no_contact(check: dict, trace: Trace, world: World, _: Translate) -> Outcome:
    contacts = trace.contacts_until(trace.end_time)
    if not contacts:
        return Outcome(True, _("it touched nothing"))
    t, x, y = contacts[0]
    what = _obstacle_word(world, x, y, _)
    if len(contacts) == 1:
        why = _("it touched %(what)s %(seconds)s s into the run") % {
            "what": what,
            "seconds": _s(t),
        }
    else:
        why = _(
            "it touched %(what)s %(seconds)s s into the run, and %(count)s times more after"
        ) % {"what": what, "seconds": _s(t), "count": len(contacts) - 1}
    return Outcome(False, why)


def _stop_near_wall(check: dict, trace: Trace, world: World, _: Translate) -> Outcome:
    low, high = check["min_m"], check["max_m"]
    band = {"min": _m(low), "max": _m(high)}
    if not trace.still_at_end():
        if trace.end is not None and trace.end.time_limit:
            return Outcome(
                False,
                _("it was still moving when the time was up, after %(seconds)s s")
                % {"seconds": _s(trace.end_time)},
            )
        return Outcome(
            False,
            _("it was still moving when the program ended, after %(seconds)s s")
            % {"seconds": _s(trace.end_time)},
        )
    x, y, _theta = trace.final_pose()
    gap = max(0.0, world.clearance(x, y) - trace.radius)
    nearest = _nearest_word(world, x, y, _)
    passed = low <= gap + 5e-4 and gap - 5e-4 <= high  # read at the millimetre
    shown = _m(gap)
    if passed != (low <= float(shown) <= high):  # not to read as in the band, or out of it
        shown = f"{gap:.3f}"
    words = {"gap": shown, "nearest": nearest, **band}
    if passed:
        return Outcome(
            True,
            _("it stopped %(gap)s m from the nearest %(nearest)s, within %(min)s–%(max)s m")
            % words,
        )
    return Outcome(
        False,
        _("it stopped %(gap)s m from the nearest %(nearest)s; the exercise wants %(min)s–%(max)s m")
        % words,
    )


def _ends_within(check: dict, trace: Trace, world: World, _: Translate) -> Outcome:
    seconds = check["seconds"]
    end = trace.end
    if end is None:
        return Outcome(False, _("the run has no end recorded"))
    at = _s(end.t)
    if end.time_limit:
        return Outcome(
            False,
            _("it was still running when the time was up, after %(seconds)s s") % {"seconds": at},
        )
    if end.state == "stopped":
        return Outcome(
            False,
            _("it did not end on its own: it was stopped after %(seconds)s s") % {"seconds": at},
        )
    if end.state != "finished" or end.exit_code != 0:
        if end.exit_code is None:
            return Outcome(False, _("it failed after %(seconds)s s") % {"seconds": at})
        return Outcome(
            False,
            _("it ended with an error (exit code %(code)s) after %(seconds)s s")
            % {"code": end.exit_code, "seconds": at},
        )
    if end.t > seconds:
        return Outcome(
            False,
            _("it ended on its own after %(seconds)s s; the exercise wants it to end within "
              "%(within)s s") % {"seconds": _late(end.t, seconds), "within": f"{seconds:g}"},
        )  # fmt: skip
    return Outcome(True, _("it ended on its own after %(seconds)s s") % {"seconds": at})


def _output_matches(check: dict, trace: Trace, world: World, _: Translate) -> Outcome:
    flags = regex.IGNORECASE if check.get("flags") == "i" else 0
    pattern = regex.compile(check["pattern"], flags)
    # A pattern that backtracks without end on what a program printed would hold the process
    # that checks (the server's, embedded): the `regex` module's matches give up in time.
    deadline = time.monotonic() + MATCH_SECONDS
    for t, source, text in trace.texts():
        try:
            found = pattern.search(
                text[:MAX_MATCHED_CHARS], timeout=max(deadline - time.monotonic(), 0.001)
            )
        except TimeoutError:
            return Outcome(
                False,
                _("the check's pattern took more than %(seconds)s s to match the output: "
                  "ask your teacher to simplify it") % {"seconds": f"{MATCH_SECONDS:g}"},
            )  # fmt: skip
        if found:
            if source == "said":
                why = _("it said a matching text %(seconds)s s into the run")
            else:
                why = _("it printed a matching line %(seconds)s s into the run")
            return Outcome(True, why % {"seconds": _s(t)})
    return Outcome(
        False,
        _("no output line or said text matched what the exercise expects (it printed "
          "%(lines)s lines and said %(said)s texts)")
        % {"lines": len(trace.output), "said": len(trace.said)},
    )  # fmt: skip


JUDGES: dict[str, Callable[[dict, Trace, World, Translate], Outcome]] = {
    "reach_zone": _reach_zone,
    "zones_in_order": _zones_in_order,
    "no_contact": _no_contact,
    "stop_near_wall": _stop_near_wall,
    "ends_within": _ends_within,
    "output_matches": _output_matches,
}


# -- the world in words ------------------------------------------------------------------------


def _world_zone(world: World, name: str):
    return next((zone for zone in world.zones if zone.name == name), None)


def _nearest_is_box(world: World, x: float, y: float) -> bool:
    """Whether the obstacle nearest a point is a box (else a wall: the arena's or an inner
    one). The world's edges are the arena's four, then four per wall, then four per box."""
    distances = world.edges.distances(x, y)
    if not len(distances):
        return False
    return int(distances.argmin()) >= 4 + 4 * len(world.walls)


def _obstacle_word(world: World, x: float, y: float, _: Translate) -> str:
    return _("a box") if _nearest_is_box(world, x, y) else _("a wall")


def _nearest_word(world: World, x: float, y: float, _: Translate) -> str:
    return _("box") if _nearest_is_box(world, x, y) else _("wall")
