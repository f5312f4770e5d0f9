"""A round differential-drive robot on a floor with walls and boxes, moving with sliding contact.

The robot follows the arc of its commanded speeds. Touching something stops only the part of its
motion that goes into it: the component of each step's displacement along the contact normal
is removed and the rest is kept, so the robot slides along a wall it meets at an angle, backs or
turns away freely, and stops dead only when pushing straight in (or into a corner, where the
contacts are resolved in turn, a few times a step). Turning on the spot is always allowed: the
robot is round. Nothing is ever passed through: each step's travel is swept against the edges
(a circle against segments and their end points, solved exactly), and steps are at most
``STEP`` long.

Time is cut into steps of ``STEP / |linear|`` seconds from the moment of each command, and the
state is committed at those instants only; a reading between two of them adds a partial step
it does not keep. So the path depends on the commands and when they were given, not on how
often it is read. Stretches that cannot touch anything (the free distance is larger than the
travel, or the whole circle of an arc is clear) are jumped in one closed-form arc.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from rhal.kinematics import advance_pose, normalize_angle
from rhal.simulator.geometry import Edges
from rhal.simulator.world import World

Pose = tuple[float, float, float]

STEP = 0.01  # m: the most a step travels; far thinner than any wall or box
SKIN = 1e-9  # m: stop this short of a contact so rounding never puts the robot inside
SLIDES = 4  # contacts resolved per step (corners need more than one)
BUMPER_REACH = 1e-3  # m: the bumper reads pressed this close to a surface
LOOKAHEAD = 200  # steps whose reachable edges are picked out at once
MAX_STEPS = 10_000  # per update (100 m in contact): a longer unread stretch is cut short


class Motion:
    """The robot's pose over time in ``world``: ``command()`` and ``pose_at()``."""

    #: Told (sim time, pose) of each step committed near something, while a trace is recorded
    #: (rhal.simulator.trace); free stretches jumped in one arc touch nothing.
    observer: Callable[[float, Pose], None] | None = None

    def __init__(self, world: World, radius: float, pose: Pose, now: float) -> None:
        self.world = world
        self.radius = radius
        self.place(pose, now)

    def place(self, pose: Pose, now: float) -> None:
        """Put the robot at ``pose``, stopped, with a fresh odometer."""
        self._pose: Pose = (pose[0], pose[1], normalize_angle(pose[2]))
        self._command = (0.0, 0.0)
        self._origin = now  # when the current command began: the steps' time grid starts here
        self._steps = 0  # steps committed since then
        self._distance = 0.0
        self._moving = (0.0, 0.0)  # the speeds of the last step: (linear, angular)
        self._reading: tuple[float, Pose, float] = (now, self._pose, 0.0)

    @property
    def command_speeds(self) -> tuple[float, float]:
        return self._command

    def command(self, linear: float, angular: float, now: float) -> None:
        """New speeds from ``now``: the motion so far is committed up to that instant."""
        pose, distance, moving = self._advance(now, commit=True)
        self._pose, self._distance = pose, distance
        self._command = (linear, angular)
        self._origin, self._steps = now, 0
        self._moving = (linear, angular)  # until a step says otherwise
        self._reading = (now, pose, distance)

    def pose_at(self, now: float) -> Pose:
        """The pose at ``now`` (never earlier than the last command)."""
        when, pose, _ = self._reading
        if now != when:
            pose, distance, self._moving = self._advance(now, commit=False)
            self._reading = (now, pose, distance)
        return pose

    def distance_at(self, now: float) -> float:
        """Metres actually travelled since placed, at ``now``."""
        self.pose_at(now)
        return self._reading[2]

    @property
    def velocity(self) -> tuple[float, float]:
        """(linear, angular) of the latest step: linear counts only the travel actually made."""
        return self._moving

    def clearance(self, pose: Pose) -> float:
        return self.world.clearance(pose[0], pose[1])

    def bumper(self, pose: Pose) -> bool:
        return self.world.edges.nearest(pose[0], pose[1]) <= self.radius + BUMPER_REACH

    # -- stepping ----------------------------------------------------------------------------

    def _advance(self, now: float, *, commit: bool) -> tuple[Pose, float, tuple[float, float]]:
        """The pose, odometer and speeds at ``now``; with ``commit``, ``now`` becomes a grid
        instant (a command's), else only whole steps are kept."""
        linear, angular = self._command
        elapsed = now - self._origin
        if elapsed <= 0 or (linear == 0.0 and angular == 0.0):
            return self._pose, self._distance, (0.0, 0.0) if elapsed > 0 else self._moving
        if linear == 0.0:  # turning on the spot: never touches anything, exact from the origin
            x, y, theta = self._pose
            turned = normalize_angle(theta + angular * elapsed)
            return (x, y, turned), self._distance, (0.0, angular)
        step = STEP / abs(linear)
        moving = self._commit_steps(math.floor(elapsed / step), step)
        pose, distance = self._pose, self._distance
        rest = elapsed - self._steps * step
        if rest > 0:
            travel = abs(linear) * rest
            if self.world.edges.nearest(pose[0], pose[1]) - self.radius > travel + SKIN:
                pose, fraction = advance_pose(*pose, linear, angular, rest), 1.0
            else:
                edges = self.world.edges.near(pose[0], pose[1], self.radius + travel + 0.02)
                pose, fraction = self._step(pose, linear, angular, rest, edges)
            distance += travel * fraction
            moving = (linear * fraction, angular)
            if commit:
                self._pose, self._distance = pose, distance
                if self.observer is not None:
                    self.observer(now, pose)
        return pose, distance, moving

    def _commit_steps(self, whole: int, step: float) -> tuple[float, float]:
        """Commit the grid steps up to step number ``whole``; the speeds of the last one."""
        linear, angular = self._command
        moving = self._moving
        done = 0
        while self._steps < whole:
            left = whole - self._steps
            # The edges within reach of the next few hundred steps (or all that are left).
            reach = abs(linear) * step * min(left, LOOKAHEAD)
            edges = self.world.edges.near(self._pose[0], self._pose[1], self.radius + reach + 0.02)
            batch_end = self._steps + min(left, LOOKAHEAD)
            while self._steps < batch_end:
                jump = self._free_steps(edges, step, batch_end - self._steps)
                if jump >= 2:
                    self._pose = advance_pose(*self._pose, linear, angular, jump * step)
                    self._distance += abs(linear) * step * jump
                    self._steps += jump
                    moving = (linear, angular)
                    continue
                self._pose, fraction = self._step(self._pose, linear, angular, step, edges)
                self._distance += abs(linear) * step * fraction
                self._steps += 1
                moving = (linear * fraction, angular)
                done += 1
                if self.observer is not None:
                    self.observer(self._origin + self._steps * step, self._pose)
                if fraction == 0.0 and angular == 0.0:  # pushing straight in: it stays so
                    self._steps = whole
                    return (0.0, 0.0)
            if done >= MAX_STEPS:  # cut short: the rest of the time it stays where it got to
                self._steps = whole
        return moving

    def _free_steps(self, edges: Edges, step: float, left: int) -> int:
        """How many of the next ``left`` steps surely touch nothing."""
        linear, angular = self._command
        x, y, theta = self._pose
        free = edges.nearest(x, y) - self.radius
        if free == math.inf:  # nothing within reach of all of them
            return left
        steps = math.floor(free / (abs(linear) * step)) - 1
        if steps >= left:
            return left
        if angular and free > STEP:
            # The whole circle of the arc clear: the robot can go round it forever.
            turn = linear / angular
            cx, cy = x - turn * math.sin(theta), y + turn * math.cos(theta)
            if self.world.clearance(cx, cy) >= abs(turn) + self.radius + SKIN:
                return left
        return max(steps, 0)

    def _step(
        self, pose: Pose, linear: float, angular: float, dt: float, edges: Edges
    ) -> tuple[Pose, float]:
        """One step along the arc, sliding on contacts: (the new pose, fraction of the
        commanded travel made)."""
        target = advance_pose(*pose, linear, angular, dt)
        x, y = pose[0], pose[1]
        dx, dy = target[0] - x, target[1] - y
        wanted = math.hypot(dx, dy)
        if wanted == 0.0:
            return target, 1.0
        normals: list[tuple[float, float]] = []
        free = True
        for _ in range(SLIDES):
            if dx == 0.0 and dy == 0.0:
                break
            t, normal = edges.first_contact(self.radius, x, y, dx, dy)
            if t >= 1.0:
                x, y = x + dx, y + dy
                dx = dy = 0.0
                break
            free = False
            t = max(0.0, t - SKIN / math.hypot(dx, dy))
            x, y = x + dx * t, y + dy * t
            dx, dy = dx * (1 - t), dy * (1 - t)
            normals.append(normal)
            dx, dy = _slide(dx, dy, normals)
        if free:
            return target, 1.0
        if edges.nearest(x, y) < self.radius - 1e-7:
            x, y = pose[0], pose[1]  # rounding never puts the robot inside: it stays instead
        moved = math.hypot(x - pose[0], y - pose[1])
        if moved < 1e-12:  # pushing straight in: not a crumb of travel
            return (pose[0], pose[1], target[2]), 0.0
        return (x, y, target[2]), min(1.0, moved / wanted)


def _slide(dx: float, dy: float, normals: list[tuple[float, float]]) -> tuple[float, float]:
    """The displacement without its components into the contacts (normals point away)."""
    for _ in range(len(normals) + 1):
        into = [(nx, ny) for nx, ny in normals if dx * nx + dy * ny < 0.0]
        if not into:
            return dx, dy
        nx, ny = into[-1]
        along = dx * nx + dy * ny
        dx, dy = dx - along * nx, dy - along * ny
    # Still into one of them: a corner narrower than 180 degrees pins the robot.
    if any(dx * nx + dy * ny < -1e-12 for nx, ny in normals):
        return 0.0, 0.0
    return dx, dy
