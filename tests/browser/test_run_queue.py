"""Three students share the sim robot in a real browser: the queue on the robot's page and on a
waiting run's page, with places that change live as staff reorder it and the robot frees up."""

import pytest
from playwright.sync_api import Page, expect

from tests.appliance import wait_for
from tests.browser.test_pages import sign_in

DRIVES = """\
import time
import robot

bot = robot.Robot()
bot.drive(0.0, 0.3)
print("driving", flush=True)
time.sleep(120)
"""
SLEEPS = "import time\nprint('my turn', flush=True)\ntime.sleep(120)\n"
PASSWORD = "user-pass-1234"


@pytest.fixture
def students(appliance):
    return {name: appliance.new_user(name, PASSWORD) for name in ("alice", "bob", "carol")}


def run_as(appliance, token: str, name: str, source: str) -> int:
    program = appliance.create_program(name, source, token=token)
    return appliance.run_program(program["id"], token=token)["id"]


def signed_in(new_page, username: str, password: str = PASSWORD) -> Page:
    page = new_page()
    sign_in(page, username, password)
    return page


def test_a_shared_robot_queues_runs_and_shows_each_its_place(
    appliance, students, new_page, screenshot
):
    alice = run_as(appliance, students["alice"], "Spin", DRIVES)
    appliance.wait_run(alice, states=("running",))
    wait_for(
        lambda: "driving" in appliance.api("GET", f"/api/runs/{alice}/log").text,
        what="alice's program driving",
    )
    bob = run_as(appliance, students["bob"], "Wait", SLEEPS)
    carol = run_as(appliance, students["carol"], "Patient", SLEEPS)
    assert appliance.wait_run(bob, states=("queued",))["queue_position"] == 1
    assert appliance.wait_run(carol, states=("queued",))["queue_position"] == 2

    # Carol's run page says where she is.
    carols = signed_in(new_page, "carol")
    carols.goto(f"/runs/{carol}/")
    status = carols.locator("#run-status")
    expect(status).to_contain_text("queued — 2nd in line")
    expect(carols.get_by_role("button", name="✕ Cancel")).to_be_visible()
    screenshot(carols, "run-queued")

    # Staff see the line on the robot's page, whose each run is, and may reorder it.
    page = signed_in(new_page, "admin", appliance.env["ROBOTIDE_ADMIN_PASSWORD"])
    page.goto("/robots/sim/")
    queue = page.locator("#robot-queue")
    expect(queue.locator(f'li[data-run="{bob}"]')).to_contain_text("queued — 1st in line")
    expect(queue.locator(f'li[data-run="{carol}"]')).to_contain_text("queued — 2nd in line")
    expect(queue).to_contain_text("bob")
    expect(page.locator("#control")).to_contain_text(f"alice's program (run #{alice})")
    screenshot(page, "run-queue")

    page.get_by_role("button", name=f"Move to the front: run #{carol}").click()
    expect(queue.locator(f'li[data-run="{carol}"]')).to_contain_text("1st in line")
    expect(queue.locator(f'li[data-run="{bob}"]')).to_contain_text("2nd in line")
    expect(status).to_contain_text("queued — 1st in line")  # carol's page, live

    # Alice's run ends: carol's starts at once, holding the robot; her page says so.
    appliance.api("POST", f"/api/runs/{alice}/stop")
    expect(status).to_contain_text("running")
    expect(page.locator("#control")).to_contain_text(f"carol's program (run #{carol})")
    expect(queue.locator(f'li[data-run="{bob}"]')).to_contain_text("1st in line")
    expect(page.locator("#robot-running")).to_contain_text(f"#{carol}")

    # Bob changes his mind, from his own view of the robot's page.
    bobs = signed_in(new_page, "bob")
    bobs.goto("/robots/sim/")
    bobs.get_by_role("button", name=f"Cancel run #{bob}").click()
    expect(page.locator("#robot-queue li")).to_have_count(0)
    ended = appliance.wait_run(bob)
    assert (ended["state"], ended["reason"]) == ("stopped", "cancelled while queued")
    appliance.api("POST", f"/api/runs/{carol}/stop")
    assert appliance.wait_run(carol)["state"] == "stopped"
