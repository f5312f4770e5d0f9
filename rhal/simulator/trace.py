"""A run's trace, recorded from the simulator's motion: poses, contacts, commands, said texts.

The exercise checks (classroom.checks) judge a run by its trace, so the trace must be the
path the physics made, not the path somebody happened to read: ``Motion`` commits its state
only at instants fixed by the commands (rhal.simulator.physics), and the recorder samples it
on a grid of its own, every ``SAMPLE`` sim seconds from the trace's start, plus at each change
of command. Whoever owns the motion calls ``catch_up(now)`` before asking the motion anything
at ``now``: the grid instants up to ``now`` are sampled first, in order, so reading the robot
every millisecond or never gives the same trace.

Contacts are seen where the physics steps one step at a time (near walls and boxes: the
motion tells the recorder of each step it commits there), at the grid instants and at
commands: a contact begins when the bumper goes from free to pressed (within
``BUMPER_REACH`` of a surface, what the robot's bumper reading says).

The trace (times in sim seconds since the start; ``start_trace`` in rhal.sim):
``{"version": 1, "speed", "radius", "start": {"x", "y", "theta"}, "poses": [[t, x, y, theta],
...], "contacts": [[t, x, y], ...], "commands": [[t, linear, angular], ...], "said": [[t,
text], ...], "truncated": bool}``. Poses are kept while the robot moves (a stationary robot's
repeated pose is not), at most ``MAX_POSES`` of them, and the last is at the end.
"""

from __future__ import annotations

import math
from typing import Any

from rhal.simulator.physics import Motion, Pose

VERSION = 1
SAMPLE = 0.05  # sim s between poses while moving
MAX_POSES = 100_000
MAX_EVENTS = 100_000  # contacts, commands and said texts, each
MAX_SAID_CHARS = 500
DIGITS = 6  # decimals kept of times (s), metres and radians


class Recorder:
    """One recording of ``motion`` from sim time ``now`` (see the module's docstring)."""

    def __init__(self, motion: Motion, now: float, *, speed: float) -> None:
        self.motion = motion
        self.zero = now
        self.speed = speed
        pose = motion.pose_at(now)
        self.start = pose
        self.poses: list[list[float]] = [_pose_row(0.0, pose)]
        self.contacts: list[list[float]] = []
        self.commands: list[list[float]] = []
        self.said: list[list[Any]] = []
        self.truncated = False
        self._sampled = 0  # the grid instant last sampled: zero + _sampled * SAMPLE
        self._last_pose = pose
        self._held: list[float] | None = None  # the last of a stationary stretch, not kept yet
        # Touching already when the recording starts is no contact of the run's.
        self._touching = motion.bumper(pose)
        speeds = motion.command_speeds
        if speeds != (0.0, 0.0):
            self.commands.append([0.0, *speeds])
        motion.observer = self._stepped

    def time(self, now: float) -> float:
        return now - self.zero

    # -- fed by the robot ------------------------------------------------------------------

    def catch_up(self, now: float) -> None:
        """Sample the grid instants up to ``now``; call before the motion is asked about
        ``now``."""
        last = math.floor((now - self.zero) / SAMPLE + 1e-9)
        if last <= self._sampled:
            return
        if self.motion.command_speeds == (0.0, 0.0):  # standing still until the next command
            self._sampled = last
            return
        for index in range(self._sampled + 1, last + 1):
            when = self.zero + index * SAMPLE
            pose = self.motion.pose_at(when)
            self._touch(when, pose)
            self._pose(when, pose)
        self._sampled = last

    def command(self, now: float, linear: float, angular: float) -> None:
        """Speeds about to be commanded at ``now`` (after ``catch_up(now)``)."""
        if (linear, angular) == self.motion.command_speeds:
            return
        pose = self.motion.pose_at(now)
        self._touch(now, pose)
        self._pose(now, pose, force=True)
        if len(self.commands) < MAX_EVENTS:
            self.commands.append([_round(self.time(now)), linear, angular])
        else:
            self.truncated = True

    def placed(self, now: float) -> None:
        """The robot was put somewhere else (reset) at ``now``: the new pose, its contact."""
        pose = self.motion.pose_at(now)
        if self.commands and self.commands[-1][1:] != [0.0, 0.0]:
            self.commands.append([_round(self.time(now)), 0.0, 0.0])
        self._touching = False
        self._touch(now, pose)
        self._pose(now, pose, force=True)

    def say(self, now: float, text: str) -> None:
        if len(self.said) < MAX_EVENTS:
            self.said.append([_round(self.time(now)), str(text)[:MAX_SAID_CHARS]])
        else:
            self.truncated = True

    def finish(self, now: float) -> dict[str, Any]:
        """The trace up to ``now`` (its last pose); the motion is no longer watched."""
        self.catch_up(now)
        pose = self.motion.pose_at(now)
        self._touch(now, pose)
        t = _round(self.time(now))
        if self.poses[-1][0] != t:
            self.poses.append(_pose_row(t, pose))  # the last at the end, even past the cap
        self.motion.observer = None
        x, y, theta = self.start
        return {
            "version": VERSION,
            "speed": self.speed,
            "radius": self.motion.radius,
            "start": {"x": _round(x), "y": _round(y), "theta": _round(theta)},
            "poses": self.poses,
            "contacts": self.contacts,
            "commands": self.commands,
            "said": self.said,
            "truncated": self.truncated,
        }

    def stop(self) -> None:
        """Stop watching the motion without a trace."""
        if self.motion.observer == self._stepped:
            self.motion.observer = None

    # -- inside ----------------------------------------------------------------------------

    def _stepped(self, when: float, pose: Pose) -> None:
        """The motion committed a step near something at ``when``."""
        if when >= self.zero:
            self._touch(when, pose)

    def _touch(self, when: float, pose: Pose) -> None:
        touching = self.motion.bumper(pose)
        if touching and not self._touching:
            if len(self.contacts) < MAX_EVENTS:
                self.contacts.append([_round(self.time(when)), _round(pose[0]), _round(pose[1])])
            else:
                self.truncated = True
        self._touching = touching

    def _pose(self, when: float, pose: Pose, *, force: bool = False) -> None:
        t = _round(self.time(when))
        if pose == self._last_pose and (not force or self.poses[-1][0] == t):
            # Not kept while it stands; the stretch's end is, once it moves again.
            self._held = None if self.poses[-1][0] == t else _pose_row(t, pose)
            return
        if self._held is not None and self._held[0] < t:
            self._keep(self._held)
        self._held = None
        self._last_pose = pose
        self._keep(_pose_row(t, pose))

    def _keep(self, row: list[float]) -> None:
        if len(self.poses) >= MAX_POSES:
            self.truncated = True
            return
        self.poses.append(row)


def _round(value: float) -> float:
    return round(value, DIGITS)


def _pose_row(t: float, pose: Pose) -> list[float]:
    return [_round(t), _round(pose[0]), _round(pose[1]), _round(pose[2])]
