"""A run's recorded trace (``trace.json`` in the run's directory) as checks read it.

The simulator records poses, contacts, commands and said texts (rhal.simulator.trace); the
agent adds the program's output lines and how it ended. ``Trace.from_dict`` checks the
document's types and says what is wrong (ValueError) and where; the helpers answer what the
checks ask: where the robot was at a time, when it first entered a rectangle, whether it
stood still when the program ended. Plain Python and numpy, no Django.

Times are sim seconds since the run began. "The end" is when the program ended
(``end["t"]``): what the robot did after it (the agent stopping it) is not the program's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

END_STATES = ("finished", "failed", "stopped")
MAX_ROWS = 200_000
STILL_WINDOW = 0.5  # sim s: a robot whose pose did not change over this long stands still
STILL_DISTANCE = 1e-3  # m
STILL_TURN = 1e-2  # rad

Row = tuple[float, ...]


@dataclass(frozen=True)
class End:
    t: float
    state: str  # finished | failed | stopped
    exit_code: int | None
    reason: str
    time_limit: bool


@dataclass(frozen=True)
class Trace:
    speed: float
    radius: float
    start: tuple[float, float, float]
    poses: tuple[tuple[float, float, float, float], ...]
    contacts: tuple[tuple[float, float, float], ...] = ()
    commands: tuple[tuple[float, float, float], ...] = ()
    said: tuple[tuple[float, str], ...] = ()
    output: tuple[tuple[float, str], ...] = ()
    end: End | None = None
    truncated: bool = False
    version: int = 1

    # -- reading ---------------------------------------------------------------------------

    @classmethod
    def from_dict(cls, doc: Any) -> Trace:
        """The trace of a document as rhal.simulator.trace and the agent write it;
        ValueError, naming the place, for anything of the wrong type or shape."""
        if not isinstance(doc, dict):
            raise ValueError("a trace is a JSON object")
        version = doc.get("version", 1)
        if version != 1:
            raise ValueError(f"version: a trace of version {version!r} cannot be read")
        start = doc.get("start")
        if not isinstance(start, dict):
            raise ValueError('start: an object {"x", "y", "theta"} is needed')
        poses = _rows(doc, "poses", (_number,) * 4, required=True)
        if not poses:
            raise ValueError("poses: at least one pose is needed")
        _in_time_order(poses, "poses")
        contacts = _rows(doc, "contacts", (_number,) * 3)
        commands = _rows(doc, "commands", (_number,) * 3)
        _in_time_order(commands, "commands")
        said = _rows(doc, "said", (_number, _text))
        output = _rows(doc, "output", (_number, _text))
        truncated = doc.get("truncated", False)
        if not isinstance(truncated, bool):
            raise ValueError("truncated: true or false")
        return cls(
            version=1,
            speed=_positive(doc.get("speed", 1.0), "speed"),
            radius=_positive(doc.get("radius"), "radius"),
            start=tuple(_number(start.get(k), f"start.{k}") for k in ("x", "y", "theta")),  # type: ignore[arg-type]
            poses=poses,  # type: ignore[arg-type]
            contacts=contacts,  # type: ignore[arg-type]
            commands=commands,  # type: ignore[arg-type]
            said=said,  # type: ignore[arg-type]
            output=output,  # type: ignore[arg-type]
            end=_end(doc.get("end")),
            truncated=truncated,
        )

    def to_dict(self) -> dict[str, Any]:
        x, y, theta = self.start
        doc: dict[str, Any] = {
            "version": self.version,
            "speed": self.speed,
            "radius": self.radius,
            "start": {"x": x, "y": y, "theta": theta},
            "poses": [list(row) for row in self.poses],
            "contacts": [list(row) for row in self.contacts],
            "commands": [list(row) for row in self.commands],
            "said": [list(row) for row in self.said],
            "output": [list(row) for row in self.output],
            "truncated": self.truncated,
        }
        if self.end is not None:
            e = self.end
            doc["end"] = {"t": e.t, "state": e.state, "exit_code": e.exit_code,
                          "reason": e.reason, "time_limit": e.time_limit}  # fmt: skip
        return doc

    # -- asking ----------------------------------------------------------------------------

    @property
    def end_time(self) -> float:
        """When the program ended; without an end, the last pose's time."""
        return self.end.t if self.end is not None else self.poses[-1][0]

    def pose_at(self, t: float) -> tuple[float, float, float]:
        """The pose at ``t``, between two recorded ones by a straight line (they are at most
        a few centimetres apart while it moves)."""
        poses = self.poses
        if t <= poses[0][0]:
            return poses[0][1:]  # type: ignore[return-value]
        if t >= poses[-1][0]:
            return poses[-1][1:]  # type: ignore[return-value]
        times = self._times()
        i = int(np.searchsorted(times, t, side="right")) - 1
        t0, x0, y0, h0 = poses[i]
        t1, x1, y1, h1 = poses[i + 1]
        f = (t - t0) / (t1 - t0) if t1 > t0 else 1.0
        turn = math.remainder(h1 - h0, math.tau)
        heading = math.remainder(h0 + f * turn, math.tau)
        return (x0 + f * (x1 - x0), y0 + f * (y1 - y0), heading)

    def final_pose(self) -> tuple[float, float, float]:
        return self.pose_at(self.end_time)

    def command_at_end(self) -> tuple[float, float]:
        """The speeds in force when the program ended: the last command up to the end (a
        stop the agent gave once it ended is not the program's)."""
        end = self.end_time
        speeds = (0.0, 0.0)
        for t, linear, angular in self.commands:
            if t > end:
                break
            speeds = (linear, angular)
        return speeds

    def still_at_end(self) -> bool:
        """Whether the robot stood still when the program ended: told to stop, or not moved
        over the last moments (pushing against a wall)."""
        if self.command_at_end() == (0.0, 0.0):
            return True
        end = self.end_time
        x0, y0, h0 = self.pose_at(end - STILL_WINDOW)
        x1, y1, h1 = self.pose_at(end)
        return (
            math.hypot(x1 - x0, y1 - y0) <= STILL_DISTANCE
            and abs(math.remainder(h1 - h0, math.tau)) <= STILL_TURN
        )

    def contacts_until(self, t: float) -> list[tuple[float, float, float]]:
        return [row for row in self.contacts if row[0] <= t]

    def texts(self) -> list[tuple[float, str, str]]:
        """(t, "output" | "said", text) of every output line and said text, in time order."""
        rows = [(t, "output", line) for t, line in self.output]
        rows += [(t, "said", text) for t, text in self.said]
        return sorted(rows, key=lambda row: row[0])

    def first_time_in(
        self,
        rect: tuple[float, float, float, float],
        after: float = 0.0,
        until: float | None = None,
    ) -> float | None:
        """When the robot's centre first was inside ``rect`` (x, y, width, height: centre and
        size) at or after ``after`` and not later than ``until`` (default: the end); None if
        it never was. The path between recorded poses is a straight line."""
        until = self.end_time if until is None else until
        cx, cy, w, h = rect
        low = np.array([cx - w / 2, cy - h / 2])
        high = np.array([cx + w / 2, cy + h / 2])
        rows = self._array()
        if after > until:
            return None
        last = rows[-1]
        if len(rows) == 1 or last[0] < until:  # it stays where it was last seen
            rows = np.vstack([rows, [max(until, last[0]), *last[1:]]])
        a, b = rows[:-1], rows[1:]
        ta, tb = a[:, 0], b[:, 0]
        span = tb - ta
        # Each piece cut to [after, until] in time: its part s in [s_lo, s_hi].
        with np.errstate(divide="ignore", invalid="ignore"):
            s_lo = np.where(span > 0, (after - ta) / span, np.where(ta >= after, 0.0, 1.0))
            s_hi = np.where(span > 0, (until - ta) / span, np.where(ta <= until, 1.0, 0.0))
        s_lo = np.clip(s_lo, 0.0, 1.0)
        s_hi = np.clip(s_hi, 0.0, 1.0)
        start, move = a[:, 1:3], b[:, 1:3] - a[:, 1:3]
        enter, leave = s_lo.copy(), s_hi.copy()
        for axis in (0, 1):  # Liang-Barsky, one axis at a time
            d = move[:, axis]
            p = start[:, axis]
            with np.errstate(divide="ignore", invalid="ignore"):
                s1 = (low[axis] - p) / d
                s2 = (high[axis] - p) / d
            still = d == 0
            inside = (p >= low[axis]) & (p <= high[axis])
            s_in = np.where(still, np.where(inside, -np.inf, np.inf), np.minimum(s1, s2))
            s_out = np.where(still, np.where(inside, np.inf, -np.inf), np.maximum(s1, s2))
            enter = np.maximum(enter, s_in)
            leave = np.minimum(leave, s_out)
        hit = (enter <= leave) & (ta <= until) & (tb >= after)
        if not hit.any():
            return None
        i = int(np.argmax(hit))
        when = float(ta[i] + enter[i] * span[i])
        return max(when, after)

    def _times(self) -> np.ndarray:
        return self._array()[:, 0]

    def _array(self) -> np.ndarray:
        cached = self.__dict__.get("_poses_array")
        if cached is None:
            cached = np.array(self.poses, dtype=float).reshape(-1, 4)
            object.__setattr__(self, "_poses_array", cached)
        return cached


# -- checking a document -----------------------------------------------------------------


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value):
        raise ValueError(f"{where}: a finite number is needed, got {value!r:.40}")
    return float(value)


def _text(value: Any, where: str) -> str:
    if not isinstance(value, str):
        raise ValueError(f"{where}: a text is needed, got {value!r:.40}")
    return value


def _positive(value: Any, where: str) -> float:
    number = _number(value, where)
    if number <= 0:
        raise ValueError(f"{where}: a number above 0 is needed, got {value!r}")
    return number


def _rows(doc: dict, key: str, kinds: tuple, *, required: bool = False) -> tuple[Row, ...]:
    rows = doc.get(key)
    if rows is None and not required:
        return ()
    if not isinstance(rows, list):
        raise ValueError(f"{key}: a list is needed")
    if len(rows) > MAX_ROWS:
        raise ValueError(f"{key}: more than {MAX_ROWS} rows")
    out = []
    for index, row in enumerate(rows):
        if not isinstance(row, list | tuple) or len(row) != len(kinds):
            raise ValueError(f"{key}[{index}]: a list of {len(kinds)} values is needed")
        out.append(tuple(kind(v, f"{key}[{index}]") for kind, v in zip(kinds, row, strict=True)))
    return tuple(out)


def _in_time_order(rows: tuple[Row, ...], key: str) -> None:
    for index in range(1, len(rows)):
        if rows[index][0] < rows[index - 1][0]:
            raise ValueError(f"{key}[{index}]: earlier than the one before it")


def _end(doc: Any) -> End | None:
    if doc is None:
        return None
    if not isinstance(doc, dict):
        raise ValueError("end: an object is needed")
    state = doc.get("state")
    if state not in END_STATES:
        raise ValueError(f"end.state: one of {', '.join(END_STATES)} is needed, got {state!r:.40}")
    exit_code = doc.get("exit_code")
    if exit_code is not None and (isinstance(exit_code, bool) or not isinstance(exit_code, int)):
        raise ValueError(f"end.exit_code: a whole number or null is needed, got {exit_code!r:.40}")
    reason = doc.get("reason") or ""
    if not isinstance(reason, str):
        raise ValueError("end.reason: a text is needed")
    time_limit = doc.get("time_limit", False)
    if not isinstance(time_limit, bool):
        raise ValueError("end.time_limit: true or false")
    return End(_number(doc.get("t"), "end.t"), state, exit_code, reason, time_limit)
