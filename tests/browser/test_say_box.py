"""The "Say to the robot" box: on the sim robot's page, "move" typed (and Enter) is what the
paper's voice example running there hears, as its log shows; the box without scripts is a
plain form; the workbench's robot panel has the box too. Before, the example exited 1 on the
sim (no microphone) and there was no box."""

import pytest
from playwright.sync_api import Page, expect

from programs.languages import CLIENTS_DIR
from tests.appliance import wait_for
from tests.browser.test_pages import sign_in

VOICE_MOVE = (CLIENTS_DIR.parent / "examples" / "voice_move.py").read_text()


@pytest.fixture
def page(new_page) -> Page:
    page = new_page()
    sign_in(page)
    return page


def stop_the_example(appliance, run_id: int) -> None:
    """ "stop" said once it listens: the example ends (the robot free for the next test)."""

    def said():
        body = {"text": "stop", "queue": False}
        return appliance.api("POST", "/api/robots/sim/hear", body).status_code == 200

    wait_for(said, what="the example listening, to say stop")
    appliance.wait_run(run_id)


def test_move_typed_into_the_robot_page_is_heard_by_the_voice_example(page, appliance, screenshot):
    program = appliance.create_program("voice", VOICE_MOVE)
    run_id = appliance.run_program(program["id"])["id"]
    page.goto("/robots/sim/")
    heard = page.locator("#heard")
    expect(page.locator("#listening")).to_be_visible()  # its listen() waits
    box = page.get_by_label("Say to the robot")
    box.fill("move")
    box.press("Enter")
    # Taken by the listen() waiting, or (typed between two of its calls) by the next one.
    expect(page.locator("#say-status")).to_contain_text("Said “move”")
    expect(box).to_have_value("")  # ready for the next phrase
    expect(heard).to_contain_text("Last heard: “move” (typed by admin).")
    for width in (390, 1366):
        page.set_viewport_size({"width": width, "height": 900})
        screenshot(page, f"robot-say-box-{width}")
    run_page = page.context.new_page()
    run_page.goto(f"/runs/{run_id}/")
    expect(run_page.locator("body")).to_contain_text("heard: move")
    stop_the_example(appliance, run_id)


def test_the_box_without_scripts_is_a_form_on_a_page_that_does_not_reload(new_page, appliance):
    """The robot's page, without scripts, reloads itself every 2 s: it links to the box on a
    page of its own, whose form posts and comes back to it."""
    page = new_page(java_script_enabled=False)
    sign_in(page)
    page.goto("/robots/sim/")
    page.get_by_role("link", name="Type on a page that does not reload itself").click()
    expect(page).to_have_url(f"{appliance.url}/robots/sim/say")
    page.get_by_label("Say to the robot").fill("hello robot")
    page.get_by_role("button", name="Say", exact=True).click()
    expect(page).to_have_url(f"{appliance.url}/robots/sim/say")
    expect(page.locator(".messages")).to_contain_text("Said “hello robot”: no program listens yet")


def test_the_workbench_panel_has_the_box(page, appliance, screenshot):
    program = appliance.create_program("voice on the bench", VOICE_MOVE)
    run_id = appliance.run_program(program["id"])["id"]
    page.goto(f"/programs/{program['id']}/")
    panel = page.locator("#bench-robot")
    expect(panel.locator("#listening")).to_be_visible()  # its listen() waits
    box = panel.get_by_label("Say to the robot")
    box.fill("left")
    box.press("Enter")
    expect(panel.locator("#heard")).to_contain_text("Last heard: “left” (typed by admin).")
    for width in (390, 1366):
        page.set_viewport_size({"width": width, "height": 900})
        screenshot(page, f"workbench-say-box-{width}")
    stop_the_example(appliance, run_id)
