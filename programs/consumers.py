"""Live run output and the live list of runs, as HTML fragments for htmx's ws extension."""

import asyncio
import contextlib
import json
import logging
import time
from urllib.parse import parse_qs, urlencode

from channels.db import database_sync_to_async
from channels.generic.websocket import AsyncWebsocketConsumer
from django.http import Http404
from django.template.loader import render_to_string
from django.utils.html import escape
from django.utils.translation import ngettext

from programs import watch_pass
from programs.access import ACCESS_STANDS_SECONDS, get_program_for_user, get_run_for_user
from programs.models import Run
from programs.runlog import (
    count_lines_between,
    lines_after,
    log_length,
    places_for,
    places_in,
    render_lines,
    tail,
)
from programs.views import run_tables_context
from robotide.consumers import DirectDispatch
from robotide.security import plain_number
from robotide.ws_user import user_of
from robots.bus import RUNS_GROUP, console_group, run_group

LIST_REFRESH_INTERVAL = 0.5
# A log up to this size is read on the event loop (a start's, well under a millisecond); a
# larger one in a worker thread (a tail counts the lines before it: 64 MB took 30 ms here).
LOOP_READ_BYTES = 256 * 1024
# How long a viewer's access stands before what it is sent (output, a state) makes it read again.
ACCESS_RECHECK_SECONDS = ACCESS_STANDS_SECONDS
log = logging.getLogger(__name__)


def skipped_line(count: int) -> str:
    text = ngettext(
        "… %(count)s line(s) not shown live: the full log has them (Download log)",
        "… %(count)s line(s) not shown live: the full log has them (Download log)",
        count,
    ) % {"count": count}
    return f'<div class="ln s">{escape(text)}</div>'


class RunConsumer(DirectDispatch, AsyncWebsocketConsumer):
    """A run's output from its first line, then live; and its state as it changes."""

    group: str | None = None
    _state_task: asyncio.Task | None = None
    _state_stale = False

    async def connect(self):
        run_id = self.scope["url_route"]["kwargs"]["run_id"]
        page_offset = shown_up_to(self.scope)  # read before joining: nothing to undo if bad
        given = watch_pass.read(query_param(self.scope, "pass"), run_id, session_key(self.scope))
        # Join first, then read the file: lines already in it are skipped by offset. Nothing
        # of the group reaches a viewer who may not see the run: its events wait for
        # connect() to return, and then it has left the group.
        self.group = run_group(run_id)
        await self.channel_layer.group_add(self.group, self.channel_name)
        try:
            if given is not None and _small(Run.log_path_of(run_id)):  # no trip at all
                first = self.seen_on_pass(given, page_offset)
            elif given is not None:  # no database trip; a large log read aside
                first = await asyncio.to_thread(self.seen_on_pass, given, page_offset)
            else:
                first = await self.see_run(run_id, page_offset)
        except BaseException:  # leave no member behind in the run's group
            await self.leave_run_group()
            raise
        if first is None:
            await self.leave_run_group()
            await self.close(code=4404)
            return
        await self.accept()
        await self.send(first)
        if given is not None:
            await self.run_state({})  # the run's state, read now: the page's may be older
        else:
            await self.send_status()

    async def leave_run_group(self):
        await self.channel_layer.group_discard(self.group, self.channel_name)
        self.group = None

    def seen(self, run_id: int, page_offset: int | None) -> str | None:
        """The run if this viewer may see it, and what the page lacks of its log."""
        try:
            self.run = get_run_for_user(self.scope["user"], run_id)
        except Http404:
            return None
        self.run_id, self.log_path = run_id, self.run.log_path
        self.place_of = places_in(self.run)
        self.checked = time.monotonic()
        return self.catch_up(page_offset)

    def seen_on_pass(self, given: watch_pass.WatchPass, page_offset: int | None) -> str:
        """What the page lacks of the log, on the access its pass stands for."""
        self.run_id, self.log_path = given.run_id, Run.log_path_of(given.run_id)
        self.place_of = places_for(given.language, given.program_name)
        self.checked = time.monotonic() - given.age
        return self.catch_up(page_offset)

    @database_sync_to_async
    def may_still_see(self) -> bool:
        """Access read again (at most every ACCESS_RECHECK_SECONDS, as output comes)."""
        self.checked = time.monotonic()
        try:
            get_run_for_user(self.scope["user"], self.run_id)
        except Http404:
            return False
        return True

    # One trip to a worker thread: a start's first line waits for it.
    see_run = database_sync_to_async(seen)

    def catch_up(self, page_offset: int | None) -> str:
        """What the page lacks: the lines after those it was rendered with, else a new tail."""
        if page_offset is not None:
            lines, end = lines_after(self.log_path, page_offset)
            if lines is not None:
                self.offset = end
                html = render_lines(lines, self.place_of)
                return f'<div id="log-lines" hx-swap-oob="beforeend">{html}</div>'
        lines, skipped, self.offset = tail(self.log_path)
        head = skipped_line(skipped) if skipped else ""
        return f'<div id="log-lines">{head}{render_lines(lines, self.place_of)}</div>'

    async def disconnect(self, code):
        if self._state_task is not None:
            self._state_task.cancel()
        if self.group:
            await self.channel_layer.group_discard(self.group, self.channel_name)

    async def run_output(self, event):
        if self.group is None:  # turned away, with this already on its way
            return
        if time.monotonic() - self.checked >= ACCESS_RECHECK_SECONDS:
            if not await self.may_still_see():  # its teacher left the class, a share went
                await self.leave_run_group()
                await self.close(code=4404)
                return
        fresh = [line for line in event["lines"] if line[0] >= self.offset]
        if not fresh:
            return
        skipped = event.get("skipped", 0)
        if skipped and event["skipped_from"] < self.offset:
            # Part of the gap was in the log tail this viewer got first: count what it missed.
            skipped = await asyncio.to_thread(
                count_lines_between, self.log_path, self.offset, fresh[0][0]
            )
        head = skipped_line(skipped) if skipped else ""
        html = render_lines([(tag, text) for _number, tag, text in fresh], self.place_of)
        await self.send(f'<div id="log-lines" hx-swap-oob="beforeend">{head}{html}</div>')

    async def run_debug(self, event):
        """The run's debugger paused, goes on, or is at a line (robots.debugger): JSON text
        {"debug": event}, beside the log's HTML, to viewers who may still see the run."""
        if self.group is None or event.get("run_id") != getattr(self, "run_id", None):
            return  # turned away, or a run this console followed before
        if time.monotonic() - self.checked >= ACCESS_RECHECK_SECONDS:
            if not await self.may_still_see():
                await self.leave_run_group()
                await self.close(code=4404)
                return
        await self.send(json.dumps({"debug": event["event"]}))

    async def run_state(self, event):
        # Read and rendered aside, so output lines queued behind a state change do not wait
        # for a database trip (a start's first line comes right after "running").
        if self.group is None:
            return
        self._state_stale = True
        if self._state_task is None or self._state_task.done():
            self._state_task = asyncio.create_task(self._refresh_state())

    async def _refresh_state(self):
        try:
            while self._state_stale and self.group is not None:
                self._state_stale = False
                html = await self.fresh_status()
                if html is None:  # access taken away
                    await self.close()
                    return
                await self.send(html)
        except OSError:  # uvicorn's ClientDisconnected: the viewer left meanwhile
            return
        except Exception:
            log.exception("run %s: could not send its state", self.run_id)

    @database_sync_to_async
    def fresh_status(self) -> str | None:
        """The run as it is now, rendered: one trip to a worker thread (a start's first lines
        come while it is made); the viewer's access read again if it no longer stands (the
        session and the user, on a pass: not while the run's first lines go out)."""
        try:
            if time.monotonic() - self.checked < ACCESS_RECHECK_SECONDS:
                self.run = Run.objects.select_related("robot", "owner").get(pk=self.run_id)
            else:
                self.run = get_run_for_user(self.scope["user"], self.run_id)
                self.checked = time.monotonic()
        except (Http404, Run.DoesNotExist):
            return None
        return self.status_html()

    def status_html(self) -> str:
        context = {"run": self.run, "oob": True, "user": self.scope["user"]}
        return render_to_string("runs/_status.html", context)

    async def send_status(self):
        await self.send(await database_sync_to_async(self.status_html)())


class ConsoleConsumer(RunConsumer):
    """The workbench's console: open before Run is pressed, so a run's first lines need no
    new connection. A run started from the workbench is attached to it (``console.attach``);
    the console then shows that run as its page would, from its first line."""

    async def connect(self):
        program_id = self.scope["url_route"]["kwargs"]["program_id"]
        if not await self.may_see(program_id):
            await self.close(code=4404)
            return
        self.console = console_group(program_id, self.scope["user"].pk)
        await self.channel_layer.group_add(self.console, self.channel_name)
        await self.accept()

    @database_sync_to_async
    def may_see(self, program_id: int) -> bool:
        try:
            get_program_for_user(self.scope["user"], program_id)
        except Http404:
            return False
        return True

    async def disconnect(self, code):
        if getattr(self, "console", None):
            await self.channel_layer.group_discard(self.console, self.channel_name)
        await super().disconnect(code)

    async def console_attach(self, event):
        """Follow this run from now on: join its group first, then read its log (as
        RunConsumer.connect does, so no line falls between the two)."""
        if self.group:
            await self.channel_layer.group_discard(self.group, self.channel_name)
        self.group = run_group(event["run_id"])
        await self.channel_layer.group_add(self.group, self.channel_name)
        html = await self.see_attached(event["run_id"])
        if html is None:
            await self.channel_layer.group_discard(self.group, self.channel_name)
            self.group = None
            return
        await self.send(html)

    @database_sync_to_async
    def see_attached(self, run_id: int) -> str | None:
        """The console showing the run, if this viewer may see it (one trip, as see_run)."""
        lines = self.seen(run_id, None)
        if lines is None:
            return None
        context = {"run": self.run, "lines": lines, "attached": True}
        return render_to_string("programs/_console.html", context)


class RunListConsumer(DirectDispatch, AsyncWebsocketConsumer):
    """The running and recent runs tables, re-rendered for this user when a run changes."""

    async def connect(self):
        if not (await user_of(self.scope)).is_authenticated:
            await self.close(code=4401)
            return
        self.robot = query_param(self.scope, "robot") or None
        self._pending: asyncio.TimerHandle | None = None
        await self.channel_layer.group_add(RUNS_GROUP, self.channel_name)
        await self.accept()

    async def disconnect(self, code):
        if self.scope["user"].is_authenticated:
            await self.channel_layer.group_discard(RUNS_GROUP, self.channel_name)
        if getattr(self, "_pending", None) is not None:
            self._pending.cancel()

    async def runs_changed(self, event):
        if self.robot and event.get("robot") != self.robot:
            return
        # Many runs ending at once become one refresh.
        if self._pending is None:
            self._pending = asyncio.get_running_loop().call_later(
                LIST_REFRESH_INTERVAL, lambda: asyncio.ensure_future(self.refresh())
            )

    async def refresh(self):
        self._pending = None
        try:
            html = await database_sync_to_async(self._render)()
        except Exception:
            log.exception("could not render the runs list")
            return
        with contextlib.suppress(OSError):  # ClientDisconnected: the viewer left meanwhile
            await self.send(html)

    def _render(self) -> str:
        user = self.scope["user"]
        context = run_tables_context(user, self.robot)
        next_url = "/runs/" + (f"?{urlencode({'robot': self.robot})}" if self.robot else "")
        extra = {"oob": True, "user": user, "next_url": next_url}
        return render_to_string("runs/_tables.html", {**context, **extra})


def query_param(scope, name: str) -> str | None:
    values = parse_qs(scope["query_string"].decode(errors="replace")).get(name)
    return values[0] if values else None


def _small(path) -> bool:
    return log_length(path) <= LOOP_READ_BYTES  # plain or compressed; 0 if none yet


def session_key(scope) -> str | None:
    """The session key the websocket's cookie names (read without the database)."""
    session = scope.get("session")
    return session.session_key if session is not None else None


def shown_up_to(scope) -> int | None:
    """The log offset the page was rendered with; None (a fresh tail) if absent or not a
    plain number."""
    return plain_number(query_param(scope, "from"), digits=18)
