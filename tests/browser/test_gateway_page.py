"""The MAVLink gateway card on a real MAVLink robot's page, in a real browser.

A real appliance (``robotide up``, its agent in the server process) drives the ArduPilot
Rover emulator (tests/rhal/mavlink_emulator.py) over TCP, on an event loop of its own in this
process; the card reloads itself, and an endpoint added through its form really routes.
"""

import socket

import pytest
from playwright.sync_api import Page, expect

from tests.appliance import Appliance
from tests.browser.conftest import SCREENSHOTS
from tests.browser.test_pages import sign_in
from tests.peers import peer_in_thread

ROBOT = "rover"


@pytest.fixture(scope="module")
def appliance(tmp_path_factory):
    """Its own appliance: the gateway's default endpoints on any free loopback port."""
    env = {"ROBOTIDE_GATEWAY_GCS": "127.0.0.1:0", "ROBOTIDE_GATEWAY_PROGRAMS": "127.0.0.1:0"}
    app = Appliance(tmp_path_factory.mktemp("gateway-appliance"), extra_env=env)
    app.start()
    yield app
    app.stop()


@pytest.fixture(scope="module")
def vehicle(tmp_path_factory):
    """The emulated rover, served from a thread's event loop while this module's tests run."""
    folder = tmp_path_factory.mktemp("vehicle")
    with peer_in_thread("mavlink", folder, other_process=True) as peer:
        yield peer


@pytest.fixture(scope="module")
def rover(appliance, vehicle):
    response = appliance.api("POST", "/api/robots", {"name": ROBOT, "url": vehicle.url})
    assert response.status_code == 201, response.text
    return ROBOT


@pytest.fixture
def listener():
    """A ground station's UDP port on this computer, for an endpoint that sends to it."""
    sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    sock.bind(("127.0.0.1", 0))
    sock.settimeout(10)
    yield sock
    sock.close()


def msgs_in(page: Page, row: str) -> float:
    return float(page.locator(row).get_attribute("data-msgs-in"))


def test_the_gateway_card_is_live_and_endpoints_come_and_go(
    new_page, appliance, vehicle, rover, listener, screenshot
):
    vehicle_url = vehicle.url
    page = new_page()
    sign_in(page)
    page.goto(f"/robots/{rover}/")
    card = page.locator("#gateway")
    expect(card.get_by_role("heading", name="MAVLink gateway")).to_be_visible()
    vehicle = card.locator("#endpoint-vehicle")
    expect(vehicle).to_contain_text("vehicle link")
    expect(vehicle).to_contain_text("tcp:" + vehicle_url.partition("//")[2])  # the robot's URL
    # The tables reload themselves: mark them, and wait for fresh ones.
    page.evaluate("() => { document.getElementById('gateway-live').dataset.old = 'yes'; }")
    page.wait_for_function("() => !document.getElementById('gateway-live').dataset.old")
    expect(vehicle).to_have_attribute("data-status", "up")
    page.wait_for_function(
        "() => Number(document.querySelector('#endpoint-vehicle').dataset.msgsIn) > 0"
    )
    assert msgs_in(page, "#endpoint-vehicle") > 0
    expect(vehicle.locator("td.systems")).to_contain_text("1:1")
    for name in ("this robot's driver", "ground stations", "programs (ROBOT_MAVLINK)"):
        expect(card.locator("tbody th", has_text=name)).to_have_count(1)

    # A ground station elsewhere: a UDP client endpoint, added through the card's form.
    address = f"127.0.0.1:{listener.getsockname()[1]}"
    card.get_by_text("Add an endpoint").click()
    form = card.locator("form.endpoint-form")
    form.get_by_label("Type").select_option("udp")
    form.get_by_label("Mode").select_option("client")
    form.get_by_label("Address").fill(address)
    form.get_by_label("Block ids").fill("999999999")  # not a message id: refused, kept
    form.get_by_role("button", name="Add").click()
    expect(card.locator(".gateway-message.error")).to_contain_text("block must be")
    expect(form.get_by_label("Address")).to_have_value(address)
    form.get_by_label("Block ids").fill("")
    form.get_by_role("button", name="Add").click()
    expect(card.locator(".gateway-message")).to_contain_text(f"Endpoint udp:{address} added.")
    added = card.locator("tbody tr", has_text=f"udp:{address}")
    expect(added).to_have_attribute("data-status", "up")
    data, _ = listener.recvfrom(65536)  # the vehicle's telemetry reaches it
    assert data[0] in (0xFD, 0xFE), data[:8]
    expect(added.locator("td.num").nth(1)).not_to_have_text("0")  # msg/s out, after a reload
    card.scroll_into_view_if_needed()
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    card.screenshot(path=str(SCREENSHOTS / "robot-gateway.png"))
    screenshot(page, "robot-gateway-page")

    added.get_by_role("button", name=f"Remove udp:{address}").click()
    expect(card.locator(".gateway-message")).to_contain_text(f"Endpoint udp:{address} removed.")
    expect(card.locator("tbody tr", has_text=f"udp:{address}")).to_have_count(0)
    rows = appliance.api("GET", f"/api/robots/{rover}/endpoints").json()
    assert [row["role"] for row in rows] == ["vehicle", "robot", "gcs", "programs"]
