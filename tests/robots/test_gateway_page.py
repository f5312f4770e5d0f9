"""The robot page's gateway card: the MAVLink router's endpoints and the serial bridges, live,
and endpoints added and removed there by whoever may configure the robot.

The agent's answers are stubbed here (``gateway_api.live_stats``, ``bridges_api.live_stats``)
with what a router and a bridge answer (robots.gateway.Gateway.stats, robots.bridges); a real
agent and a real vehicle are in tests/browser/test_gateway_page.py and tests/e2e/test_gateway.py.
"""

import pytest
from django.contrib.auth.models import Group, User

from robots import bridges_api, gateway_api
from robots.bus import AgentUnavailable
from robots.models import GatewayEndpoint, Robot, SerialBridge

pytestmark = pytest.mark.django_db

HTMX = {"HTTP_HX_REQUEST": "true"}


def figures(frames_in, frames_out, bytes_in, bytes_out, drops=0, parse_errors=0):
    return dict(
        frames_in=frames_in, frames_out=frames_out, bytes_in=bytes_in, bytes_out=bytes_out,
        drops=drops, parse_errors=parse_errors,
    )  # fmt: skip


def endpoint(name, status="up", error="", rates=None, stats=None, systems=(), **extra):
    return {
        "id": 7, "name": name, "read_only": False, "status": status, "error": error,
        "stats": stats or figures(0, 0, 0, 0), "rates": rates or figures(0, 0, 0, 0),
        "systems": [{"system": s, "component": c, "seen": 0.4} for s, c in systems], **extra,
    }  # fmt: skip


@pytest.fixture
def owner():
    return User.objects.create_user("owner")


@pytest.fixture
def rover(owner):
    robot = Robot.objects.create(
        name="rover", url="mavlink+tcp://127.0.0.1:5760", owner=owner, gateway_seeded=True
    )
    for role, address in (("gcs", "0.0.0.0:0"), ("programs", "127.0.0.1:14551")):
        row = GatewayEndpoint(robot=robot, role=role)
        row.set_spec({"type": "udp", "mode": "server", "address": address, "read_only": False,
                      "allow": None, "block": []})  # fmt: skip
        row.save()
    return robot


@pytest.fixture
def live(rover, monkeypatch):
    """The agent's answers: its router's endpoints and its serial bridges, as it sends them."""
    gcs, programs = (rover.endpoints.get(role=role).pk for role in ("gcs", "programs"))
    vehicle_spec = {"type": "tcp", "mode": "client", "address": "127.0.0.1:5760",
                    "read_only": False, "allow": None, "block": []}  # fmt: skip
    endpoints = {
        "vehicle": endpoint(
            "vehicle",
            rates=figures(52.3, 11.0, 2436.0, 520.0),
            stats=figures(5230, 1100, 243600, 52000, parse_errors=2),
            systems=[(1, 1)],
            spec=vehicle_spec,
        ),
        "robot": endpoint(
            "local",
            rates=figures(11.0, 52.3, 520.0, 2436.0),
            stats=figures(1100, 5230, 52000, 243600),
            systems=[(245, 190)],
        ),
        str(gcs): endpoint(
            "udpin:0.0.0.0:0",
            rates=figures(1.0, 52.3, 21.0, 1_234_567.0),
            stats=figures(100, 5230, 2100, 243600, drops=3),
            systems=[(255, 190)],
            bound="0.0.0.0:14550",
            peers=["127.0.0.1:50123"],
        ),
        str(programs): {"status": "error", "error": "[Errno 98] Address already in use"},
    }
    bridges = {}
    state = {"gateway": endpoints, "bridges": bridges, "asked": []}

    def gateway_live(robot, kind="gateway.stats"):
        state["asked"].append(kind)
        return state["gateway"]

    def bridges_live(robot, kind="bridges.stats"):
        state["asked"].append(kind)
        return state["bridges"]

    monkeypatch.setattr(gateway_api, "live_stats", gateway_live)
    monkeypatch.setattr(bridges_api, "live_stats", bridges_live)
    return state


@pytest.fixture
def no_robot_state(monkeypatch):
    """The robot page's own ask for the robot's state: answered by nobody, at once."""

    def away(name, kind, **_):
        raise AgentUnavailable(f"The agent of robot {name!r} did not answer; is it running?")

    monkeypatch.setattr("robots.views.ask_agent_sync", away)


def card(client, name="rover", **headers):
    response = client.get(f"/robots/{name}/gateway", **headers)
    assert response.status_code == 200, response.content.decode()
    return response.content.decode()


def row_of(page: str, row_id) -> str:
    start = page.index(f'id="endpoint-{row_id}"')
    return page[start : page.index("</tr>", start)]


def test_the_card_shows_every_endpoint_with_its_figures(client, owner, rover, live):
    client.force_login(owner)
    page = card(client)
    assert 'hx-trigger="every 2s"' in page and 'hx-swap="outerHTML"' in page
    assert f'hx-get="/robots/{rover.name}/gateway"' in page
    vehicle = row_of(page, "vehicle")
    assert "vehicle link" in vehicle and "tcp:127.0.0.1:5760" in vehicle
    assert ">up<" in vehicle and ">52<" in vehicle and ">11<" in vehicle  # msg/s in and out
    assert "2.4 kB/s" in vehicle and "520 B/s" in vehicle
    assert '<td class="num warn"' in vehicle  # its 2 parse errors stand out
    assert "1:1" in vehicle and "1:1 0.4 s ago" in vehicle
    driver = row_of(page, "robot")
    assert "this robot&#x27;s driver" in driver and "245:190" in driver
    gcs = row_of(page, rover.endpoints.get(role="gcs").pk)
    assert "ground stations" in gcs and 'title="asked for udpin:0.0.0.0:0"' in gcs
    assert "listening on <code>0.0.0.0:14550</code>" in gcs  # the port it got
    assert "1.2 MB/s" in gcs and "peers 127.0.0.1:50123" in gcs and "255:190" in gcs
    assert '<td class="num warn" title="0 a second now">3<' in gcs  # dropped for its peer
    programs = row_of(page, rover.endpoints.get(role="programs").pk)
    assert "programs (ROBOT_MAVLINK)" in programs and ">error<" in programs
    assert "udpin:127.0.0.1:14551" in programs
    assert "Address already in use" in programs and "—" in programs
    # The owner may remove the rows kept in the database, not the vehicle link nor the driver.
    assert "Remove" not in vehicle and "Remove" not in driver
    assert "Remove ground stations" in gcs and "Add an endpoint" in page


def test_the_robot_page_includes_the_card_once_and_only_for_a_router_or_bridges(
    client, owner, rover, live, no_robot_state
):
    client.force_login(owner)
    page = client.get(f"/robots/{rover.name}/").content.decode()
    assert page.count('id="gateway"') == 1
    # The robot's agent was away for the page: the card is not asked again, and says so.
    assert "not answering" in page and live["asked"] == []
    assert "ground stations" in page and ">unknown<" in page
    Robot.objects.create(name="plain", url="sim://")
    assert 'id="gateway"' not in client.get("/robots/plain/").content.decode()
    assert card(client, "plain") == ""  # the card goes away if the robot loses its router


def test_serial_bridges_show_their_clients(client, owner, live):
    robot = Robot.objects.create(name="arm", url="sim://", owner=owner)
    shared = SerialBridge.objects.create(robot=robot, device="/dev/ttyUSB0", baud=115200,
                                         address="127.0.0.1:4001", protocol="rfc2217")  # fmt: skip
    own = SerialBridge.objects.create(robot=robot, address="127.0.0.1:0")
    live["bridges"] = {
        str(shared.pk): {
            "status": "up", "address": "127.0.0.1:4001", "device_open": True, "refused": 1,
            "last_error": "",
            "clients": [{"peer": "127.0.0.1:40000", "mode": "read_only", "since": 1.0,
                         "bytes_in": 10, "bytes_out": 2990}],
        },
        str(own.pk): {"status": "error",
                      "error": "the robot's driver does not share what it reads"},
    }  # fmt: skip
    client.force_login(owner)
    page = card(client, "arm")
    assert "Serial bridges" in page and "MAVLink gateway" not in page
    assert "/dev/ttyUSB0" in page and "RFC 2217" in page and "115200 bit/s" in page
    assert "127.0.0.1:40000" in page and "readonly" in page and "3.0 kB" in page
    assert "1 refused" in page
    assert "robot&#x27;s port" in page and "does not share what it reads" in page
    assert "Add an endpoint" not in page  # no router: no endpoints to add


def test_the_owner_adds_an_endpoint_with_a_plain_form(client, owner, rover, live, no_robot_state):
    client.force_login(owner)
    response = client.post(
        f"/robots/{rover.name}/gateway/endpoints",
        {"type": "udp", "mode": "client", "address": "127.0.0.1:14600", "device": "",
         "baud": "57600", "allow": "", "block": "66, 69", "read_only": "on"},
    )  # fmt: skip
    assert response.status_code == 302 and response.url == f"/robots/{rover.name}/"
    added = rover.endpoints.get(role="")
    assert added.spec() == {"type": "udp", "mode": "client", "address": "127.0.0.1:14600",
                            "read_only": True, "allow": None, "block": [66, 69],
                            "control": "always"}  # fmt: skip
    assert "gateway.reload" in live["asked"]
    page = client.get(response.url).content.decode()
    assert "Endpoint udp:127.0.0.1:14600 added" in page


def test_an_endpoint_added_with_htmx_comes_back_in_the_card(client, owner, rover, live):
    client.force_login(owner)
    response = client.post(
        f"/robots/{rover.name}/gateway/endpoints",
        {"type": "serial", "device": "/dev/ttyAMA0", "baud": "921600", "allow": "0, 1,33"},
        **HTMX,
    )
    assert response.status_code == 200
    added = rover.endpoints.get(role="")
    assert (added.device, added.baud, added.allow) == ("/dev/ttyAMA0", 921600, [0, 1, 33])
    live["gateway"][str(added.pk)] = endpoint(
        "/dev/ttyAMA0:921600", status="connecting", error="[Errno 2] No such file or directory"
    )
    page = card(client)
    row = row_of(page, added.pk)
    assert "/dev/ttyAMA0:921600" in row and "only 0, 1, 33" in row
    assert ">connecting<" in row and "No such file or directory" in row


@pytest.mark.parametrize(
    "form, why",
    [
        ({"type": "udp", "mode": "client", "address": "127.0.0.1:0"}, "a client needs the port"),
        ({"type": "tcp", "mode": "server", "address": "nowhere"}, "not HOST:PORT"),
        ({"type": "serial", "device": "ttyUSB0", "baud": "57600"}, "device must be a path"),
        ({"type": "serial", "device": "/dev/ttyUSB0", "baud": "1234"}, "baud must be"),
        ({"type": "udp", "address": "127.0.0.1:1", "block": "HEARTBEAT"}, "not &#x27;HEARTBEAT"),
        ({"type": "udp", "address": "127.0.0.1:1", "allow": "99999999"}, "allow must be"),
    ],
)
def test_a_bad_endpoint_is_refused_with_the_reason(
    client, owner, rover, live, no_robot_state, form, why
):
    client.force_login(owner)
    url = f"/robots/{rover.name}/gateway/endpoints"
    response = client.post(url, form, **HTMX)
    # htmx swaps only 2xx answers (htmx 2's default responseHandling): the card says why.
    assert response.status_code == 200
    page = response.content.decode()
    assert 'class="gateway-message error"' in page and why in page
    assert " open>" in page  # the form stays open, filled as it was
    if form.get("address"):
        assert f'value="{form["address"]}"' in page
    plain = client.post(url, form, follow=True).content.decode()
    assert "Endpoint not added" in plain and why in plain
    assert not rover.endpoints.filter(role="").exists()


def test_the_owner_removes_an_endpoint(client, owner, rover, live):
    client.force_login(owner)
    gcs, programs = (rover.endpoints.get(role=role) for role in ("gcs", "programs"))
    response = client.post(f"/robots/{rover.name}/gateway/endpoints/{gcs.pk}/delete")
    assert response.status_code == 302 and response.url == f"/robots/{rover.name}/"
    assert not rover.endpoints.filter(pk=gcs.pk).exists()
    assert live["asked"][-1] == "gateway.reload"
    response = client.post(f"/robots/{rover.name}/gateway/endpoints/{programs.pk}/delete", **HTMX)
    assert response.status_code == 200
    page = response.content.decode()
    assert "Endpoint udpin:127.0.0.1:14551 removed." in page
    assert f'id="endpoint-{programs.pk}"' not in page
    assert client.post(f"/robots/{rover.name}/gateway/endpoints/{gcs.pk}/delete").status_code == 404
    other = Robot.objects.create(name="other", url="mavlink+udp://127.0.0.1:14555", owner=owner)
    row = GatewayEndpoint(robot=other, type="udp", mode="server", address="127.0.0.1:1")
    row.save()
    assert client.post(f"/robots/rover/gateway/endpoints/{row.pk}/delete").status_code == 404
    assert client.get(f"/robots/{rover.name}/gateway/endpoints/{row.pk}/delete").status_code == 405


def test_a_student_sees_the_tables_but_changes_nothing(client, rover, live):
    student = User.objects.create_user("student")
    student.groups.add(Group.objects.create(name="class-a"))
    client.force_login(student)
    page = card(client)
    assert "ground stations" in page and "52" in page
    assert "Add an endpoint" not in page and "Remove" not in page
    add = {"type": "udp", "mode": "client", "address": "127.0.0.1:14600"}
    assert client.post(f"/robots/{rover.name}/gateway/endpoints", add).status_code == 403
    assert client.post(f"/robots/{rover.name}/gateway/endpoints", add, **HTMX).status_code == 403
    gcs = rover.endpoints.get(role="gcs")
    delete = f"/robots/{rover.name}/gateway/endpoints/{gcs.pk}/delete"
    assert client.post(delete).status_code == 403
    assert rover.endpoints.count() == 2
    staff = User.objects.create_user("teacher", is_staff=True)
    client.force_login(staff)
    assert "Add an endpoint" in card(client)
    assert client.post(delete).status_code == 302


def test_hidden_robots_and_robots_without_a_router(client, owner, rover, live):
    secret = Robot.objects.create(name="secret", url="mavlink+tcp://127.0.0.1:1")
    secret.groups.add(Group.objects.create(name="class-b"))
    student = User.objects.create_user("student")
    client.force_login(student)
    assert client.get("/robots/secret/gateway").status_code == 404
    client.logout()
    assert client.get(f"/robots/{rover.name}/gateway").status_code == 302  # to sign in
    Robot.objects.create(name="plain", url="sim://", owner=owner)
    client.force_login(owner)
    add = {"type": "udp", "mode": "client", "address": "127.0.0.1:14600"}
    assert client.post("/robots/plain/gateway/endpoints", add).status_code == 409


def test_an_agent_that_does_not_answer_is_said_once(client, owner, rover, live, monkeypatch):
    SerialBridge.objects.create(robot=rover, address="127.0.0.1:4001")
    asked = []
    monkeypatch.setattr(gateway_api, "live_stats", lambda robot, kind="": asked.append(kind))
    client.force_login(owner)
    page = card(client)
    assert page.count("not answering") == 1 and asked == [""]  # the bridges are not asked
    assert ">unknown<" in row_of(page, "vehicle") and "ground stations" in page
    assert "robot&#x27;s port" in page and "Add an endpoint" in page
