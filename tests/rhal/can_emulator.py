"""Robot bases on the far side of python-can's in-process ``virtual`` bus, for the can:// tests.

``Cia402Drive`` is one CiA 402 servo drive: a canopen LocalNode (the library's SDO server, NMT
slave and heartbeat producer) loaded with the EDS the driver ships, on a bus handle of its own.
Its 402 state machine, statusword and motion are written here again from the standard rather
than taken from canopen's BaseNode402, which the driver uses, so a mistake cannot hide by being
made on both sides. It enforces the state machine: a controlword moves it only along the
standard's transitions, and the wheel turns only in OPERATION ENABLED, in mode 3 (profile
velocity), with the halt bit clear. It integrates its velocity into a position, re-reads the PDO
mapping the driver wrote over SDO when started (NMT OPERATIONAL), sends its TPDOs on SYNC and
its heartbeat at the period the driver set in 0x1017.

``Cia402BaseEmulator`` pairs two drives into a differential base and integrates a pose.
``DbcBaseEmulator`` is the base of ``rhal/can_profiles/example_base.dbc``: it decodes commands
with cantools from its own bus handle, obeys them until its 0.5 s command timeout, and sends
feedback and status frames at 20 Hz.

Both bases offer the emulator interface every driver's tests share: ``await start()``, ``url``,
``commanded()``, ``stops``, ``await unplug()``, ``await replug()``, ``await stop()``.

They run on python-can's ``virtual`` bus, which joins buses of one process. For a driver in
another process, ``interface="udp_multicast"`` puts them on an IPv6 *interface-local*
multicast group (``ff11::...``), which the kernel never sends out of the computer. Every
udp_multicast bus on the computer shares one UDP port, so run one such base at a time.
"""

from __future__ import annotations

import asyncio
import contextlib
import math
import threading
import time
import uuid
from dataclasses import dataclass
from urllib.parse import urlencode

import can
import canopen
import cantools
from canopen.sdo import SdoAbortedError

from rhal.canbus import CIA402_EDS, EXAMPLE_DBC

#: CiA 402 statusword bits 0-3, 5 and 6 of each state.
STATUS_BITS = {
    "NOT READY TO SWITCH ON": 0x0000,
    "SWITCH ON DISABLED": 0x0040,
    "READY TO SWITCH ON": 0x0021,
    "SWITCHED ON": 0x0023,
    "OPERATION ENABLED": 0x0027,
    "QUICK STOP ACTIVE": 0x0007,
    "FAULT REACTION ACTIVE": 0x000F,
    "FAULT": 0x0008,
}
VOLTAGE_ENABLED, REMOTE, TARGET_REACHED = 0x0010, 0x0200, 0x0400
HALT, FAULT_RESET = 0x0100, 0x0080
SUPPORTED_MODES = (1, 3)  # as 0x6502 in the EDS says: profile position and profile velocity
ABORT_VALUE_RANGE = 0x06090030
# s a drive waits for the others to answer the SYNC before, at most: a deadline for a partner
# that stopped answering while still OPERATIONAL (none does here), not how long it takes. A
# partner that leaves OPERATIONAL says so at once. 0.1 s let a loaded machine's lagging drive
# pair one wheel's hand turn with the other's older position.
STEP_WAIT = 5.0


def _channel(interface: str, channel: str | None) -> str:
    if channel:
        return channel
    if interface == "udp_multicast":
        return f"ff11::{uuid.uuid4().hex[:4]}:{uuid.uuid4().hex[:4]}"  # interface-local
    return f"rhal-can-{uuid.uuid4().hex[:12]}"


@dataclass
class Received:
    """A write to the drive: controlword and target velocity as one RPDO, or one SDO."""

    controlword: int | None
    target: int | None
    via: str  # "rpdo" or "sdo"
    at: float


def _next_state(state: str, controlword: int) -> str:
    """Where a controlword command (fault reset aside) takes the 402 state machine."""
    if state in ("NOT READY TO SWITCH ON", "FAULT REACTION ACTIVE", "FAULT"):
        return state
    command = controlword & 0x0F
    if not command & 0b0010:  # disable voltage: transitions 7, 9, 10, 12
        return "SWITCH ON DISABLED"
    if not command & 0b0100:  # quick stop: 7, 10, 11
        if state == "OPERATION ENABLED":
            return "QUICK STOP ACTIVE"
        if state in ("READY TO SWITCH ON", "SWITCHED ON"):
            return "SWITCH ON DISABLED"
        return state
    if command & 0b0111 == 0b0110:  # shutdown: 2, 6, 8
        if state in ("SWITCH ON DISABLED", "SWITCHED ON", "OPERATION ENABLED"):
            return "READY TO SWITCH ON"
        return state
    if command == 0b0111:  # switch on (3) or disable operation (5)
        return {"READY TO SWITCH ON": "SWITCHED ON", "OPERATION ENABLED": "SWITCHED ON"}.get(
            state, state
        )
    if command == 0b1111:  # switch on + enable operation: 3 + 4, 4, 16
        if state in ("READY TO SWITCH ON", "SWITCHED ON", "QUICK STOP ACTIVE"):
            return "OPERATION ENABLED"
    return state


class Cia402Drive:
    """One CiA 402 drive on a virtual CAN channel. Its methods block: call them in a thread."""

    def __init__(
        self, node_id: int, channel: str, *, eds=CIA402_EDS, on_motion=None, interface="virtual"
    ) -> None:
        self.node_id, self.channel, self.eds = node_id, channel, str(eds)
        self.interface = interface
        self.on_motion = on_motion  # called before the wheel's speed changes
        self.lock = threading.RLock()
        self.received: list[Received] = []
        self.stops = 0  # halt with a zero target: the driver's stop
        self.tpdos_sent = 0
        self.bad_rpdos = 0
        self.boots = 0
        self.position = 0.0  # counts; an absolute encoder: it survives a power cycle
        self.syncs_seen = 0
        self.answered = 0  # the last SYNC whose TPDOs this drive has sent
        self.in_step_with: list[Cia402Drive] = []  # drives that answer each SYNC together
        self.step = threading.Condition()  # shared with them
        self.nudges: list[tuple[int, float]] = []  # (at SYNC number, counts): hand turns
        self.online = False
        self.operational = False  # NMT OPERATIONAL
        self.network: canopen.Network | None = None
        self.node: canopen.LocalNode | None = None
        self._tpdos: list = []
        self._syncs: dict[int, int] = {}
        self._moved_at = time.monotonic()
        self._power_on()

    def _power_on(self) -> None:
        self.state = "SWITCH ON DISABLED"  # NOT READY TO SWITCH ON passes by itself
        self.mode = 0
        self.controlword = 0
        self.target = 0
        self.error_code = 0
        self.fault_sticks = False

    # -- what tests look at ----------------------------------------------------------------

    @property
    def velocity(self) -> int:
        """Velocity actual, counts/s: the target only where the standard lets the wheel turn."""
        if (
            self.online
            and self.state == "OPERATION ENABLED"
            and self.mode == 3
            and not self.controlword & HALT
        ):
            return self.target
        return 0

    @property
    def statusword(self) -> int:
        word = STATUS_BITS[self.state] | VOLTAGE_ENABLED | REMOTE
        if self.state == "OPERATION ENABLED" and self.velocity == self.target:
            word |= TARGET_REACHED
        return word

    @property
    def nmt_state(self) -> str | None:
        return self.node.nmt.state if self.node is not None and self.online else None

    def pdo_objects(self, kind: str, number: int) -> list[int]:
        """The objects mapped in this drive's TPDO or RPDO ``number``, as it holds them."""
        communication = (0x1800 if kind == "tpdo" else 0x1400) + number - 1
        mapping = (0x1A00 if kind == "tpdo" else 0x1600) + number - 1
        sdo = self.node.sdo  # the node's own SDO server: reads its object dictionary
        if sdo[communication][1].raw & 0x80000000:
            return []  # not valid: disabled
        count = sdo[mapping][0].raw
        return [sdo[mapping][entry].raw >> 16 for entry in range(1, count + 1)]

    def transmission_type(self, number: int) -> int:
        return self.node.sdo[0x1800 + number - 1][2].raw

    def heartbeat_ms(self) -> int:
        return self.node.sdo[0x1017].raw

    def fault(self, code: int = 0x2310, *, sticky: bool = False) -> None:
        """Trip: FAULT with ``code`` in 0x603F and an EMCY. A sticky fault survives a reset."""
        with self.lock:
            self._moving()
            self.state, self.error_code, self.fault_sticks = "FAULT", code, sticky
        if self.node is not None and self.online:
            with contextlib.suppress(can.CanError, RuntimeError):
                self.node.emcy.send(code, 0x01)

    # -- the link --------------------------------------------------------------------------

    def start(self) -> None:
        """Power on: boot-up message, PRE-OPERATIONAL, no heartbeat until 0x1017 is set."""
        bus = can.Bus(interface=self.interface, channel=self.channel)
        network = canopen.Network(bus)
        network.NOTIFIER_CYCLE = 0.05
        node = canopen.LocalNode(self.node_id, self.eds)
        network.add_node(node)
        node.add_read_callback(self._on_read)
        node.add_write_callback(self._on_write)
        network.subscribe(0, self._on_nmt)  # after the NMT slave's own handler
        network.subscribe(0x80, self._on_sync)  # 0x1005 COB-ID SYNC
        with self.lock:
            self._moving()
            self._power_on()
            self.network, self.node = network, node
            self.online, self.operational = True, False
            self._tpdos, self._syncs = [], {}
            self.boots += 1
        with self.step:  # powered again while the others ran: it joins their SYNC count
            counts = [other.syncs_seen for other in self.in_step_with]
            self.syncs_seen = self.answered = max(counts, default=self.syncs_seen)
        network.connect()
        node.nmt.state = "INITIALISING"  # sends the boot-up message
        node.nmt.state = "PRE-OPERATIONAL"

    def unplug(self) -> None:
        """Power off: the wheel stops, nothing more is sent or answered."""
        with self.lock:
            self._moving()
            self.online = self.operational = False
            network, self.network = self.network, None
        self._answered(self.answered)  # a partner waiting on this drive waits no more
        if network is not None:
            network.disconnect()

    # -- in the Notifier thread ------------------------------------------------------------

    def _on_nmt(self, can_id, data, timestamp) -> None:
        node = self.node
        state = node.nmt.state
        if state == "INITIALISING":  # reset node / communication: boot again
            command = data[0]
            with self.lock:
                self._moving()
                if command == 0x81:
                    self._power_on()
                    node.data_store.clear()
                else:
                    for index in list(node.data_store):
                        if 0x1000 <= index < 0x2000:
                            del node.data_store[index]
                self.operational = False
            self._answered(self.answered)
            node.nmt.state = "INITIALISING"
            node.nmt.state = "PRE-OPERATIONAL"
            return
        if state == "OPERATIONAL" and not self.operational:
            # Apply the PDO mapping the master wrote while we were PRE-OPERATIONAL.
            node.tpdo.read()
            node.rpdo.read()
            with self.lock:
                self._tpdos = [pdo for pdo in node.tpdo.map.values() if pdo.enabled]
                self._syncs = {}
            for pdo in self._tpdos:
                # read() listens on the TPDO's own COB-ID too: a frame another node put there
                # would then become this drive's next TPDO.
                with contextlib.suppress(KeyError, ValueError):
                    self.network.unsubscribe(pdo.cob_id, pdo.on_message)
            for pdo in node.rpdo.map.values():
                pdo.callbacks = [self._on_rpdo]
        self.operational = state == "OPERATIONAL"
        self._answered(self.answered)

    def _on_sync(self, can_id, data, timestamp) -> None:
        with self.lock:
            # Every drive hears every SYNC, whatever its NMT state: counted alike, the drives
            # apply a hand turn on the same one even when they were started a SYNC apart.
            self.syncs_seen += 1
            number = self.syncs_seen
            for nudge in [n for n in self.nudges if n[0] <= number]:
                self.nudges.remove(nudge)
                self.position += nudge[1]
            if not self.operational:
                self._answered(number)
                return
            self._advance()
            values = self._values()
            due = []
            for pdo in self._tpdos:
                kind = pdo.trans_type
                if kind == 0 or 1 <= kind <= 240:  # synchronous; event-driven ones are not
                    count = self._syncs[pdo.cob_id] = self._syncs.get(pdo.cob_id, 0) + 1
                    if kind == 0 or count % kind == 0:
                        due.append(pdo)
        self._await_partners(number)
        for pdo in due:
            pdo.data = bytearray((pdo.length + 7) // 8)
            for variable in pdo:
                if variable.index in values:
                    variable.raw = values[variable.index]
            with contextlib.suppress(can.CanError):
                pdo.transmit()
                self.tpdos_sent += 1
        self._answered(number)

    def _await_partners(self, number: int) -> None:
        # On a real bus every drive answers a SYNC within microseconds, long before the next.
        # Each emulated drive answers in its own thread, which a busy machine can hold back a
        # SYNC period or more: without this wait one drive's answer to SYNC n+1 could reach the
        # master before the other's to SYNC n, a pair of positions no real bus gives. Bounded:
        # a drive that stopped answering (reset, unplugged) must not hold this one's SDO
        # answers and RPDOs back, which wait in the same thread.
        with self.step:
            self.step.wait_for(
                lambda: all(
                    other.answered >= number - 1 or not other.operational
                    for other in self.in_step_with
                ),
                timeout=STEP_WAIT,
            )

    def _answered(self, number: int) -> None:
        with self.step:
            self.answered = number
            self.step.notify_all()

    def _on_rpdo(self, pdo_map) -> None:
        if not self.operational:
            return  # PDOs count only in OPERATIONAL
        if len(pdo_map.data) != (pdo_map.length + 7) // 8:
            self.bad_rpdos += 1
            return
        self._apply({variable.index: variable.raw for variable in pdo_map}, "rpdo")

    def _on_write(self, index, subindex, od, data) -> None:
        if index not in (0x6040, 0x60FF, 0x6060):
            return
        value = od.decode_raw(data)
        if index == 0x6060 and value not in SUPPORTED_MODES:
            raise SdoAbortedError(ABORT_VALUE_RANGE)
        self._apply({index: value}, "sdo")

    def _on_read(self, index, subindex, od):
        with self.lock:
            self._advance()
            return self._values().get(index)

    # -- the drive -------------------------------------------------------------------------

    def _apply(self, values: dict[int, int], via: str) -> None:
        with self.lock:
            self._moving()
            if 0x6060 in values:
                self.mode = values[0x6060]
            if 0x60FF in values:
                self.target = values[0x60FF]
            controlword = values.get(0x6040)
            if controlword is not None:
                self._controlword(controlword)
            self.received.append(Received(controlword, values.get(0x60FF), via, time.monotonic()))
            if controlword is not None and controlword & HALT and self.target == 0:
                self.stops += 1

    def _controlword(self, controlword: int) -> None:
        previous, self.controlword = self.controlword, controlword
        if controlword & FAULT_RESET:
            # Fault reset acts on the rising edge; while the bit is held nothing else acts.
            if not previous & FAULT_RESET and self.state == "FAULT" and not self.fault_sticks:
                self.state, self.error_code = "SWITCH ON DISABLED", 0
            return
        self.state = _next_state(self.state, controlword)

    def _moving(self) -> None:
        """Bring the position up to now before anything changes the speed."""
        self._advance()
        if self.on_motion is not None:
            self.on_motion()

    def _advance(self) -> None:
        now = time.monotonic()
        self.position += self.velocity * (now - self._moved_at)
        self._moved_at = now

    def _values(self) -> dict[int, int]:
        position = (round(self.position) + (1 << 31)) % (1 << 32) - (1 << 31)
        return {
            0x1001: 0x01 if self.state == "FAULT" else 0,
            0x603F: self.error_code,
            0x6040: self.controlword,
            0x6041: self.statusword,
            0x6060: self.mode,
            0x6061: self.mode,
            0x6064: position,
            0x606C: self.velocity,
            0x60FF: self.target,
        }


class Cia402BaseEmulator:
    """Two CiA 402 drives, left and right, turning the wheels of a differential base."""

    def __init__(
        self,
        *,
        channel: str | None = None,
        interface: str = "virtual",
        left: int = 1,
        right: int = 2,
        track: float = 0.4,
        wheel_diameter: float = 0.2,
        counts_per_rev: int = 4096,
        invert_right: bool = True,
        **options,
    ) -> None:
        self.channel = _channel(interface, channel)
        self.track = track
        self.counts_per_metre = counts_per_rev / (math.pi * wheel_diameter)
        self.signs = {"left": 1, "right": -1 if invert_right else 1}
        self.left = Cia402Drive(left, self.channel, on_motion=self._advance, interface=interface)
        self.right = Cia402Drive(right, self.channel, on_motion=self._advance, interface=interface)
        self.left.in_step_with, self.right.in_step_with = [self.right], [self.left]
        self.left.step = self.right.step = threading.Condition()
        query = {
            "profile": "cia402",
            "left": left,
            "right": right,
            "track": track,
            "wheel_diameter": wheel_diameter,
            "counts_per_rev": counts_per_rev,
            "invert_right": "true" if invert_right else "false",
            **options,
        }
        self.url = f"can://{interface}/{self.channel}?{urlencode(query)}"
        self.x = self.y = self.theta = 0.0  # m, m, rad counter-clockwise from +x
        self._lock = threading.Lock()
        self._at = time.monotonic()

    @property
    def drives(self) -> dict[str, Cia402Drive]:
        return {"left": self.left, "right": self.right}

    async def start(self) -> None:
        for drive in self.drives.values():
            await asyncio.to_thread(drive.start)

    async def unplug(self) -> None:
        for drive in self.drives.values():
            await asyncio.to_thread(drive.unplug)

    async def replug(self) -> None:
        await self.start()

    async def stop(self) -> None:
        await self.unplug()

    def commanded(self) -> tuple[float, float]:
        """(linear m/s, angular rad/s) from the target velocities last written to the drives."""
        speeds = {}
        for side, drive in self.drives.items():
            target = 0 if drive.controlword & HALT else drive.target
            speeds[side] = target * self.signs[side] / self.counts_per_metre
        return (
            (speeds["left"] + speeds["right"]) / 2.0,
            (speeds["right"] - speeds["left"]) / self.track,
        )

    @property
    def stops(self) -> int:
        """Stops both drives have received (halt bit with a zero target)."""
        return min(self.left.stops, self.right.stops)

    def turn_wheels(self, left: float, right: float) -> None:
        """Turn the idle wheels by hand, ``left`` and ``right`` metres forwards.

        Both drives apply it on the same SYNC, a couple from now, so each pair of positions
        the base reports is a consistent one.
        """
        with self.left.lock, self.right.lock:
            at = max(self.left.syncs_seen, self.right.syncs_seen) + 2
            for side, metres in (("left", left), ("right", right)):
                counts = metres * self.signs[side] * self.counts_per_metre
                self.drives[side].nudges.append((at, counts))

    def pose(self) -> tuple[float, float, float]:
        self._advance()
        return self.x, self.y, self.theta

    def heading(self) -> float:
        """Compass degrees, clockwise from north (+y)."""
        return (90.0 - math.degrees(self.pose()[2])) % 360.0

    def _advance(self) -> None:
        # Reads the drives without their locks: a drive calls this holding its own lock.
        with self._lock:
            now = time.monotonic()
            dt, self._at = now - self._at, now
            wheels = {
                side: drive.velocity * self.signs[side] / self.counts_per_metre
                for side, drive in self.drives.items()
            }
            linear = (wheels["left"] + wheels["right"]) / 2.0
            angular = (wheels["right"] - wheels["left"]) / self.track
            self.x, self.y, self.theta = _arc(self.x, self.y, self.theta, linear, angular, dt)


class DbcBaseEmulator:
    """The example DBC's base: BaseCommand in, BaseFeedback and BaseStatus out at 20 Hz."""

    def __init__(
        self,
        *,
        channel: str | None = None,
        interface: str = "virtual",
        dbc=EXAMPLE_DBC,
        period: float = 0.05,
        command_timeout: float = 0.5,
        arena: float = 2.0,
    ) -> None:
        self.channel = _channel(interface, channel)
        self.interface = interface
        self.db = cantools.database.load_file(str(dbc))
        self.command_message = self.db.get_message_by_name("BaseCommand")
        self.feedback_message = self.db.get_message_by_name("BaseFeedback")
        self.status_message = self.db.get_message_by_name("BaseStatus")
        query = {
            "profile": "dbc",
            "heading": "BaseFeedback.Heading",
            "battery": "BaseStatus.Battery",
            "range": "BaseStatus.Range",
        }
        if str(dbc) != str(EXAMPLE_DBC):
            query["dbc"] = str(dbc)
        self.url = f"can://{interface}/{self.channel}?{urlencode(query)}"
        self.period, self.command_timeout, self.arena = period, command_timeout, arena
        self.commands: list[dict] = []  # decoded BaseCommand frames, with "raw" and "at"
        self.bad_frames = 0
        self.stops = 0
        self.speed = self.turn = 0.0  # last commanded
        self.mode = 0
        self.x = self.y = self.theta = 0.0  # facing east from the middle of the arena
        self.battery = 24.0
        self.bumper = False
        self.feedback_sent = 0
        self._commanded_at = -math.inf
        self._at = time.monotonic()
        self._lock = threading.Lock()
        self._bus: can.BusABC | None = None
        self._notifier: can.Notifier | None = None
        self._ticker: asyncio.Task | None = None

    async def start(self) -> None:
        self._bus = await asyncio.to_thread(can.Bus, interface=self.interface, channel=self.channel)
        self._notifier = can.Notifier(self._bus, [self._on_message], timeout=0.05)
        self._ticker = asyncio.get_running_loop().create_task(self._tick())

    async def unplug(self) -> None:
        if self._ticker is not None:
            self._ticker.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._ticker
            self._ticker = None
        notifier, bus, self._notifier, self._bus = self._notifier, self._bus, None, None
        if notifier is not None:
            await asyncio.to_thread(notifier.stop, 1.0)
        if bus is not None:
            bus.shutdown()

    async def replug(self) -> None:
        await self.start()

    async def stop(self) -> None:
        await self.unplug()

    def commanded(self) -> tuple[float, float]:
        return self.speed, self.turn

    def inject(self, frame: can.Message) -> None:
        """Put a frame on the bus, as if another node had sent it."""
        self._bus.send(frame)

    def heading(self) -> float:
        return (90.0 - math.degrees(self.theta)) % 360.0

    def range(self) -> float:
        """Distance ahead to the arena's square wall."""
        distances = []
        for direction, place in ((math.cos(self.theta), self.x), (math.sin(self.theta), self.y)):
            if direction > 1e-9:
                distances.append((self.arena - place) / direction)
            elif direction < -1e-9:
                distances.append((-self.arena - place) / direction)
        return min(distances)

    def _on_message(self, msg: can.Message) -> None:  # in the Notifier thread
        if msg.arbitration_id != self.command_message.frame_id or msg.is_extended_id:
            return
        try:
            values = self.command_message.decode(bytes(msg.data), decode_choices=False)
        except Exception:  # noqa: BLE001 - a frame the base cannot read is ignored
            self.bad_frames += 1
            return
        with self._lock:
            self._advance()
            self.speed, self.turn = values["LinearSpeed"], values["TurnRate"]
            self.mode = values["Mode"]
            self._commanded_at = time.monotonic()
            self.commands.append({**values, "raw": bytes(msg.data), "at": self._commanded_at})
            if self.speed == 0 and self.turn == 0:
                self.stops += 1

    def _moving(self) -> tuple[float, float]:
        fresh = time.monotonic() - self._commanded_at <= self.command_timeout
        if fresh and self.mode == 1:
            return self.speed, self.turn
        return 0.0, 0.0

    def _advance(self) -> None:
        now = time.monotonic()
        dt, self._at = now - self._at, now
        self.x, self.y, self.theta = _arc(self.x, self.y, self.theta, *self._moving(), dt)

    async def _tick(self) -> None:
        while True:
            await asyncio.sleep(self.period)
            with self._lock:
                self._advance()
                speed, turn = self._moving()
                feedback = {"Speed": speed, "TurnRate": turn, "Heading": self.heading()}
                status = {"Battery": self.battery, "Range": self.range(), "Bumper": self.bumper}
            for message, values in ((self.feedback_message, feedback),
                                    (self.status_message, status)):  # fmt: skip
                data = message.encode(_in_range(message, values))
                self._bus.send(can.Message(arbitration_id=message.frame_id, data=data,
                                           is_extended_id=False))  # fmt: skip
            self.feedback_sent += 1


def _in_range(message, values: dict) -> dict:
    result = {}
    for signal in message.signals:
        value = float(values[signal.name])
        result[signal.name] = min(signal.maximum, max(signal.minimum, value))
    return result


def _arc(x, y, theta, linear, angular, dt):
    """Pose after ``dt`` s at constant speeds, along the arc (straight when not turning)."""
    if abs(angular) < 1e-12:
        return x + linear * dt * math.cos(theta), y + linear * dt * math.sin(theta), theta
    radius = linear / angular
    turned = theta + angular * dt
    return (
        x + radius * (math.sin(turned) - math.sin(theta)),
        y - radius * (math.cos(turned) - math.cos(theta)),
        math.remainder(turned, math.tau),
    )
