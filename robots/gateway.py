"""A robot agent's MAVLink gateway: the router that shares a mavlink:// robot's vehicle link.

Its endpoints: the vehicle link (the robot's URL), the RHAL driver (an endpoint inside this
process), the robot's GatewayEndpoint rows (by default one for ground stations and one for
programs, whose port reaches runs as ``ROBOT_MAVLINK``), and one endpoint per run: the UDP
socket at that port in the run's own network namespace (``serve_run``), which no other run or
robot reaches. Rows are applied at start and on ``gateway.reload``; ``gateway.stats`` answers
with every endpoint's live stats.

Who may command the vehicle (gateway.control tells a command from a read): a run, while it
holds the robot's control lease (its first command takes a free one, as drive() does; a
refused COMMAND_LONG/INT is answered DENIED), never after an emergency stop; a ground
station as its row's ``control`` says: ``always`` (a pilot must be able to take over),
``lease`` (while no program holds the robot, and not after an emergency stop) or ``never``.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time

from channels.db import database_sync_to_async
from django.conf import settings

from gateway import specs
from gateway.control import commands_vehicle, denied_ack
from gateway.local import RouterLink, open_local_link
from gateway.router import BoundUdpEndpoint, Endpoint, Router, TcpServerEndpoint
from gateway.tlog import TlogRecorder
from robots.lease import Holder, LeaseHeld
from robots.models import GatewayEndpoint, Robot

log = logging.getLogger(__name__)

VEHICLE_WAIT = 3.0  # s the driver waits for a serial or TCP vehicle link being opened


class Gateway:
    def __init__(self, agent):
        self.agent = agent
        self.router: Router | None = None
        self.vehicle: Endpoint | None = None
        self.vehicle_spec: dict | None = None
        self.vehicle_error = ""
        self.running: dict[int, tuple[dict, Endpoint]] = {}  # row id -> (spec, endpoint)
        self.failed: dict[int, tuple[dict, str]] = {}  # row id -> (spec, why it did not start)
        self.roles: dict[int, str] = {}
        self.link: RouterLink | None = None  # the driver's: it holds one at a time
        self._ticker: asyncio.Task | None = None
        self._applying = asyncio.Lock()
        self.recorder: TlogRecorder | None = None
        self.handlers = {
            "gateway.stats": self._stats_asked,
            "gateway.reload": self._reload_asked,
            "gateway.record": self._record_asked,
        }

    # -- the driver --------------------------------------------------------------------------

    async def attach(self, driver) -> None:
        """Before ``driver`` opens: route its link if it is a MAVLink one, else no router."""
        if not hasattr(driver, "vehicle_link"):
            await self.close()
            return
        if self.router is None:
            self.router = Router()
            self._ticker = asyncio.create_task(self.router.ticking(), name="gateway ticks")
            await self._seed_defaults()
            await self.reload()
        await self._use_vehicle(driver.vehicle_link())
        driver.link_factory = self.open_driver_link

    async def _use_vehicle(self, spec: dict) -> None:
        if spec == self.vehicle_spec and self.vehicle is not None:
            return
        if self.vehicle is not None:
            await self.router.remove(self.vehicle)
        self.vehicle, self.vehicle_spec, self.vehicle_error = None, spec, ""
        endpoint = specs.build(spec, name="vehicle")
        if hasattr(endpoint, "lost_listeners"):
            endpoint.lost_listeners.append(self._vehicle_lost)
        try:
            self.vehicle = await self.router.add(endpoint)
        except OSError as exc:
            self.vehicle_error = str(exc)
            log.error("agent %s: vehicle link %s: %s", self.agent.name, endpoint.name, exc)

    async def open_driver_link(self) -> RouterLink:
        """The driver's link for one connection: an endpoint of the router."""
        vehicle = self.vehicle
        if vehicle is None:
            raise ConnectionError(f"the vehicle link cannot be opened: {self.vehicle_error}")
        connected = getattr(vehicle, "connected", None)
        if connected is not None and not connected.is_set():
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(connected.wait(), VEHICLE_WAIT)
            if not connected.is_set():
                why = vehicle.last_error or "not connected yet"
                raise ConnectionError(f"the vehicle link {vehicle.name} is down: {why}")
        self.link = await open_local_link(self.router)
        return self.link

    def _vehicle_lost(self, why: str) -> None:
        # The driver hears it now rather than after its HEARTBEAT timeout.
        if self.link is not None:
            self.link.endpoint.abort(f"the vehicle link {self.vehicle.name} was lost: {why}")

    # -- the rows ----------------------------------------------------------------------------

    async def _seed_defaults(self) -> None:
        await database_sync_to_async(seed_defaults)(self.agent.name)

    async def reload(self) -> None:
        """Make the running endpoints what the rows say: start new, restart changed, stop gone."""
        rows = await database_sync_to_async(_rows_of)(self.agent.name)
        async with self._applying:
            for row_id in set(self.running) - set(rows):
                await self.router.remove(self.running.pop(row_id)[1])
            for row_id in set(self.failed) - set(rows):
                del self.failed[row_id]
            for row_id, (role, spec) in rows.items():
                self.roles[row_id] = role
                if row_id in self.running and self.running[row_id][0] == spec:
                    continue
                if row_id in self.failed and self.failed[row_id][0] == spec:
                    continue
                await self._start_row(row_id, spec)

    async def _start_row(self, row_id: int, spec: dict) -> None:
        if row_id in self.running:
            await self.router.remove(self.running.pop(row_id)[1])
        self.failed.pop(row_id, None)
        try:
            endpoint = specs.build(spec, name=specs.describe(spec))
            endpoint.guard = self._station_guard(spec["control"], endpoint)
            await self.router.add(endpoint)
        except (OSError, ValueError) as exc:  # in use, no such host: this endpoint alone
            self.failed[row_id] = (spec, str(exc) or type(exc).__name__)
            log.warning("agent %s: endpoint %s: %s", self.agent.name, row_id, exc)
            return
        self.running[row_id] = (spec, endpoint)

    # -- who commands the vehicle ---------------------------------------------------------------

    def _station_guard(self, control: str, endpoint: Endpoint):
        """A row's guard: its commands pass as ``control`` says, and are noted (the robot's
        page shows a ground station commanding)."""
        lease = self.agent.lease

        def guard(frame, msgid, sender, target) -> bool:
            if not commands_vehicle(frame, msgid):
                return True
            if control == "never" or (control == "lease" and lease.holder is not None
                                      and lease.holder.kind in ("run", "estop")):  # fmt: skip
                _answer_denied(endpoint, frame, msgid, sender, target)
                return False
            endpoint.commanded_at = time.monotonic()
            return True

        return guard

    async def serve_run(self, sock) -> RunLink:
        """A run's own endpoint, on the UDP socket its box bound at ROBOT_MAVLINK's port (a
        box is made before its run: RunLink.belongs_to names the run when it begins)."""
        link = RunLink(self, sock)
        if self.router is None:
            sock.close()  # not a MAVLink robot (any more): nothing to reach
            return link
        await self.router.add(link.endpoint)
        return link

    # -- what others ask -----------------------------------------------------------------------

    def program_env(self) -> dict[str, str]:
        """``ROBOT_MAVLINK``: the programs' endpoint, as pymavlink's connection string."""
        for row_id, (_, endpoint) in self.running.items():
            if self.roles.get(row_id) == "programs" and getattr(endpoint, "bound", None):
                host, port = endpoint.bound[:2]
                if host in ("0.0.0.0", "::"):
                    host = "127.0.0.1"
                return {"ROBOT_MAVLINK": f"udpout:{host}:{port}", "MAVLINK20": "1"}
        return {}

    def stats(self) -> dict:
        if self.router is None:
            return {"active": False, "endpoints": {}, "recording": None}
        found: dict = {}
        if self.vehicle is not None:
            found["vehicle"] = self.vehicle.as_dict()
        else:
            found["vehicle"] = {"status": "error", "error": self.vehicle_error}
        found["vehicle"]["spec"] = self.vehicle_spec
        if self.link is not None and not self.link.endpoint.closed:
            found["robot"] = self.link.endpoint.as_dict()
        for row_id, (_, endpoint) in self.running.items():
            found[row_id] = _with_clients(endpoint)
        for row_id, (_, why) in self.failed.items():
            found[row_id] = {"status": "error", "error": why}
        recording = self.recorder.as_dict() if self.recorder else None
        return {"active": True, "endpoints": found, "recording": recording}

    async def _stats_asked(self, message: dict) -> None:
        await self.agent.reply(message, self.stats())

    async def _reload_asked(self, message: dict) -> None:
        if self.router is not None:
            await self.reload()
        await self.agent.reply(message, self.stats())

    # -- recording ------------------------------------------------------------------------------

    async def record(self, on: bool) -> None:
        """Start writing every routed frame to a new .tlog in recordings_dir(), or stop."""
        if on and self.recorder is None and self.router is not None:
            folder = recordings_dir(self.agent.name)
            folder.mkdir(parents=True, exist_ok=True)
            stamp = time.strftime("%Y%m%d-%H%M%S")
            recorder = TlogRecorder(folder / f"{self.agent.name}-{stamp}.tlog")
            await asyncio.to_thread(recorder.start)
            self.router.taps.append(recorder)
            self.recorder = recorder
        elif not on and self.recorder is not None:
            recorder, self.recorder = self.recorder, None
            with contextlib.suppress(ValueError):
                self.router.taps.remove(recorder)
            await asyncio.to_thread(recorder.close)  # a slow disk must not hold the loop

    async def _record_asked(self, message: dict) -> None:
        try:
            await self.record(bool(message.get("on")))
        except OSError as exc:
            await self.agent.reply(message, {"error": f"cannot record: {exc}"})
            return
        await self.agent.reply(message, self.stats())

    async def close(self) -> None:
        await self.record(False)
        if self._ticker is not None:
            self._ticker.cancel()
            self._ticker = None
        if self.router is not None:
            await self.router.close()
        self.router, self.vehicle, self.vehicle_spec = None, None, None
        self.running.clear()
        self.failed.clear()
        self.link = None


class RunLink:
    """One run's MAVLink endpoint: its reads always pass, its commands only while its run
    holds the robot's control lease."""

    def __init__(self, gateway: Gateway, sock):
        self.gateway = gateway
        self.run_id: int | None = None  # none yet: a box made ahead, waiting for its run
        self.user = ""
        self.endpoint = BoundUdpEndpoint(name="a run (not begun)", sock=sock, guard=self._guard)

    def belongs_to(self, run_id: int, user: str) -> None:
        self.run_id, self.user = run_id, user
        self.endpoint.name = f"run #{run_id}"

    def _guard(self, frame, msgid, sender, target) -> bool:
        if not commands_vehicle(frame, msgid) or self._may_command():
            return True
        _answer_denied(self.endpoint, frame, msgid, sender, target)
        return False

    def _may_command(self) -> bool:
        agent = self.gateway.agent
        active = agent.runs.get(self.run_id)
        if active is None or agent.tokens.get(active.token) is not active:
            return False  # not begun, ended, or emergency-stopped
        if not active.confirmed_now():
            return False  # its claim is not answered yet (or was a no)
        if active.process.stop_requested:
            return False  # asked to stop: it may clean up, not command
        try:  # the first command takes a free lease, as drive() does
            agent.take_lease(Holder("run", self.run_id, self.user))
        except LeaseHeld:
            return False
        return True

    async def close(self) -> None:
        router = self.gateway.router
        if router is not None and self.endpoint.id in router.endpoints:
            await router.remove(self.endpoint)
        else:
            await self.endpoint.stop()


def _answer_denied(endpoint: Endpoint, frame, msgid, sender, target) -> None:
    """A refused command that waits for an answer (COMMAND_LONG/INT) is told DENIED."""
    ack = denied_ack(frame, msgid, sender, target)
    if ack is not None:
        with contextlib.suppress(OSError):
            endpoint.send([ack])


def recordings_dir(robot_name: str):
    return settings.DATA_DIR / "recordings" / robot_name


def _with_clients(endpoint: Endpoint) -> dict:
    row = endpoint.as_dict()
    if isinstance(endpoint, TcpServerEndpoint):
        clients = [client.as_dict() for client in endpoint.clients]
        row["clients"] = clients
        for key in row["stats"]:
            row["stats"][key] = sum(client["stats"][key] for client in clients)
        for key in row["rates"]:
            row["rates"][key] = round(sum(client["rates"][key] for client in clients), 1)
        row["systems"] = [system for client in clients for system in client["systems"]]
    return row


def _rows_of(robot_name: str) -> dict[int, tuple[str, dict]]:
    rows = GatewayEndpoint.objects.filter(robot__name=robot_name)
    found = {}
    for row in rows:
        try:
            found[row.pk] = (row.role, specs.check(row.spec()))
        except ValueError:
            found[row.pk] = (row.role, row.spec())  # fails to build: shown as its error
    return found


def seed_defaults(robot_name: str) -> None:
    """A MAVLink robot's first endpoints: ground stations and programs (once: a user who
    deletes them does not get them back)."""
    robot = Robot.objects.get(name=robot_name)
    if robot.gateway_seeded:
        return
    defaults = settings.GATEWAY_DEFAULTS
    for role in ("gcs", "programs"):
        spec = specs.check({"type": "udp", "mode": "server", "address": defaults[role]})
        row = GatewayEndpoint(robot=robot, role=role)
        row.set_spec(spec)
        row.save()
    Robot.objects.filter(pk=robot.pk).update(gateway_seeded=True)
