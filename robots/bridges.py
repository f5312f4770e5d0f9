"""A robot agent's serial bridges: its SerialBridge rows, each a gateway.serial_bridge on TCP.

The robot's own serial device follows the control lease: a bridge client that connects while
nobody drives takes the lease (programs' drive() is then refused, naming it) and the driver
lets go of the device until the client leaves; one that connects while a program drives
watches what the driver reads, or is refused, as the bridge's ``when_busy`` says. Another
device of the robot (a GPS, a lidar) is the bridge's alone.
"""

from __future__ import annotations

import asyncio
import logging

from channels.db import database_sync_to_async

from gateway.serial_bridge import SerialBridge
from robots.lease import Holder, LeaseHeld
from robots.models import SerialBridge as BridgeRow

log = logging.getLogger(__name__)


class Bridges:
    def __init__(self, agent):
        self.agent = agent
        self.running: dict[int, tuple[tuple, SerialBridge]] = {}
        self.failed: dict[int, tuple[tuple, str]] = {}
        self.holder: Holder | None = None  # the client holding the robot for its bridge
        self.closing = False
        self._applying = asyncio.Lock()
        self.handlers = {"bridges.stats": self._stats_asked, "bridges.reload": self._reload_asked}

    async def reload(self) -> None:
        rows = await database_sync_to_async(_rows_of)(self.agent.name)
        async with self._applying:
            for row_id in set(self.running) - set(rows):
                await self.running.pop(row_id)[1].stop()
            for row_id in set(self.failed) - set(rows):
                del self.failed[row_id]
            for row_id, config in rows.items():
                if self.running.get(row_id, (None,))[0] == config:
                    continue
                if self.failed.get(row_id, (None,))[0] == config:
                    continue
                await self._start(row_id, config)

    async def _start(self, row_id: int, config: tuple) -> None:
        if row_id in self.running:
            await self.running.pop(row_id)[1].stop()
        self.failed.pop(row_id, None)
        device, baud, address, protocol, when_busy = config
        own = not device
        device = device or self._driver_device()
        if not device:
            self.failed[row_id] = (config, "the robot's driver holds no serial device")
            return
        bridge = SerialBridge(
            device, baud=baud, address=address, protocol=protocol, when_busy=when_busy,
            acquire=self._acquire if own else None, release=self._release if own else None,
            tap=self._tap if own else None,
        )  # fmt: skip
        try:
            await bridge.start()
        except (OSError, ValueError) as exc:
            self.failed[row_id] = (config, str(exc) or type(exc).__name__)
            return
        self.running[row_id] = (config, bridge)

    def _driver_device(self) -> str | None:
        driver = self.agent.driver
        return driver.wire_device if driver is not None else None

    # -- the robot's own device: the lease and the driver ----------------------------------------

    async def _acquire(self, peer: str) -> str | None:
        holder = Holder("bridge", f"bridge {peer}", peer)
        try:
            self.agent.take_lease(holder)
        except LeaseHeld:
            return f"the robot is controlled by {self.agent.lease.holder.describe()}"
        self.holder = holder
        await self.agent.lend_driver(holder.describe())
        return None

    async def _release(self) -> None:
        holder, self.holder = self.holder, None
        if holder is not None and self.agent.lease.release(holder.key):
            self.agent._lease_changed()
        if not self.closing:  # the agent is going: its driver stays closed
            await self.agent.take_driver_back()

    def _tap(self, feed):
        driver = self.agent.driver
        if driver is None or driver.wire_device is None:
            raise RuntimeError("the robot's driver does not share what it reads")
        return driver.tap_wire(feed)

    def evict(self) -> int:
        """An emergency stop: the clients of every bridge go, so the robot's device comes back
        to its driver (whose stop goes on the wire then). How many clients there were."""
        return sum(bridge.evict() for _, bridge in self.running.values())

    # -- what others ask --------------------------------------------------------------------------

    def stats(self) -> dict:
        found = {row_id: bridge.as_dict() for row_id, (_, bridge) in self.running.items()}
        for row_id, (_, why) in self.failed.items():
            found[row_id] = {"status": "error", "error": why}
        for row in found.values():
            row.setdefault("status", "up")
        return {"bridges": found}

    async def _stats_asked(self, message: dict) -> None:
        await self.agent.reply(message, self.stats())

    async def _reload_asked(self, message: dict) -> None:
        await self.reload()
        await self.agent.reply(message, self.stats())

    async def close(self) -> None:
        self.closing = True
        for _, bridge in self.running.values():
            await bridge.stop()
        self.running.clear()


def _rows_of(robot_name: str) -> dict[int, tuple]:
    rows = BridgeRow.objects.filter(robot__name=robot_name)
    return {r.pk: (r.device, r.baud, r.address, r.protocol, r.when_busy) for r in rows}
