"""The robot agent: the only process that owns a robot's hardware and its programs.

It takes commands from the channel layer (run.start, run.stop, robot.estop, robot.sensors,
robot.state, hand driving and the control lease, robot.reconfigure, and through `handlers`
the camera hub's camera.*), serves the Robot API socket to the programs it launched, and
publishes their output, the run states and the robot's telemetry to groups. Embedded mode runs
one agent per robot inside the web server process (AgentManager); fleet mode runs
`robotide agent NAME`.
"""

import asyncio
import contextlib
import itertools
import logging
import os
import secrets
import shutil
import socket
import tempfile
import time
import zlib
from collections.abc import Awaitable, Callable
from dataclasses import dataclass, field
from datetime import timedelta
from functools import partial
from pathlib import Path
from signal import SIGKILL

from channels.db import database_sync_to_async
from channels.layers import get_channel_layer
from django.conf import settings
from django.utils import timezone

import rhal
from programs import blocks_worker
from programs.blocks import failing
from programs.languages import CLIENTS_DIR, LanguageUnavailable, get_language
from programs.models import Run
from robots import check_sims, debugger, messages, rpc, sims
from robots.bridges import Bridges
from robots.bus import RUNS_GROUP, run_group
from robots.camera import CameraHub
from robots.gateway import Gateway, RunLink
from robots.lease import ControlLease, Holder, LeaseHeld
from robots.models import Robot, RobotStop, agent_channel, manager_channel, robot_group
from robots.readings import age_shows
from robots.robot_api import RobotApi
from robots.run_queue import RunQueue
from robots.sim_view import PoseStream, sim_info
from robots.start_pose import StartPose
from runbox import SYSTEM_PATH, cgroups, launcher, seccomp, timescale
from runbox.ahead import Ahead, discard
from runbox.box import Launch, Listener, make_box
from runbox.isolation import InForce, IsolationUnavailable, Policy, run_uid
from runbox.relays import relay_to_host
from runbox.share import Share, release_parent, runs_cgroups
from runbox.supervisor import RunProcess
from runbox.watch import RunWatch, signal_account
from runlogs.writer import QuotaRunProcess
from worlds.resolve import driver_options as world_driver_options

log = logging.getLogger(__name__)

MB = 1024 * 1024
# The outcome of a run whose box was made but which had been marked lost or failed meanwhile
# (its state in the database stays as it is).
NOT_OURS = "not started"
# Inside a run's own network namespace the Robot API's TCP side is always here.
ROBOT_API_PORT = 7010
TELEMETRY_INTERVAL = 0.25
SHOWS_SNAPSHOT_EVERY = 4  # telemetry ticks
RETRY_DELAY = 1.0
LINK_RETRY_MAX = 30.0  # seconds between tries to open a robot that is away
# A hand drive lasts this long unless the browser repeats it: a page that hangs, loses its
# network or is closed without a goodbye cannot leave the robot driving.
TELEOP_DEADMAN = 0.4
DRIVER_BACK_TIMEOUT = 2.0  # s an emergency stop waits for a bridge to give the device back
# How long a run this agent gave a box is remembered, so that its start asked again (by the
# untaken scan and its run.start both, or a run.start delivered twice) is dropped: longer than
# a channel message lives (60 s) and than the scan looks back (AGENT_START_TIMEOUT).
STARTED_REMEMBERED = 300.0


@dataclass(frozen=True)
class BoxKind:
    """What a run's box is made for: one made ahead for other settings is not used."""

    isolation: InForce
    limits: launcher.Limits
    services: tuple[str, ...]  # "tcp:7010", "udp:14551": what its 127.0.0.1 offers
    grace: float
    mavlink: str = ""  # the service of these that is the run's own MAVLink endpoint


@dataclass
class ActiveRun:
    run_id: int
    token: str
    process: RunProcess
    watcher: asyncio.Task | None = field(default=None, repr=False)
    user: str = ""  # who started it, as the control lease names it
    # Its claim (Run.claim): True once it is this agent's to run. The program starts while
    # it is asked; nothing of the robot is its until the answer is yes.
    claimed: asyncio.Future | None = field(default=None, repr=False)
    # A check sim's run: its trace, recorded from its start pose (robots.check_sims).
    trace: "check_sims.TraceRecorder | None" = field(default=None, repr=False)
    limit: asyncio.Task | None = field(default=None, repr=False)  # its time limit's watch
    # A run under the debugger (robots.debugger): its breakpoints, watches and pauses.
    debugger: "debugger.RunDebugger | None" = field(default=None, repr=False)

    def confirmed_now(self) -> bool:
        """Its claim has been answered yes."""
        claim = self.claimed
        if claim is None:
            return True
        return claim.done() and not claim.cancelled() and not claim.exception() and claim.result()

    async def confirmed(self) -> bool:
        """Its claim's answer, waited for (a claim that failed is a no)."""
        if self.claimed is not None and not self.claimed.done():
            try:
                await asyncio.shield(self.claimed)
            except asyncio.CancelledError:
                if not self.claimed.cancelled():
                    raise  # the waiter's own cancellation, not the claim's
            except Exception:
                pass
        return self.confirmed_now()

    def signed_in(self) -> None:
        """Its program signed in on the Robot API (robots.robot_api's auth): a check run's
        trace and time limit count from its first sign-in, not its launch (TraceRecorder)."""
        if self.trace is not None:
            self.trace.signed_in()

    def disowned(self) -> bool:
        """Its claim was answered no: it was lost or failed meanwhile, its end is not ours
        to record (a claim that could not be asked is no answer)."""
        claim = self.claimed
        if claim is None or not claim.done() or claim.cancelled() or claim.exception():
            return False
        return not claim.result()


class RobotAgent:
    def __init__(self, name: str):
        self.name = name
        self.channel = agent_channel(name)
        self.group = robot_group(name)
        self.runs: dict[int, ActiveRun] = {}
        self.tokens: dict[str, ActiveRun] = {}
        self.shows: dict[str, dict] = {}
        # Whose drive() the robot follows now: a run id, or a browser's channel name.
        self.motion_owner: int | str | None = None
        self._deadman: asyncio.Task | None = None
        self.lease = ControlLease()
        self.cancelled: set[int] = set()  # stopped before their start was handled
        self.estops = 0  # emergency stops so far: a drive on its way sees one come
        self._shows_snapshot_due = True
        self.layer = get_channel_layer()
        # This robotide's (its data folder's) runs of this robot, among all on the machine.
        # A dot ends the robot's name (a slug has none): robot "pi" sweeping its leftovers at
        # its start must not take robot "pi-2"'s live runs for its own.
        instance = zlib.crc32(str(settings.DATA_DIR).encode())
        self.cgroup_prefix = f"{instance:08x}-{name}."
        self.driver: rhal.Robot | None = None
        self.link_error: str | None = None
        self.world_error: rhal.RhalError | None = None  # its sim's world not to be had
        self.api = RobotApi(self)
        # A short private folder: Unix socket paths are limited to 107 bytes.
        self.socket_dir = Path(tempfile.mkdtemp(prefix="robotide-"))
        self.server = rpc.RobotApiServer(
            self.api.handle,
            unix_path=self.socket_dir / "api.sock",
            quick=self.api.quick,
            closed=self.api.forget,
        )
        self.ready = asyncio.Event()
        self._opening = asyncio.Lock()
        # More message kinds -> coroutine(message), for parts that live in modules of their own.
        self.handlers: dict[str, Callable[[dict], Awaitable[None]]] = {}
        self.camera = CameraHub(self)
        self.handlers.update(self.camera.handlers)
        self.gateway = Gateway(self)
        self.handlers.update(self.gateway.handlers)
        self.bridges = Bridges(self)
        self.handlers.update(self.bridges.handlers)
        self.queue = RunQueue(self)  # runs waiting their turn while the robot is busy
        self.boxes = Ahead(self._make_box, self.cgroup_prefix)  # one made ahead of its run
        self._shutting_down = False
        self.handlers.update(self.queue.handlers)
        self.handlers.update(self.api.host.handlers)  # robot.hear: the "Say to the robot" box
        self.starts = StartPose(self)  # robot.reset; where each run starts
        self.handlers.update(self.starts.handlers)
        self.poses = PoseStream(self)  # a sim's pose for pages that draw it (robot.world)
        self.handlers.update(self.poses.handlers)
        self.handlers.update(debugger.channel_handlers(self))  # run.debug: the page's commands
        self.lent_to: str | None = None  # a serial bridge client has the robot's device
        self._driver_back = asyncio.Event()  # set while the driver has its device
        self._outbox: asyncio.Queue = asyncio.Queue()
        self._tasks: list[asyncio.Task] = []
        self._starting: set[asyncio.Task] = set()
        # One start per run (see start_run): the runs whose start is under way, and those
        # given a box lately (run id -> loop time).
        self._taking: set[int] = set()
        self._boxed: dict[int, float] = {}
        self._last_press = 0  # the record (RobotStop id) of the last press heard
        self.checking, self.check_time_limit = False, None  # a check sim's (_load_robot)

    # -- life cycle -----------------------------------------------------------------------

    async def serve(self) -> None:
        """Run until cancelled; always shuts down its programs and robot on the way out."""
        try:
            await self.start()
            await asyncio.gather(*self._tasks)
        finally:
            await self.shutdown()

    async def start(self) -> None:
        robot = await self._load_robot()
        self.driver, self.world_error = await self._connect(robot)
        await self.gateway.attach(self.driver)
        await self.open_robot()
        self.units = flat_units(self.driver.capabilities().get("sensors", {}))
        pressed = await database_sync_to_async(RobotStop.pressed)(robot.pk)
        if pressed is not None:  # pressed while this agent was away: still in force
            self.lease.estop(pressed.username)
            self._last_press = pressed.pk
            self.queue.held = True
        lost = await database_sync_to_async(Run.mark_lost)(self.name)
        for run_id in lost:
            end_leftovers(run_id)
            self.publish(run_group(run_id), {"type": "run.state", "run_id": run_id})
        if self.cgroups.available:  # runs of a dead agent, lost or not, end with their cgroups
            await asyncio.to_thread(cgroups.sweep, self.cgroups, self.cgroup_prefix)
        await self.bridges.reload()
        self.api_address = await self.server.start()
        # Run accounts reach the socket; the token, not the file mode, decides who is served.
        self.socket_dir.chmod(0o711)
        self.server.unix_path.chmod(0o666)
        self._tasks = [
            asyncio.create_task(self._receive_loop(), name=f"{self.name}-receive"),
            asyncio.create_task(self._publish_loop(), name=f"{self.name}-publish"),
            asyncio.create_task(self._telemetry_loop(), name=f"{self.name}-telemetry"),
            asyncio.create_task(self.poses.serve(), name=f"{self.name}-poses"),
            asyncio.create_task(self._keep_robot_open(), name=f"{self.name}-link"),
            asyncio.create_task(self._heartbeat_loop(), name=f"{self.name}-heartbeat"),
            asyncio.create_task(self.queue.serve(), name=f"{self.name}-queue"),
        ]
        self.ready.set()
        await self._take_untaken()
        self._box_ahead()
        log.info("agent %s: %s, Robot API on %s", self.name, robot.url, self.api_address)

    async def _take_untaken(self) -> None:
        """Runs asked of this robot before its agent listened (a robot added and run at
        once; fleet mode's channel layer keeps nothing for whoever does not listen yet):
        started from the database. The in-memory layer keeps their run.start and hands it
        over as well: start_run drops whichever comes second."""
        for message in await database_sync_to_async(untaken_runs)(self.name):
            task = asyncio.create_task(self.start_run(message))
            self._starting.add(task)
            task.add_done_callback(self._starting.discard)

    async def _load_robot(self) -> Robot:
        """The robot's row, and what it says about runs here."""
        robot = await database_sync_to_async(Robot.objects.get)(name=self.name)
        self.limits = robot.run_limits(settings.RUN_DEFAULTS)
        self.start_each_run = robot.settings.get("start_each_run") is True  # robots.start_pose
        # A check sim (robots.check_sims): one run, its trace recorded, then it is removed.
        self.checking = robot.checking
        self.check_time_limit = check_sims.time_limit_of(robot.settings)
        # Off the event loop: the first look may start a process and compile the seccomp filter.
        self.isolation, self.isolation_error = await asyncio.to_thread(resolve_isolation, robot)
        if self.isolation is not None:  # runs' cgroups inside this robotide's parent, if any
            self.cgroups = self.isolation.cgroups
        else:
            self.cgroups = await asyncio.to_thread(cgroups.detect)
        await database_sync_to_async(Robot.objects.filter(name=self.name).update)(
            isolation=self.isolation.describe(launcher.Limits.from_settings(self.limits))
            if self.isolation
            else self.isolation_error
        )
        return robot

    async def reconfigure(self) -> None:
        """Reopen the robot as its row says now (a new URL or new driver options).

        Motion stops; programs keep running and see the robot again once it is open.
        """
        robot = await self._load_robot()
        await self.boxes.close()  # made for the settings of old
        self._box_ahead()
        try:
            driver, world_error = await self._connect(robot)
        except (TypeError, ValueError, rhal.RhalError) as exc:  # the edit paths check first
            log.error("agent %s: new settings refused, keeping the old: %s", self.name, exc)
            return
        old, self.driver, self.motion_owner = self.driver, driver, None
        self.world_error = world_error
        with contextlib.suppress(Exception):
            await old.close()  # stops the motors first
        await self.gateway.attach(driver)
        self.units = flat_units(driver.capabilities().get("sensors", {}))
        self.link_error = None
        await self.open_robot()
        log.info("agent %s: reopened as %s", self.name, robot.url)

    async def _connect(self, robot: Robot) -> tuple[rhal.Robot, rhal.RhalError | None]:
        """Its driver, a sim's stored world resolved to its document (worlds.resolve), and
        why it must not open (a world unknown, or its owner's no longer), or None."""
        options, world_error = await database_sync_to_async(world_driver_options)(robot)
        return rhal.connect(robot.url, **options), world_error

    async def open_robot(self) -> bool:
        """Open the robot's link; a robot away (unplugged, not yet on) is no reason to stop
        serving: its agent answers with the reason and tries again."""
        async with self._opening:  # the link keeper and a reconfigure may both try
            driver = self.driver
            if driver.is_open:
                return True
            if self.lent_to is not None:
                return False
            if self.world_error is not None:  # a sim opens in its own world or not at all
                return self._open_failed(self.world_error)
            try:
                await driver.open()
            except rhal.RhalError as exc:
                return self._open_failed(exc)
        self.link_error = None
        return True

    async def lend_driver(self, to: str) -> None:
        """A serial bridge client takes the robot's device: the driver lets go of it."""
        self.lent_to = to
        self._driver_back.clear()
        async with self._opening:
            try:
                await self.driver.close()  # stops the motors first
            except Exception:  # a robot already gone: its device is free all the same
                log.exception("agent %s: closing the robot for the bridge failed", self.name)
        self.link_error = f"the robot's serial port is lent to {to}"

    async def take_driver_back(self) -> None:
        self.lent_to = None
        self.link_error = None
        try:
            await self.open_robot()
        finally:
            self._driver_back.set()

    def _open_failed(self, exc: rhal.RhalError) -> bool:
        if str(exc) != self.link_error:
            log.error("agent %s: cannot open the robot: %s", self.name, exc)
        self.link_error = str(exc)
        return False

    async def _keep_robot_open(self) -> None:
        delay = 1.0
        while True:
            await asyncio.sleep(delay)
            if self.driver.is_open or await self.open_robot():
                delay = 1.0
            else:
                delay = min(delay * 2, LINK_RETRY_MAX)

    async def shutdown(self) -> None:
        self._shutting_down = True  # runs ending now make no box ahead: nobody would close it
        await self.queue.close()  # nothing more starts from the queue
        await self.boxes.close()
        if self._starting:  # let starts under way finish, so their programs are stopped too
            await asyncio.wait(self._starting, timeout=5)
        for active in list(self.runs.values()):
            active.process.stop("robot agent shutting down")
        watchers = [a.watcher for a in self.runs.values() if a.watcher]
        if watchers:
            await asyncio.wait(watchers, timeout=settings.RUN_DEFAULTS["stop_grace_seconds"] + 2)
        if getattr(self, "cgroups", None) is not None:  # the last agent leaves no parent behind
            await asyncio.to_thread(release_parent, self.cgroups)
        await self.camera.close()
        await self.server.close()
        shutil.rmtree(self.socket_dir, ignore_errors=True)
        if self.driver is not None:
            with contextlib.suppress(Exception):
                await self.driver.stop()
            try:
                await self.driver.close()
            except Exception:  # the rest of the shutdown must happen all the same
                log.exception("agent %s: closing the robot failed", self.name)
        with contextlib.suppress(Exception):
            await self.gateway.close()  # after the driver: it disarms through the router
        with contextlib.suppress(Exception):
            await self.bridges.close()
        for task in self._tasks:
            task.cancel()
        # Deliver what is queued (the final run states) before going away.
        while not self._outbox.empty():
            group, message = self._outbox.get_nowait()
            with contextlib.suppress(Exception):
                await self.layer.group_send(group, message)

    # -- commands from the web tier ---------------------------------------------------------

    async def _receive_loop(self) -> None:
        while True:
            try:
                message = await self.layer.receive(self.channel)
            except Exception:  # e.g. Redis restarting: keep serving the programs, retry
                log.exception("agent %s: channel layer receive failed; retrying", self.name)
                await asyncio.sleep(RETRY_DELAY)
                continue
            try:
                await self.dispatch(message)
            except rhal.RhalError as exc:  # the robot away: say why, at once
                why = f"not connected ({self.link_error})" if self.link_error else str(exc)
                await self.reply(message, {"error": f"robot {self.name}: {why}"})
            except Exception:
                log.exception("agent %s: %s failed", self.name, message.get("type"))
                await self.reply(message, {"error": f"agent failed on {message.get('type')}"})

    async def dispatch(self, message: dict) -> None:
        if (why := messages.check(message)) is not None:  # fleet mode: Redis is open to others
            messages.log_refused(self.name, why)
            if reply_to := messages.reply_channel(message):
                with contextlib.suppress(Exception):
                    refused = {"type": "agent.reply", "error": f"message refused: {why}"}
                    await self.layer.send(reply_to, refused)
            return
        kind = message.get("type")
        if kind == "run.start":
            # In a task: a stop or an emergency stop must not wait behind a program's start.
            task = asyncio.create_task(self.start_run(message))
            self._starting.add(task)
            task.add_done_callback(self._starting.discard)
        elif kind == "run.stop":
            if not self.stop_run(message["run_id"], "stopped by user"):
                self.cancelled.add(message["run_id"])
                self.queue.cancel(message["run_id"])  # if it waits in line
        elif kind == "robot.estop":
            self._last_press = max(self._last_press, message.get("record") or 0)
            ended = await self.estop(message.get("by", ""))
            await self.reply(message, {"stopped": len(ended), "runs": ended})
        elif kind == "robot.resume":
            resumed = self.resume_from(message.get("after")) and await self.resume()
            await self.reply(message, {"resumed": resumed})
        elif kind == "robot.sensors":
            await self.reply(message, {"sensors": await self.driver.sensors()})
        elif kind == "robot.state":
            capabilities = self.driver.capabilities()
            camera = capabilities.get("camera") is not None
            state = {"sensors": await self.readings(), "units": self.units, "camera": camera}
            state["drive"] = capabilities["drive"]
            state["model"] = capabilities.get("model")  # a driver's robot model, if it has one
            state["sim"] = sim_info(self.driver)  # pages draw a sim themselves
            state["lease"] = self.lease.holder.as_dict() if self.lease.holder else None
            state["heard"] = self.api.host.last_heard  # what the last listen() heard
            state["resettable"] = self.starts.can_reset()  # a Reset button (robots.reset)
            await self.reply(message, {**state, "shows": self.shows})
        elif kind == "robot.teleop":
            holder = Holder("teleop", message["owner"], message.get("user", "?"))
            await self.teleop(holder, message["linear"], message["angular"])
        elif kind == "robot.teleop_stop":
            await self.stop_motion_of(message["owner"])
        elif kind == "robot.release":
            await self.release(message["owner"])
        elif kind == "robot.take_control":
            await self.take_control(Holder("teleop", message["owner"], message["user"]))
        elif kind == "robot.reconfigure":
            await self.reconfigure()
        elif kind in self.handlers:
            await self.handlers[kind](message)
        else:
            log.warning("agent %s: unknown message %r", self.name, kind)

    async def reply(self, message: dict, data: dict) -> None:
        if message.get("reply_to"):
            await self.layer.send(message["reply_to"], {"type": "agent.reply", **data})

    # -- runs -------------------------------------------------------------------------------

    async def start_run(self, message: dict) -> None:
        """In a task of its own, so whatever goes wrong is logged and ends the run.

        Once per run, whatever order its starts come in: a second start would make a second
        box, and its program would run beside the first until the claim said no."""
        run_id = message["run_id"]
        if not self._take(run_id):
            log.info("agent %s: run %s is being started or ran here: not again", self.name, run_id)
            return
        try:
            await self._start_run(message)
        except Exception:
            log.exception("agent %s: run %s could not start", self.name, run_id)
            with contextlib.suppress(Exception):
                reason = "could not start: internal error (see the server's log)"
                await self._end_run(run_id, "failed", None, reason)
        finally:
            self._taking.discard(run_id)

    def _take(self, run_id: int) -> bool:
        """The run's start is this one's, before anything is awaited: False if another start
        of it is under way, or it was given a box here lately. A run that went to the queue
        got no box: the queue's start of it, later, is its one start."""
        if run_id in self._taking or run_id in self.runs or run_id in self._boxed:
            return False
        self._taking.add(run_id)
        return True

    def _boxing(self, run_id: int) -> None:
        """The run gets its box now: remembered for a while, so no other start makes one."""
        now = asyncio.get_running_loop().time()
        for old, when in list(self._boxed.items()):  # oldest first
            if now - when < STARTED_REMEMBERED:
                break
            del self._boxed[old]
        self._boxed[run_id] = now

    async def _start_run(self, message: dict) -> None:
        run_id = message["run_id"]
        if await self.queue.waits(message):  # the robot is busy: it waits its turn
            return
        # Only a run still waiting to start: not one marked lost or failed meanwhile. Asked
        # once its box has the program, in the write that marks it running: one database trip,
        # not two, while its first lines go out. The program does not wait for the answer;
        # its token and its MAVLink endpoint do (ActiveRun.confirmed), and a no ends it.
        claimed = asyncio.get_running_loop().create_future()
        try:
            active = await self._launch(run_id, message, claimed, partial(self._may_start, run_id))
        except (
            LanguageUnavailable, launcher.LauncherUnavailable, IsolationUnavailable,
            ValueError, OSError,
        ) as exc:  # fmt: skip
            if await database_sync_to_async(Run.claim)(run_id):
                await self._end_run(run_id, "failed", None, f"could not start: {exc}")
            return
        await self._claim(active)
        if not await active.confirmed():
            if claimed.exception() is not None:
                log.error("agent %s: run %s could not be claimed", self.name, run_id,
                          exc_info=claimed.exception())  # fmt: skip
                active.process.kill("could not start: internal error (see the server's log)",
                                    "failed")  # fmt: skip
            else:
                active.process.kill("it no longer waited to start", NOT_OURS)
            return
        if active.process.started:
            self._run_changed(run_id)

    async def _claim(self, active: ActiveRun) -> None:
        """The run's claim answered, and the run marked running if its program started."""
        pid = active.process.pid if active.process.started else None
        try:
            answer = await database_sync_to_async(Run.claim)(active.run_id, running_pid=pid)
        except Exception as exc:  # said where the answer is read
            active.claimed.set_exception(exc)
        else:
            active.claimed.set_result(answer)
        finally:
            if not active.claimed.done():  # cancelled on its way: no answer, nobody waits
                active.claimed.cancel()

    async def _may_start(self, run_id: int) -> tuple[str, str] | None:
        """The gate of a run's box: None lets its program run."""
        active = self.runs.get(run_id)
        if run_id in self.cancelled or (active and active.process.stop_requested):
            self.cancelled.discard(run_id)
            return "stopped", "stopped by user before it started"
        if self.lease.estopped:  # pressed while its start was decided (its share's admission)
            return "stopped", "emergency stop"
        await self.starts.before_run(run_id)  # at the start pose, if it is to start there
        # Its trace begins there, and again when its program signs in (ActiveRun.signed_in).
        if active is not None and active.trace is not None:
            active.trace.start()
            limit = self._time_limit(active)
            active.limit = asyncio.create_task(limit, name=f"run-{run_id}-limit")
        return None

    async def _time_limit(self, active: ActiveRun) -> None:
        """A check run is stopped when its sim time is up, its trace ending there: counted
        from its program's first sign-in on the Robot API, until then from its launch."""
        speed = max(float(getattr(self.driver, "speed", 1.0) or 1.0), 0.01)
        while active.run_id in self.runs:
            left = active.trace.left()
            if left is None:
                return
            if left <= 0:
                active.trace.time_limit = True
                active.trace.take()
                reason = check_sims.TIME_LIMIT_REASON % active.trace.time_limit_s
                self.stop_run(active.run_id, reason)
                return
            await asyncio.sleep(min(left / speed, 1.0))

    async def _launch(self, run_id: int, message: dict, claimed=None, gate=None) -> ActiveRun:
        if (why := messages.check_filename(message["filename"])) is not None:
            raise ValueError(why)
        if self.isolation is None:
            raise IsolationUnavailable(self.isolation_error)
        language = get_language(message["language"])
        program_env = self.gateway.program_env()
        kind = self._box_kind(program_env)
        self._boxing(run_id)
        process = await self.boxes.take(kind, f"run-{run_id}")
        try:
            return await self._begin(run_id, message, language, process, program_env, claimed, gate)
        except BaseException:
            await discard(process)  # its cgroup and descriptors go with it
            raise

    async def _begin(self, run_id, message, language, process, program_env, claimed, gate):
        """The program in its box, as the run's process, registered before it starts."""
        uid = self.isolation.uid(run_id, str(settings.DATA_DIR))
        token = secrets.token_urlsafe(24)
        extra = {
            "ROBOT_API": f"unix:{self.isolation.api_dir() / self.server.unix_path.name}",
            "ROBOT_TOKEN": token,
            "ROBOT_NAME": self.name,
            "ROBOT_RUN_ID": str(run_id),
        }
        if self.isolation.network != "none":
            extra |= {"ROBOT_API_TCP": f"127.0.0.1:{ROBOT_API_PORT}", **program_env}
        env = launcher.environment(
            language, self.isolation.home(), extra, clients_dir=self.isolation.clients()
        )
        # What runs: the source, or what its language compiles it to (a blocks program: Python)
        # Compiled (blocks) in a thread: a large program must not hold up the robot's loop;
        # the others are their source, with no thread hop on every start.
        filename, source = message["filename"], message["source"]
        debug, source_map = message.get("debug"), None
        if debug is not None and language.name == "blocks":  # its Python, mapped to its blocks
            filename, source, source_map = await asyncio.to_thread(
                blocks_mapped, language, filename, source
            )
            if source_map is None:  # the blocks cannot run: the program that says why, plainly
                debug = None
        elif language.compiler is not None:
            filename, source = await asyncio.to_thread(language.program_file, filename, source)
        program = self.isolation.home() / filename
        command = language.command if debug is None else language.debug_command
        argv = [*command(str(program)), *map(str, message.get("args", ()))]
        # A sim faster than real time: the program's clock too (runbox.timescale).
        argv = timescale.command(argv, timescale.speed_of(self.driver.capabilities()))
        launch = Launch(
            filename, source.encode(),
            self.isolation.program_command(argv, uid), env,
        )  # fmt: skip
        # The token is good before the program starts: it may call auth at once.
        active = ActiveRun(run_id, token, process, user=message.get("user", ""), claimed=claimed)
        if debug is not None:
            active.debugger = debugger.RunDebugger(self, run_id, debug, filename, source_map)
        on_output = partial(self._publish_output, run_id)
        if self.checking and check_sims.TraceRecorder.possible(self.driver):
            active.trace = check_sims.TraceRecorder(self.driver, self.check_time_limit)
            on_output = partial(self._check_output, active.trace, on_output)
        self.runs[run_id] = active
        self.tokens[token] = active
        for served in process.box.served:
            if isinstance(served, RunLink):  # its MAVLink endpoint: this run's from now
                served.belongs_to(run_id, active.user)
        try:
            await process.begin(
                launch, gate, log_path=Run.log_path_of(run_id), on_output=on_output,
            )  # fmt: skip
        except BaseException:
            self.runs.pop(run_id, None)
            self.tokens.pop(token, None)
            raise
        active.watcher = asyncio.create_task(self._watch(active))
        return active

    def _box_ahead(self, now: bool = False) -> None:
        # Not for a check sim: its one run is asked as its agent starts, and takes its box then.
        if self.isolation is not None and not self._shutting_down and not self.checking:
            self.boxes.soon(self._box_kind(self.gateway.program_env()), now)

    def _box_kind(self, program_env: dict) -> "BoxKind":
        limits = launcher.Limits.from_settings(self.limits)
        services: list[str] = []
        if self.isolation.network != "none":
            services = [f"tcp:{ROBOT_API_PORT}", *self.isolation.policy.loopback_ports]
        mavlink = ""
        if self.isolation.network != "none" and "ROBOT_MAVLINK" in program_env:
            # udpout:127.0.0.1:PORT: the run's own endpoint, at the programs' endpoint's port
            mavlink = f"udp:{program_env['ROBOT_MAVLINK'].rsplit(':', 1)[1]}"
            services.append(mavlink)
        grace = float(self.limits["stop_grace_seconds"])
        return BoxKind(self.isolation, limits, tuple(dict.fromkeys(services)), grace, mavlink)

    def _make_box(self, name: str, kind: "BoxKind") -> RunProcess:
        """A run's box, not spawned yet: bubblewrap (or the rootless inbox) and its cgroup."""
        cgroup = self._cgroup(name, kind.limits)
        try:
            box = make_box(
                kind.isolation,
                socket_dir=self.socket_dir,
                disk_mb=kind.limits.disk_mb,
                listeners=[self._listener(service, kind.mavlink) for service in kind.services],
                seccomp_fd=seccomp.open_filter_fd(),
                cgroup=cgroup,
                rlimits=kind.limits.rlimits(address_space=cgroup is None),
            )
        except BaseException:
            if cgroup is not None:
                cgroup.remove()
            raise
        settings.RUNS_DIR.mkdir(parents=True, exist_ok=True)
        return QuotaRunProcess(  # its log kept within its owner's quota (runlogs)
            box.command(),
            env={"PATH": SYSTEM_PATH},  # the program's own comes with its run (Launch)
            cwd=settings.RUNS_DIR,
            max_log_bytes=kind.limits.log_size_mb * MB,
            output_rate=kind.limits.output_kb_per_second * 1024,
            grace=kind.grace,
            watch=RunWatch(kind.limits, box),
            box=box,
        )

    def _cgroup(self, name: str, limits: launcher.Limits) -> cgroups.RunCgroup | None:
        """The run's cgroup, where this machine gives one (else rlimits alone, as shown on the
        robot's page); one that cannot be made refuses the run."""
        if not self.cgroups.available:
            return None
        try:
            return cgroups.RunCgroup.create(
                name, self.cgroups,
                memory_bytes=limits.memory_mb * MB, pids=limits.processes,
                cpu_percent=limits.cpu_percent, cpu_seconds=limits.cpu_seconds,
            )  # fmt: skip
        except (cgroups.CgroupError, OSError) as exc:
            raise IsolationUnavailable(f"its cgroup could not be made: {exc}") from None

    def _listener(self, service: str, mavlink: str = "") -> Listener:
        """What the run's robot gives programs on 127.0.0.1 inside the run's namespace: the
        Robot API, the run's own MAVLink endpoint (`mavlink`: its service), relays."""
        if service == f"tcp:{ROBOT_API_PORT}":
            return Listener(service, self.server.serve_socket)
        if service == mavlink:
            return Listener(service, self.gateway.serve_run)
        return Listener(service, partial(relay_to_host, service))

    @staticmethod
    def _check_output(trace, publish, lines: list, skipped: int, skipped_from: int) -> None:
        trace.lines(lines, skipped)
        publish(lines, skipped, skipped_from)

    async def _watch(self, active: ActiveRun) -> None:
        outcome = await active.process.wait()
        if active.trace is not None:  # where the program left the robot, before it is stopped
            active.trace.take()
        # The token dies with the run, before anything else can use it, and so do the
        # connections it signed in (another program may hold them), with what they hold.
        self.tokens.pop(active.token, None)
        self.runs.pop(active.run_id, None)
        self.server.close_where(lambda session: session.run is active)
        if active.debugger is not None:  # its waits end with it
            active.debugger.close()
        # Its motion ends with it, however it ended, and so does its control of the robot.
        await self.stop_motion_of(active.run_id)
        if self.lease.release(active.run_id):
            self._lease_changed()
        await active.process.box.close()
        # After its claim (a program may end before the answer): marked running, then ended.
        await active.confirmed()
        if outcome.state != NOT_OURS and not active.disowned():  # else its state stays
            if active.trace is not None:  # saved before the run is marked ended: its check
                await self._save_trace(active, outcome)  # reads it (classroom.checking)
            await self._end_run(active.run_id, outcome.state, outcome.exit_code, outcome.reason)
        if not self.runs:  # the robot's next run finds its box made
            self._box_ahead(now=True)

    async def _save_trace(self, active: ActiveRun, outcome) -> None:
        doc = active.trace.document(outcome.state, outcome.exit_code, outcome.reason)
        if doc is None:  # its program never started: no trace (its check says why)
            return
        try:
            await asyncio.to_thread(
                check_sims.save_trace, Run.log_path_of(active.run_id).parent, doc
            )
        except OSError:
            log.exception("agent %s: run %s's trace not saved", self.name, active.run_id)

    async def _end_run(self, run_id, state, exit_code, reason) -> None:
        await database_sync_to_async(Run.mark_ended)(run_id, state, exit_code, reason)
        self._run_changed(run_id)
        self.queue.ended(run_id)  # its share is free: runs waiting for one may start
        if self.checking:
            await self._check_sim_done()

    async def _check_sim_done(self) -> None:
        """A check sim's run ended (its trace saved): the sim is removed, this agent stops."""
        try:
            if await database_sync_to_async(check_sims.remove_after_run)(self.name):
                self._shutting_down = True  # no box made ahead: no run will come
                await sims.tell_removed_async(self.name)
        except Exception:  # the reaper removes it (robots.sims.check_sims_done)
            log.exception("agent %s: the check sim could not be removed", self.name)

    def stop_run(self, run_id: int, reason: str) -> bool:
        """Stop: SIGTERM, then SIGKILL after the grace. The program may clean up meanwhile,
        but its drive() is refused from now (RobotApi.drive) and its motion stops now."""
        active = self.runs.get(run_id)
        if active is None:
            return False
        active.process.stop(reason)
        if self.motion_owner == run_id:
            asyncio.ensure_future(self.stop_motion_of(run_id))
        return True

    async def estop(self, by: str = "") -> list[int]:
        """The emergency stop. All at once, before anything is awaited: every run's token
        dies (nothing a program sends after this instant is obeyed) and its processes get
        SIGKILL, no grace; the lease goes to the emergency stop, so no program, hand, queue
        or staff moves the robot until someone resumes. Then the robot's own stop on the
        wire; a drive already on its way there is stopped after it (see drive_for).
        Returns the runs it ended."""
        self.estops += 1
        ended = [self._end_now(active, "emergency stop") for active in list(self.runs.values())]
        self.lease.estop(by or "someone")
        self.motion_owner = None
        if self._deadman is not None:
            self._deadman.cancel()
        self.queue.hold()
        self._lease_changed()
        if self.lent_to is not None:  # a serial bridge client has the device: it goes
            self.bridges.evict()
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._driver_back.wait(), DRIVER_BACK_TIMEOUT)
        try:
            await self.driver.stop()
        except rhal.RhalError:  # link down: the robot's own watchdog stops it
            log.exception("agent %s: emergency stop could not reach the robot", self.name)
        return ended

    def _end_now(self, active: ActiveRun, reason: str) -> int:
        self.tokens.pop(active.token, None)
        active.process.kill(reason)
        return active.run_id

    def resume_from(self, after: int | None) -> bool:
        """Whether a resume that follows record `after` (robots.stops) is in time: not older
        than the last press heard. Redis orders a channel's messages by each sender's clock,
        so a press sent after a resume may come first."""
        return after is None or after > self._last_press

    async def resume(self) -> bool:
        """After an emergency stop: the robot may move again, and its queue moves; the runs
        the stop held stay in line until started again (robots.run_queue)."""
        if not self.lease.end_estop():
            return False
        self._lease_changed()
        await self.queue.resume()
        return True

    # -- driving by hand, and who may drive ------------------------------------------------

    def take_lease(self, holder: Holder) -> None:
        """Hold the control lease for ``holder``; LeaseHeld if someone else holds it."""
        if self.lease.acquire(holder):
            self._lease_changed()

    async def teleop(self, holder: Holder, linear: float, angular: float) -> None:
        """A browser drives: with the lease, until it stops, leaves or goes quiet."""
        owner = holder.key
        try:
            await self.drive_for(holder, linear, angular)
        except (LeaseHeld, rhal.RhalError, ValueError) as exc:
            await self.layer.send(owner, {"type": "robot.teleop_error", "error": str(exc)})
            return
        if self._deadman is not None:
            self._deadman.cancel()
        self._deadman = asyncio.create_task(self._stop_after(owner, TELEOP_DEADMAN))

    async def drive_for(self, holder: Holder, linear: float, angular: float):
        """Drive as `holder`, who must hold the lease (LeaseHeld else). An emergency stop
        that comes while the command is on its way has the last word: the robot is stopped
        again after it, and the caller told. So does the holder's losing the lease meanwhile
        (its run ended, staff took over): nobody would stop what it sent."""
        self.take_lease(holder)
        estops = self.estops
        applied = await self.driver.drive(linear, angular)
        self.poses.wake()
        if self.estops != estops:
            with contextlib.suppress(rhal.RhalError):
                await self.driver.stop()
            raise LeaseHeld(f"{self.lease.holder.describe()} came first: the robot stays stopped")
        if self.lease.holder is None or self.lease.holder.key != holder.key:
            with contextlib.suppress(rhal.RhalError):
                await self.driver.stop()
            raise LeaseHeld("the robot's control ended while this command was on its way")
        self.motion_owner = holder.key
        return applied

    async def stop_motion_of(self, owner: int | str) -> None:
        """Stop the motors if ``owner``'s commands are what they follow now."""
        if self.motion_owner == owner:
            self.motion_owner = None
            with contextlib.suppress(rhal.RhalError):
                await self.driver.stop()

    async def release(self, owner: str) -> None:
        """The browser lets go or left: its motion stops and the lease is free."""
        await self.stop_motion_of(owner)
        if self.lease.release(owner):
            self._lease_changed()

    async def take_control(self, holder: Holder) -> None:
        """Staff take over: whoever drove is stopped and now gets a clear error."""
        previous = self.lease.holder
        try:
            self.lease.acquire(holder, take_over=True)
        except LeaseHeld as exc:  # the emergency stop's, until resumed
            await self.layer.send(holder.key, {"type": "robot.teleop_error", "error": str(exc)})
            return
        if previous is not None and self.motion_owner == previous.key:
            await self.stop_motion_of(previous.key)
        self._lease_changed()

    async def _stop_after(self, owner: str, seconds: float) -> None:
        await asyncio.sleep(seconds)
        await self.stop_motion_of(owner)

    def _lease_changed(self) -> None:
        holder = self.lease.holder.as_dict() if self.lease.holder else None
        self.publish(self.group, {"type": "robot.lease", "robot": self.name, "holder": holder})
        self.queue.wake()  # free now? the next in line starts

    # -- publishing -------------------------------------------------------------------------

    def publish(self, group: str, message: dict) -> None:
        """Queue a group event; one task sends them in order (a layer may reorder tasks)."""
        self._outbox.put_nowait((group, message))

    def _publish_output(self, run_id: int, lines: list, skipped: int, skipped_from: int) -> None:
        message = {"type": "run.output", "run_id": run_id, "lines": lines}
        if skipped:
            message.update(skipped=skipped, skipped_from=skipped_from)
        self.publish(run_group(run_id), message)

    def _run_changed(self, run_id: int) -> None:
        self.publish(run_group(run_id), {"type": "run.state", "run_id": run_id})
        self.publish(RUNS_GROUP, {"type": "runs.changed", "run_id": run_id, "robot": self.name})
        self.publish(self.group, {"type": "robot.runs", "robot": self.name})

    async def _publish_loop(self) -> None:
        while True:
            group, message = await self._outbox.get()
            try:
                await self.layer.group_send(group, message)
            except Exception:
                log.exception("agent %s: could not publish to %s", self.name, group)

    async def readings(self) -> dict:
        """The robot's readings, or ``{"error": why}`` while it cannot be reached."""
        try:
            return await self.driver.sensors()
        except rhal.RhalError as exc:
            if not self.driver.is_open and self.link_error:
                return {"error": f"not connected ({self.link_error})"}
            return {"error": str(exc)}

    async def _telemetry_loop(self) -> None:
        """Latest-state snapshots, throttled at the source; all shown values once a second."""
        for tick in itertools.count():
            sensors = await self.readings()
            self.poses.noticed(sensors)
            self._age_shows()
            changed, self.api.changed_shows = self.api.changed_shows, {}
            full = self._shows_snapshot_due or tick % SHOWS_SNAPSHOT_EVERY == 0
            self._shows_snapshot_due = False
            shows = dict(self.shows) if full else changed
            self.publish(
                self.group,
                {
                    "type": "robot.telemetry",
                    "robot": self.name,
                    "sensors": sensors,
                    "units": self.units,
                    "shows": shows,
                    "all_shows": full,  # a full snapshot replaces what the page shows
                },
            )
            await asyncio.sleep(TELEMETRY_INTERVAL)

    def _age_shows(self) -> None:
        """An ended run's values leave the page (and this memory) a while after its end:
        until then only who may see the run sees them (robots.readings)."""
        marked, gone = age_shows(
            self.shows, self.runs, time.monotonic(), settings.SHOWS_KEEP_SECONDS
        )
        for name in gone:
            self.api.show_costs.pop(name, None)
            self.api.changed_shows.pop(name, None)
        if marked or gone:
            self._shows_snapshot_due = True  # a full snapshot: pages drop or mark them

    async def _heartbeat_loop(self) -> None:
        """The portal counts a robot online while this goes on (Robot.online)."""
        beat = database_sync_to_async(Robot.objects.filter(name=self.name).update)
        # Who serves the robot and since when, with the first beat that gets through
        first = {"agent_host": socket.gethostname(), "agent_started": timezone.now()}
        while True:
            try:
                await beat(last_seen=timezone.now(), **first)
                first = {}
            except Exception:  # the database away for a moment (or a SQLite table locked),
                # even at the first beat, must not stop the robot and its programs
                log.exception("agent %s: heartbeat failed", self.name)
            await asyncio.sleep(settings.AGENT_HEARTBEAT)


def flat_units(specs: dict) -> dict[str, str]:
    """{"position": {"unit": {"x": "m"}}} -> {"position.x": "m"}, as the page names readings."""
    units = {}
    for name, spec in specs.items():
        unit = spec.get("unit", "")
        if isinstance(unit, dict):
            units.update({f"{name}.{part}": value for part, value in unit.items()})
        else:
            units[name] = unit
    return units


def blocks_mapped(language, filename: str, source: str) -> tuple[str, str, list | None]:
    """A blocks program to run under the debugger: (file name, its Python, the block of each
    of its lines, the first at 0), made in a worker; if the blocks cannot run, the program
    that fails saying why, as a plain run has it, and no map."""
    name = str(Path(filename).with_suffix(language.compiled_extension))
    try:
        python, blocks = blocks_worker.to_python_mapped(source)
    except ValueError as exc:  # a BlocksError (a worker busy too): its message says why
        return name, failing(str(exc)), None
    return name, python, blocks


def untaken_runs(robot_name: str) -> list[dict]:
    """The start messages of the runs waiting for this robot's agent to take them, asked
    within AGENT_START_TIMEOUT (older ones the presence watch fails)."""
    since = timezone.now() - timedelta(seconds=settings.AGENT_START_TIMEOUT)
    runs = Run.objects.filter(
        robot__name=robot_name, state=Run.State.STARTING, pid__isnull=True, created__gte=since
    ).select_related("owner")
    found = []
    for run in runs.order_by("pk"):
        with contextlib.suppress(Exception):  # e.g. its language is gone: the watch fails it
            found.append(run.start_message())
    return found


def end_leftovers(run_id: int) -> None:
    """Whatever a lost run left running ends now: its account's processes are all its own."""
    if os.geteuid() == 0:
        signal_account(run_uid(run_id, str(settings.DATA_DIR)), SIGKILL)


def resolve_isolation(robot: Robot) -> tuple[InForce | None, str]:
    """What the robot's runs get here, or why they cannot run (said to whoever starts one)."""
    try:
        policy = Policy.from_settings(robot.run_isolation(settings.RUN_ISOLATION))
        share = Share.from_settings(settings.RUNS_SHARE)
        in_force = policy.resolve(CLIENTS_DIR, runs_cgroups(share, str(settings.DATA_DIR)))
    except IsolationUnavailable as exc:
        log.error("robot %s: its programs cannot run: %s", robot.name, exc)
        return None, str(exc)
    return in_force, ""


class AgentManager:
    """Agents in this process: every robot's in embedded mode (``start``), or those that
    `robotide agent` names. One that fails is started again, after a growing pause."""

    def __init__(self):
        self.agents: dict[str, tuple[RobotAgent, asyncio.Task]] = {}
        self._listener: asyncio.Task | None = None
        self._reaper: asyncio.Task | None = None
        self._failures: dict[str, int] = {}
        self._closing = False
        self.personal_only = False

    async def start(self, personal_only: bool = False) -> None:
        """Every robot's agent but removed personal sims' (or, ``personal_only``, the personal
        sims' alone: `robotide agent --personal-sims`), those added later, and the reaper of
        idle personal sims (robots.sims)."""
        self.personal_only = personal_only
        names = await database_sync_to_async(sims.robots_to_serve)(personal_only)
        for name in names:
            self.start_agent(name)
        self._listener = asyncio.create_task(self._listen())
        self._reaper = asyncio.create_task(sims.reap_loop(self.stop_agent), name="sims-reaper")

    async def stop_agent(self, name: str) -> None:
        """Its robot is gone (a personal sim removed): its agent shuts down, not to restart."""
        found = self.agents.pop(name, None)
        if found is not None:
            found[1].cancel()
            await asyncio.gather(found[1], return_exceptions=True)

    def start_agent(self, name: str) -> RobotAgent:
        if name in self.agents and not self.agents[name][1].done():
            return self.agents[name][0]
        agent = RobotAgent(name)
        task = asyncio.create_task(agent.serve(), name=f"agent-{name}")
        task.add_done_callback(partial(self._agent_ended, name))
        self.agents[name] = (agent, task)
        return agent

    def _agent_ended(self, name: str, task: asyncio.Task) -> None:
        if task.cancelled() or self._closing:
            return
        failures = self._failures[name] = self._failures.get(name, 0) + 1
        delay = min(RETRY_DELAY * 2 ** (failures - 1), LINK_RETRY_MAX)
        log.error("agent %s stopped: %r; again in %g s", name, task.exception(), delay)
        asyncio.get_running_loop().call_later(delay, self._restart, name)

    def _restart(self, name: str) -> None:
        if not self._closing:
            self.start_agent(name)

    async def _listen(self) -> None:
        layer = get_channel_layer()
        while True:
            try:
                message = await layer.receive(manager_channel())
            except Exception:
                log.exception("agent manager: channel layer receive failed; retrying")
                await asyncio.sleep(RETRY_DELAY)
                continue
            if message.get("type") == "robot.added":
                if await database_sync_to_async(sims.serves)(message["name"], self.personal_only):
                    self.start_agent(message["name"])
            elif message.get("type") == "robot.removed":
                await self.stop_agent(message["name"])

    async def shutdown(self) -> None:
        self._closing = True
        for task in (self._listener, self._reaper):
            if task:
                task.cancel()
        for _, task in self.agents.values():
            task.cancel()
        await asyncio.gather(*(t for _, t in self.agents.values()), return_exceptions=True)
