"""The sim robot's sensor models (docs/simulator.md describes them for users).

- Range: a cone ``cone_deg`` wide straight ahead, sampled by ``rays`` rays spread evenly across
  it (its edges included); every obstacle corner inside the cone echoes too, so a thin wall's end
  or a box's corner between two rays is not missed. The reading is the nearest echo, measured
  from the robot's centre, clamped to [min, max]: nothing in reach reads the maximum, something
  nearer than the minimum reads the minimum.
- Sonar ring: one such cone per stated angle (degrees counter-clockwise from ahead), each as wide
  as the range cone.
- Floor sensor: looks straight down ``FLOOR_SENSOR_AHEAD`` in front of the centre and reports the
  floor's colour name and light (a painted line over a painted zone over the white floor).

Everything here is numpy over the world's obstacle edges; callers recompute only when the pose
changes.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from rhal.simulator.world import World

FLOOR_SENSOR_AHEAD = 0.1  # m in front of the robot's centre


@dataclass(frozen=True)
class Cone:
    """A range sensor's beam: ``width`` radians, ``rays`` rays, readings in [low, high]."""

    width: float
    rays: int
    low: float
    high: float

    def offsets(self) -> np.ndarray:
        if self.rays == 1 or self.width == 0:
            return np.zeros(1)
        return np.linspace(-self.width / 2, self.width / 2, self.rays)


class SensorModel:
    """The readings of a world's robot at a pose: range, sonar ring, floor, zone."""

    def __init__(
        self,
        world: World,
        *,
        cone_deg: float,
        rays: int,
        min_range: float,
        max_range: float,
        sonar: tuple[float, ...],
        floor_sensor: bool,
    ) -> None:
        self.world = world
        self.cone = Cone(math.radians(cone_deg), rays, min_range, max_range)
        self.sonar = tuple(sonar)
        self.floor_sensor = floor_sensor
        self._offsets = self.cone.offsets()
        self._sonar_angles = np.radians(np.array(self.sonar, dtype=float))
        # Corners that can echo: the segments' ends, once each.
        ends = world.segments.reshape(-1, 2)
        self._corners = np.unique(ends, axis=0) if len(ends) else ends

    def range_at(self, x: float, y: float, theta: float) -> float:
        return float(self._cones(x, y, np.array([theta]))[0])

    def sonar_at(self, x: float, y: float, theta: float) -> list[float]:
        if not self.sonar:
            return []
        return [float(r) for r in self._cones(x, y, theta + self._sonar_angles)]

    def floor_at(self, x: float, y: float, theta: float) -> dict[str, object]:
        px = x + FLOOR_SENSOR_AHEAD * math.cos(theta)
        py = y + FLOOR_SENSOR_AHEAD * math.sin(theta)
        name, _, light = self.world.floor_at(px, py)
        return {"colour": name, "light": light}

    def _cones(self, x: float, y: float, headings: np.ndarray) -> np.ndarray:
        """The nearest echo in the cone around each heading, clamped to the cone's range."""
        cone = self.cone
        angles = (headings[:, None] + self._offsets[None, :]).ravel()
        hits = self.world.edges.ray_hits(x, y, angles).reshape(len(headings), -1)
        nearest = hits.min(axis=1)
        if cone.width > 0 and len(self._corners):
            nearest = np.minimum(nearest, self._corner_echoes(x, y, headings))
        return np.clip(nearest, cone.low, cone.high)

    def _corner_echoes(self, x: float, y: float, headings: np.ndarray) -> np.ndarray:
        """The nearest visible obstacle corner inside each cone (inf: none)."""
        dx = self._corners[:, 0] - x
        dy = self._corners[:, 1] - y
        distance = np.hypot(dx, dy)
        near = (distance <= self.cone.high) & (distance > 1e-9)
        if not near.any():
            return np.full(len(headings), np.inf)
        dx, dy, distance = dx[near], dy[near], distance[near]
        bearing = np.arctan2(dy, dx)
        off = np.abs((bearing[None, :] - headings[:, None] + math.pi) % math.tau - math.pi)
        inside = off <= self.cone.width / 2
        if not inside.any():
            return np.full(len(headings), np.inf)
        # A corner behind another surface is hidden: it echoes only if no edge is nearer along
        # its bearing (a ray to it stops at it or just after).
        candidates = np.where(inside.any(axis=0))[0]
        blocked = self.world.edges.ray_hits(x, y, bearing[candidates])
        visible = np.full(len(bearing), False)
        visible[candidates] = blocked >= distance[candidates] - 1e-9
        echo = np.where(inside & visible[None, :], distance[None, :], np.inf)
        return echo.min(axis=1)
