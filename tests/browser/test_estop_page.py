"""The emergency stop on the robot's page, in a real browser: a student presses it while
another user's program drives, the page says the robot is held and by whom, the history
records it, and the student who pressed it resumes."""

import re
import subprocess

import pytest
from playwright.sync_api import expect

from tests.appliance import ROBOTIDE, ROOT, wait_for
from tests.browser.test_pages import sign_in

DRIVES = """\
import robot, signal, time
signal.signal(signal.SIGTERM, signal.SIG_IGN)
bot = robot.Robot()
while True:
    bot.drive(0.2, 0.0)
    time.sleep(0.05)
"""


@pytest.fixture
def student(appliance):
    name, password = "estop-student", "a long enough passphrase"
    argv = [ROBOTIDE, "user", "add", name, "--password-stdin"]
    subprocess.run(argv, input=password, env=appliance.env, cwd=ROOT, check=True,
                   capture_output=True, text=True)  # fmt: skip
    return name, password


def test_a_student_presses_the_emergency_stop_and_resumes(new_page, appliance, student,
                                                          screenshot):  # fmt: skip
    program = appliance.create_program("estop page drives", DRIVES)
    run = appliance.api("POST", f"/api/programs/{program['id']}/run", {"robot": "sim"})
    run_id = run.json()["id"]
    page = new_page()
    sign_in(page, *student)
    wait_for(lambda: appliance.api("GET", f"/api/runs/{run_id}").json()["state"] == "running",
             what="the admin's program running")  # fmt: skip
    page.goto("/robots/sim/")  # the student sees the robot, not the admin's run
    page.get_by_role("button", name="EMERGENCY STOP").click()
    banner = page.get_by_role("alert")
    expect(banner).to_contain_text("pressed by estop-student")
    expect(banner).to_contain_text("until it is resumed")
    history = page.locator("ul.stops")
    expect(history).to_contain_text("emergency stop")
    expect(history).to_contain_text(re.compile(rf"#{run_id} estop page drives \(admin\)"))
    screenshot(page, "robot-estopped")
    assert appliance.api("GET", f"/api/runs/{run_id}").json()["reason"] == "emergency stop"

    page.get_by_role("button", name=re.compile("Resume")).click()
    expect(page.get_by_role("alert")).to_have_count(0)
    expect(history).to_contain_text("resumed")
    screenshot(page, "robot-resumed")
