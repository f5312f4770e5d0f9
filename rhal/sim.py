"""A simulated differential-drive robot in a world of walls and boxes, for ``sim://`` URLs.

Options, also accepted in the URL query (``sim://?world=maze&speed=10``):
``world`` (a built-in world's name: boxes, the default, square, maze, line or rooms; or, from
code, a world document as rhal.simulator.world describes: the agent passes a stored world so),
``arena`` (the old name of ``world``, kept), ``speed`` (1 to 10: the sim's clock runs this many
times faster than real time), ``max_linear``, ``max_angular``, ``language``; and, to make it a
twin of a real robot, ``sonar`` (angles in degrees, "90,45,0,-45,-90"), ``floor_sensor`` and
``range_cone_deg``, which override the world's robot. From code also ``clock``, a callable
returning seconds (default ``time.monotonic``) so tests can step time.

The physics and the sensor models are rhal.simulator's (docs/simulator.md): contact stops only
the motion into what is touched, so the robot slides along walls and backs away freely; the
range sensor is a cone; the world's robot may have a sonar ring and a floor sensor. Nothing runs
in the background: each call first brings the motion up to now.

Two cameras: ``camera_jpeg()`` looks down on the world (the robot's page shows it to scripts-off
browsers), and ``front_camera_jpeg()`` sees what a camera on the robot's nose would: walls, boxes
and the QR code landmarks on the walls (``capabilities()["front_camera"]``). The Robot API's
``snapshot()`` and ``scan_barcode()`` use the front camera of a driver that has one.

It hears no sound: a program's ``listen()`` hears the phrases typed to it (``hearing``).
"""

from __future__ import annotations

import asyncio
import dataclasses
import math
import time
from collections.abc import Callable
from typing import Any

from rhal.base import Robot
from rhal.kinematics import compass_heading
from rhal.sim_words import LANGUAGES as SIM_LANGUAGES
from rhal.simulator.physics import Motion
from rhal.simulator.sensors import SensorModel
from rhal.simulator.trace import Recorder
from rhal.simulator.world import RobotSpec, World, WorldError
from rhal.simulator.worlds import BUILTIN, load

ROBOT_RADIUS = 0.15  # m, the default robot's (a world may say otherwise)
MAX_RANGE = 4.0  # m, the default range sensor's reach
START_POSE = (0.0, 0.0, math.pi / 2)  # the default world's start: its centre, facing north
CAMERA_SIZE = (320, 240)
FRONT_CAMERA_SIZE = (640, 480)
FRONT_CAMERA_FOV = 62.0  # degrees, horizontal: a Raspberry Pi camera's
SPEEDS = (1.0, 10.0)  # the time scales a sim runs at
BATTERY_DRAIN = 0.05  # percent per metre travelled

Pose = tuple[float, float, float]


class SimRobot(Robot):
    kind = "sim"
    option_help = {
        **Robot.option_help,
        "world": "the world it runs in: a built-in one (boxes, square, maze, line, rooms) or a "
        "stored world's name or number",
        "arena": "the old name of the world option",
        "speed": "how many times faster than real time it runs, 1 to 10",
        "language": "the language of the words drawn on its camera's picture",
        "sonar": "angles of a sonar ring, degrees to the left of ahead (90,45,0,-45,-90); "
        "blank: the world's robot's",
        "floor_sensor": "a floor colour sensor under its nose; blank: the world's robot's",
        "range_cone_deg": "the range sensor's beam width, degrees; blank: the world's robot's",
    }
    option_choices = {"arena": tuple(BUILTIN), "language": SIM_LANGUAGES}
    quick = True  # computed in-process: nothing to wait for
    # No microphone: the Robot API's listen() hears what is typed into the robot page's "Say
    # to the robot" box instead (robots.typed_speech). A robot that hears through the
    # computer's microphone has no such attribute (or "microphone").
    hearing = "typed"

    def __init__(
        self,
        url: str = "sim://",
        *,
        world: str | dict[str, Any] | None = None,
        arena: str = "boxes",
        speed: float = 1.0,
        language: str = "en",
        sonar: str | float | list[float] | None = None,
        floor_sensor: bool | None = None,
        range_cone_deg: float | None = None,
        clock: Callable[[], float] = time.monotonic,
        **limits: Any,
    ) -> None:
        super().__init__(url, **limits)
        if language not in SIM_LANGUAGES:
            known = ", ".join(SIM_LANGUAGES)
            raise ValueError(f"unknown language {language!r}; choose one of: {known}")
        self.language = language
        self.world = _world(world if world is not None else arena)
        self.arena_name = self.world.name
        self.speed = _speed(speed)
        self.robot_spec = _robot_spec(self.world.robot, sonar, floor_sensor, range_cone_deg)
        spec = self.robot_spec
        self._sensing = SensorModel(
            self.world,
            cone_deg=spec.cone_deg,
            rays=spec.rays,
            min_range=spec.min_range,
            max_range=spec.max_range,
            sonar=spec.sonar,
            floor_sensor=spec.floor_sensor,
        )
        self._real_clock = clock
        self._clock_zero = clock()
        now = self._clock()
        self._opened_at = now
        self._motion = Motion(self.world, spec.radius, self.world.start_pose, now)
        self._derived_for: Pose | None = None
        self._recorder: Recorder | None = None  # a trace being recorded (start_trace)
        self._trace_zero: float | None = None

    def _now(self) -> float:
        """The sim's time, with a trace being recorded brought up to it first."""
        now = self._clock()
        if self._recorder is not None:
            self._recorder.catch_up(now)
        return now

    def _clock(self) -> float:
        """The sim's time: ``speed`` times as fast as the real clock since it was made."""
        real = self._real_clock()
        return self._clock_zero + (real - self._clock_zero) * self.speed

    async def reset(self, pose: Pose | None = None) -> None:
        """Stop and put the robot at ``pose`` (x m, y m, theta rad), or the world's start pose,
        with a fresh odometer and battery. ValueError, in plain words, for a pose outside the
        arena or overlapping something."""
        place = self.world.start_pose if pose is None else _pose(pose)
        self._check_place(place)
        now = self._now()
        self._motion.place(place, now)
        self._derived_for = None
        if self._recorder is not None:
            self._recorder.placed(now)

    def world_doc(self) -> dict[str, Any]:
        """The world it runs in, as a document."""
        return self.world.to_doc()

    def robot_doc(self) -> dict[str, Any]:
        """Its size and sensors (radius, range cone, sonar angles, floor sensor)."""
        return self.robot_spec.to_doc()

    # -- trace (rhal.simulator.trace): what a run did, for the exercise checks -------------

    def start_trace(self) -> None:
        """Begin a fresh recording: its time 0 is now, its start the current pose."""
        if self._recorder is not None:
            self._recorder.stop()
        now = self._now()
        self._recorder = Recorder(self._motion, now, speed=self.speed)
        self._trace_zero = now

    def trace_time(self) -> float:
        """Sim seconds since the last ``start_trace()`` (also after ``take_trace()``)."""
        if self._trace_zero is None:
            raise RuntimeError("no trace was started on this sim")
        return self._now() - self._trace_zero

    def take_trace(self) -> dict[str, Any]:
        """The trace recorded up to now (rhal.simulator.trace); the recording stops."""
        if self._recorder is None:
            raise RuntimeError("no trace is being recorded on this sim")
        now = self._now()
        recorder, self._recorder = self._recorder, None
        return recorder.finish(now)

    def note_said(self, text: str) -> None:
        """A text a program said (the host speaks it, robots.host_services): kept in the
        trace being recorded."""
        if self._recorder is not None:
            self._recorder.say(self._now(), text)

    # The pose, for code that places the robot directly (the camera tests).
    @property
    def _pose(self) -> Pose:
        return self._motion.pose_at(self._now())

    @_pose.setter
    def _pose(self, pose: Pose) -> None:
        speeds = self._motion.command_speeds
        now = self._now()
        self._motion.place(pose, now)
        if self._recorder is not None:
            self._recorder.placed(now)
            self._recorder.command(now, *speeds)
        self._motion.command(*speeds, now)

    # -- hooks -----------------------------------------------------------------------------

    async def _open(self) -> None:
        now = self._now()
        self._opened_at = now
        self._motion.place(self.world.start_pose, now)
        self._derived_for = None
        if self._recorder is not None:
            self._recorder.placed(now)

    async def _drive(self, linear: float, angular: float) -> None:
        now = self._now()
        if self._recorder is not None:
            self._recorder.command(now, linear, angular)
        self._motion.command(linear, angular, now)

    async def _read_sensors(self) -> dict[str, Any]:
        now = self._now()
        pose = self._motion.pose_at(now)
        self._derive_readings(pose)
        x, y, theta = pose
        linear, angular = self._motion.velocity
        distance = self._motion.distance_at(now)
        readings = {
            "heading": self._heading,
            "range": self._range,
            "position": {"x": x, "y": y, "theta": theta},
            "velocity": {"linear": linear, "angular": angular},
            "odometry": {"distance": distance},
            "bumper": self._bumper,
            "battery": max(0.0, 100.0 - BATTERY_DRAIN * distance),
            "time": now - self._opened_at,
            "zone": self._zone,
        }
        if self.robot_spec.sonar:
            readings["sonar"] = list(self._sonar)
        if self.robot_spec.floor_sensor:
            readings["floor"] = dict(self._floor)
        return readings

    def _sensor_specs(self) -> dict[str, dict[str, Any]]:
        spec = self.robot_spec
        specs: dict[str, dict[str, Any]] = {
            "heading": {"unit": "deg"},
            "range": {"unit": "m", "max": spec.max_range},
            "position": {"unit": {"x": "m", "y": "m", "theta": "rad"}},
            "velocity": {"unit": {"linear": "m/s", "angular": "rad/s"}},
            "odometry": {"unit": {"distance": "m"}},
            "bumper": {"unit": "bool"},
            "battery": {"unit": "%"},
            "time": {"unit": "s"},
            "zone": {"unit": "name"},
        }
        if spec.sonar:
            specs["sonar"] = {
                "unit": "m",
                "max": spec.max_range,
                "count": len(spec.sonar),
                "angles": list(spec.sonar),
            }
        if spec.floor_sensor:
            specs["floor"] = {"unit": {"colour": "name", "light": "%"}}
        return specs

    def _camera_spec(self) -> dict[str, Any]:
        width, height = CAMERA_SIZE
        return {"width": width, "height": height, "format": "jpeg"}

    def capabilities(self) -> dict[str, Any]:
        width, height = FRONT_CAMERA_SIZE
        front = {"width": width, "height": height, "format": "jpeg", "fov": FRONT_CAMERA_FOV}
        sim = {"world": self.world.name, "speed": self.speed, **self.robot_doc()}
        return {**super().capabilities(), "front_camera": front, "sim": sim}

    async def _camera_jpeg(self) -> bytes:
        pose = self._motion.pose_at(self._now())
        self._derive_readings(pose)
        return await asyncio.to_thread(
            _render,
            self.world,
            pose,
            self.robot_spec.radius,
            self._range,
            self._bumper,
            self.language,
        )

    async def front_camera_jpeg(self) -> bytes:
        """What a camera on the robot's nose sees now, as JPEG bytes."""
        self._require_open()
        pose = self._motion.pose_at(self._now())
        return await asyncio.to_thread(_render_front, self.world, pose, self.robot_spec.radius)

    # -- readings --------------------------------------------------------------------------

    def _derive_readings(self, pose: Pose) -> None:
        """Recompute pose-derived readings, only when the pose has changed: a stationary
        robot's readings cost a comparison."""
        if pose == self._derived_for:
            return
        self._derived_for = pose
        x, y, theta = pose
        sensing = self._sensing
        self._heading = compass_heading(theta)
        self._range = sensing.range_at(x, y, theta)
        self._bumper = self._motion.bumper(pose)
        self._zone = self.world.zone_at(x, y)
        self._sonar = sensing.sonar_at(x, y, theta)
        self._floor = sensing.floor_at(x, y, theta) if sensing.floor_sensor else None

    def _check_place(self, pose: Pose) -> None:
        x, y, _ = pose
        world, radius = self.world, self.robot_spec.radius
        if abs(x) > world.half_width or abs(y) > world.half_height:
            raise ValueError(
                f"the pose (x {x:.2f} m, y {y:.2f} m) is outside the arena, which reaches "
                f"x +-{world.half_width:.2f} m and y +-{world.half_height:.2f} m"
            )
        clear = world.clearance(x, y)
        if clear < radius - 1e-9:
            where = "inside a wall or box" if clear < 0 else f"{clear:.2f} m from a wall or box"
            raise ValueError(
                f"the robot cannot stand at x {x:.2f} m, y {y:.2f} m: that is {where}, and "
                f"the robot (radius {radius:.2f} m) needs {radius:.2f} m clear around it"
            )


def _world(world: str | dict[str, Any]) -> World:
    try:
        return load(world)
    except WorldError as exc:
        if isinstance(world, str):
            known = ", ".join(BUILTIN)
            raise ValueError(f"unknown world {world!r}; choose one of: {known}") from None
        where = f" (at {exc.path})" if exc.path else ""
        raise ValueError(f"the world cannot be used{where}: {exc}") from None


def _speed(speed: object) -> float:
    low, high = SPEEDS
    if isinstance(speed, bool) or not isinstance(speed, int | float) or not low <= speed <= high:
        raise ValueError(f"speed must be a number from {low:g} to {high:g}, got {speed!r}")
    return float(speed)


def _robot_spec(
    spec: RobotSpec, sonar: object, floor_sensor: bool | None, cone_deg: float | None
) -> RobotSpec:
    """The world's robot with the twin options that are given."""
    changes: dict[str, Any] = {}
    if sonar is not None:
        changes["sonar"] = _sonar_angles(sonar)
    if floor_sensor is not None:
        if not isinstance(floor_sensor, bool):
            raise ValueError(f"floor_sensor must be true or false, got {floor_sensor!r}")
        changes["floor_sensor"] = floor_sensor
    if cone_deg is not None:
        if isinstance(cone_deg, bool) or not isinstance(cone_deg, int | float):
            raise ValueError(f"range_cone_deg must be a number, got {cone_deg!r}")
        if not 0 <= cone_deg <= 90:
            raise ValueError(f"range_cone_deg must be 0 to 90 degrees, got {cone_deg!r}")
        changes["cone_deg"] = float(cone_deg)
    return dataclasses.replace(spec, **changes)


def _sonar_angles(value: object) -> tuple[float, ...]:
    """Sonar angles from a list, one number, or a text of numbers ("90,45,0" or "90 45 0")."""
    if isinstance(value, str):
        parts = value.replace(",", " ").split()
        try:
            items: list[Any] = [float(part) for part in parts]
        except ValueError:
            raise ValueError(
                f"sonar must be angles in degrees like 90,0,-90, got {value!r}"
            ) from None
    elif isinstance(value, int | float) and not isinstance(value, bool):
        items = [value]
    elif isinstance(value, list | tuple):
        items = list(value)
    else:
        raise ValueError(f"sonar must be a list of angles in degrees, got {value!r}")
    if len(items) > 32:
        raise ValueError("sonar has at most 32 angles")
    angles = []
    for item in items:
        ok = isinstance(item, int | float) and not isinstance(item, bool)
        if not ok or not math.isfinite(item) or not -180 <= item <= 180:
            raise ValueError(f"each sonar angle must be -180 to 180 degrees, got {item!r}")
        angles.append(float(item))
    return tuple(angles)


def _pose(pose: object) -> Pose:
    try:
        x, y, theta = (float(v) for v in pose)  # type: ignore[union-attr]
    except (TypeError, ValueError):
        raise ValueError(f"a pose is (x, y, theta) in metres and radians, got {pose!r}") from None
    if not all(math.isfinite(v) for v in (x, y, theta)):
        raise ValueError(f"a pose's x, y and theta must be finite numbers, got {pose!r}")
    return x, y, theta


def _render(
    world: World, pose: Pose, radius: float, range_m: float, bumper: bool, language: str
) -> bytes:
    # Imported here, in the worker thread, so Pillow costs nothing until a camera is watched.
    from rhal.sim_render import render_top_view

    return render_top_view(world, pose, radius, range_m, bumper, CAMERA_SIZE, language=language)


def _render_front(world: World, pose: Pose, radius: float) -> bytes:
    from rhal.sim_render import render_front_view

    fov = math.radians(FRONT_CAMERA_FOV)
    return render_front_view(world, pose, radius, FRONT_CAMERA_SIZE, fov)
