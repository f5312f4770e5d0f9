"""The emergency stop seen from the workbench, in a real browser (issue 29, item 6): a student
presses it on the robot's page while a teacher has the robot's panel open beside her editor.
The panel shows the stop (who, when) and a Resume, live; her Resume clears the stop on both
pages without reloading either."""

import re
import subprocess

import pytest
from playwright.sync_api import expect

from tests.appliance import ROBOTIDE, ROOT
from tests.browser.test_pages import assert_not_reloaded, mark_page, sign_in
from tests.browser.test_workbench import new_program, open_bench

STUDENT = "estop-bench-student"


@pytest.fixture(scope="module")
def student(appliance):
    password = "a long enough passphrase"
    argv = [ROBOTIDE, "user", "add", STUDENT, "--password-stdin"]
    subprocess.run(argv, input=password, env=appliance.env, cwd=ROOT, check=True,
                   capture_output=True, text=True)  # fmt: skip
    return STUDENT, password


def test_a_stop_pressed_on_the_robot_page_shows_on_the_workbench_which_resumes_it(
    new_page, appliance, student, screenshot
):
    appliance.resume()  # whatever an earlier test pressed
    bench = new_page()
    sign_in(bench)  # admin: staff, who may resume any stop
    open_bench(bench, new_program(appliance, "Bench beside a stop", "print('hi')\n"))
    panel = bench.locator("#bench-panel")
    expect(panel.locator(".estopped")).to_have_count(0)
    mark_page(bench)

    robot_page = new_page()
    sign_in(robot_page, *student)
    robot_page.goto("/robots/sim/")
    try:
        robot_page.get_by_role("button", name="EMERGENCY STOP").click()
        expect(robot_page.get_by_role("alert")).to_contain_text(f"pressed by {STUDENT}")
        mark_page(robot_page)
        for width in (390, 1366):
            robot_page.set_viewport_size({"width": width, "height": 860})
            screenshot(robot_page, f"robot-estop-banner-{width}")

        # The open workbench hears of it: who pressed it, when, and a Resume for staff.
        stop = panel.locator(".estopped")
        pressed = re.compile(rf"EMERGENCY STOP pressed by {STUDENT} at \d\d:\d\d")
        expect(stop).to_contain_text(pressed)
        expect(stop).to_contain_text("Who may resume it: staff, the robot's owner or whoever")
        resume = stop.get_by_role("button", name=re.compile("Resume"))
        expect(resume).to_be_visible()
        bench.set_viewport_size({"width": 1366, "height": 860})
        screenshot(bench, "workbench-estopped-1366")
        bench.set_viewport_size({"width": 390, "height": 844})
        stop.scroll_into_view_if_needed()
        screenshot(bench, "workbench-estopped-390")
        bench.set_viewport_size({"width": 1366, "height": 860})

        resume.click()
        expect(panel.locator(".estopped")).to_have_count(0)
        expect(robot_page.get_by_role("alert")).to_have_count(0)  # live, on the other page too
        assert_not_reloaded(bench)
        assert_not_reloaded(robot_page)
        screenshot(bench, "workbench-resumed-1366")
    finally:
        appliance.resume()


def test_a_stop_pressed_on_the_workbench_shows_live_on_the_robot_page(new_page, appliance, student):
    """The other way round: the student presses on her workbench; its panel offers her (who
    pressed it) Resume; the teacher's open robot page shows the stop without a reload, and its
    Resume (a plain form, rendered on the websocket) clears it on both."""
    appliance.resume()
    token = appliance.cli("token", STUDENT).strip()
    program = appliance.create_program("Bench with a stop", "print('hi')\n", token=token)
    robot_page = new_page()
    sign_in(robot_page)  # admin: staff
    robot_page.goto("/robots/sim/")
    expect(robot_page.locator("#sensors")).to_be_visible()
    mark_page(robot_page)

    bench = new_page()
    sign_in(bench, *student)
    open_bench(bench, program["id"])
    try:
        bench.locator("#bench-estop").click()
        stop = bench.locator("#bench-panel .estopped")
        expect(stop).to_contain_text(f"pressed by {STUDENT}")
        expect(stop.get_by_role("button", name=re.compile("Resume"))).to_be_visible()

        banner = robot_page.locator("#estop-banner .estopped")
        expect(banner).to_contain_text(f"pressed by {STUDENT}")
        assert_not_reloaded(robot_page)  # it came on the robot's websocket
        banner.get_by_role("button", name=re.compile("Resume")).click()
        expect(robot_page.locator(".messages")).to_contain_text("may move again")
        expect(robot_page.get_by_role("alert")).to_have_count(0)
        expect(stop).to_have_count(0)
    finally:
        appliance.resume()
