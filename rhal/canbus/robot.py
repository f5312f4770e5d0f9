"""The can:// robot: its URL, its options, and which profile drives the base."""

from __future__ import annotations

import inspect
from typing import Any
from urllib.parse import unquote, urlsplit

import can

from rhal.base import Robot
from rhal.canbus.cia402 import Cia402
from rhal.canbus.dbc import Dbc
from rhal.canbus.profile import Profile, positive
from rhal.errors import RobotConnectionError

DEFAULT_INTERFACE, DEFAULT_CHANNEL = "socketcan", "can0"
#: Interfaces whose channel is a serial port: their channel may be an absolute path.
SERIAL_INTERFACES = frozenset({"slcan", "serial", "robotell", "seeedstudio"})


class CanRobot(Robot):
    kind = "can"
    quick = False  # every call waits on the bus
    option_help = {
        **Robot.option_help,
        "profile": "cia402: two CiA 402 wheel drives; dbc: a base described by a DBC file",
        "bitrate": "bit/s, for interfaces that set it (slcan, pcan...); socketcan's is set "
        "with ip link",
        "timeout": "s of silence (no heartbeat / no feedback frame) before the link counts as "
        "lost; blank: 0.5 for cia402, 1 for dbc",
        "left": "cia402: node id of the left wheel's drive",
        "right": "cia402: node id of the right wheel's drive",
        "eds": "cia402: the drives' EDS file (blank: the generic CiA 402 one shipped)",
        "track": "cia402: m between the wheels' contact points",
        "wheel_diameter": "cia402: m",
        "counts_per_rev": "cia402: position counts (0x6064) per wheel turn, gearbox included",
        "counts_per_metre": "cia402: position counts per metre of travel (blank: from "
        "counts_per_rev and wheel_diameter)",
        "velocity_per_mps": "cia402: units of 0x60FF/0x606C per m/s (blank: counts_per_metre, "
        "for drives whose velocity is in counts/s)",
        "invert_left": "cia402: the left drive turns the wheel backwards for a positive speed",
        "invert_right": "cia402: the right drive turns the wheel backwards for a positive speed "
        "(usual: it is mounted mirrored)",
        "heartbeat": "cia402: s between the drives' heartbeats (0x1017)",
        "sync": "cia402: s between the SYNCs the driver sends; the drives answer each with "
        "their TPDOs",
        "dbc": "dbc: the base's DBC file (blank: the example base shipped)",
        "command": "dbc: the message the driver sends",
        "speed": "dbc: Message.Signal for the forward speed the driver sends",
        "turn": "dbc: Message.Signal for the turn rate (counter-clockwise) the driver sends",
        "feedback_speed": "dbc: Message.Signal of the measured forward speed",
        "feedback_turn": "dbc: Message.Signal of the measured turn rate",
        "heading": "dbc: Message.Signal of a compass heading, degrees (blank: none)",
        "battery": "dbc: Message.Signal of the battery voltage (blank: none)",
        "range": "dbc: Message.Signal of the distance ahead (blank: none)",
        "rate": "dbc: Hz at which a command is repeated while moving (0: sent once)",
    }
    option_choices = {"profile": ("cia402", "dbc")}

    def __init__(
        self,
        url: str = "can://",
        *,
        profile: str = "cia402",
        bitrate: int | None = 500000,
        timeout: float | None = None,
        # cia402
        left: int = 1,
        right: int = 2,
        eds: str | None = None,
        track: float = 0.4,
        wheel_diameter: float = 0.2,
        counts_per_rev: float = 4096,
        counts_per_metre: float | None = None,
        velocity_per_mps: float | None = None,
        invert_left: bool = False,
        invert_right: bool = True,
        heartbeat: float = 0.1,
        sync: float = 0.05,
        # dbc
        dbc: str | None = None,
        command: str = "BaseCommand",
        speed: str = "BaseCommand.LinearSpeed",
        turn: str = "BaseCommand.TurnRate",
        feedback_speed: str = "BaseFeedback.Speed",
        feedback_turn: str = "BaseFeedback.TurnRate",
        heading: str = "",
        battery: str = "",
        range: str = "",  # the option's documented name, though a builtin's
        rate: float = 20.0,
        max_linear: float = 0.5,
        max_angular: float = 2.0,
    ) -> None:
        super().__init__(url, max_linear=max_linear, max_angular=max_angular)
        self.interface, self.channel = parse_url(url)
        if bitrate is not None:
            bitrate = positive(int, "bitrate", bitrate)
        self.bitrate = bitrate
        given = dict(locals())
        profiles: dict[str, type[Profile]] = {"cia402": Cia402, "dbc": Dbc}
        if profile not in profiles:
            raise ValueError(f"unknown CAN profile {profile!r}; use one of: {', '.join(profiles)}")
        self.profile = profile
        defaults = {
            name: parameter.default
            for name, parameter in inspect.signature(CanRobot.__init__).parameters.items()
        }
        mine = profiles[profile].options
        for other, cls in profiles.items():
            for name in cls.options:
                value = given[name]
                if other != profile and name not in mine and value not in (None, defaults[name]):
                    raise ValueError(
                        f"{name} is an option of the {other} profile; this robot's profile "
                        f"is {profile}"
                    )
        self._profile: Profile = profiles[profile](
            self, timeout=timeout, **{name: given[name] for name in mine}
        )

    @property
    def errors(self) -> int:
        """Frames dropped so far: error frames, wrong lengths, frames that did not decode."""
        return self._profile.errors

    @property
    def connected(self) -> bool:
        return self._profile.link is not None

    @property
    def timeout(self) -> float:
        return self._profile.timeout

    # -- hooks -----------------------------------------------------------------------------

    async def _open(self) -> None:
        await self._profile.open()

    async def _close(self) -> None:
        await self._profile.close()

    async def _drive(self, linear: float, angular: float) -> None:
        await self._profile.drive(linear, angular)

    async def _stop(self) -> None:
        try:
            await self._profile.stop()
        except RobotConnectionError:
            # While closing, a lost link is no reason to fail: the drives' own watchdogs act.
            if self.is_open:
                raise

    async def _read_sensors(self) -> dict[str, Any]:
        return self._profile.readings()

    def _sensor_specs(self) -> dict[str, dict[str, Any]]:
        return self._profile.sensor_specs()

    def make_bus(self) -> can.BusABC:
        """Open the bus (blocking: called in a worker thread)."""
        config: dict[str, Any] = {"interface": self.interface, "channel": self.channel}
        if self.bitrate is not None:
            config["bitrate"] = self.bitrate
        try:
            return can.Bus(**config)
        except (can.CanError, OSError, ValueError) as exc:
            raise RobotConnectionError(
                f"cannot open the CAN bus {self.interface}:{self.channel}: {exc}"
            ) from exc


def parse_url(url: str) -> tuple[str, str | None]:
    """``can://<interface>/<channel>`` -> (python-can interface, channel)."""
    parts = urlsplit(url)
    if parts.scheme.lower() != "can":
        raise ValueError(f"not a CAN URL: {url!r}; use can://<interface>/<channel>")
    interface = parts.netloc.lower() or DEFAULT_INTERFACE
    if interface not in can.VALID_INTERFACES:
        known = ", ".join(sorted(can.VALID_INTERFACES))
        raise ValueError(f"unknown python-can interface {interface!r} in {url!r}; known: {known}")
    path = unquote(parts.path)
    channel = path[1:]
    if interface in SERIAL_INTERFACES and "/" in channel:
        channel = path  # can://slcan/dev/ttyACM0 -> /dev/ttyACM0; can://slcan/COM3 -> COM3
    if not channel:
        return interface, DEFAULT_CHANNEL if interface == DEFAULT_INTERFACE else None
    return interface, channel
