"""A run under the debugger, as its agent sees it (programs/clients/PROTOCOL.md, "The debugger").

The debugger itself runs in the run's box (clients/python/robot_debug.py, on bdb) and talks to
the agent over the run's own Robot API connections: the methods here act on the signed-in run's
RunDebugger only, so no parameter names a run. The page's commands come on the agent's channel
as "run.debug" messages (programs.views_debug), and the agent tells the run's viewers what the
debugger does as "run.debug" events on the run's group (programs.consumers.RunConsumer).

A pause is a motion stop: while the debugger waits in debug_paused the run's motion is stopped
and its drive() refused (RobotApi.drive), until a command lets it go on. Continue gives the robot
back the run's motion (its last drive, unless it stopped the robot itself since; if the run still
holds the robot) before the program goes on: a program that drives once and then watches its
sensors, as most do, must not find its robot standing for good after a pause. Steps leave it
stopped: a line stepped over runs with the robot still, where a student can follow what it
reads (unless the line drives).
"""

from __future__ import annotations

import asyncio
import json
import logging
import math
import time

import rhal
from robots.bus import run_group
from robots.lease import Holder, LeaseHeld
from robots.rpc import INVALID_PARAMS, ROBOT_ERROR, RpcError, bind_params

log = logging.getLogger(__name__)

MAX_STATE_BYTES = 256 * 1024  # a pause's state, as JSON
MAX_POLL_TIMEOUT = 5.0  # s a debug_poll may wait for a change
AT_INTERVAL = 0.1  # s between "at" events: at most 10 a second
# How often a blocks program's debugger says where it is (its running block is highlighted);
# a Python program's is not asked (its page shows the line of a pause).
BLOCKS_REPORT_LINE = AT_INTERVAL
RESUMING = ("continue", "step_over", "step_into", "step_out")
PAUSED_HERE = "paused in the debugger"

_encode = json.JSONEncoder(separators=(",", ":"), check_circular=False).encode


class RunDebugger:
    """One debug run's breakpoints and watches, and where its debugger is: paused (waiting in
    debug_paused for the page's command) or running (its poll waiting for a change)."""

    def __init__(self, agent, run_id: int, spec: dict, filename: str, source_map=None):
        self.agent, self.run_id, self.filename = agent, run_id, filename
        # A blocks program's map: the block that made each line of its Python (line i at i-1).
        self.source_map: list[str | None] | None = source_map
        self.first_lines: dict[str, int] = {}  # block -> the first line it made
        for number, made_by in reversed(list(enumerate(source_map or (), start=1))):
            if made_by is not None:
                self.first_lines[made_by] = number
        self.breakpoints: list[dict] = list(spec.get("breakpoints", []))  # as the page says
        self.watches: list[str] = list(spec.get("watches", []))
        self.started = False
        self.paused = False  # its drive() is refused while this holds
        self.state: dict | None = None  # the last pause's
        self.waiter: asyncio.Future | None = None  # debug_paused's, for the page's command
        self.waiter_session = None
        self.polls: dict[asyncio.Future, object] = {}  # debug_poll waiters -> their session
        self.pause_asked = False
        # A command that came after an update's answer, before the debugger paused again
        # (the page's Continue right after adding a watch): the new pause's answer.
        self.pending: str | None = None
        self.changed = False  # breakpoints or watches the running debugger has not had
        self.at_line: int | None = None  # the last "at" said, and when
        self.at_time = -math.inf
        self._at_later: asyncio.TimerHandle | None = None
        self._at_pending: int | None = None
        self.closed = False
        # The run's last drive (linear, angular), until it stops the robot itself: what
        # Continue gives back after its pauses and steps.
        self.motion: tuple[float, float] | None = None

    # -- what the debugger in the box is given ----------------------------------------------

    @property
    def report_line(self) -> float | None:
        return BLOCKS_REPORT_LINE if self.source_map is not None else None

    def line_breakpoints(self) -> list[dict]:
        """The breakpoints as lines of the file that runs: a block's is the first line it
        made (a block that made none has no breakpoint)."""
        lines = []
        for point in self.breakpoints:
            line = point.get("line")
            if line is None:
                line = self.first_line_of(point["block"])
            if line is not None:
                lines.append({"line": line, "condition": point.get("condition")})
        return lines

    def first_line_of(self, block: str) -> int | None:
        return self.first_lines.get(block)

    def block_at(self, line) -> str | None:
        if self.source_map is None or type(line) is not int or not 0 < line <= len(self.source_map):
            return None
        return self.source_map[line - 1]

    def as_now(self) -> dict:
        return {"breakpoints": self.line_breakpoints(), "watches": list(self.watches)}

    # -- the Robot API methods (the debugger in the box) -------------------------------------

    def start(self) -> dict:
        if self.started:
            raise RpcError(ROBOT_ERROR, "the debugger has started already")
        self.started = True
        self.changed = False
        return {**self.as_now(), "file": self.filename, "report_line": self.report_line}

    async def pause(self, state, session) -> dict:
        """debug_paused: the robot stops, the page is told; the page's command is the answer."""
        if not isinstance(state, dict):
            raise RpcError(INVALID_PARAMS, "state must be an object")
        if len(_encode(state)) > MAX_STATE_BYTES:
            raise RpcError(INVALID_PARAMS, f"state larger than {MAX_STATE_BYTES // 1024} KB")
        if self.waiter is not None:
            raise RpcError(ROBOT_ERROR, "the debugger is paused already")
        self.paused, self.pause_asked, self.state = True, False, state
        self.waiter = asyncio.get_running_loop().create_future()
        self.waiter_session = session
        waiter = self.waiter
        await self.agent.stop_motion_of(self.run_id)  # the lease stays the run's
        block = self.block_at(state.get("line"))
        self.tell({"state": "paused", "paused": state, "block": block})
        if self.pending is not None:
            pending, self.pending = self.pending, None
            self.command(pending)
        try:
            command = await waiter  # cancelled if its connection or the run ends
        finally:
            if self.waiter is waiter:
                self.waiter = self.waiter_session = None
        self.changed = False  # the answer has the breakpoints and watches as they are now
        return {"command": command, **self.as_now()}

    async def poll(self, line, timeout, session):
        """debug_poll: where the program is (said to the page, "at"); a change, if one comes
        within `timeout`, else None."""
        if line is not None and (type(line) is not int or line <= 0):
            raise RpcError(INVALID_PARAMS, "line must be a line number or null")
        if (
            isinstance(timeout, bool) or not isinstance(timeout, int | float)
            or not 0 <= timeout <= MAX_POLL_TIMEOUT
        ):  # fmt: skip
            raise RpcError(INVALID_PARAMS, f"timeout must be 0 to {MAX_POLL_TIMEOUT:g} seconds")
        if line is not None and not self.paused:
            self.at(line)
        if not self.due():
            waiter = asyncio.get_running_loop().create_future()
            self.polls[waiter] = session
            try:
                await asyncio.wait_for(waiter, timeout)
            except TimeoutError:
                pass
            finally:
                self.polls.pop(waiter, None)
                waiter.cancel()
            if not self.due():
                return None
        pause, self.pause_asked, self.changed = self.pause_asked, False, False
        return {**self.as_now(), "pause": pause}

    def due(self) -> bool:
        """Something for a poll to say: only while running (a pause's answer says it)."""
        return not self.paused and (self.changed or self.pause_asked)

    def wake_polls(self) -> None:
        for waiter in list(self.polls):
            if not waiter.done():
                waiter.set_result(None)

    def at(self, line: int) -> None:
        """The program is at `line`: said to the page on a change, at most 10 times a second
        (the last one said later if it comes sooner)."""
        self._at_pending = line
        wait = self.at_time + AT_INTERVAL - time.monotonic()
        if wait <= 0:
            self._say_at()
        elif self._at_later is None:
            self._at_later = asyncio.get_running_loop().call_later(wait, self._say_at)

    def _say_at(self) -> None:
        self._at_later = None
        line, self._at_pending = self._at_pending, None
        if line is None or line == self.at_line or self.paused or self.closed:
            return
        self.at_line, self.at_time = line, time.monotonic()
        self.tell({"state": "at", "line": line, "block": self.block_at(line)})

    # -- the page's commands ------------------------------------------------------------------

    def command(self, command: str, breakpoints=None, watches=None) -> None:
        if self.closed:
            return
        if breakpoints is not None or watches is not None:
            if breakpoints is not None:
                self.breakpoints = list(breakpoints)
            if watches is not None:
                self.watches = list(watches)
            self.changed = True
        if command == "stop":
            self.agent.stop_run(self.run_id, "stopped by user")
            self.answer("stop")
        elif self.waiter is not None:  # paused
            if command == "continue" and self.motion is not None:
                asyncio.ensure_future(self._continue_moving(self.waiter))
            elif command in RESUMING:
                self.answer(command)
            elif command == "update":
                self.answer("update")  # it says the pause again, watches evaluated anew
        elif self.paused and command in RESUMING:  # between an update's answer and its pause
            self.pending = command
        elif command == "pause":
            self.pause_asked = True
        if self.due():
            self.wake_polls()

    # -- motion: what a pause stops and Continue gives back --------------------------------

    def moved(self, linear: float, angular: float) -> None:
        """The run drove (RobotApi.drive): what a pause would stop."""
        self.motion = (linear, angular)

    def stopped(self) -> None:
        """The run stopped its robot itself (RobotApi.stop)."""
        self.motion = None

    async def _continue_moving(self, waiter: asyncio.Future) -> None:
        """Continue: the run's motion as its program left it (its last drive), then the
        program goes on (it cannot drive meanwhile: it waits for this answer). Not if the run
        no longer holds the robot (staff took it, the emergency stop): the robot stays as
        they left it."""
        active, motion = self.agent.runs.get(self.run_id), self.motion
        if active is not None and motion is not None and self.agent.lease.holds(self.run_id):
            try:
                await self.agent.drive_for(Holder("run", self.run_id, active.user), *motion)
            except (LeaseHeld, rhal.RhalError, ValueError) as exc:
                log.info("run %s: its motion not given back after a pause: %s", self.run_id, exc)
        if self.waiter is waiter:  # not ended or answered meanwhile
            self.answer("continue")

    def answer(self, command: str) -> None:
        """The waiting debug_paused answers `command`; the robot may move again unless it is
        an update (the debugger pauses again at once)."""
        if self.waiter is not None and not self.waiter.done():
            self.waiter.set_result(command)
        if command != "update" and self.paused:
            self.paused = False
            self.at_line = None  # where it goes from here is news
            if command != "stop":
                self.tell({"state": "running"})

    # -- the run's end, a connection's --------------------------------------------------------

    def forget(self, session) -> None:
        """A connection closed: what it waited for ends now (no task left pending)."""
        if self.waiter is not None and self.waiter_session is session:
            self.waiter.cancel()
            self.waiter = self.waiter_session = None
            self.paused = False  # nobody pauses the program on that connection now
        for waiter, owner in list(self.polls.items()):
            if owner is session:
                waiter.cancel()

    def close(self) -> None:
        """The run ended: every waiter ends."""
        self.closed = True
        self.paused = False
        if self.waiter is not None:
            self.waiter.cancel()
            self.waiter = self.waiter_session = None
        for waiter in list(self.polls):
            waiter.cancel()
        if self._at_later is not None:
            self._at_later.cancel()
            self._at_later = None

    def tell(self, event: dict) -> None:
        self.agent.publish(
            run_group(self.run_id), {"type": "run.debug", "run_id": self.run_id, "event": event}
        )


# -- the Robot API methods, for RobotApi (they need the connection: session) ---------------------


def debugger_of(active) -> RunDebugger:
    found = getattr(active, "debugger", None)
    if found is None:
        raise RpcError(ROBOT_ERROR, "this run is not under the debugger")
    return found


async def debug_start(active, params, session=None):
    bind_params(params, (), 0)
    return debugger_of(active).start()


async def debug_paused(active, params, session=None):
    (state,) = bind_params(params, ("state",), 1)
    return await debugger_of(active).pause(state, session)


async def debug_poll(active, params, session=None):
    line, timeout = bind_params(params, ("line", "timeout"), 2)
    return await debugger_of(active).poll(line, timeout, session)


METHODS = {"debug_start": debug_start, "debug_paused": debug_paused, "debug_poll": debug_poll}


# -- the agent's channel: the page's commands --------------------------------------------------


def channel_handlers(agent) -> dict:
    async def run_debug(message: dict) -> None:
        """A command from the run's page (robots.messages has checked its fields; the view,
        who sent it)."""
        active = agent.runs.get(message["run_id"])
        found = getattr(active, "debugger", None)
        if found is None:
            log.info("agent %s: run.debug for run %s, not debugged here", agent.name,
                     message["run_id"])  # fmt: skip
            return
        found.command(message["command"], message.get("breakpoints"), message.get("watches"))

    return {"run.debug": run_debug}
