"""The cia402 profile: two CiA 402 wheel drives through canopen, and its option checks."""

from __future__ import annotations

import asyncio
import contextlib
import math
from typing import TYPE_CHECKING, Any

import canopen

from rhal.canbus.cia402_link import CW_ENABLE, CW_HALT, SIDES, Cia402Link
from rhal.canbus.profile import PROFILE_DIR, Profile, positive
from rhal.errors import RobotConnectionError
from rhal.kinematics import advance_pose, compass_heading

if TYPE_CHECKING:
    from rhal.canbus.robot import CanRobot

CIA402_EDS = PROFILE_DIR / "cia402_drive.eds"
INT32 = 1 << 32
#: Objects the cia402 profile reads or writes; its EDS must have all of them.
CIA402_OBJECTS = {
    0x1000: "device type",
    0x1017: "producer heartbeat time",
    0x1400: "RPDO1 communication",
    0x1600: "RPDO1 mapping",
    0x1800: "TPDO1 communication",
    0x1801: "TPDO2 communication",
    0x1A00: "TPDO1 mapping",
    0x1A01: "TPDO2 mapping",
    0x603F: "error code",
    0x6040: "controlword",
    0x6041: "statusword",
    0x6060: "modes of operation",
    0x6061: "modes of operation display",
    0x6064: "position actual value",
    0x606C: "velocity actual value",
    0x60FF: "target velocity",
}


class Cia402(Profile):
    name = "cia402"
    default_timeout = 0.5
    options = (
        "left", "right", "eds", "track", "wheel_diameter", "counts_per_rev", "counts_per_metre",
        "velocity_per_mps", "invert_left", "invert_right", "heartbeat", "sync",
    )  # fmt: skip

    def __init__(
        self,
        robot: CanRobot,
        *,
        timeout: float | None,
        left: int,
        right: int,
        eds: str | None,
        track: float,
        wheel_diameter: float,
        counts_per_rev: float,
        counts_per_metre: float | None,
        velocity_per_mps: float | None,
        invert_left: bool,
        invert_right: bool,
        heartbeat: float,
        sync: float,
    ) -> None:
        super().__init__(robot, timeout)
        self.nodes = {"left": _node_id("left", left), "right": _node_id("right", right)}
        if left == right:
            raise ValueError(f"left and right must be different node ids, both are {left}")
        self.eds = str(eds or CIA402_EDS)
        _check_eds(self.eds)
        self.track = positive(float, "track", track)
        self.wheel_diameter = positive(float, "wheel_diameter", wheel_diameter)
        self.counts_per_rev = positive(float, "counts_per_rev", counts_per_rev)
        if counts_per_metre is None:
            counts_per_metre = self.counts_per_rev / (math.pi * self.wheel_diameter)
        self.counts_per_metre = positive(float, "counts_per_metre", counts_per_metre)
        if velocity_per_mps is None:
            velocity_per_mps = self.counts_per_metre  # the drive counts velocity in counts/s
        self.velocity_per_mps = positive(float, "velocity_per_mps", velocity_per_mps)
        self.signs = {"left": -1 if _flag("invert_left", invert_left) else 1,
                      "right": -1 if _flag("invert_right", invert_right) else 1}  # fmt: skip
        self.heartbeat = positive(float, "heartbeat", heartbeat)
        if not 0.001 <= self.heartbeat <= 65.535:
            raise ValueError(f"heartbeat must be 0.001 to 65.535 s, got {heartbeat!r}")
        if self.timeout <= self.heartbeat:
            raise ValueError(
                f"timeout ({self.timeout:g} s) must be longer than the heartbeat period "
                f"({self.heartbeat:g} s)"
            )
        self.sync = positive(float, "sync", sync)
        self._pose = (0.0, 0.0, 0.0)
        self._counts: dict[str, int] | None = None  # positions odometry last took

    def describe(self, side: str) -> str:
        return f"the {side} drive (node {self.nodes[side]})"

    def _reset(self) -> None:
        self._pose = (0.0, 0.0, 0.0)

    def _new_link(self, loop: asyncio.AbstractEventLoop) -> Cia402Link:
        self._counts = None  # the drives may have restarted: take new reference positions
        return Cia402Link(self, loop)

    async def _watch(self, link: Cia402Link) -> str:
        reason = await super()._watch(link)
        # A drive that can still hear must not go on with the last speeds.
        with contextlib.suppress(RobotConnectionError):
            await self.call(link.command, dict.fromkeys(SIDES, 0), CW_ENABLE | CW_HALT)
        return reason

    async def _tend(self, link: Cia402Link) -> None:
        for side in SIDES:
            if link.state(side) == "FAULT" and link.fault[side] is None:
                link.fault[side] = await self.call(link.read_fault, side)
            elif link.state(side) != "FAULT":
                link.fault[side] = None

    # -- motion ----------------------------------------------------------------------------

    async def drive(self, linear: float, angular: float) -> None:
        link = self.require_link()
        for side in SIDES:
            state = link.state(side)
            if state != "OPERATION ENABLED":
                fault = f" ({link.fault[side]})" if link.fault[side] else ""
                raise RobotConnectionError(
                    f"{self.describe(side)} of the CAN base at {self.url!r} is in {state}{fault}, "
                    "not OPERATION ENABLED; close and open the robot to enable it again"
                )
        half = angular * self.track / 2.0
        speeds = {"left": linear - half, "right": linear + half}
        targets = {side: self._target(side, speed) for side, speed in speeds.items()}
        await self.call(link.command, targets, CW_ENABLE)

    async def _halt(self, link: Any) -> None:
        # Whatever state the drives are in: a stop is always sent, halt bit and zero target.
        await self.call(link.command, {"left": 0, "right": 0}, CW_ENABLE | CW_HALT)

    def _target(self, side: str, speed: float) -> int:
        value = round(speed * self.velocity_per_mps) * self.signs[side]
        return max(-(1 << 31), min((1 << 31) - 1, value))

    # -- readings --------------------------------------------------------------------------

    def take_position(self, link: Cia402Link) -> None:
        """Odometry from both wheels' position actual values (in the loop's thread).

        Called once both drives have sent a new position since the last call: the pair from
        one SYNC, so one wheel's move is never taken without the other's.
        """
        if link is not self.link and link is not self._pending:
            return
        counts = dict(link.position)
        last, self._counts = self._counts, counts
        if last is None:
            return
        moved = {
            side: _wrap32(counts[side] - last[side]) * self.signs[side] / self.counts_per_metre
            for side in SIDES
        }
        distance = (moved["left"] + moved["right"]) / 2.0
        turn = (moved["right"] - moved["left"]) / self.track
        self._pose = advance_pose(*self._pose, distance, turn, 1.0)

    def readings(self) -> dict[str, Any]:
        link = self.require_link()
        wheels = {
            side: link.velocity[side] * self.signs[side] / self.velocity_per_mps for side in SIDES
        }
        x, y, theta = self._pose
        return {
            "position": {"x": x, "y": y, "theta": theta},
            "velocity": {
                "linear": (wheels["left"] + wheels["right"]) / 2.0,
                "angular": (wheels["right"] - wheels["left"]) / self.track,
            },
            "heading": compass_heading(theta),
            "wheels": wheels,
            "drives": {
                side: {
                    "node": self.nodes[side],
                    "state": link.state(side),
                    "mode": link.mode[side],
                    "fault": link.fault[side],
                }
                for side in SIDES
            },
            "errors": self.errors,
        }

    def sensor_specs(self) -> dict[str, dict[str, Any]]:
        return {
            "position": {"unit": {"x": "m", "y": "m", "theta": "rad"}, "source": "odometry"},
            "velocity": {"unit": {"linear": "m/s", "angular": "rad/s"}},
            "heading": {"unit": "deg", "source": "odometry"},
            "wheels": {"unit": {"left": "m/s", "right": "m/s"}},
            "drives": {
                "unit": {"node": "id", "state": "CiA 402 state", "mode": "0x6061", "fault": "text"}
            },
            "errors": {"unit": "count"},
        }


def _check_eds(path: str) -> None:
    try:
        od = canopen.import_od(path, 1)
    except Exception as exc:  # noqa: BLE001 - OSError, configparser's errors...: a bad file
        raise ValueError(f"cannot read the EDS file {path!r}: {exc}") from exc
    missing = [f"0x{index:04X} {name}" for index, name in CIA402_OBJECTS.items() if index not in od]
    if missing:
        needed = ", ".join(missing)
        raise ValueError(f"the EDS file {path!r} lacks objects the cia402 profile needs: {needed}")


def _wrap32(delta: int) -> int:
    """A difference of two 32-bit counters, across their wrap."""
    return (delta + (1 << 31)) % INT32 - (1 << 31)


def _node_id(name: str, value: Any) -> int:
    if isinstance(value, bool) or not isinstance(value, int) or not 1 <= value <= 127:
        raise ValueError(f"{name} must be a CANopen node id from 1 to 127, got {value!r}")
    return value


def _flag(name: str, value: Any) -> bool:
    if not isinstance(value, bool):
        raise ValueError(f"{name} must be true or false, got {value!r}")
    return value
