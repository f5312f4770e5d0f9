"""A robot's live page: sensor readings, values shown by programs, its running programs."""

import json
import math

from asgiref.sync import sync_to_async
from channels.db import database_sync_to_async
from channels.generic.websocket import AsyncWebsocketConsumer
from django.http import Http404
from django.template.loader import render_to_string

from programs.access import runs_for_user
from programs.models import Run
from robots.bus import send_to_agent
from robots.models import get_robot_for_user, robot_group
from robots.readings import link_error, sensor_rows, show_items


def parse_teleop(text: str | None) -> tuple[float, float] | str | None:
    """(linear, angular), "stop", or None for anything that is not a hand-driving command."""
    try:
        message = json.loads(text or "")
    except ValueError:
        return None
    if not isinstance(message, dict):
        return None
    if message.get("stop") is True:
        return "stop"
    drive = message.get("drive")
    if (
        isinstance(drive, list)
        and len(drive) == 2
        and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in drive)
        and all(math.isfinite(v) for v in drive)
    ):
        return float(drive[0]), float(drive[1])
    return None


@database_sync_to_async
def _get_robot(user, name):
    try:
        return get_robot_for_user(user, name)
    except Http404:
        return None


class RobotConsumer(AsyncWebsocketConsumer):
    async def connect(self):
        self.robot = await _get_robot(self.scope["user"], self.scope["url_route"]["kwargs"]["name"])
        if self.robot is None:
            await self.close(code=4404)
            return
        self.shows: dict[str, dict] = {}
        self.drove = False
        self.group = robot_group(self.robot.name)
        await self.channel_layer.group_add(self.group, self.channel_name)
        await self.accept()
        # What ran or ended between the page's render and this connection.
        await self.robot_runs({})

    async def disconnect(self, code):
        if getattr(self, "group", None):
            await self.channel_layer.group_discard(self.group, self.channel_name)
            if self.drove:  # a browser that leaves never leaves its robot driving
                await send_to_agent(self.robot.name, "robot.release", owner=self.channel_name)

    async def receive(self, text_data=None, bytes_data=None):
        """Driving by hand: ``{"drive": [linear, angular]}`` repeated while held, or
        ``{"stop": true}``. Anything else is ignored: the page also sends htmx's own frames."""
        command = parse_teleop(text_data)
        if command is None:
            return
        if command == "stop":
            await send_to_agent(self.robot.name, "robot.release", owner=self.channel_name)
            return
        self.drove = True
        linear, angular = command
        await send_to_agent(
            self.robot.name, "robot.teleop", owner=self.channel_name, linear=linear, angular=angular
        )

    async def robot_teleop_error(self, event):
        html = render_to_string("robots/_teleop_status.html", {"error": event["error"]})
        await self.send(html)

    async def robot_telemetry(self, event):
        shows_changed = bool(event["shows"] or event.get("all_shows"))
        if event.get("all_shows"):
            self.shows = {}
        self.shows.update(event["shows"])
        # Rendering is CPU work for each viewer, four times a second: off the event loop.
        html = await sync_to_async(self._render, thread_sensitive=False)(event, shows_changed)
        await self.send(html)

    def _render(self, event: dict, shows_changed: bool) -> str:
        sensors = event["sensors"]
        rows = sensor_rows(sensors, event.get("units", {}))
        context = {"rows": rows, "link_error": link_error(sensors), "oob": True}
        html = render_to_string("robots/_sensors.html", context)
        if shows_changed:
            context = {"shows": show_items(self.shows), "oob": True}
            html += render_to_string("robots/_shows.html", context)
        return html

    async def robot_runs(self, event):
        await self.send(await database_sync_to_async(self._render_runs)())

    def _render_runs(self) -> str:
        running = runs_for_user(self.scope["user"]).filter(robot=self.robot, state__in=Run.ACTIVE)
        return render_to_string("robots/_running.html", {"running": running, "oob": True})
