"""The workbench's debugger in a real browser (issue 32), on the appliance's sim robot.

The example *Stop before the wall* (programs/examples/wall.py, every user's copy): a breakpoint
set by clicking the gutter beside the loop's `bot.show(...)` line, Debug, it pauses there with
`distance` among the variables while the robot stands still; Step over moves the paused line;
a watch says `distance < STOP_AT` False, and True later; Continue runs to the end. Also: the
emergency stop ends a paused run, a conditional breakpoint pauses only when its condition
holds, a program's values are shown as text (never as HTML), axe-core on the paused page, and
breakpoints follow their lines and are kept per program. Screenshots (1280 and 390 wide):
test-artifacts/screenshots/debugger-*.png.
"""

import re

import pytest
from playwright.sync_api import Page, expect

from tests.appliance import wait_for
from tests.browser.test_accessibility import AXE, AXE_URL, axe_violations
from tests.browser.test_pages import (
    _no_runs_left,  # noqa: F401 (autouse: a failed test's run stopped)
    assert_not_reloaded,
    mark_page,
    sign_in,
)
from tests.browser.test_workbench import new_program

WALL = "Stop before the wall"
SHOW_LINE = 13  # bot.show("range", round(distance, 2)), inside the loop
IF_LINE = 14  # if distance < STOP_AT:
BREAK_LINE = 15  # break: only once the robot is near the wall


@pytest.fixture
def bench(new_page, appliance) -> Page:
    """Admin's browser (axe at hand), the sim robot at its start and free to move."""
    appliance.resume()  # whatever an earlier test pressed
    appliance.api("POST", "/api/robots/sim/reset")
    page = new_page()
    page.route(
        f"**{AXE_URL}", lambda route: route.fulfill(path=AXE, content_type="text/javascript")
    )
    sign_in(page)
    return page


def open_example(page: Page, name: str = WALL) -> None:
    """The example as every user has it: copied among their programs."""
    page.goto("/programs/")
    page.locator("#programs").get_by_role("link", name=name, exact=True).click()
    expect(page.locator(".CodeMirror")).to_be_visible()
    expect(page.locator("#bench-panel #sensors")).to_be_visible()  # the robot, live


def open_program(page: Page, program_id: int) -> None:
    page.goto(f"/programs/{program_id}/")
    expect(page.locator(".CodeMirror")).to_be_visible()
    expect(page.locator("#bench-panel #sensors")).to_be_visible()


def gutter(page: Page, line: int):
    """The line's number in the editor's gutter (1-based), what a student clicks."""
    return page.locator(".CodeMirror-linenumber").filter(has_text=re.compile(rf"^{line}$"))


def line_text(page: Page, line: int) -> str:
    return page.evaluate("n => window.robotideEditor.getLine(n - 1)", line)


def breakpoints(page: Page) -> list[dict]:
    return page.evaluate("window.robotideBreakpoints.list()")


def status(page: Page):
    return page.locator("#debug-status")


def variable(page: Page, name: str):
    """A variable's line in the Variables panel (its name exactly)."""
    return page.locator("#debug-globals .var, #debug-locals .var").filter(
        has=page.locator(".var-name", has_text=re.compile(rf"^{re.escape(name)}$"))
    )


def paused_line(page: Page):
    return page.locator(".CodeMirror .debug-line")


def command_button(page: Page, command: str):
    return page.locator(f'#debug-panel button[data-command="{command}"]')


def velocity(appliance) -> float:
    return appliance.api("GET", "/api/robots/sim/sensors").json()["velocity"]["linear"]


def watch(page: Page, expression: str):
    return page.locator("#debug-watches li.debug-watch").filter(has_text=expression)


def add_watch(page: Page, expression: str) -> None:
    page.get_by_role("textbox", name="Watch an expression").fill(expression)
    page.get_by_role("textbox", name="Watch an expression").press("Enter")


def run_state(appliance, run_id: int) -> str:
    return appliance.api("GET", f"/api/runs/{run_id}").json()["state"]


def debug_run_id(page: Page) -> int:
    run = page.locator("#console #console-run[data-run]")
    expect(run).to_have_count(1)
    return int(run.get_attribute("data-run"))


# -- breakpoints in the editor (no run) ------------------------------------------------------


def test_breakpoints_follow_their_lines_and_are_kept_per_program(bench, appliance, screenshot):
    page = bench
    program = new_program(appliance, "Debug breakpoints", "a = 1\nb = 2\nc = 3\nprint(a + b + c)\n")
    open_program(page, program)
    gutter(page, 3).click()  # a click beside the number: a breakpoint
    expect(page.locator(".CodeMirror .breakpoint")).to_have_count(1)
    assert breakpoints(page) == [{"line": 3, "condition": None}]

    # F9 on the cursor's line, from the keyboard.
    page.evaluate("window.robotideEditor.setCursor({line: 0, ch: 0})")
    page.locator(".CodeMirror textarea").focus()
    page.keyboard.press("F9")
    assert breakpoints(page) == [{"line": 1, "condition": None}, {"line": 3, "condition": None}]

    # A line typed above: the breakpoints move with their lines.
    page.keyboard.press("Home")
    page.keyboard.press("Enter")  # the line's text pushed down, and its breakpoint
    page.keyboard.press("ArrowUp")
    page.keyboard.type("import robot")
    assert breakpoints(page) == [{"line": 2, "condition": None}, {"line": 4, "condition": None}]
    assert line_text(page, 4) == "c = 3"

    # Shift+click: a condition, in a small form under the line (not a prompt).
    gutter(page, 4).click(modifiers=["Shift"])
    condition = page.get_by_label("Pause at line 4 only when")
    expect(condition).to_be_focused()
    condition.fill("a + b > 2")
    condition.press("Enter")
    expect(page.locator(".breakpoint-form")).to_have_count(0)
    expect(page.locator(".CodeMirror .breakpoint.conditional")).to_have_count(1)
    assert breakpoints(page)[1] == {"line": 4, "condition": "a + b > 2"}
    # The right button opens it too; Esc leaves it as it was.
    gutter(page, 2).click(button="right")
    expect(page.get_by_label("Pause at line 2 only when")).to_be_focused()
    page.keyboard.press("Escape")
    expect(page.locator(".breakpoint-form")).to_have_count(0)
    screenshot(page, "debugger-breakpoints")

    # Kept in this browser, per program: the page again (saved first) has them.
    page.keyboard.press("Control+s")
    expect(page.locator("#save-state")).to_contain_text("Saved")
    page.reload()
    expect(page.locator(".CodeMirror .breakpoint")).to_have_count(2)
    assert breakpoints(page) == [
        {"line": 2, "condition": None},
        {"line": 4, "condition": "a + b > 2"},
    ]
    gutter(page, 2).click()  # a click again: gone
    assert breakpoints(page) == [{"line": 4, "condition": "a + b > 2"}]
    other = new_program(appliance, "Debug other", "print(1)\n")
    open_program(page, other)
    assert breakpoints(page) == []


def test_debug_is_offered_for_languages_with_a_debugger_only(bench, appliance):
    page = bench
    open_program(page, new_program(appliance, "Debug which", "print(1)\n"))
    debug = page.get_by_role("button", name="Debug", exact=True)
    expect(debug).to_be_enabled()
    expect(page.locator("#bench-no-debugger")).to_be_hidden()
    page.locator("#editor-form select[name=language]").select_option("shell")
    expect(debug).to_be_disabled()
    expect(debug).to_have_attribute("title", re.compile(r"Shell has no debugger yet"))
    link = page.get_by_role("link", name="No debugger yet")
    expect(link).to_have_attribute("href", "/languages/")
    page.locator("#editor-form select[name=language]").select_option("python")
    expect(debug).to_be_enabled()
    page.locator("details.shortcuts summary").click()
    keys = page.locator("details.shortcuts")
    for said in ("step over", "step into", "step out", "continue, or pause", "a breakpoint"):
        expect(keys).to_contain_text(said)


# -- the scenario ----------------------------------------------------------------------


def debug(page: Page) -> None:
    page.get_by_role("button", name="Debug", exact=True).click()
    expect(page.locator("#debug-panel")).to_be_visible()


def pause_in_the_loop(page: Page, appliance) -> float:
    """The example with a breakpoint on its loop's `bot.show(...)` line, Debug: it pauses
    there, the line shown, `distance` among the variables, the robot still. The distance."""
    open_example(page)
    mark_page(page)
    assert "bot.show(" in line_text(page, SHOW_LINE)
    gutter(page, SHOW_LINE).click()
    debug(page)
    expect(status(page)).to_have_text(f"Paused at line {SHOW_LINE} (breakpoint)", timeout=30_000)
    expect(paused_line(page)).to_contain_text("bot.show(")
    distance = variable(page, "distance")
    expect(distance.locator(".var-type")).to_have_text("float")
    first = float(distance.locator(".var-value").inner_text())
    assert first > 0.5
    expect(variable(page, "STOP_AT").locator(".var-value")).to_have_text("0.5")
    # A pause is a motion stop: the robot stands still while it lasts.
    wait_for(lambda: velocity(appliance) == 0.0, timeout=5, what="the robot stopped")
    return first


def test_stop_before_the_wall_pauses_in_its_loop_and_steps(bench, appliance, screenshot):
    page = bench
    pause_in_the_loop(page, appliance)
    run_id = debug_run_id(page)
    assert run_state(appliance, run_id) == "running"
    for width in (1280, 390):
        page.set_viewport_size({"width": width, "height": 860})
        page.locator("#debug-panel").scroll_into_view_if_needed()
        screenshot(page, f"debugger-paused-{width}")
    page.set_viewport_size({"width": 1280, "height": 860})

    # Step over: the next line.
    page.get_by_role("button", name="Step over").click()
    expect(status(page)).to_have_text(f"Paused at line {IF_LINE} (step)")
    expect(paused_line(page)).to_contain_text("if distance < STOP_AT:")
    page.keyboard.press("F10")  # and by key: the sleep, the robot still far from the wall
    expect(paused_line(page)).to_contain_text("time.sleep(0.02)")

    # A watch added while paused: the debugger evaluates it, the pause is said again.
    add_watch(page, "distance < STOP_AT")
    expect(watch(page, "distance < STOP_AT").locator(".var-value")).to_have_text("False")
    expect(watch(page, "distance < STOP_AT").locator(".changed")).to_have_count(0)  # just added
    assert velocity(appliance) == 0.0
    screenshot(page, "debugger-watch")

    command_button(page, "stop").click()
    expect(page.locator("#console #run-status")).to_have_attribute("data-state", "stopped")
    expect(status(page)).to_have_text("Ended (stopped)")
    expect(paused_line(page)).to_have_count(0)
    for command in ("continue", "step_over", "step_into", "step_out", "pause", "stop"):
        expect(command_button(page, command)).to_be_disabled()
    assert run_state(appliance, run_id) == "stopped"
    assert_not_reloaded(page)


def test_stop_before_the_wall_continues_to_its_end(bench, appliance):
    page = bench
    first = pause_in_the_loop(page, appliance)
    run_id = debug_run_id(page)
    add_watch(page, "distance < STOP_AT")
    expect(watch(page, "distance < STOP_AT").locator(".var-value")).to_have_text("False")

    # Near the wall: the breakpoint moves to `break`, which runs only then (the debugger is
    # told as it changes); Continue (F8) runs on to it.
    gutter(page, SHOW_LINE).click()
    gutter(page, BREAK_LINE).click()
    page.keyboard.press("F8")
    expect(status(page)).to_have_text(f"Paused at line {BREAK_LINE} (breakpoint)", timeout=30_000)
    expect(watch(page, "distance < STOP_AT").locator(".var-value")).to_have_text("True")
    distance = variable(page, "distance")
    expect(distance.locator(".var-value")).not_to_have_text(str(first))
    expect(distance).to_have_class(re.compile(r"\bchanged\b"))  # since the last pause

    # Continue: to the end.
    page.get_by_role("button", name="Continue").click()
    console = page.locator("#console")
    expect(console.locator("#run-status")).to_have_attribute(
        "data-state", "finished", timeout=30_000
    )
    expect(console.locator("#log-lines .ln.o").last).to_contain_text(
        re.compile(r"Stopped \d\.\d\d m before the wall")
    )
    expect(status(page)).to_have_text("Ended (finished)")
    expect(paused_line(page)).to_have_count(0)
    assert run_state(appliance, run_id) == "finished"


def test_the_emergency_stop_ends_a_paused_run(bench, appliance):
    page = bench
    open_example(page)
    gutter(page, SHOW_LINE).click()
    debug(page)
    expect(status(page)).to_have_text(f"Paused at line {SHOW_LINE} (breakpoint)", timeout=30_000)
    run_id = debug_run_id(page)
    try:
        page.get_by_role("button", name="EMERGENCY STOP").click()
        console = page.locator("#console")
        expect(console.locator("#run-status")).to_have_attribute("data-state", "stopped")
        expect(status(page)).to_have_text("Ended (stopped)")
        expect(paused_line(page)).to_have_count(0)
        expect(command_button(page, "continue")).to_be_disabled()
        assert run_state(appliance, run_id) == "stopped"
    finally:
        appliance.resume()  # the shared appliance's robot, for the tests after this one


def test_a_conditional_breakpoint_pauses_only_when_it_holds(bench, appliance, screenshot):
    page = bench
    open_example(page)
    gutter(page, SHOW_LINE).click(button="right")
    condition = page.get_by_label(f"Pause at line {SHOW_LINE} only when")
    condition.fill("distance < 1.0")
    condition.press("Enter")
    assert breakpoints(page) == [{"line": SHOW_LINE, "condition": "distance < 1.0"}]
    debug(page)
    expect(status(page)).to_have_text(f"Paused at line {SHOW_LINE} (breakpoint)", timeout=30_000)
    paused_at = float(variable(page, "distance").locator(".var-value").inner_text())
    assert 0.5 <= paused_at < 1.0  # it drove on, unpaused, until the condition held
    # axe-core on the page as it is while paused (the console's output box still empty)
    found = axe_violations(page)
    assert not found, "\n".join(f"{v['id']}: {v['help']} {v['targets']}" for v in found)
    screenshot(page, "debugger-conditional")
    command_button(page, "stop").click()
    expect(page.locator("#console #run-status")).to_have_attribute("data-state", "stopped")
    expect(status(page)).to_have_text("Ended (stopped)")


NASTY = """\
evil = '<img src=x onerror="window.pwned = 1">'
things = {"<b>key</b>": [evil, "<script>window.pwned = 2</script>"]}


def near(d):
    close = d < 1.0
    return close


answer = near(0.5)
print("done", answer)
"""


def test_values_are_text_and_steps_go_into_functions_and_out(bench, appliance, screenshot):
    page = bench
    open_program(page, new_program(appliance, "Debug nasty values", NASTY))
    gutter(page, 10).click()  # answer = near(0.5)
    debug(page)
    expect(status(page)).to_have_text("Paused at line 10 (breakpoint)", timeout=30_000)
    # A program's values are shown as text: a repr that reads as HTML is not made into HTML.
    evil = variable(page, "evil").locator(".var-value")
    expect(evil).to_have_text("""'<img src=x onerror="window.pwned = 1">'""")
    things = page.locator("#debug-globals > li > details").filter(has_text="things")
    things.locator("summary").first.click()
    expect(things.locator(".var-name", has_text="['<b>key</b>']")).to_be_visible()
    things.locator("details summary").first.click()
    expect(things).to_contain_text("'<script>window.pwned = 2</script>'")
    add_watch(page, "<i>not python</i>")
    expect(watch(page, "<i>not python</i>").locator(".watch-error")).to_contain_text("SyntaxError")
    panel = page.locator("#debug-panel")
    assert panel.locator("img, b, script, i").count() == 0
    assert page.evaluate("window.pwned") is None
    screenshot(page, "debugger-text-only")

    # Step into the function, its locals and the stack; step out; unfolded stays unfolded.
    page.keyboard.press("F11")
    expect(status(page)).to_have_text("Paused at line 6 (step)")
    expect(page.locator("#debug-stack li")).to_have_count(2)
    expect(page.locator("#debug-stack li").first).to_contain_text("near")
    expect(page.locator("#debug-locals .var-name").first).to_have_text("d")
    page.keyboard.press("F10")
    expect(status(page)).to_have_text("Paused at line 7 (step)")
    close = variable(page, "close")
    expect(close.locator(".var-value")).to_have_text("True")
    expect(close).to_have_class(re.compile(r"\bchanged\b"))  # new since the last pause
    expect(variable(page, "d")).not_to_have_class(re.compile(r"\bchanged\b"))
    page.keyboard.press("Shift+F11")
    expect(status(page)).to_have_text(re.compile(r"Paused at line (7|10|11) \(step\)"))
    expect(page.locator("#debug-stack li")).to_have_count(1)
    expect(things.locator("details").first).to_have_attribute("open", "")
    page.keyboard.press("F8")
    expect(page.locator("#console #run-status")).to_have_attribute("data-state", "finished")
    expect(page.locator("#console #log-lines .ln.o")).to_have_text(["done True"])


COUNTING = """\
import time

i = 0
print("counting")
while True:
    i += 1
    time.sleep(0.05)
"""


def test_pause_a_running_program_then_go_on(bench, appliance):
    page = bench
    open_program(page, new_program(appliance, "Debug counting", COUNTING))
    debug(page)  # no breakpoint: it runs
    expect(status(page)).to_have_text("Running")
    expect(command_button(page, "pause")).to_be_enabled()
    expect(command_button(page, "continue")).to_be_disabled()
    # In its loop (a Pause before the program's first line pauses there, at line 1)
    expect(page.locator("#console #log-lines .ln.o")).to_have_text(["counting"])
    command_button(page, "pause").click()
    expect(status(page)).to_have_text(re.compile(r"Paused at line [5-7] \(paused\)"))
    count = int(variable(page, "i").locator(".var-value").inner_text())
    expect(command_button(page, "pause")).to_be_disabled()
    page.keyboard.press("F8")  # continue
    expect(status(page)).to_have_text("Running")
    # A breakpoint set while it runs: the debugger is told, and pauses there.
    gutter(page, 6).click()
    expect(status(page)).to_have_text("Paused at line 6 (breakpoint)")
    gutter(page, 6).click()  # gone again (told while paused)
    page.keyboard.press("F8")
    expect(status(page)).to_have_text("Running")
    page.keyboard.press("F8")  # and pause again
    expect(status(page)).to_have_text(re.compile(r"Paused at line [5-7] \(paused\)"))
    assert int(variable(page, "i").locator(".var-value").inner_text()) >= count
    command_button(page, "stop").click()
    expect(page.locator("#console #run-status")).to_have_attribute("data-state", "stopped")
