"""A run's page in a real browser: its running time counts up, a silent run says it has no
output yet, and the robot's view (the sim's drawing: its camera) is beside the output."""

import re

import pytest
from playwright.sync_api import Page, expect

from tests.browser.test_pages import sign_in

SLEEPS = "import time\ntime.sleep(120)\n"
# Silent until it is stopped: then it says goodbye (the Stop button, pressed by the test, is
# the event its output waits for; no timing).
QUIET_UNTIL_STOPPED = """\
import signal, time

def goodbye(*_):
    print("goodbye from the program", flush=True)
    raise RuntimeError("stopped")

signal.signal(signal.SIGTERM, goodbye)
time.sleep(120)
"""
SILENT = "x = 1\n"


def seconds_shown(status: str) -> float:
    """The seconds a status line's "running for 3 min 04 s" (or "0.3 s") says."""
    found = re.search(r"running for (?:(\d+) h )?(?:(\d+) min)?(?: ?([\d.,]+) s)?", status)
    assert found and any(found.groups()), status
    hours, minutes, secs = (float((g or "0").replace(",", ".")) for g in found.groups())
    return hours * 3600 + minutes * 60 + secs


@pytest.fixture
def running(appliance):
    """Starts a program on the sim and stops it after the test."""
    started = []

    def start(source: str, name: str = "Run page") -> int:
        program = appliance.create_program(name, source)
        run = appliance.run_program(program["id"])["id"]
        started.append(run)
        appliance.wait_run(run, states=("running",))
        return run

    yield start
    for run in started:
        appliance.api("POST", f"/api/runs/{run}/stop")
        appliance.wait_run(run)


def signed_in(new_page) -> Page:
    page = new_page()
    sign_in(page)
    return page


def test_the_running_time_counts_up_and_stops_at_the_end(appliance, new_page, running, screenshot):
    run = running(SLEEPS, "Counts")
    page = signed_in(new_page)
    page.goto(f"/runs/{run}/")
    status = page.locator("#run-status")
    expect(status).to_contain_text("running for")
    shown = status.text_content()
    first = later = seconds_shown(shown)
    # A later value, without the page asking the server again: each change waited for (the
    # first may be the server's 0.4 s shown by the page as 0 s).
    while later <= first:
        expect(status).not_to_have_text(shown)
        shown = status.text_content()
        later = seconds_shown(shown)
    page.get_by_role("button", name="■ Stop").click()
    expect(status).to_contain_text("took")
    expect(status).not_to_contain_text("running for")


def test_a_silent_run_says_so_until_it_prints(appliance, new_page, running, screenshot):
    run = running(QUIET_UNTIL_STOPPED, "Quiet")
    page = signed_in(new_page)
    page.goto(f"/runs/{run}/")
    placeholder = page.locator("#log .log-empty")
    expect(placeholder).to_have_text("No output yet.", use_inner_text=True)
    expect(placeholder).to_be_visible()
    for width, height in ((390, 844), (1366, 900)):
        page.set_viewport_size({"width": width, "height": height})
        screenshot(page, f"run-page-silent-{width}")
    page.get_by_role("button", name="■ Stop").click()
    expect(page.locator("#log-lines .ln.o")).to_have_text("goodbye from the program")
    expect(placeholder).to_be_hidden()
    # Its traceback came live: its lines link to the program's, as the server renders them.
    expect(page.locator('#log-lines a[href="#line-5"]')).to_contain_text("in goodbye")
    page.locator('#log-lines a[href="#line-5"]').click()
    expect(page.locator("#line-5")).to_be_visible()


def test_a_run_that_printed_nothing_says_so(appliance, new_page):
    program = appliance.create_program("Silent", SILENT)
    run = appliance.run_program(program["id"])["id"]
    assert appliance.wait_run(run)["state"] == "finished"
    page = signed_in(new_page)
    page.goto(f"/runs/{run}/")
    placeholder = page.locator("#log .log-empty")
    expect(placeholder).to_be_visible()
    expect(placeholder).to_have_text("The program printed nothing.", use_inner_text=True)


def test_the_run_page_shows_the_robot_beside_the_output(appliance, new_page, running, screenshot):
    run = running(QUIET_UNTIL_STOPPED, "Watched")
    page = signed_in(new_page)
    page.set_viewport_size({"width": 1366, "height": 900})
    page.goto(f"/runs/{run}/")
    view = page.locator(".run-robot canvas.simview-canvas")
    view.scroll_into_view_if_needed()
    # The panel is fetched once the page is shown; its drawing of the sim comes then.
    expect(view).to_have_attribute("data-pose", re.compile(r"\S"))
    log, robot = page.locator("#log").bounding_box(), view.bounding_box()
    assert robot["x"] >= log["x"] + log["width"], "the robot's view is beside the output"
    screenshot(page, "run-page-1366")
    page.set_viewport_size({"width": 390, "height": 844})
    log, robot = page.locator("#log").bounding_box(), view.bounding_box()
    assert robot["y"] >= log["y"] + log["height"], "on a phone, the view is under the output"
    assert page.evaluate("document.documentElement.scrollWidth <= innerWidth")
    screenshot(page, "run-page-390")
