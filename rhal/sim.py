"""A simulated differential-drive robot in a walled arena, for ``sim://`` URLs.

Options, also accepted in the URL query (``sim://?arena=square&max_linear=0.3``):
``arena`` ("boxes", the default, or "square"), ``max_linear``, ``max_angular``; from code also
``clock``, a callable returning seconds (default ``time.monotonic``) so tests can step time.

Two cameras: ``camera_jpeg()`` looks down on the arena (the robot's page shows it), and
``front_camera_jpeg()`` sees what a camera on the robot's nose would: the walls, the boxes and
the QR code landmarks on the walls, in perspective (``capabilities()["front_camera"]``). The
Robot API's ``snapshot()`` and ``scan_barcode()`` use the front camera of a driver that has one.

It hears no sound: a program's ``listen()`` hears the phrases typed to it (``hearing``).

The robot starts at the arena centre (0, 0) facing north. Nothing runs in the background: each
call first advances the pose from the last update to now along the exact arc of the commanded
speeds. Travel is checked against walls and boxes every centimetre, so no time step is large
enough to tunnel; on contact the robot stops there, bumper pressed, until the next command.
"""

from __future__ import annotations

import asyncio
import math
import time
from collections.abc import Callable
from typing import Any

from rhal.arena import ARENAS, Arena
from rhal.base import Robot
from rhal.kinematics import advance_pose, compass_heading
from rhal.sim_words import LANGUAGES as SIM_LANGUAGES

ROBOT_RADIUS = 0.15  # m
MAX_RANGE = 4.0  # m, the range sensor's reach
START_POSE = (0.0, 0.0, math.pi / 2)  # arena centre, facing north
CAMERA_SIZE = (320, 240)
FRONT_CAMERA_SIZE = (640, 480)
FRONT_CAMERA_FOV = 62.0  # degrees, horizontal: a Raspberry Pi camera's

SUBSTEP = 0.01  # m of travel between collision checks; far thinner than any wall or box
CONTACT_TOLERANCE = 1e-6  # m: how exactly a contact is located
BUMPER_REACH = 1e-3  # m: the bumper reads pressed this close to a surface
BATTERY_DRAIN = 0.05  # percent per metre travelled

Pose = tuple[float, float, float]


class SimRobot(Robot):
    kind = "sim"
    option_help = {
        **Robot.option_help,
        "arena": "the walled arena the robot starts in",
        "language": "the language of the words drawn on its camera's picture",
    }
    option_choices = {"arena": tuple(ARENAS), "language": SIM_LANGUAGES}
    quick = True  # computed in-process: nothing to wait for
    # No microphone: the Robot API's listen() hears what is typed into the robot page's "Say
    # to the robot" box instead (robots.typed_speech). A robot that hears through the
    # computer's microphone has no such attribute (or "microphone").
    hearing = "typed"

    def __init__(
        self,
        url: str = "sim://",
        *,
        arena: str = "boxes",
        language: str = "en",
        clock: Callable[[], float] = time.monotonic,
        **limits: Any,
    ) -> None:
        super().__init__(url, **limits)
        if arena not in ARENAS:
            raise ValueError(f"unknown arena {arena!r}; choose one of: {', '.join(ARENAS)}")
        if language not in SIM_LANGUAGES:
            known = ", ".join(SIM_LANGUAGES)
            raise ValueError(f"unknown language {language!r}; choose one of: {known}")
        self.language = language
        self.arena_name = arena
        self._arena: Arena = ARENAS[arena]
        self._clock = clock
        self._opened_at = self._updated_at = clock()
        self._place_at_start()

    async def reset(self) -> None:
        """Stop and put the robot back at the start pose with a fresh odometer and battery."""
        self._updated_at = self._clock()
        self._place_at_start()

    def _place_at_start(self) -> None:
        self._pose: Pose = START_POSE
        self._command = (0.0, 0.0)
        self._blocked = False
        self._distance = 0.0
        self._derived_for: Pose | None = None

    # -- hooks -----------------------------------------------------------------------------

    async def _open(self) -> None:
        self._opened_at = self._updated_at = self._clock()
        self._place_at_start()

    async def _drive(self, linear: float, angular: float) -> None:
        self._advance(self._clock())
        self._command = (linear, angular)
        self._blocked = False

    async def _read_sensors(self) -> dict[str, Any]:
        now = self._clock()
        self._advance(now)
        self._derive_readings()
        x, y, theta = self._pose
        linear, angular = (0.0, 0.0) if self._blocked else self._command
        return {
            "heading": self._heading,
            "range": self._range,
            "position": {"x": x, "y": y, "theta": theta},
            "velocity": {"linear": linear, "angular": angular},
            "odometry": {"distance": self._distance},
            "bumper": self._bumper,
            "battery": max(0.0, 100.0 - BATTERY_DRAIN * self._distance),
            "time": now - self._opened_at,
        }

    def _sensor_specs(self) -> dict[str, dict[str, Any]]:
        return {
            "heading": {"unit": "deg"},
            "range": {"unit": "m", "max": MAX_RANGE},
            "position": {"unit": {"x": "m", "y": "m", "theta": "rad"}},
            "velocity": {"unit": {"linear": "m/s", "angular": "rad/s"}},
            "odometry": {"unit": {"distance": "m"}},
            "bumper": {"unit": "bool"},
            "battery": {"unit": "%"},
            "time": {"unit": "s"},
        }

    def _camera_spec(self) -> dict[str, Any]:
        width, height = CAMERA_SIZE
        return {"width": width, "height": height, "format": "jpeg"}

    def capabilities(self) -> dict[str, Any]:
        width, height = FRONT_CAMERA_SIZE
        front = {"width": width, "height": height, "format": "jpeg", "fov": FRONT_CAMERA_FOV}
        return {**super().capabilities(), "front_camera": front}

    async def _camera_jpeg(self) -> bytes:
        self._advance(self._clock())
        self._derive_readings()
        return await asyncio.to_thread(
            _render, self._arena, self._pose, self._range, self._bumper, self.language
        )

    async def front_camera_jpeg(self) -> bytes:
        """What a camera on the robot's nose sees now, as JPEG bytes."""
        self._require_open()
        self._advance(self._clock())
        return await asyncio.to_thread(_render_front, self._arena, self._pose)

    # -- simulation ------------------------------------------------------------------------

    def _advance(self, now: float) -> None:
        """Move the robot from the last update to ``now`` at the commanded speeds."""
        dt = now - self._updated_at
        if dt <= 0.0:
            return
        self._updated_at = now
        linear, angular = self._command
        if self._blocked or (linear == 0.0 and angular == 0.0):
            return
        if linear == 0.0:
            # Turning on the spot never hits anything: the robot is round.
            self._pose = advance_pose(*self._pose, 0.0, angular, dt)
            return
        self._pose, moved_for, self._blocked = self._sweep(linear, angular, dt)
        self._distance += abs(linear) * moved_for

    def _sweep(self, linear: float, angular: float, dt: float) -> tuple[Pose, float, bool]:
        """Follow the arc for ``dt`` seconds; return (pose, seconds moved, hit something)."""
        start = self._pose
        # An arc that closes into a free circle repeats forever, so one lap is enough to check.
        lap = math.tau / abs(angular) if angular else math.inf
        span = min(dt, lap)
        steps = max(1, math.ceil(abs(linear) * span / SUBSTEP))
        safe = 0.0
        for step in range(1, steps + 1):
            t = span * step / steps
            pose = advance_pose(*start, linear, angular, t)
            if self._collides(pose):
                safe = self._contact_time(start, linear, angular, safe, t)
                return advance_pose(*start, linear, angular, safe), safe, True
            safe = t
        if dt > lap:
            pose = advance_pose(*start, linear, angular, dt)
        return pose, dt, False

    def _contact_time(
        self, start: Pose, linear: float, angular: float, safe: float, hit: float
    ) -> float:
        """Bisect between a free and a colliding time for the last free moment."""
        while (hit - safe) * abs(linear) > CONTACT_TOLERANCE:
            middle = (safe + hit) / 2.0
            if self._collides(advance_pose(*start, linear, angular, middle)):
                hit = middle
            else:
                safe = middle
        return safe

    def _collides(self, pose: Pose) -> bool:
        return self._arena.clearance(pose[0], pose[1]) < ROBOT_RADIUS

    def _derive_readings(self) -> None:
        """Recompute pose-derived readings, only when the pose has changed."""
        if self._pose is self._derived_for:
            return
        x, y, theta = self._derived_for = self._pose
        self._heading = compass_heading(theta)
        self._range = self._arena.ray_distance(x, y, theta, MAX_RANGE)
        self._bumper = self._arena.clearance(x, y) <= ROBOT_RADIUS + BUMPER_REACH


def _render(arena: Arena, pose: Pose, range_m: float, bumper: bool, language: str) -> bytes:
    # Imported here, in the worker thread, so Pillow costs nothing until a camera is watched.
    from rhal.sim_render import render_top_view

    return render_top_view(
        arena, pose, ROBOT_RADIUS, range_m, bumper, CAMERA_SIZE, language=language
    )


def _render_front(arena: Arena, pose: Pose) -> bytes:
    from rhal.sim_render import render_front_view

    fov = math.radians(FRONT_CAMERA_FOV)
    return render_front_view(arena, pose, ROBOT_RADIUS, FRONT_CAMERA_SIZE, fov)
