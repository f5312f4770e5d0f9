"""The cia402 profile's link: one canopen Network, the drives set up, watched and commanded."""

from __future__ import annotations

import asyncio
import concurrent.futures
import contextlib
import time
from collections.abc import Callable
from functools import partial
from typing import TYPE_CHECKING, Any

import can
import canopen
from canopen.emcy import EmcyError
from canopen.network import MessageListener
from canopen.nmt import NMT_STATES
from canopen.profiles.p402 import State402

from rhal.canbus.profile import NOTIFIER_CYCLE, Link
from rhal.errors import RobotConnectionError
from rhal.linked import QuietClock

if TYPE_CHECKING:
    from rhal.canbus.cia402 import Cia402

SIDES = ("left", "right")
PROFILED_VELOCITY = 3  # 0x6060 modes of operation
CW_ENABLE = 0x000F  # controlword: enable operation
CW_HALT = 0x0100  # controlword bit 8: halt
CW_SHUTDOWN = 0x0006  # controlword: shutdown, to READY TO SWITCH ON (power stage off)
NMT_OPERATIONAL = 5
# Set-up waits are deadlines for an answer, not how long one takes: a drive answers in
# milliseconds, but the computer it answers may be busy (a program hogging the robot's
# computer), and then its own threads hear the answer late. canopen's 0.3 s SDO and 0.2-0.8 s
# state-machine waits, and 1 s here, failed the set-up on a 2-core machine at a load of 20.
# Only a drive that does not answer at all waits them out.
SDO_RESPONSE_TIMEOUT = 3.0
SETUP_WAIT = 3.0  # s, at least, for a TPDO, a state change or a heartbeat during set-up
#: The PDOs the driver maps: (TPDO or RPDO, number) -> objects. TPDOs go on every SYNC, the
#: RPDO at once; the drives' other predefined PDOs are switched off.
PDO_LAYOUT = {
    ("rpdo", 1): (0x6040, 0x60FF),
    ("tpdo", 1): (0x6041, 0x6061),
    ("tpdo", 2): (0x6064, 0x606C),
}


class Cia402Link(Link):
    """One canopen Network with the two drives as BaseNode402 nodes."""

    def __init__(self, profile: Cia402, loop: asyncio.AbstractEventLoop) -> None:
        super().__init__(profile, loop)
        self.profile: Cia402 = profile
        self.network: canopen.Network | None = None
        self.nodes: dict[str, canopen.BaseNode402] = {}
        self.sizes: dict[int, int] = {}  # COB-ID -> the only length its frames may have
        # How long each drive's heartbeat has been missing, as the watch ticks.
        self.quiet = {side: QuietClock(profile.tick) for side in SIDES}
        self.nmt: dict[str, int | None] = dict.fromkeys(SIDES)  # NMT state it said
        self.nmt_seen: dict[str, int | None] = dict.fromkeys(SIDES)  # the same, thread side
        self.status: dict[str, int | None] = dict.fromkeys(SIDES)
        self.mode: dict[str, int | None] = dict.fromkeys(SIDES)
        self.position: dict[str, int | None] = dict.fromkeys(SIDES)
        self.fresh: set[str] = set()  # wheels with a position odometry has not taken yet
        self.velocity: dict[str, int] = dict.fromkeys(SIDES, 0)
        self.fault: dict[str, str | None] = dict.fromkeys(SIDES)

    # -- in the loop's thread --------------------------------------------------------------

    def state(self, side: str) -> str:
        status = self.status[side]
        if status is None:
            return "UNKNOWN"
        for name, (mask, bits) in State402.SW_MASK.items():
            if status & mask == bits:
                return name
        return "UNKNOWN"

    def problem(self) -> str | None:
        reason = self.bus_problem()
        if reason:
            return reason
        for side in SIDES:
            what = self.profile.describe(side)
            if self.quiet[side].look() > self.profile.timeout:
                return f"no heartbeat from {what} for {self.profile.timeout:g} s"
            state = self.nmt[side]
            if state == 0:
                return f"{what} restarted (boot-up message)"
            if state is not None and state != NMT_OPERATIONAL:
                return f"{what} left OPERATIONAL: its heartbeat says {NMT_STATES.get(state, state)}"
        return None

    def _heartbeat(self, side: str, state: int) -> None:
        self.quiet[side].heard()
        self.nmt[side] = state

    def _tpdo(self, side: str, values: dict[int, int]) -> None:
        if 0x6041 in values:
            self.status[side] = values[0x6041]
        if 0x6061 in values:
            self.mode[side] = values[0x6061]
        if 0x606C in values:
            self.velocity[side] = values[0x606C]
        if 0x6064 in values:
            self.position[side] = values[0x6064]
            self.fresh.add(side)
            if len(self.fresh) == len(SIDES):
                self.fresh.clear()
                self.profile.take_position(self)

    # -- in the Notifier thread ------------------------------------------------------------

    def _on_tpdo(self, side: str, pdo_map: canopen.pdo.PdoMap) -> None:
        values = {variable.index: variable.raw for variable in pdo_map}
        self.soon(self._tpdo, side, values)

    def _on_heartbeat(self, side: str, state: int) -> None:
        self.nmt_seen[side] = state  # for bring_up, which runs in a worker thread
        self.soon(self._heartbeat, side, state)

    # -- in a worker thread ----------------------------------------------------------------

    def bring_up(self) -> None:
        profile = self.profile
        bus = profile.robot.make_bus()
        network = canopen.Network(bus)
        network.NOTIFIER_CYCLE = NOTIFIER_CYCLE
        network.listeners = [_CheckedListener(network, self)]
        self.network = network
        for side in SIDES:
            node_id = profile.nodes[side]
            node = canopen.BaseNode402(node_id, profile.eds)
            # canopen's waits, stretched to a few SYNC periods so a slow bus still makes it.
            node.TIMEOUT_CHECK_TPDO = max(SETUP_WAIT, 4 * profile.sync)
            node.TIMEOUT_SWITCH_STATE_SINGLE = max(SETUP_WAIT / 3, 8 * profile.sync)
            node.TIMEOUT_SWITCH_STATE_FINAL = max(SETUP_WAIT, 16 * profile.sync)
            node.sdo.RESPONSE_TIMEOUT = SDO_RESPONSE_TIMEOUT
            network.add_node(node)
            node.nmt.add_heartbeat_callback(partial(self._on_heartbeat, side))
            self.nodes[side] = node
            self.sizes.update({0x700 + node_id: 1, 0x580 + node_id: 8, 0x80 + node_id: 8})
        network.connect()
        self.notifier = network.notifier
        for node in self.nodes.values():
            node.nmt.state = "PRE-OPERATIONAL"
        for side, node in self.nodes.items():
            self._sdo(side, self._configure, side, node)
        self.check_aborted()
        network.sync.start(profile.sync)
        for node in self.nodes.values():
            node.nmt.state = "OPERATIONAL"
        # Both drives walk their state machines at once: each step waits for a SYNC.
        with concurrent.futures.ThreadPoolExecutor(len(SIDES), "rhal-can-402") as pool:
            walks = [pool.submit(self._sdo, side, self._enable, side, node)
                     for side, node in self.nodes.items()]  # fmt: skip
        for walk in walks:
            walk.result()
        for side in SIDES:
            self._await_operational(side)
        # A drive that was already enabled keeps its last target: motion must not resume.
        self.command(dict.fromkeys(SIDES, 0), CW_ENABLE)
        self.check_aborted()

    def _sdo(self, side: str, step: Callable[..., None], *args: Any) -> None:
        what = self.profile.describe(side)
        try:
            step(*args)
        except canopen.SdoCommunicationError as exc:
            raise RobotConnectionError(f"no answer from {what}: {exc}") from None
        except canopen.SdoAbortedError as exc:
            raise RobotConnectionError(f"{what} refused a setting: {exc}") from None
        except can.CanError as exc:
            raise RobotConnectionError(f"cannot send to {what}: {exc}") from None

    def _configure(self, side: str, node: canopen.BaseNode402) -> None:
        self.check_aborted()
        what = self.profile.describe(side)
        device_type = node.sdo[0x1000].raw
        if device_type & 0xFFFF != 402:
            raise RobotConnectionError(
                f"{what} is not a CiA 402 drive: its device type is 0x{device_type:08X}"
            )
        node.sdo[0x1017].raw = round(self.profile.heartbeat * 1000)
        maps = {"tpdo": node.tpdo, "rpdo": node.rpdo}
        for kind, pdos in maps.items():
            for number, pdo_map in pdos.map.items():
                if pdo_map.predefined_cob_id is None:
                    continue  # beyond the predefined four: left as the drive has it
                objects = PDO_LAYOUT.get((kind, number))
                pdo_map.cob_id = pdo_map.predefined_cob_id
                pdo_map.clear()
                pdo_map.enabled = objects is not None
                for index in objects or ():
                    pdo_map.add_variable(index)
                if objects is not None:
                    pdo_map.trans_type = 1 if kind == "tpdo" else 255  # every SYNC / at once
                pdo_map.save()
                if objects is not None and kind == "tpdo":
                    self.sizes[pdo_map.cob_id] = (pdo_map.length + 7) // 8
        node.sdo[0x6060].raw = PROFILED_VELOCITY  # by SDO: no PDO carries it
        node.setup_pdos(upload=False)  # BaseNode402 learns the mapping just saved
        for rpdo in node.rpdo.map.values():
            # canopen listens on our own RPDOs too: a bus that echoes what it sends
            # (udp_multicast) would put an old frame back into the one about to go out.
            with contextlib.suppress(KeyError, ValueError):
                self.network.unsubscribe(rpdo.cob_id, rpdo.on_message)
        for number in (1, 2):
            node.tpdo[number].add_callback(partial(self._on_tpdo, side))

    def _enable(self, side: str, node: canopen.BaseNode402) -> None:
        self.check_aborted()
        what = self.profile.describe(side)
        wait = max(SETUP_WAIT, 10 * self.profile.sync)
        for number in (1, 2):
            tpdo = node.tpdo[number]
            if tpdo.timestamp is None and tpdo.wait_for_reception(wait) is None:
                raise RobotConnectionError(f"no TPDO{number} from {what} {wait:g} s after SYNC")
        mode = node.tpdo_values.get(0x6061)
        if mode != PROFILED_VELOCITY:
            raise RobotConnectionError(
                f"{what} did not take profile velocity mode (0x6060 = 3): it reports mode {mode}"
            )
        node.rpdo_pointers[0x60FF].raw = 0
        try:
            node.state = "OPERATION ENABLED"
        except (RuntimeError, ValueError) as exc:
            state = node.state
            fault = f" ({self.read_fault(side)})" if state == "FAULT" else ""
            raise RobotConnectionError(
                f"{what} did not reach OPERATION ENABLED: it stays in {state}{fault} ({exc})"
            ) from None

    def _await_operational(self, side: str) -> None:
        # Its heartbeat must say OPERATIONAL before the link is watched: one sent before the
        # NMT start would otherwise read as the drive leaving OPERATIONAL.
        deadline = time.monotonic() + max(SETUP_WAIT, 3 * self.profile.heartbeat)
        while self.nmt_seen[side] != NMT_OPERATIONAL:
            if time.monotonic() > deadline:
                state = self.nmt_seen[side]
                raise RobotConnectionError(
                    f"{self.profile.describe(side)} did not start: its heartbeat says "
                    f"{NMT_STATES.get(state, state) if state is not None else 'nothing'}"
                )
            time.sleep(0.005)

    def read_fault(self, side: str) -> str:
        try:
            code = self.nodes[side].sdo[0x603F].raw
        except Exception as exc:  # noqa: BLE001 - a garbled answer must not end the watch
            return f"error code unreadable: {exc}"
        return str(EmcyError(code, 0, b"", 0))

    def command(self, targets: dict[str, int], controlword: int) -> None:
        """Target velocity and controlword to both drives, one RPDO each."""
        if self.dropped:  # a call queued behind the one that dropped the link
            raise RobotConnectionError(f"no link to the CAN base at {self.profile.url!r}")
        try:
            for side, node in self.nodes.items():
                node.rpdo_pointers[0x60FF].raw = targets[side]
                node.rpdo_pointers[0x6040].raw = controlword
                node.rpdo_pointers[0x6040].pdo_parent.transmit()
        except (can.CanError, RuntimeError) as exc:
            raise RobotConnectionError(f"lost the CAN bus at {self.profile.url!r}: {exc}") from exc

    def goodbye(self) -> None:
        """An orderly end: power stages off, PDOs stopped, then the bus closed."""
        with contextlib.suppress(can.CanError, RobotConnectionError, RuntimeError):
            self.command({"left": 0, "right": 0}, CW_SHUTDOWN)
            for node in self.nodes.values():
                node.nmt.state = "PRE-OPERATIONAL"
        self.drop()

    def drop(self) -> None:
        self.dropped = True
        network, self.network = self.network, None
        if network is not None:
            # disconnect() re-raises an error the Notifier thread died of: it is known already.
            with contextlib.suppress(Exception):
                network.disconnect()


class _CheckedListener(MessageListener):
    """canopen's listener, after dropping (and counting) frames no drive can have sent."""

    def __init__(self, network: canopen.Network, link: Cia402Link) -> None:
        super().__init__(network)
        self.link = link

    def on_message_received(self, msg: can.Message) -> None:
        if msg.is_error_frame:
            self.link.count_error()
            return
        if msg.is_extended_id:
            return  # CANopen speaks 11-bit identifiers: a 29-bit frame is someone else's
        size = self.link.sizes.get(msg.arbitration_id)
        if size is not None and not msg.is_remote_frame and len(msg.data) != size:
            self.link.count_error()
            return
        super().on_message_received(msg)
