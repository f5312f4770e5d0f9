"""A page's browser console stays clean: no htmx error for a swap with no target, and no
request answered 404 (the icon every browser asks for)."""

from playwright.sync_api import expect

from tests.browser.test_pages import sign_in
from tests.browser.test_workbench import new_program, open_bench


def test_the_workbench_logs_no_error_and_asks_for_nothing_missing(new_page, appliance):
    page = new_page()
    errors, missing = [], []
    page.on("console", lambda m: m.type in ("error", "warning") and errors.append(m.text))
    page.on("response", lambda r: r.status == 404 and missing.append(r.url))
    page.add_init_script(
        "document.addEventListener('htmx:oobErrorNoTarget',"
        " e => console.error('htmx:oobErrorNoTarget ' + e.detail.content.id))"
    )
    sign_in(page)
    program = new_program(appliance, "Console clean", "print('one line')\n")
    open_bench(page, program)
    page.keyboard.press("Control+Enter")
    # A run's start and end reach the robot's websocket as its list of runs: the workbench,
    # which shows none, is sent none.
    expect(page.locator("#console #run-status .state")).to_have_text("finished")
    page.goto("/robots/sim/")  # the robot page still gets its list and queue
    expect(page.locator("#robot-running")).to_be_visible()
    icon = page.evaluate("fetch('/favicon.ico').then(r => [r.status, r.url])")
    assert icon[0] == 200 and icon[1].endswith(".svg"), icon
    assert page.locator("link[rel=icon]").count() == 1
    assert not [e for e in errors if "oobErrorNoTarget" in e], errors
    assert not missing, missing
