"""The robot page as a lab uses it: readings and plots moving live, driving by hand with the
keyboard and the on-screen pad, the control lease, and the emergency stop."""

import re

import pytest
from playwright.sync_api import Page, expect

from tests.browser.test_pages import sign_in

DRIVER = """\
import time
import robot

bot = robot.Robot()
bot.drive(0.0, 0.5)
time.sleep(60)
"""


@pytest.fixture
def page(new_page) -> Page:
    page = new_page()
    sign_in(page)
    return page


def reading(page: Page, name: str):
    return page.locator(f'#sensors tr[data-name="{name}"]')


def value_of(page: Page, name: str) -> float:
    return float(reading(page, name).get_attribute("data-value"))


def start(appliance, name: str, source: str) -> int:
    program = appliance.create_program(name, source)
    return appliance.run_program(program["id"])["id"]


def test_the_arrow_keys_drive_and_letting_go_stops(page, appliance, screenshot):
    page.goto("/robots/sim/")
    expect(page.locator("#control")).to_contain_text("Nobody controls the robot")
    page.wait_for_function("() => document.querySelector('#robot-status.connected')")
    page.keyboard.down("ArrowUp")
    expect(reading(page, "velocity.linear")).to_have_attribute("data-value", re.compile(r"^0\.2"))
    expect(page.locator("#control")).to_contain_text("You control the robot")
    screenshot(page, "robot-driving-by-hand")
    page.keyboard.up("ArrowUp")
    expect(reading(page, "velocity.linear")).to_have_attribute("data-value", "0.0")
    # The on-screen pad: held, then let go.
    button = page.get_by_role("button", name="Turn left")
    box = button.bounding_box()
    page.mouse.move(box["x"] + box["width"] / 2, box["y"] + box["height"] / 2)
    page.mouse.down()
    expect(reading(page, "velocity.angular")).to_have_attribute("data-value", "1.0")
    page.mouse.up()
    expect(reading(page, "velocity.angular")).to_have_attribute("data-value", "0.0")
    page.get_by_role("button", name="Release control").click()
    expect(page.locator("#control")).to_contain_text("Nobody controls the robot")


def test_readings_and_plots_move_while_a_program_drives(page, appliance, screenshot):
    page.goto("/robots/sim/")
    first = value_of(page, "heading")
    run_id = start(appliance, "Turner", DRIVER)
    page.wait_for_function(
        "first => Number(document.querySelector('#sensors tr[data-name=heading]')"
        ".dataset.value) !== first",
        arg=first,
    )
    expect(page.locator("#control")).to_contain_text(f"(run #{run_id})")
    # A person cannot drive while the program holds the robot: the pad is greyed out.
    expect(page.get_by_role("button", name="Forward")).to_have_css("opacity", "0.4")
    plot = page.locator('#plots figure[data-name="heading"] canvas')
    expect(plot).to_be_visible()
    screenshot(page, "robot-plots")
    page.get_by_role("button", name="EMERGENCY STOP").click()
    assert appliance.wait_run(run_id)["state"] == "stopped"
    appliance.resume()  # it holds the robot until then


def test_the_emergency_stop_ends_every_program_and_halts_the_robot(page, appliance, screenshot):
    runs = [start(appliance, f"Busy {i}", DRIVER if i == 0 else "import time\ntime.sleep(60)\n")
            for i in range(2)]  # fmt: skip
    page.goto("/robots/sim/")
    running = page.locator("#robot-running")
    for run_id in runs:
        expect(running).to_contain_text(f"#{run_id}")
    expect(reading(page, "velocity.angular")).to_have_attribute("data-value", "0.5")
    page.get_by_role("button", name="EMERGENCY STOP").click()
    expect(page.locator(".messages")).to_contain_text("2 program(s) ended")
    for run_id in runs:
        assert appliance.wait_run(run_id)["state"] == "stopped"
    expect(running).to_contain_text("No program is running.")
    expect(reading(page, "velocity.angular")).to_have_attribute("data-value", "0.0")
    expect(page.locator("#control")).to_contain_text("Controlled by the emergency stop admin")
    screenshot(page, "robot-after-estop-two-programs")
    page.get_by_role("button", name="Resume: let it move again").click()
    expect(page.locator("#control")).to_contain_text("Nobody controls the robot")


def test_a_command_button_runs_its_program_with_its_arguments(page, appliance, screenshot):
    appliance.create_program("Say", "import sys\nprint('asked to', ' '.join(sys.argv[1:]))\n")
    page.goto("/robots/sim/")
    page.get_by_role("link", name="set up").click()
    page.get_by_label("Label").fill("Dock")
    page.get_by_label("Program").select_option(label="Say")
    page.get_by_label("Arguments").fill('dock "bay two"')
    page.get_by_role("button", name="Save").click()
    expect(page.locator("table.list")).to_contain_text("dock 'bay two'")
    screenshot(page, "robot-buttons")
    page.get_by_role("link", name="sim").click()
    page.get_by_role("button", name="Dock").click()
    outcome = page.locator("#button-outcome")
    expect(outcome).to_contain_text(re.compile(r"Dock: run #\d+ started"))
    screenshot(page, "robot-button-pressed")
    outcome.get_by_role("link").click()
    expect(page.locator("#log-lines")).to_contain_text("asked to dock bay two")


FAKE_GAMEPAD = """
window.__pad = { connected: true, axes: [0, 0], buttons: [] };
navigator.getGamepads = () => [window.__pad];
"""


def test_a_gamepad_stick_drives_and_centring_it_stops(page, appliance):
    page.add_init_script(FAKE_GAMEPAD)  # Chromium headless has no gamepad: the API's shape
    page.goto("/robots/sim/")
    page.wait_for_function("() => document.querySelector('#robot-status.connected')")
    page.evaluate("window.dispatchEvent(new Event('gamepadconnected'))")
    page.evaluate("window.__pad.axes = [0, -1]")  # stick pushed forward
    expect(reading(page, "velocity.linear")).to_have_attribute("data-value", re.compile(r"^0\.2"))
    page.evaluate("window.__pad.axes = [-0.05, 0.1]")  # back in the dead zone
    expect(reading(page, "velocity.linear")).to_have_attribute("data-value", "0.0")
    page.get_by_role("button", name="Release control").click()
