"""A robot's live page: sensor readings, values shown by programs, its running programs."""

import asyncio
import contextlib
import json
import math
import time

from asgiref.sync import sync_to_async
from channels.db import database_sync_to_async
from channels.generic.websocket import AsyncWebsocketConsumer
from django.conf import settings
from django.http import Http404
from django.template.loader import render_to_string
from django.utils.translation import gettext as _

from programs.access import ACCESS_STANDS_SECONDS, runs_for_user
from programs.models import Run
from robotide.consumers import DirectDispatch
from robots import stops
from robots.bus import send_to_agent
from robots.models import get_robot_for_user, robot_group
from robots.readings import ended_runs, runs_seen, sensor_rows, show_items, shows_seen, status
from robots.say import SayOnSocket, parse_say
from robots.sim_view import WATCH_RENEW


def parse_control(text: str | None) -> tuple[str, tuple[float, float] | None] | None:
    """A control command from the page: ("drive", (linear, angular)), ("stop", None),
    ("release", None), ("take", None); None for anything else (htmx sends its own frames)."""
    try:
        message = json.loads(text or "")
    except ValueError:
        return None
    if not isinstance(message, dict):
        return None
    for flag in ("stop", "release", "take"):
        if message.get(flag) is True:
            return flag, None
    drive = message.get("drive")
    if (
        isinstance(drive, list)
        and len(drive) == 2
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in drive)
        and all(math.isfinite(v) for v in drive)
    ):
        return "drive", (float(drive[0]), float(drive[1]))
    return None


# robot.pose's fields a page's canvas draws from (robots.sim_view).
POSE = frozenset(("x", "y", "theta", "linear", "angular", "bumper", "range", "sonar", "t"))

# How long a connection's access stands before it is read again (the robot's classes, who may
# drive it): at the next command or telemetry after that.
ACCESS_RECHECK_SECONDS = ACCESS_STANDS_SECONDS


@database_sync_to_async
def _access(user, name):
    """The robot if `user` may see it, and whether they may drive it, in one trip."""
    try:
        robot = get_robot_for_user(user, name)
    except Http404:
        return None, False
    return robot, robot.drivable_by(user)


class RobotConsumer(SayOnSocket, DirectDispatch, AsyncWebsocketConsumer):
    async def connect(self):
        name = self.scope["url_route"]["kwargs"]["name"]
        self.robot, self.may_drive = await _access(self.scope["user"], name)
        if self.robot is None:
            await self.close(code=4404)
            return
        self.shows: dict[str, dict] = {}
        # Of the ended runs whose values are still shown: those asked about, those this
        # viewer may see (robots.readings.shows_seen); asked again when access is re-read.
        self.runs_asked: set[int] = set()
        self.runs_seen: set[int] = set()
        self.drove = False
        # The workbench's robot panel (?panel=1) shows no list of runs: it is sent none, so
        # its queue's refresh (relative to the robot page's URL) never reaches a page without it.
        self.panel = b"panel=1" in self.scope.get("query_string", b"").split(b"&")
        self.checked = time.monotonic()
        self.group = robot_group(self.robot.name)
        await self.channel_layer.group_add(self.group, self.channel_name)
        await self.accept()
        # What ran or ended between the page's render and this connection; the stop in force
        # (the workbench's panel is rendered without it).
        await self.robot_runs({})
        await self.robot_stop({})
        self.watching = None
        if self.robot.url.startswith("sim:"):  # its agent streams poses while it is watched
            self.watching = asyncio.create_task(self._watch_poses())

    async def _watch_poses(self) -> None:
        while True:
            await send_to_agent(self.robot.name, "pose.watch", viewer=self.channel_name)
            await asyncio.sleep(WATCH_RENEW)

    async def disconnect(self, code):
        if getattr(self, "watching", None) is not None:
            self.watching.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self.watching
            await send_to_agent(self.robot.name, "pose.unwatch", viewer=self.channel_name)
        if getattr(self, "group", None):
            await self.channel_layer.group_discard(self.group, self.channel_name)
            if self.drove:  # a browser that leaves never leaves its robot driving
                await send_to_agent(self.robot.name, "robot.release", owner=self.channel_name)

    async def receive(self, text_data=None, bytes_data=None):
        """Driving by hand: ``{"drive": [linear, angular]}`` repeated while held,
        ``{"stop": true}`` when let go, ``{"release": true}`` to give up control,
        ``{"take": true}`` for staff to take control over; ``{"say": text}`` from the "Say
        to the robot" box (robots.say)."""
        if (said := parse_say(text_data)) is not None:
            await self.say_typed(said)
            return
        command = parse_control(text_data)
        if command is None or not await self.still_allowed():
            return
        kind, speeds = command
        user = self.scope["user"]
        robot, owner = self.robot.name, self.channel_name
        if kind in ("drive", "take") and not self.may_drive:
            error = _("Only %(who)s may drive %(robot)s.") % {
                "who": self.robot.get_drive_by_display(),
                "robot": robot,
            }
            await self.robot_teleop_error({"error": error})
            return
        if kind == "drive":
            self.drove = True
            linear, angular = speeds
            await send_to_agent(
                robot, "robot.teleop", owner=owner, user=user.get_username(),
                linear=linear, angular=angular,
            )  # fmt: skip
        elif kind == "stop":
            await send_to_agent(robot, "robot.teleop_stop", owner=owner)
        elif kind == "release":
            await send_to_agent(robot, "robot.release", owner=owner)
        elif kind == "take" and user.is_staff:
            self.drove = True
            await send_to_agent(robot, "robot.take_control", owner=owner, user=user.get_username())

    async def robot_lease(self, event):
        html = render_to_string(
            "robots/_control.html",
            {"holder": event["holder"], "mine": self._mine(event["holder"]),
             "user": self.scope["user"], "oob": True},
        )  # fmt: skip
        await self.send(html)

    def _mine(self, holder: dict | None) -> bool:
        return holder is not None and holder["key"] == self.channel_name

    async def robot_teleop_error(self, event):
        html = render_to_string("robots/_teleop_status.html", {"error": event["error"]})
        await self.send(html)

    async def still_allowed(self) -> bool:
        """Access read again once ACCESS_RECHECK_SECONDS have passed (a class losing the
        robot, its owner narrowing who drives it): a viewer who may no longer see it is
        closed, and what it drove released."""
        if time.monotonic() - self.checked < ACCESS_RECHECK_SECONDS:
            return True
        self.checked = time.monotonic()
        self.runs_asked, self.runs_seen = set(), set()
        robot, may_drive = await _access(self.scope["user"], self.robot.name)
        if self.drove and not may_drive:
            await send_to_agent(self.robot.name, "robot.release", owner=self.channel_name)
            self.drove = False
        self.may_drive = may_drive
        if robot is None:
            await self.channel_layer.group_discard(self.group, self.channel_name)
            self.group = None
            await self.close(code=4404)
            return False
        self.robot = robot
        return True

    async def robot_telemetry(self, event):
        if not await self.still_allowed():
            return
        shows_changed = bool(event["shows"] or event.get("all_shows"))
        if event.get("all_shows"):
            self.shows = {}
        self.shows.update(event["shows"])
        shown = await self._shows_seen() if shows_changed else {}
        # Rendering is CPU work for each viewer, four times a second: off the event loop.
        html = await sync_to_async(self._render, thread_sensitive=False)(
            event, shows_changed, shown
        )
        await self.send(html)

    async def robot_pose(self, event):
        """A sim's pose (robots.sim_view), up to 20 times a second while it moves: passed on
        as a small JSON frame that the page's canvas reads (static/robotide/simview.js), not
        HTML: the browser draws it."""
        if not await self.still_allowed():
            return
        pose = {k: v for k, v in event.items() if k in POSE}
        frame = {"type": "robot.pose", "pose": pose}
        await self.send(json.dumps(frame, separators=(",", ":")))

    async def _shows_seen(self) -> dict:
        """The shown values this viewer sees: ended runs' only if they may see the run."""
        unasked = ended_runs(self.shows) - self.runs_asked
        if unasked:
            user = self.scope["user"]
            self.runs_seen |= await database_sync_to_async(runs_seen)(user, unasked)
            self.runs_asked |= unasked
        return shows_seen(self.shows, self.runs_seen)

    def _render(self, event: dict, shows_changed: bool, shown: dict) -> str:
        sensors, units = event["sensors"], event.get("units", {})
        context = {"rows": sensor_rows(sensors, units), **status(sensors, units), "oob": True}
        html = render_to_string("robots/_sensors.html", context)
        html += render_to_string("robots/_status.html", context)
        if shows_changed:
            context = {"shows": show_items(shown), "oob": True}
            html += render_to_string("robots/_shows.html", context)
        return html

    async def robot_stop(self, event):
        """An emergency stop pressed or resumed (robots.stops): the banner shows it, and a
        Resume for whoever may."""
        user = self.scope["user"]
        context = await database_sync_to_async(stops.banner_context)(user, self.robot)
        # A plain form on the robot's page posts the session's CSRF secret (the cookie's value,
        # which Django takes as a token); the panel's posts with htmx's header.
        token = self.scope.get("cookies", {}).get(settings.CSRF_COOKIE_NAME, "")
        context.update(oob=True, panel=self.panel, csrf_token=token)
        await self.send(render_to_string("robots/_estop.html", context))

    async def robot_runs(self, event):
        if self.panel:
            return
        await self.send(await database_sync_to_async(self._render_runs)())

    def _render_runs(self) -> str:
        running = runs_for_user(self.scope["user"]).filter(robot=self.robot, state__in=Run.ACTIVE)
        return render_to_string("robots/_running.html", {"running": running, "oob": True})
