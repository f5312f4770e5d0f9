"""Line segments in bulk: distances, rays and a moving circle's first contact, with numpy.

``Edges`` keeps each segment's direction and length worked out once, since the simulator asks
about the same edges on every step and every reading; calls on small sets are dominated by
numpy's per-call cost, so each query is a handful of whole-array operations.
"""

from __future__ import annotations

import math

import numpy as np


class Edges:
    """Segments (N, 4): x1, y1, x2, y2 per row."""

    __slots__ = ("array", "ax", "ay", "bx", "by", "ex", "ey", "length", "inv2", "ux", "uy")

    def __init__(self, array: np.ndarray) -> None:
        self.array = np.asarray(array, dtype=float).reshape(-1, 4)
        self.ax, self.ay, self.bx, self.by = (self.array[:, i].copy() for i in range(4))
        self.ex, self.ey = self.bx - self.ax, self.by - self.ay
        self.length = np.hypot(self.ex, self.ey)
        squared = self.length * self.length
        safe = np.where(squared > 0, squared, 1.0)
        self.inv2 = np.where(squared > 0, 1.0 / safe, 0.0)
        self.ux, self.uy = self.ex * np.sqrt(self.inv2), self.ey * np.sqrt(self.inv2)

    def __len__(self) -> int:
        return len(self.array)

    def distances(self, x: float, y: float) -> np.ndarray:
        """Distance from a point to each segment."""
        t = ((x - self.ax) * self.ex + (y - self.ay) * self.ey) * self.inv2
        t = np.minimum(np.maximum(t, 0.0), 1.0)
        return np.hypot(self.ax + t * self.ex - x, self.ay + t * self.ey - y)

    def nearest(self, x: float, y: float) -> float:
        """Distance from a point to the nearest segment (inf: there are none)."""
        return float(self.distances(x, y).min()) if len(self.array) else math.inf

    def near(self, x: float, y: float, reach: float) -> Edges:
        """The segments within ``reach`` of a point."""
        if not len(self.array):
            return self
        return Edges(self.array[self.distances(x, y) <= reach])

    def ray_hits(self, x: float, y: float, angles: np.ndarray) -> np.ndarray:
        """Distance along each ray from (x, y) to the first segment it meets (inf: none)."""
        if not len(self.array):
            return np.full(len(angles), np.inf)
        rx, ry = np.cos(angles)[:, None], np.sin(angles)[:, None]
        qx, qy = (self.ax - x)[None, :], (self.ay - y)[None, :]
        sx, sy = self.ex[None, :], self.ey[None, :]
        denom = rx * sy - ry * sx
        parallel = denom == 0
        denom = np.where(parallel, 1.0, denom)
        t = (qx * sy - qy * sx) / denom
        u = (qx * ry - qy * rx) / denom
        hit = ~parallel & (t >= 0) & (u >= 0) & (u <= 1)
        return np.where(hit, t, np.inf).min(axis=1)

    def first_contact(
        self, radius: float, x: float, y: float, dx: float, dy: float
    ) -> tuple[float, tuple[float, float]]:
        """When a circle of ``radius`` at (x, y) moving by (dx, dy) first touches a segment, as
        a fraction of the move (inf: never), and the contact normal, pointing to the circle.
        A circle already touching (or a rounding error inside) and moving in touches at 0."""
        if not len(self.array):
            return math.inf, (0.0, 0.0)
        move = math.hypot(dx, dy)
        tiny = 1e-9 * move
        nx, ny = -self.uy, self.ux
        # The faces: the centre reaching the line offset by the radius, between the ends.
        s0 = (x - self.ax) * nx + (y - self.ay) * ny
        dn = dx * nx + dy * ny
        side = np.where(s0 > 0, 1.0, np.where(s0 < 0, -1.0, -np.sign(dn)))
        approaching = side * dn < -tiny
        t_face = np.maximum((side * radius - s0) / np.where(approaching, dn, 1.0), 0.0)
        along = (x + dx * t_face - self.ax) * self.ux + (y + dy * t_face - self.ay) * self.uy
        t_face = np.where(approaching & (along >= 0) & (along <= self.length), t_face, np.inf)
        # The ends: the centre reaching a circle of the radius around each end point.
        ex = np.concatenate([self.ax, self.bx])
        ey = np.concatenate([self.ay, self.by])
        fx, fy = x - ex, y - ey
        b = fx * dx + fy * dy
        c = fx * fx + fy * fy - radius * radius
        closing = b < -tiny * np.sqrt(fx * fx + fy * fy)
        disc = b * b - move * move * c
        root = (-b - np.sqrt(np.maximum(disc, 0.0))) / (move * move)
        t_end = np.where(closing & (disc >= 0), root, np.inf)
        t_end = np.where(closing & (c <= 0), 0.0, t_end)
        t_end = np.where(t_end >= 0, t_end, np.inf)
        i_face, i_end = int(np.argmin(t_face)), int(np.argmin(t_end))
        face, end = float(t_face[i_face]), float(t_end[i_end])
        if face <= end:
            if face == math.inf:
                return math.inf, (0.0, 0.0)
            return face, (float(side[i_face] * nx[i_face]), float(side[i_face] * ny[i_face]))
        px, py = x + dx * end - float(ex[i_end]), y + dy * end - float(ey[i_end])
        norm = math.hypot(px, py) or 1.0
        return end, (px / norm, py / norm)
