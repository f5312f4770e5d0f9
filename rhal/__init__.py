"""Robot Hardware Abstraction Layer: one async interface in front of every kind of robot.

    robot = rhal.connect("sim://?arena=square")
    async with robot:
        await robot.drive(0.2, 0.0)
        print(await robot.sensors())

Plain Python with no Django imports, so robot agents and tools can use it on their own.
"""

from rhal.base import Robot
from rhal.errors import (
    DriverUnavailableError,
    NotSupportedError,
    RhalError,
    RobotConnectionError,
    UnknownDriverError,
)
from rhal.registry import DRIVERS, connect

__all__ = [
    "DRIVERS",
    "DriverUnavailableError",
    "NotSupportedError",
    "RhalError",
    "Robot",
    "RobotConnectionError",
    "UnknownDriverError",
    "connect",
]
