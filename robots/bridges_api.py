"""/api/robots/{name}/bridges: the robot's serial devices shared over TCP, with their clients."""

from __future__ import annotations

from typing import Literal

from django.utils.translation import gettext as _
from ninja import Field, Router, Schema
from ninja.errors import HttpError
from ninja.responses import Status
from pydantic import field_validator

from gateway import specs
from gateway.router import split_address
from programs.api import Error
from robotide.names import Name
from robotide.schemas import Body
from robots.bus import AgentUnavailable, ask_agent_sync
from robots.models import Robot, SerialBridge, get_robot_for_user

bridges_router = Router(tags=["gateway"])


class BridgeIn(Body):
    device: str = Field("", max_length=200, description="a serial device; empty: the robot's own")
    baud: int = Field(9600, json_schema_extra={"enum": list(specs.BAUDS)})
    address: str = Field(max_length=200, description="HOST:PORT to listen on, e.g. 0.0.0.0:4001")
    protocol: Literal["raw", "rfc2217"] = "raw"
    when_busy: Literal["read_only", "refuse"] = Field(
        "read_only", description="a client that comes while a program drives the robot"
    )

    @field_validator("device")
    @classmethod
    def a_path(cls, value):
        if value and not value.startswith("/"):
            raise ValueError(_("device must be a path such as /dev/ttyUSB0, or empty"))
        return value

    @field_validator("baud")
    @classmethod
    def a_speed(cls, value):
        if value not in specs.BAUDS:
            raise ValueError(
                _("baud must be a serial speed (%(bauds)s)")
                % {"bauds": ", ".join(map(str, specs.BAUDS))}
            )
        return value

    @field_validator("address")
    @classmethod
    def host_port(cls, value):
        split_address(value)
        return value


class BridgeOut(Schema):
    id: int
    device: str
    baud: int
    address: str
    protocol: str
    when_busy: str
    status: str = Field(description="up, error, or unknown (agent away)")
    error: str = ""
    live: dict = Field({}, description="the bound address, device open, clients, refusals")


def _robot(request, name: str, change: bool = False) -> Robot:
    robot = get_robot_for_user(request.user, name)
    if change and not robot.configurable_by(request.user):
        raise HttpError(403, _("Only the robot's owner or staff change its serial bridges."))
    if change and robot.personal and not request.user.is_staff:  # a device path is the host's
        raise HttpError(403, _("A personal sim has no serial port to share; staff add bridges."))
    return robot


def live_stats(robot: Robot, kind: str = "bridges.stats") -> dict | None:
    try:
        reply = ask_agent_sync(robot.name, kind, timeout=2.0)
    except AgentUnavailable:
        return None
    return {str(key): value for key, value in reply.get("bridges", {}).items()}


def bridge_out(row: SerialBridge, live: dict | None) -> dict:
    fields = {k: getattr(row, k) for k in ("id", "device", "baud", "address", "protocol")}
    fields["when_busy"] = row.when_busy
    if live is None:
        return {**fields, "status": "unknown", "error": _("the robot's agent is not answering")}
    found = dict(live.get(str(row.pk)) or {"status": "error", "error": _("not started")})
    status, error = found.pop("status", "up"), found.pop("error", "")
    return {
        **fields,
        "status": status,
        "error": error or found.get("last_error", ""),
        "live": found,
    }


@bridges_router.get("/{name}/bridges", response=list[BridgeOut])
def list_bridges(request, name: Name):
    return bridge_rows(_robot(request, name))


def bridge_rows(robot: Robot) -> list[dict]:
    """The robot's serial bridges as the API lists them, with the agent's live view."""
    live = live_stats(robot)
    return [bridge_out(row, live) for row in robot.bridges.all()]


@bridges_router.post("/{name}/bridges", response={201: BridgeOut, 409: Error})
def add_bridge(request, name: Name, data: BridgeIn):
    """Share a serial device over TCP; it listens at once (or says why it cannot)."""
    robot = _robot(request, name, change=True)
    row = SerialBridge.objects.create(robot=robot, **data.dict())
    return Status(201, bridge_out(row, live_stats(robot, "bridges.reload")))


@bridges_router.delete("/{name}/bridges/{int:bridge_id}", response={204: None})
def delete_bridge(request, name: Name, bridge_id: int):
    robot = _robot(request, name, change=True)
    deleted, _rows = robot.bridges.filter(pk=bridge_id).delete()
    if not deleted:
        raise HttpError(
            404,
            _("Robot %(robot)s has no serial bridge %(id)s.")
            % {"robot": repr(robot.name), "id": bridge_id},
        )
    live_stats(robot, "bridges.reload")
    return Status(204, None)
