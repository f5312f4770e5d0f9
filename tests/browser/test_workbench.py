"""The workbench in a real browser: write, run and watch on one page, stop by key, and never
lose what was typed (unsaved-changes guard, an expired sign-in, a conflicting save)."""

import re
from pathlib import Path

import pytest
from playwright.sync_api import Page, expect

from tests.browser.test_pages import (
    FOREVER,
    assert_not_reloaded,
    editor_text,
    mark_page,
    set_editor_text,
    sign_in,
)

ROOT = Path(__file__).resolve().parents[2]
COUNTDOWN = """\
import robot, time

bot = robot.Robot()
bot.drive(0.2, 1.0)
for i in (3, 2, 1):
    print("countdown", i)
    time.sleep(0.4)
bot.stop()
"""


@pytest.fixture
def bench(new_page) -> Page:
    """A browser signed in as admin."""
    page = new_page()
    sign_in(page)
    return page


def new_program(appliance, name: str, source: str) -> int:
    response = appliance.api(
        "POST", "/api/programs", {"name": name, "language": "python", "source": source}
    )
    assert response.status_code == 201, response.text
    return response.json()["id"]


def open_bench(page: Page, program_id: int) -> None:
    page.goto(f"/programs/{program_id}/")
    expect(page.locator(".CodeMirror")).to_be_visible()
    expect(page.locator("#bench-panel #sensors")).to_be_visible()  # the robot, live


def test_type_ctrl_enter_and_watch_the_output_and_the_robot(bench, appliance, screenshot):
    page = bench
    program = new_program(appliance, "Bench countdown", "print('first')\n")
    open_bench(page, program)
    mark_page(page)
    set_editor_text(page, COUNTDOWN)
    page.locator(".CodeMirror").click()  # and a line typed by hand, as a student would
    page.keyboard.press("Control+End")
    page.keyboard.type('print("typed")')
    expect(page.locator("#save-state")).to_have_text("Unsaved changes")
    camera = page.locator("#bench-panel canvas.simview-canvas")
    expect(camera).to_be_visible()  # the sim, drawn by the page
    expect(camera).to_have_attribute("data-pose", re.compile(r"\S"))
    before = camera.get_attribute("data-pose")
    page.keyboard.press("Control+Enter")
    console = page.locator("#console")
    expect(console.locator("#log-lines .ln.o")).to_have_text(
        ["countdown 3", "countdown 2", "countdown 1", "typed"]
    )
    expect(console.locator("#run-status .state")).to_have_text("finished")
    expect(console.locator("#run-status")).to_contain_text("exit code 0")
    # It came over the console's websocket, open before Run: no connection of its own.
    assert console.locator("#console-run").get_attribute("ws-connect") is None
    expect(page.locator("#save-state")).to_contain_text("Saved (revision 2)")
    expect(camera).not_to_have_attribute("data-pose", before)  # it turned, and its drawing
    assert_not_reloaded(page)
    screenshot(page, "workbench-finished")
    run_link = console.get_by_role("link", name=re.compile(r"Run #\d+"))
    run_id = int(re.search(r"\d+", run_link.inner_text()).group())
    assert appliance.api("GET", f"/api/runs/{run_id}").json()["state"] == "finished"


def test_escape_twice_stops_the_run(bench, appliance, screenshot):
    page = bench
    program = new_program(appliance, "Bench forever", FOREVER)
    open_bench(page, program)
    page.get_by_role("button", name="Save and run").click()
    console = page.locator("#console")
    expect(console.locator("#log-lines .ln.o").nth(3)).to_be_visible()  # running
    expect(page.locator("#bench-stop")).to_be_enabled()
    screenshot(page, "workbench-running")
    page.keyboard.press("Escape")
    page.keyboard.press("Escape")
    expect(console.locator("#run-status .state")).to_have_text("stopped")
    expect(page.locator("#bench-stop")).to_be_disabled()


def test_leaving_with_unsaved_changes_asks_first(bench, appliance):
    page = bench
    program = new_program(appliance, "Bench unsaved", "print(1)\n")
    open_bench(page, program)
    set_editor_text(page, "print(2)\n")
    asked = []
    page.on("dialog", lambda dialog: (asked.append(dialog.type), dialog.dismiss()))
    page.close(run_before_unload=True)
    page.wait_for_timeout(500)
    assert asked == ["beforeunload"]


def test_a_save_after_the_sign_in_expired_keeps_the_text(new_page, appliance):
    program = new_program(appliance, "Bench expired", "print('old')\n")
    page = new_page()
    sign_in(page)
    open_bench(page, program)
    set_editor_text(page, "print('typed while signed out')\n")
    page.context.clear_cookies(name="sessionid")  # the session expired meanwhile
    page.keyboard.press("Control+s")
    expect(page.locator("#save-state")).to_contain_text("sign-in has expired")
    assert editor_text(page) == "print('typed while signed out')\n"
    other = page.context.new_page()  # "Sign in again" opens a new tab
    sign_in(other)
    other.close()
    page.bring_to_front()
    page.evaluate("window.dispatchEvent(new Event('focus'))")
    expect(page.locator("#save-state")).to_contain_text("Saved (revision 2)")
    saved = appliance.api("GET", f"/api/programs/{program}").json()["source"]
    assert saved == "print('typed while signed out')\n"


def test_a_second_tab_is_told_of_the_conflict_and_shown_the_difference(
    new_page, appliance, screenshot
):
    program = new_program(appliance, "Bench two tabs", "print('base')\n")
    first, second = new_page(), new_page()
    for tab in (first, second):
        sign_in(tab)
        open_bench(tab, program)
    set_editor_text(first, "print('first tab')\n")
    first.keyboard.press("Control+s")
    expect(first.locator("#save-state")).to_contain_text("Saved (revision 2)")
    set_editor_text(second, "print('second tab')\n")
    second.keyboard.press("Control+s")
    conflict = second.locator("#conflict")
    expect(conflict).to_be_visible()
    expect(conflict).to_contain_text("Revision 2 was saved after you opened")
    expect(conflict.locator("pre.diff")).to_contain_text("-print('first tab')")
    expect(conflict.locator("pre.diff")).to_contain_text("+print('second tab')")
    assert appliance.api("GET", f"/api/programs/{program}").json()["source"] == (
        "print('first tab')\n"
    )
    screenshot(second, "workbench-conflict")
    conflict.get_by_role("button", name="Save mine over it").click()
    expect(second.locator("#save-state")).to_contain_text("Saved (revision 3)")
    expect(conflict).to_be_hidden()


BROKEN = """\
import robot

def broken():
    return 1 / 0

broken()
"""


def test_a_python_error_links_to_its_line(bench, appliance, screenshot):
    page = bench
    program = new_program(appliance, "Bench broken", BROKEN)
    open_bench(page, program)
    page.keyboard.press("Control+Enter")
    console = page.locator("#console")
    expect(console.locator("#run-status .state")).to_have_text("failed")
    # The traceback's frames in the program: the call on line 6, the division on line 4.
    expect(console.locator(".ln.e[data-line]")).to_have_count(2)
    assert console.locator(".ln.e[data-line]").evaluate_all(
        "lines => lines.map(l => l.dataset.line)"
    ) == ["6", "4"]
    marked = page.locator(".CodeMirror .error-line")
    expect(marked).to_have_count(1)
    expect(marked).to_contain_text("return 1 / 0")  # the deepest frame is marked
    screenshot(page, "workbench-error")
    console.locator('.ln[data-line="6"]').click()
    assert page.evaluate("window.robotideEditor.getCursor().line") == 5
    expect(marked).to_contain_text("broken()")


def test_a_closed_tab_leaves_a_draft_that_is_offered_back(new_page, appliance, screenshot):
    program = new_program(appliance, "Bench draft", "print('saved')\n")
    page = new_page()
    sign_in(page)
    open_bench(page, program)
    set_editor_text(page, "print('typed, never saved')\n")
    page.close()  # no time for anything but the page's goodbye
    again = new_page()
    sign_in(again)
    open_bench(again, program)
    offer = again.locator("#draft-offer")
    expect(offer).to_contain_text("You have unsaved text from")
    assert editor_text(again) == "print('saved')\n"  # nothing replaced without asking
    screenshot(again, "workbench-draft")
    offer.get_by_role("button", name="Restore it").click()
    assert editor_text(again) == "print('typed, never saved')\n"
    expect(again.locator("#save-state")).to_contain_text("not saved yet")
    again.keyboard.press("Control+s")
    expect(again.locator("#save-state")).to_contain_text("Saved (revision 2)")
    again.reload()
    expect(again.locator(".CodeMirror")).to_be_visible()
    expect(again.locator("#draft-offer")).to_have_count(0)  # a save ends the draft


def test_drafts_are_kept_while_typing(bench, appliance):
    program = new_program(appliance, "Bench typing", "print('saved')\n")
    open_bench(bench, program)
    set_editor_text(bench, "print('typing')\n")
    # The page keeps it within a few seconds, without a save and without leaving.
    expect(bench.locator("#save-state")).to_have_text("Unsaved changes")
    bench.wait_for_timeout(4000)
    other = bench.context.new_page()
    open_bench(other, program)
    expect(other.locator("#draft-offer")).to_be_visible()
    other.locator("#draft-offer").get_by_role("button", name="Discard it").click()
    expect(other.locator("#draft-offer")).to_have_count(0)


def test_without_scripts_a_conflicting_save_is_refused_with_the_difference(new_page, appliance):
    program = new_program(appliance, "Bench plain", "print('base')\n")
    page = new_page(java_script_enabled=False)
    sign_in(page)
    page.goto(f"/programs/{program}/")
    response = appliance.api("PUT", f"/api/programs/{program}", {"source": "print('api')\n"})
    assert response.status_code == 200, response.text  # someone saves meanwhile
    page.locator("textarea#source").fill("print('mine')\n")
    page.get_by_role("button", name="Save", exact=True).click()
    expect(page.locator("#editor-form")).to_contain_text("Not saved: revision 2 was saved after")
    expect(page.locator("#conflict pre.diff")).to_contain_text("+print('mine')")
    expect(page.locator("textarea#source")).to_have_value("print('mine')\n")  # kept
    page.get_by_role("button", name="Save", exact=True).click()
    expect(page.locator(".messages")).to_contain_text("Saved (revision 3)")


def test_a_blocks_program_runs_on_sim_and_stops_before_the_wall(bench, appliance, screenshot):
    page = bench
    response = appliance.api(
        "POST", "/api/programs", {"name": "Bench blocks", "language": "blocks", "source": ""}
    )
    assert response.status_code == 201, response.text
    program = response.json()["id"]
    appliance.api("POST", "/api/robots/sim/resume")  # whatever an earlier test pressed
    page.goto(f"/programs/{program}/")
    expect(page.locator("#blocks-area .blocklySvg")).to_be_visible()
    expect(page.locator(".CodeMirror")).to_have_count(0)  # blocks, not text
    # Blockly's own stylesheet applies (the page's policy lets its <style> in): the toolbox
    # is a column beside the workspace, not a list across it.
    toolbox = page.locator(".blocklyToolbox, .blocklyToolboxDiv").first.bounding_box()
    assert toolbox["height"] > toolbox["width"], toolbox
    # Built through Blockly's API in the page, as dragging would: the wall example's blocks.
    wall = (ROOT / "programs" / "examples" / "wall.json").read_text()
    page.evaluate("json => window.robotideBlocksEditor.load(json)", wall)
    page.evaluate("() => window.robotideBlocksEditor.workspace.getTopBlocks()[0].moveBy(20, 0)")
    python = page.locator("#blocks-python")
    expect(python).to_contain_text("while not (bot.sensor('range') < 0.4):")
    expect(page.locator("#save-state")).to_have_text("Unsaved changes")
    screenshot(page, "workbench-blocks")
    page.keyboard.press("Control+Enter")
    console = page.locator("#console")
    expect(console.locator("#run-status .state")).to_have_text("finished", timeout=30_000)
    expect(console.locator("#log-lines .ln.o").last).to_contain_text("m before the wall")
    sensors = appliance.api("GET", "/api/robots/sim/sensors").json()
    assert 0.25 < sensors["range"] < 0.45 and not sensors["bumper"], sensors
    saved = appliance.api("GET", f"/api/programs/{program}").json()
    assert '"robot_drive"' in saved["source"]  # stored as Blockly's JSON


def test_blocks_copied_as_a_python_program(bench, appliance):
    page = bench
    wall = (ROOT / "programs" / "examples" / "square.json").read_text()
    response = appliance.api(
        "POST", "/api/programs", {"name": "Bench square", "language": "blocks", "source": wall}
    )
    program = response.json()["id"]
    page.goto(f"/programs/{program}/")
    expect(page.locator("#blocks-python")).to_contain_text("bot = robot.Robot()")
    page.get_by_role("button", name="Copy as a Python program").click()
    expect(page.get_by_role("heading", name="Bench square (Python)")).to_be_visible()
    expect(page.locator(".CodeMirror")).to_be_visible()
    assert "Generated from a blocks program" in editor_text(page)


def test_the_workbench_completes_robot_api_calls(bench, appliance):
    page = bench
    program = new_program(appliance, "Bench help", "import robot\nbot = robot.Robot()\n")
    open_bench(page, program)
    page.locator(".CodeMirror").click()
    page.keyboard.press("Control+End")
    page.keyboard.type("bot.dr")
    page.keyboard.press("Control+Space")
    hints = page.locator(".CodeMirror-hints")
    expect(hints).to_contain_text("drive")
    page.keyboard.press("Enter")
    assert "bot.drive(" in editor_text(page)


def test_the_emergency_stop_beside_the_editor(bench, appliance):
    page = bench
    program = new_program(appliance, "Bench e-stop", FOREVER)
    open_bench(page, program)
    page.keyboard.press("Control+Enter")
    console = page.locator("#console")
    expect(console.locator("#run-status .state")).to_have_text("running")
    try:
        page.get_by_role("button", name="EMERGENCY STOP").click()
        expect(page.locator("#save-state")).to_contain_text("Emergency stop: sim stopped")
        expect(console.locator("#run-status .state")).to_have_text("stopped")
    finally:
        appliance.resume()  # the shared appliance's robot, for the tests after this one


def test_the_keyboard_leaves_the_editor_and_folds_the_robot_panel(bench, appliance):
    page = bench
    program = new_program(appliance, "Bench keys", "print(1)\n")
    open_bench(page, program)
    page.locator(".CodeMirror").click()
    page.keyboard.press("Tab")  # in the editor, Tab indents
    assert editor_text(page).endswith("    ")  # spaces at the cursor, focus stays
    page.keyboard.press("Escape")
    page.keyboard.press("Tab")  # Esc then Tab: out of the editor, to the robot's choice
    assert page.evaluate("document.activeElement.id") == "bench-robot-choice"
    toggle = page.get_by_role("button", name="Hide the robot")
    toggle.focus()
    page.keyboard.press("Enter")
    expect(page.locator("#bench-panel #sensors")).to_be_hidden()
    expect(page.locator("#panel-toggle")).to_have_attribute("aria-expanded", "false")
    page.keyboard.press("Enter")
    expect(page.locator("#bench-panel #sensors")).to_be_visible()
