"""The live camera in a real browser: a plain <img> on the MJPEG stream shows the robot move."""

import time

import pytest
from playwright.sync_api import Page

from tests.browser.test_pages import sign_in

TURN = """\
import robot, time

bot = robot.Robot()
bot.drive(0.0, 0.8)
time.sleep(60)
"""


@pytest.fixture
def turning(appliance):
    """A program turning the sim robot on the spot, stopped after the test."""
    program = appliance.create_program("Turn for the camera", TURN)
    run = appliance.run_program(program["id"])
    appliance.wait_run(run["id"], states=("running",))
    yield run
    appliance.api("POST", f"/api/runs/{run['id']}/stop")
    appliance.wait_run(run["id"])


def image_shown(page: Page) -> bytes:
    return page.locator("#camera").screenshot()


def test_an_img_on_the_stream_shows_the_robot_moving(new_page, turning, screenshot):
    page = new_page()
    sign_in(page)
    # The page's own origin and policy; only its body is ours: an <img> and nothing else.
    page.set_content('<img id="camera" src="/robots/sim/camera.mjpg" alt="camera">')
    page.wait_for_function("document.getElementById('camera').naturalWidth > 0")
    size = page.evaluate("[camera.naturalWidth, camera.naturalHeight]")
    assert size == [320, 240]
    first = image_shown(page)
    time.sleep(1.0)
    second = image_shown(page)
    assert first != second, "the image did not change while the robot turned"
    screenshot(page, "camera-stream")


def test_the_stream_needs_a_signed_in_browser(new_page, appliance):
    page = new_page()
    response = page.goto("/robots/sim/camera.mjpg")
    assert "/accounts/login/" in page.url and response.ok
