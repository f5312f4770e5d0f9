"""A robot's live page: sensor readings, values shown by programs, its running programs."""

from asgiref.sync import sync_to_async
from channels.db import database_sync_to_async
from channels.generic.websocket import AsyncWebsocketConsumer
from django.http import Http404
from django.template.loader import render_to_string

from programs.access import runs_for_user
from programs.models import Run
from robots.models import get_robot_for_user, robot_group
from robots.readings import sensor_rows, show_items


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
        self.group = robot_group(self.robot.name)
        await self.channel_layer.group_add(self.group, self.channel_name)
        await self.accept()
        # What ran or ended between the page's render and this connection.
        await self.robot_runs({})

    async def disconnect(self, code):
        if getattr(self, "group", None):
            await self.channel_layer.group_discard(self.group, self.channel_name)

    async def robot_telemetry(self, event):
        shows_changed = bool(event["shows"] or event.get("all_shows"))
        if event.get("all_shows"):
            self.shows = {}
        self.shows.update(event["shows"])
        # Rendering is CPU work for each viewer, four times a second: off the event loop.
        html = await sync_to_async(self._render, thread_sensitive=False)(event, shows_changed)
        await self.send(html)

    def _render(self, event: dict, shows_changed: bool) -> str:
        rows = sensor_rows(event["sensors"], event.get("units", {}))
        html = render_to_string("robots/_sensors.html", {"rows": rows, "oob": True})
        if shows_changed:
            context = {"shows": show_items(self.shows), "oob": True}
            html += render_to_string("robots/_shows.html", context)
        return html

    async def robot_runs(self, event):
        await self.send(await database_sync_to_async(self._render_runs)())

    def _render_runs(self) -> str:
        running = runs_for_user(self.scope["user"]).filter(robot=self.robot, state__in=Run.ACTIVE)
        return render_to_string("robots/_running.html", {"running": running, "oob": True})
