"""The robot page's MAVLink gateway and serial bridges card, live, and its add/remove forms
(templates/robots/_gateway.html); the same rows as /api/robots/NAME/endpoints and bridges."""

from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.core.exceptions import PermissionDenied
from django.http import HttpRequest, HttpResponse
from django.shortcuts import get_object_or_404, redirect, render
from django.utils.translation import gettext as _
from django.views.decorators.http import require_POST

from gateway import specs
from robots import bridges_api, gateway_api
from robots.models import get_robot_for_user

# -- the MAVLink gateway and the serial bridges, live ------------------------------------------

ENDPOINT_NAMES = {
    "vehicle": "vehicle link",
    "robot": "this robot's driver",
    "gcs": "ground stations",
    "programs": "programs (ROBOT_MAVLINK)",
}
FIXED_ENDPOINTS = ("vehicle", "robot")  # they follow the robot's URL: not removed here


def gateway_context(robot, away: bool = False) -> dict | None:
    """What templates/robots/_gateway.html shows; None if the robot has neither a router nor
    a serial bridge. ``away``: the agent did not answer just now, so it is not asked again."""
    router = gateway_api.has_router(robot)
    bridges = list(robot.bridges.all())
    if not router and not bridges:
        return None
    endpoints = []
    if router:
        live = None if away else gateway_api.live_stats(robot)
        away = live is None
        if live is None:  # the rows kept, each "unknown": endpoint_rows would ask again
            rows = [{"id": "vehicle", "role": "vehicle", "type": "?", "status": "unknown"}]
            rows += [
                gateway_api.endpoint_out(e.pk, e.role, e.spec(), None)
                for e in robot.endpoints.all()
            ]
        else:
            rows = gateway_api.endpoint_rows(robot, live)
        endpoints = [_endpoint_shown(row) for row in rows]
    bridges_live = None if away else bridges_api.live_stats(robot)
    return {
        "router": router,
        "away": away or (bool(bridges) and bridges_live is None),
        "endpoints": endpoints,
        "bridges": [_bridge_shown(bridges_api.bridge_out(row, bridges_live)) for row in bridges],
        "bauds": specs.BAUDS,
    }


def _endpoint_shown(row: dict) -> dict:
    try:
        text = specs.describe(row)
    except (KeyError, TypeError):
        text = {"robot": "inside the agent", "vehicle": ""}.get(row["id"], "")
    bound = row.get("bound") or ""
    # A server asked for port 0 (any free one): the port it got is what a client needs.
    listening = bound if row.get("mode") == "server" and bound != row.get("address") else ""
    stats, rates = row.get("stats") or {}, row.get("rates") or {}
    counted = bool(stats) or bool(rates)
    systems = row.get("systems") or []
    clients = [_peer_of(client) for client in row.get("clients") or []]
    return {
        **row,
        "name": ENDPOINT_NAMES.get(row["role"]) or text or f"endpoint {row['id']}",
        "text": text if row["role"] in ENDPOINT_NAMES and not listening else "",
        "listening": listening,
        "asked": text,
        "removable": row["id"] not in FIXED_ENDPOINTS,
        "counted": counted,
        "msgs_in": _per_second(rates.get("frames_in")),
        "msgs_out": _per_second(rates.get("frames_out")),
        "bytes_in": _bytes(rates.get("bytes_in")),
        "bytes_out": _bytes(rates.get("bytes_out")),
        "drops": stats.get("drops", 0),
        # A server nobody has reached yet drops what it would send them: no alarm for that.
        "drops_warn": bool(stats.get("drops"))
        and (row.get("mode") != "server" or bool(row.get("peers") or clients)),
        "drops_rate": rates.get("drops", 0),
        "parse_errors": stats.get("parse_errors", 0),
        "parse_errors_rate": rates.get("parse_errors", 0),
        "systems_text": ", ".join(f"{s['system']}:{s['component']}" for s in systems),
        "systems_seen": ", ".join(
            f"{s['system']}:{s['component']} {s.get('seen', 0):g} s ago" for s in systems
        ),
        "peers_text": ", ".join(row.get("peers") or []),
        "clients_text": ", ".join(clients),
        "filters": _filters(row),
    }


def _peer_of(client) -> str:
    """A TCP server's client: its name ends with the peer's address."""
    if isinstance(client, dict):
        return str(client.get("name", "")).rpartition(" ")[2] or "?"
    return str(client)


def _filters(row: dict) -> str:
    said = []
    if row.get("allow") is not None:
        said.append("only " + ", ".join(map(str, row["allow"])))
    if row.get("block"):
        said.append("not " + ", ".join(map(str, row["block"])))
    return "; ".join(said)


def _bridge_shown(row: dict) -> dict:
    live = row.get("live") or {}
    clients = [
        {**client, "bytes": _bytes(client.get("bytes_in", 0) + client.get("bytes_out", 0), "")}
        for client in live.get("clients") or []
    ]
    return {
        **row,
        "device_shown": row["device"] or "robot's port",
        "bound": live.get("address") or "",
        "clients": clients,
        "refused": live.get("refused", 0),
    }


def _per_second(value) -> str:
    if not value:
        return "0"
    return f"{value:.1f}" if value < 10 else f"{value:,.0f}"


def _bytes(value, per: str = "/s") -> str:
    """1 kB = 1000 B, as network speeds are given."""
    value = value or 0
    for unit in ("B", "kB", "MB"):
        if value < 1000 or unit == "MB":
            shown = f"{value:.0f}" if unit == "B" or value >= 100 else f"{value:.1f}"
            return f"{shown} {unit}{per}"
        value /= 1000
    raise AssertionError("unreachable")


def _render_gateway(request, robot, status: int = 200, **extra) -> HttpResponse:
    context = {
        "robot": robot,
        "can_configure": robot.configurable_by(request.user),
        "gateway": gateway_context(robot),
        **extra,
    }
    if context["gateway"] is None:  # no longer a MAVLink robot: the card goes away
        return HttpResponse("")
    return render(request, "robots/_gateway.html", context, status=status)


@login_required
def robot_gateway(request: HttpRequest, name: str) -> HttpResponse:
    """The gateway card alone: the robot page reloads it every 2 s."""
    return _render_gateway(request, get_robot_for_user(request.user, name))


def _configurable(request: HttpRequest, name: str):
    robot = get_robot_for_user(request.user, name)
    if not robot.configurable_by(request.user):
        raise PermissionDenied(_("Only the robot's owner or staff change its endpoints."))
    return robot


def _no_router(robot) -> HttpResponse:
    why = gateway_api.no_router(robot.name)
    return HttpResponse(why, status=409, content_type="text/plain")


def endpoint_spec(form) -> dict:
    """The add-an-endpoint form as a spec, cleaned by gateway.specs.check (ValueError)."""
    kind = form.get("type", "").strip()
    spec: dict = {"type": kind, "read_only": form.get("read_only") in ("on", "true", "1")}
    if kind == "serial":
        spec["device"] = form.get("device", "").strip()
        baud = form.get("baud", "").strip() or "57600"
        if not baud.isdigit():
            raise ValueError(_("baud must be a serial speed, not %(baud)s") % {"baud": repr(baud)})
        spec["baud"] = int(baud)
    else:
        spec["mode"] = form.get("mode", "client").strip()
        spec["address"] = form.get("address", "").strip()
    allow = _message_ids("allow", form.get("allow", ""))
    if allow:
        spec["allow"] = allow
    spec["block"] = _message_ids("block", form.get("block", ""))
    spec["control"] = form.get("control", "always").strip() or "always"
    return specs.check(spec)


def _message_ids(name: str, text: str) -> list[int]:
    words = [word for word in text.replace(",", " ").split() if word]
    bad = [word for word in words if not word.isdigit()]
    if bad:
        raise ValueError(
            _("%(field)s: message ids are numbers separated by commas, not %(bad)s")
            % {"field": name, "bad": repr(bad[0])}
        )
    return [int(word) for word in words]


@login_required
@require_POST
def robot_endpoint_add(request: HttpRequest, name: str) -> HttpResponse:
    robot = _configurable(request, name)
    if not gateway_api.has_router(robot):
        return _no_router(robot)
    try:
        spec = endpoint_spec(request.POST)
    except ValueError as exc:
        if request.htmx:  # htmx swaps 2xx answers only: the card says what is wrong
            return _render_gateway(request, robot, error=str(exc), form=request.POST)
        messages.error(request, _("Endpoint not added: %(why)s") % {"why": exc})
        return redirect("robot-detail", robot.name)
    row = gateway_api.add_endpoint_row(robot, spec)
    said = _("Endpoint %(endpoint)s added.") % {"endpoint": specs.describe(spec)}
    if row["status"] == "error":
        said = _("Endpoint %(endpoint)s added, but it does not run: %(why)s.") % {
            "endpoint": specs.describe(spec),
            "why": row["error"],
        }
    if request.htmx:
        return _render_gateway(request, robot, notice=said)
    (messages.warning if row["status"] == "error" else messages.success)(request, said)
    return redirect("robot-detail", robot.name)


@login_required
@require_POST
def robot_endpoint_delete(request: HttpRequest, name: str, endpoint_id: int) -> HttpResponse:
    robot = _configurable(request, name)
    if not gateway_api.has_router(robot):
        return _no_router(robot)
    endpoint = get_object_or_404(robot.endpoints, pk=endpoint_id)
    try:
        text = specs.describe(endpoint.spec())
    except (KeyError, ValueError):
        text = _("endpoint %(id)s") % {"id": endpoint.pk}
    gateway_api.delete_endpoint_row(robot, endpoint.pk)
    said = _("Endpoint %(endpoint)s removed.") % {"endpoint": text}
    if request.htmx:
        return _render_gateway(request, robot, notice=said)
    messages.success(request, said)
    return redirect("robot-detail", robot.name)
