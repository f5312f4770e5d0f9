"""Reset in Chromium (issue 30): on the sim robot's page and on the workbench's robot panel,
Reset puts the robot back at its world's start pose after a run moved it (as the Robot API's
sensors() says); the page's "At a pose…" puts it where it is told; without scripts the Reset
is a plain form that comes back to the page with its message. Before, there was no Reset: a
run left the robot where it ended for the next."""

import asyncio
import math
from concurrent.futures import ThreadPoolExecutor

import pytest
from playwright.sync_api import Page, expect

import rhal
from tests.browser.test_pages import sign_in

MOVES = """import time, robot
bot = robot.Robot()
bot.drive(0.15, 0.8)
time.sleep(0.5)
bot.stop()
"""


@pytest.fixture
def page(new_page) -> Page:
    page = new_page()
    sign_in(page)
    return page


@pytest.fixture(scope="module")
def start() -> dict:
    """The world's start pose, as a fresh sim reads it."""

    async def read():
        sim = rhal.connect("sim://")
        await sim.open()
        try:
            return (await sim.sensors())["position"]
        finally:
            await sim.close()

    with ThreadPoolExecutor(1) as thread:  # Playwright's loop runs in this one
        return thread.submit(asyncio.run, read()).result()


def position(appliance) -> dict:
    return appliance.api("GET", "/api/robots/sim/sensors").json()["position"]


def at(where: dict, pose: dict) -> bool:
    return all(math.isclose(where[k], pose[k], abs_tol=1e-6) for k in ("x", "y", "theta"))


@pytest.fixture(scope="module")
def mover(appliance) -> dict:
    return appliance.create_program("moves", MOVES)


def moved_by_a_run(appliance, program: dict, start: dict) -> None:
    run = appliance.wait_run(appliance.run_program(program["id"])["id"])
    assert run["state"] == "finished", run
    assert not at(position(appliance), start)


def test_reset_on_the_robot_page(page, appliance, start, mover, screenshot):
    moved_by_a_run(appliance, mover, start)
    page.goto("/robots/sim/")
    card = page.locator(".reset-card")
    card.get_by_role("button", name="Reset").click()
    expect(card.locator(".reset-status").first).to_have_text("sim is back at its start.")
    assert at(position(appliance), start)

    card.get_by_text("At a pose…").click()
    card.get_by_label("x, metres east").fill("0.5")
    card.get_by_label("y, metres north").fill("-0.4")
    card.get_by_label("θ, radians from east").fill("0.3")
    card.get_by_role("button", name="Put it there").click()
    expect(card.locator(".reset-status").last).to_contain_text("the next run starts there")
    assert at(position(appliance), {"x": 0.5, "y": -0.4, "theta": 0.3})
    for width in (390, 1366):
        page.set_viewport_size({"width": width, "height": 900})
        card.scroll_into_view_if_needed()
        screenshot(page, f"robot-reset-{width}")
    appliance.api("POST", "/api/robots/sim/reset")  # the start for the next test's run


def test_reset_on_the_workbench_panel(page, appliance, start, mover, screenshot):
    moved_by_a_run(appliance, mover, start)
    page.goto(f"/programs/{mover['id']}/")
    panel = page.locator("#bench-robot")
    panel.get_by_role("button", name="Reset").click()
    expect(panel.locator(".reset-status")).to_have_text("sim is back at its start.")
    assert at(position(appliance), start)
    for width in (390, 1366):
        page.set_viewport_size({"width": width, "height": 900})
        panel.get_by_role("button", name="Reset").scroll_into_view_if_needed()
        screenshot(page, f"workbench-reset-{width}")


def test_reset_without_scripts_is_a_form_that_comes_back(new_page, appliance, start, mover):
    moved_by_a_run(appliance, mover, start)
    page = new_page(java_script_enabled=False)
    sign_in(page)
    page.goto("/robots/sim/")
    # The page reloads itself every 2 s without scripts: the answer is read as it comes (the
    # page the form's POST is sent back to, not a reload).
    with page.expect_response(lambda r: r.request.redirected_from is not None) as shown:
        page.locator(".reset-card").get_by_role("button", name="Reset").click()
    assert "sim is back at its start." in shown.value.text()
    assert at(position(appliance), start)
