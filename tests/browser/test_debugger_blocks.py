"""The debugger on a blocks program, in a real browser (issue 32): the example *Stop before the
wall (Blocks)* (programs/examples/wall.json) with a breakpoint on its `stop` block (set from the
block's context menu): while it runs its running block is highlighted, it pauses on the
breakpoint's block, and Continue runs it to its end, the highlight gone. Screenshots:
test-artifacts/screenshots/debugger-blocks-*.png."""

import re

import pytest
from playwright.sync_api import Page, expect

from tests.browser.test_pages import (
    _no_runs_left,  # noqa: F401 (autouse: a failed test's run stopped)
    sign_in,
)

WALL = "Stop before the wall (Blocks)"
LOOP_BLOCKS = ["wall-until", "wall-compare", "wall-range", "wall-show", "wall-wait"]


@pytest.fixture
def bench(new_page, appliance) -> Page:
    appliance.resume()  # whatever an earlier test pressed
    appliance.api("POST", "/api/robots/sim/reset")  # room to drive before the wall
    page = new_page()
    sign_in(page)
    return page


def open_example(page: Page) -> None:
    page.goto("/programs/")
    page.locator("#programs").get_by_role("link", name=WALL, exact=True).click()
    expect(page.locator("#blocks-area .blocklySvg")).to_be_visible()
    expect(page.locator("#blocks-python")).to_contain_text("bot = robot.Robot()")
    expect(page.locator("#bench-panel #sensors")).to_be_visible()


def block_path(page: Page, block_id: str):
    """The block's own shape (its group holds the blocks after it too)."""
    return page.locator(f'#blocks-area g.blocklyDraggable[data-id="{block_id}"] > path.blocklyPath')


def highlighted(page: Page) -> list[str]:
    return page.evaluate(
        "window.robotideBlocksEditor.workspace.highlightedBlocks.map(block => block.id)"
    )


def test_a_blocks_program_shows_its_running_block_and_stops_on_a_block_breakpoint(
    bench, appliance, screenshot
):
    page = bench
    open_example(page)
    block_path(page, "wall-stop").click(button="right", force=True)  # on its label
    page.locator(".blocklyContextMenu").get_by_text("Toggle breakpoint").click()
    stop_block = page.locator('#blocks-area g.blocklyDraggable[data-id="wall-stop"]')
    expect(stop_block).to_have_class(re.compile(r"robotide-breakpoint-block"))
    assert page.evaluate("window.robotideBreakpoints.list()") == [
        {"block": "wall-stop", "condition": None}
    ]

    # F9 on the selected block: on, and off again.
    page.evaluate(
        "Blockly.common.setSelected(window.robotideBlocksEditor.workspace.getBlockById('wall-print'))"
    )
    page.keyboard.press("F9")
    expect(page.locator('#blocks-area g[data-id="wall-print"]')).to_have_class(
        re.compile(r"robotide-breakpoint-block")
    )
    page.keyboard.press("F9")
    assert page.evaluate("window.robotideBreakpoints.list()") == [
        {"block": "wall-stop", "condition": None}
    ]

    page.get_by_role("button", name="Debug", exact=True).click()
    # While it drives, the block it runs is highlighted (the loop's).
    page.wait_for_function(
        "ids => window.robotideBlocksEditor.workspace.highlightedBlocks"
        ".some(block => ids.includes(block.id))",
        arg=LOOP_BLOCKS,
        timeout=30_000,
    )
    # At the wall it pauses on the breakpoint's block, highlighted.
    status = page.locator("#debug-status")
    expect(status).to_have_text(
        re.compile(r"Paused at the highlighted block: line \d+ of its Python \(breakpoint\)")
    )
    assert highlighted(page) == ["wall-stop"]
    expect(page.locator("#blocks-python .debug-line")).to_have_text("bot.stop()")  # its Python
    sensors = appliance.api("GET", "/api/robots/sim/sensors").json()
    assert sensors["velocity"]["linear"] == 0.0 and sensors["range"] < 0.5, sensors
    for width in (1280, 390):
        page.set_viewport_size({"width": width, "height": 860})
        page.locator("#debug-panel").scroll_into_view_if_needed()
        screenshot(page, f"debugger-blocks-paused-{width}")
    page.set_viewport_size({"width": 1280, "height": 860})

    page.get_by_role("button", name="Continue").click()
    console = page.locator("#console")
    expect(console.locator("#run-status")).to_have_attribute("data-state", "finished")
    expect(console.locator("#log-lines .ln.o").last).to_contain_text("m before the wall")
    expect(status).to_have_text("Ended (finished)")
    page.wait_for_function("window.robotideBlocksEditor.workspace.highlightedBlocks.length === 0")
    expect(page.locator("#blocks-python .debug-line")).to_have_count(0)
