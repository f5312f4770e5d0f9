"""The workbench's "My sim" in a real browser (issue 30, "A sim of one's own"): a student picks
"My sim (new)", runs, and her program runs on a sim of her own made for it (its agent started
by the appliance); from then on the list names it and the panel draws it. Another student
cannot open it. At a desktop's width and a phone's."""

import re

import httpx
import pytest
from playwright.sync_api import Page, expect

from tests.browser.test_pages import set_editor_text, sign_in

PASSWORD = "user-pass-1234"
PROGRAM = """\
import robot, time

bot = robot.Robot()
print("on my own sim")
bot.drive(0.2, 0.0)
time.sleep(0.5)
bot.stop()
print("done")
"""
SHOTS = "/work/notes/shots"


@pytest.fixture(scope="module")
def students(appliance):
    return {name: appliance.new_user(name, PASSWORD) for name in ("nina", "omar")}


def bench_of(new_page, appliance, students, name: str, width: int = 1366) -> tuple[Page, int]:
    body = {"name": f"Mine at {width}", "language": "python", "source": PROGRAM}
    response = appliance.api("POST", "/api/programs", body, token=students[name])
    assert response.status_code == 201, response.text
    page = new_page()
    page.set_viewport_size({"width": width, "height": 860 if width > 600 else 844})
    sign_in(page, name, PASSWORD)
    page.goto(f"/programs/{response.json()['id']}/")
    expect(page.locator(".CodeMirror")).to_be_visible()
    return page, response.json()["id"]


def test_my_sim_is_made_on_the_first_run_and_is_hers_alone(new_page, appliance, students):
    page, _program = bench_of(new_page, appliance, students, "nina")
    choice = page.locator("#bench-robot-choice")
    expect(choice.locator('option[value="+sim"]')).to_have_text("My sim (new)")
    choice.select_option("+sim")
    expect(page.locator("#bench-panel")).to_contain_text("It is made when you first run")
    page.screenshot(path=f"{SHOTS}/my-sim-before-1366.png", full_page=True)
    set_editor_text(page, PROGRAM)
    page.get_by_role("button", name=re.compile("Save and run")).click()
    console = page.locator("#console")
    expect(console.locator("#log-lines .ln.o")).to_have_text(["on my own sim", "done"])
    expect(console.locator("#run-status .state")).to_have_text("finished")
    # The choice is her sim now, by name, and the panel draws it.
    expect(choice).to_have_value("sim-nina-1")
    expect(choice.locator("option:checked")).to_have_text("sim-nina-1 (my sim)")
    expect(page.locator("#bench-panel canvas.simview-canvas")).to_be_visible()
    page.screenshot(path=f"{SHOTS}/my-sim-after-1366.png", full_page=True)
    mine = appliance.api("GET", "/api/sims", token=students["nina"]).json()
    assert [sim["name"] for sim in mine] == ["sim-nina-1"], mine
    run = appliance.api("GET", "/api/runs", token=students["nina"]).json()
    assert any(r["robot"] == "sim-nina-1" and r["state"] == "finished" for r in run), run
    # Another student: no such robot, on the pages and in the API.
    other = appliance.api("GET", "/api/robots/sim-nina-1", token=students["omar"])
    assert other.status_code == 404, other.text
    omar = new_page()
    sign_in(omar, "omar", PASSWORD)
    assert omar.goto("/robots/sim-nina-1/").status == 404
    omar.goto("/robots/")
    expect(omar.locator("main")).not_to_contain_text("sim-nina-1")


def test_my_sim_on_a_phone(new_page, appliance, students):
    """Omar at 390 px: the choice, the run, the drawn sim, all on a phone's screen."""
    page, _program = bench_of(new_page, appliance, students, "omar", width=390)
    choice = page.locator("#bench-robot-choice")
    choice.select_option("+sim")
    page.get_by_role("button", name=re.compile("Save and run")).click()
    expect(page.locator("#console #run-status .state")).to_have_text("finished")
    expect(choice).to_have_value("sim-omar-1")
    expect(page.locator("#bench-panel canvas.simview-canvas")).to_be_visible()
    width = page.evaluate("document.documentElement.scrollWidth")
    assert width <= 390, f"the page is {width} px wide at 390"
    page.screenshot(path=f"{SHOTS}/my-sim-after-390.png", full_page=True)
    assert httpx.get(appliance.url + "/healthz", timeout=10).status_code == 200
