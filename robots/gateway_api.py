"""/api/robots/{name}/endpoints: a MAVLink robot's router endpoints, with their live stats.

The vehicle link (the robot's URL) and the driver's own endpoint are listed with the ids
``"vehicle"`` and ``"robot"``; they change with the robot's URL, not here. The rows are the
robot's GatewayEndpoint records: kept in the database, applied by its agent at once.
"""

from __future__ import annotations

import re
from datetime import UTC, datetime
from urllib.parse import urlsplit

from django.http import FileResponse, HttpRequest
from django.utils.translation import gettext as _
from ninja import Field, Router, Schema
from ninja.errors import HttpError
from ninja.responses import Status
from pydantic import StrictBool, model_validator

from gateway import specs
from programs.api import Error
from robotide.names import Name
from robotide.schemas import Body
from robots.bus import AgentUnavailable, ask_agent_sync
from robots.gateway import recordings_dir
from robots.models import GatewayEndpoint, Robot, get_robot_for_user

gateway_router = Router(tags=["gateway"])

STATS_TIMEOUT = 2.0


class EndpointIn(Body):
    type: str = Field(description="udp, tcp or serial", json_schema_extra={"enum": specs.TYPES})
    mode: str | None = Field(None, description="server (listens) or client; udp and tcp")
    address: str | None = Field(None, description="HOST:PORT; udp and tcp", max_length=200)
    device: str | None = Field(None, description="serial device path", max_length=200)
    baud: int | None = Field(None, description="serial speed, bit/s")
    read_only: StrictBool = False
    allow: list[int] | None = Field(None, description="only these message ids pass")
    block: list[int] = Field([], description="these message ids never pass")
    control: str = Field(
        "always", description="may it command the vehicle: always, lease (while no program"
        " holds the robot) or never", json_schema_extra={"enum": specs.CONTROLS},
    )  # fmt: skip

    @model_validator(mode="after")
    def usable(self):
        self.spec()
        return self

    def spec(self) -> dict:
        return specs.check(self.model_dump(exclude_none=True))


class EndpointOut(Schema):
    id: int | str = Field(description='a row\'s number, or "vehicle" / "robot"')
    role: str = Field(description="vehicle, robot, gcs, programs, or empty: added by a user")
    type: str
    mode: str | None = None
    address: str | None = None
    device: str | None = None
    baud: int | None = None
    read_only: bool = False
    allow: list[int] | None = None
    block: list[int] = []
    control: str = "always"
    commanding: float | None = Field(
        None, description="seconds since it last commanded the vehicle (a ground station)"
    )
    status: str = Field(description="up, connecting, down, error, or unknown (agent away)")
    error: str = ""
    bound: str | None = Field(None, description="the address a server listens on")
    stats: dict = Field({}, description="counts: frames and bytes in and out, drops, errors")
    rates: dict = Field({}, description="the same per second, over the last second")
    systems: list[dict] = Field([], description="MAVLink systems heard here, seconds ago")
    peers: list[str] | None = None
    clients: list[dict] | None = None


LIVE_KEYS = ("status", "error", "bound", "stats", "rates", "systems", "peers", "clients",
             "commanding")  # fmt: skip


MAVLINK_SCHEMES = ("mavlink", "mavlink+tcp", "mavlink+udp")


def has_router(robot: Robot) -> bool:
    return urlsplit(robot.url).scheme in MAVLINK_SCHEMES


def _mavlink_robot(request: HttpRequest, name: str, change: bool = False) -> Robot:
    robot = get_robot_for_user(request.user, name)
    if change and not robot.configurable_by(request.user):
        raise HttpError(403, _("Only the robot's owner or staff change its endpoints."))
    if not has_router(robot):
        raise HttpError(409, no_router(name))
    return robot


def no_router(name: str) -> str:
    return _("Robot %(robot)s is not a MAVLink robot: it has no router.") % {"robot": repr(name)}


def live_stats(robot: Robot, kind: str = "gateway.stats") -> dict | None:
    try:
        reply = ask_agent_sync(robot.name, kind, timeout=STATS_TIMEOUT)
    except AgentUnavailable:
        return None
    return {str(key): value for key, value in reply.get("endpoints", {}).items()}


def endpoint_out(key, role: str, spec: dict, live: dict | None) -> dict:
    row = {"id": key, "role": role, **spec}
    if live is None:
        return {**row, "status": "unknown", "error": _("the robot's agent is not answering")}
    found = live.get(str(key))
    if found is None:
        return {**row, "status": "down", "error": _("not started")}
    return {**row, **{k: found[k] for k in LIVE_KEYS if k in found}}


def endpoint_rows(robot: Robot, live: dict | None = None) -> list[dict]:
    """The robot's endpoints as the API lists them; ``live``: the agent's stats (asked if None)."""
    live = live if live is not None else live_stats(robot)
    rows = []
    if live is not None:
        vehicle = live.get("vehicle", {})
        rows.append(endpoint_out("vehicle", "vehicle", vehicle.get("spec") or {"type": "?"}, live))
        if "robot" in live:
            rows.append(endpoint_out("robot", "robot", {"type": "local"}, live))
    for endpoint in robot.endpoints.all():
        rows.append(endpoint_out(endpoint.pk, endpoint.role, endpoint.spec(), live))
    return rows


@gateway_router.get("/{name}/endpoints", response={200: list[EndpointOut], 409: Error})
def list_endpoints(request, name: Name):
    """Every endpoint of the robot's router, with its live stats."""
    robot = _mavlink_robot(request, name)
    return endpoint_rows(robot)


@gateway_router.post("/{name}/endpoints", response={201: EndpointOut, 409: Error})
def add_endpoint(request, name: Name, data: EndpointIn):
    """Add an endpoint; it starts at once. One that cannot (its address in use, no such host)
    is kept with its error, and the others route on."""
    robot = _mavlink_robot(request, name, change=True)
    return Status(201, add_endpoint_row(robot, data.spec()))


def add_endpoint_row(robot: Robot, spec: dict) -> dict:
    """Keep the endpoint (a spec gateway.specs.check cleaned) and have the agent start it."""
    endpoint = GatewayEndpoint(robot=robot)
    endpoint.set_spec(spec)
    endpoint.save()
    return endpoint_out(endpoint.pk, "", endpoint.spec(), live_stats(robot, "gateway.reload"))


@gateway_router.put("/{name}/endpoints/{int:endpoint_id}", response={200: EndpointOut, 409: Error})
def change_endpoint(request, name: Name, endpoint_id: int, data: EndpointIn):
    """Replace an endpoint's description; the router restarts it so."""
    robot = _mavlink_robot(request, name, change=True)
    endpoint = _row(robot, endpoint_id)
    endpoint.set_spec(data.spec())
    endpoint.save()
    return endpoint_out(
        endpoint.pk, endpoint.role, endpoint.spec(), live_stats(robot, "gateway.reload")
    )


@gateway_router.delete("/{name}/endpoints/{int:endpoint_id}", response={204: None, 409: Error})
def delete_endpoint(request, name: Name, endpoint_id: int):
    robot = _mavlink_robot(request, name, change=True)
    delete_endpoint_row(robot, endpoint_id)
    return Status(204, None)


def delete_endpoint_row(robot: Robot, endpoint_id: int) -> None:
    _row(robot, endpoint_id).delete()
    live_stats(robot, "gateway.reload")


def _row(robot: Robot, endpoint_id: int) -> GatewayEndpoint:
    try:
        return robot.endpoints.get(pk=endpoint_id)
    except GatewayEndpoint.DoesNotExist:
        raise HttpError(
            404,
            _("Robot %(robot)s has no endpoint %(id)s.")
            % {"robot": repr(robot.name), "id": endpoint_id},
        ) from None


# -- recordings ---------------------------------------------------------------------------

TLOG_NAME = re.compile(r"^[\w.-]+\.tlog$")


class RecordIn(Body):
    on: StrictBool = Field(description="true: start a new .tlog of every routed frame; false: stop")


class RecordingFile(Schema):
    name: str
    bytes: int
    modified: datetime


class Recordings(Schema):
    current: dict | None = Field(None, description="the recording under way: path, frames...")
    files: list[RecordingFile]


def _recordings(robot: Robot, current: dict | None) -> dict:
    folder = recordings_dir(robot.name)
    files = sorted(folder.glob("*.tlog"), reverse=True) if folder.is_dir() else []
    listed = [
        {"name": f.name, "bytes": f.stat().st_size,
         "modified": datetime.fromtimestamp(f.stat().st_mtime, tz=UTC)}
        for f in files
    ]  # fmt: skip
    return {"current": current, "files": listed}


@gateway_router.get("/{name}/recordings", response={200: Recordings, 409: Error})
def list_recordings(request, name: Name):
    """The robot's .tlog recordings (kept where its agent runs), and the one under way."""
    robot = _mavlink_robot(request, name)
    try:
        current = ask_agent_sync(robot.name, "gateway.stats", timeout=STATS_TIMEOUT)["recording"]
    except AgentUnavailable:
        current = None
    return _recordings(robot, current)


@gateway_router.post("/{name}/recordings", response={200: Recordings, 409: Error, 503: Error})
def record(request, name: Name, data: RecordIn):
    """Start or stop recording every frame the robot's router routes."""
    robot = _mavlink_robot(request, name, change=True)
    reply = ask_agent_sync(robot.name, "gateway.record", timeout=STATS_TIMEOUT, on=data.on)
    return _recordings(robot, reply["recording"])


@gateway_router.get(
    "/{name}/recordings/{file}",
    response={200: None, 409: Error},
    openapi_extra={"responses": {"200": {
        "description": "the .tlog",
        "content": {"application/octet-stream": {"schema": {"type": "string", "format": "binary"}}},
    }}},
)  # fmt: skip
def download_recording(request, name: Name, file: Name):
    robot = _mavlink_robot(request, name)
    path = recordings_dir(robot.name) / file
    if not TLOG_NAME.match(file) or not path.is_file():
        raise HttpError(
            404,
            _("Robot %(robot)s has no recording %(file)s.")
            % {"robot": repr(robot.name), "file": repr(file)},
        )
    return FileResponse(path.open("rb"), as_attachment=True, filename=file,
                        content_type="application/octet-stream")  # fmt: skip
