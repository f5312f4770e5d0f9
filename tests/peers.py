"""One peer per driver, each on the far side of the driver's wire, behind one small interface,
so a test can run the same program or the same stop on every kind of robot.

    peer = await start_peer("pioneer", tmp_path)
    peer.url          the robot URL that reaches this peer
    peer.commanded()  (linear m/s, angular rad/s) last decoded off the wire; (0, 0) stopped
    peer.stops        stop commands the peer has decoded so far
    await peer.stop()

Each peer decodes with its own code or a real library (a Goertzel detector, the ARCOS
emulator, nxt-python's wire format, pymavlink, canopen), never with the driver's classes.
"""

from __future__ import annotations

import asyncio
import contextlib
import importlib
import math
import threading
from collections.abc import Iterator
from pathlib import Path
from typing import Any

from tests.rhal.dtmf_decoder import decode, read_wav
from tests.waiting import DEADLINE

#: Every driver kind, as the "one program, six robots" tests run them.
KINDS = ("sim", "dtmf", "nxt", "pioneer", "mavlink", "can")
#: Kinds with a wire, whose stop a peer can see.
WIRED = KINDS[1:]
#: Kinds with a link that can be unplugged and plugged back (a sound card's cable can't tell).
LINKED = ("nxt", "pioneer", "mavlink", "can")


@contextlib.contextmanager
def peer_in_thread(kind: str, tmp_path: Path, **options: Any) -> Iterator[Any]:
    """A peer served from an event loop of its own in a thread: for tests whose own thread is
    busy elsewhere (a browser driven by Playwright's sync API)."""
    loop = asyncio.new_event_loop()
    thread = threading.Thread(target=loop.run_forever, name=f"{kind} peer", daemon=True)
    thread.start()
    peer = asyncio.run_coroutine_threadsafe(start_peer(kind, tmp_path, **options), loop)
    peer = peer.result(timeout=DEADLINE)
    try:
        yield peer
    finally:
        asyncio.run_coroutine_threadsafe(peer.stop(), loop).result(timeout=DEADLINE)
        loop.call_soon_threadsafe(loop.stop)
        thread.join(timeout=DEADLINE)


async def start_peer(
    kind: str, tmp_path: Path, *, other_process: bool = False, **options: Any
) -> Any:
    """``other_process``: the driver is in another process (a benchmark), so the peer must be
    reachable from there (CAN on an interface-local UDP multicast group, not in-process).
    ``options`` go to the peer (a Pioneer's ``model``)."""
    peer = _PEERS[kind](tmp_path, other_process=other_process, **options)
    await peer.start()
    return peer


class SimPeer:
    """The simulator has no wire: its "peer" is the driver's own state, read by the test."""

    def __init__(self, tmp_path: Path, **_: Any) -> None:
        self.url = "sim://"
        self.stops = 0

    async def start(self) -> None:
        pass

    async def stop(self) -> None:
        pass


class DtmfPeer:
    """Decodes the tones the driver wrote to its WAV file, as the MT8870 on the robot would."""

    # Digits of the default table, as the robot's H-bridges turn them into wheel directions.
    MOTION = {
        "D": (0.0, 0.0), "5": (1.0, 0.0), "0": (-1.0, 0.0), "6": (0.0, 1.0),
        "9": (0.0, -1.0), "4": (0.5, 0.5), "1": (0.5, -0.5),
    }  # fmt: skip
    STOP_REPEATS = 3

    def __init__(self, tmp_path: Path, **_: Any) -> None:
        self.path = tmp_path / "tones.wav"
        self.url = f"dtmf://?wav={self.path}"

    async def start(self) -> None:
        pass

    async def stop(self) -> None:
        pass

    def digits(self) -> list[str]:
        if not self.path.exists() or self.path.stat().st_size <= 44:
            return []
        samples, rate = read_wav(self.path)
        # The last burst may still be being written: only whole tones count.
        return [digit for digit, tone_ms, _ in decode(samples, rate) if tone_ms >= 35]

    def commanded(self) -> tuple[float, float]:
        digits = self.digits()
        return self.MOTION[digits[-1]] if digits else (0.0, 0.0)

    @property
    def stops(self) -> int:
        return self.digits().count("D") // self.STOP_REPEATS


class PioneerPeer:
    """The ARCOS robot emulator on TCP, which checks every packet's checksum itself."""

    def __init__(self, tmp_path: Path, model: str = "p3dx-sh", **_: Any) -> None:
        from tests.rhal.arcos_emulator import ArcosEmulator

        self.emulator = ArcosEmulator(model)

    async def start(self) -> None:
        self.port = await self.emulator.start_tcp()
        self.url = f"pioneer+tcp://127.0.0.1:{self.port}"

    async def stop(self) -> None:
        await self.emulator.stop()

    async def unplug(self) -> None:
        await self.emulator.stop()

    async def replug(self) -> None:
        await self.emulator.start_tcp(self.port)

    def commanded(self) -> tuple[float, float]:
        return self.emulator.vel / 1000.0, math.radians(self.emulator.rvel)

    @property
    def stops(self) -> int:
        """VEL 0 then RVEL 0: the driver's stop (a turn on the spot also sends VEL 0)."""
        motion = [(c.name, c.arg) for c in self.emulator.commands if c.name in ("VEL", "RVEL")]
        pairs = zip(motion, motion[1:], strict=False)
        return sum(1 for pair in pairs if pair == (("VEL", 0), ("RVEL", 0)))


class _Emulator:
    """A helper's emulator class that already speaks this interface."""

    module: str
    name: str

    def __init__(self, tmp_path: Path, other_process: bool = False) -> None:
        cls = getattr(importlib.import_module(self.module), self.name)
        self.emulator = cls(**(self.across_processes if other_process else {}))

    across_processes: dict[str, Any] = {}

    async def start(self) -> None:
        await self.emulator.start()
        self.url = self.emulator.url

    async def stop(self) -> None:
        await self.emulator.stop()

    def commanded(self) -> tuple[float, float]:
        return self.emulator.commanded()

    async def unplug(self) -> None:
        await self.emulator.unplug()

    async def replug(self) -> None:
        await self.emulator.replug()

    @property
    def stops(self) -> int:
        return self.emulator.stops


class MavlinkPeer(_Emulator):
    """An ArduPilot Rover emulator on TCP that enforces the mode and arming rules."""

    module, name = "tests.rhal.mavlink_emulator", "MavlinkEmulator"


class NxtPeer(_Emulator):
    """A Lego NXT brick on a pty, decoding the Direct Commands nxt-python sends it."""

    module, name = "tests.rhal.nxt_emulator", "NxtEmulator"


class CanPeer(_Emulator):
    """Two CiA 402 drives (canopen LocalNodes) on python-can's in-process virtual bus."""

    module, name = "tests.rhal.can_emulator", "Cia402BaseEmulator"
    across_processes = {"interface": "udp_multicast"}  # an interface-local IPv6 group


_PEERS = {
    "sim": SimPeer,
    "dtmf": DtmfPeer,
    "nxt": NxtPeer,
    "pioneer": PioneerPeer,
    "mavlink": MavlinkPeer,
    "can": CanPeer,
}
