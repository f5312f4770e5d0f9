"""A robot's live page: sensor readings, values shown by programs, its running programs."""

import base64

from channels.db import database_sync_to_async
from channels.generic.websocket import AsyncWebsocketConsumer
from django.http import Http404
from django.template.loader import render_to_string

from programs.access import runs_for_user
from programs.models import Run
from robots.models import get_robot_for_user, robot_group


@database_sync_to_async
def _get_robot(user, name):
    try:
        return get_robot_for_user(user, name)
    except Http404:
        return None


def flatten(readings: dict, prefix: str = "") -> list[tuple[str, object]]:
    rows = []
    for key, value in readings.items():
        if isinstance(value, dict):
            rows.extend(flatten(value, f"{prefix}{key}."))
        else:
            rows.append((f"{prefix}{key}", value))
    return rows


def show_item(name: str, entry: dict) -> dict:
    value = entry["value"]
    item = {"name": name, "run": entry["run"], "value": value, "svg": None}
    if isinstance(value, str) and value.lstrip().startswith(("<svg", "<?xml")):
        # Shown as an image: a browser runs no script from an SVG inside <img>.
        item["svg"] = "data:image/svg+xml;base64," + base64.b64encode(value.encode()).decode()
    return item


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

    async def disconnect(self, code):
        if getattr(self, "group", None):
            await self.channel_layer.group_discard(self.group, self.channel_name)

    async def robot_telemetry(self, event):
        units = event.get("units", {})
        rows = [(name, value, units.get(name, "")) for name, value in flatten(event["sensors"])]
        html = render_to_string("robots/_sensors.html", {"rows": rows, "oob": True})
        if event["shows"]:
            self.shows.update(event["shows"])
            items = [show_item(name, entry) for name, entry in sorted(self.shows.items())]
            html += render_to_string("robots/_shows.html", {"shows": items, "oob": True})
        await self.send(html)

    async def robot_runs(self, event):
        await self.send(await database_sync_to_async(self._render_runs)())

    def _render_runs(self) -> str:
        running = runs_for_user(self.scope["user"]).filter(robot=self.robot, state__in=Run.ACTIVE)
        return render_to_string("robots/_running.html", {"running": running, "oob": True})
