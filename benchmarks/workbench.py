"""The workbench in Debian's chromium: the program page loaded to editable, and a keypress to
the program's first line in the console, against the two-page flow it replaced (the form
posted, the run's own page loaded, the line arriving there) on the same program and robot.

    .venv/bin/python -m benchmarks.workbench
"""

import time

from playwright.sync_api import sync_playwright

from benchmarks.common import Figure, appliance, median, percentile, say
from tests.appliance import ADMIN_PASSWORD
from tests.browser.conftest import CHROMIUM, CHROMIUM_ARGS

BENCH = "workbench"
ROUNDS = 10
PROGRAM = "print('first line', flush=True)\n"
FIRST_LINE = "#log-lines .ln.o"

# The two-page flow: the form posted as it was before the workbench (its submit handler
# bypassed), answered by a redirect to the run's page, which streams the output.
POST_THE_FORM = """() => {
  const form = document.getElementById("editor-form");
  const action = document.createElement("input");
  action.type = "hidden"; action.name = "action"; action.value = "run";
  form.append(action);
  HTMLFormElement.prototype.submit.call(form);
}"""


def run() -> list[Figure]:
    with appliance(BENCH) as app, sync_playwright() as p:
        program = app.create_program("Bench first line", PROGRAM)["id"]
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        # bypass_csp: the page's CSP forbids the eval behind wait_for_function.
        page = browser.new_context(base_url=app.url, bypass_csp=True).new_page()
        sign_in(page)
        loads, bench, two_pages = [], [], []
        for _ in range(ROUNDS):
            loads.append(load_to_editable(page, program))
            bench.append(press_to_line(page, lambda: page.keyboard.press("Control+Enter")))
            wait_finished(page)
            load_to_editable(page, program)
            two_pages.append(press_to_line(page, lambda: page.evaluate(POST_THE_FORM)))
        browser.close()
    say(f"load {loads}\nworkbench {bench}\ntwo pages {two_pages}")
    return [
        Figure(BENCH, "program page load -> editor editable, median", median(loads), "ms"),
        Figure(BENCH, "program page load -> editor editable, p90", percentile(loads, 90), "ms"),
        Figure(
            BENCH,
            "Ctrl-Enter -> first line in the console, median",
            median(bench),
            "ms",
            "< two-page flow",
            median(bench) < median(two_pages),
        ),  # fmt: skip
        Figure(
            BENCH, "Ctrl-Enter -> first line in the console, p90", percentile(bench, 90), "ms"
        ),  # fmt: skip
        Figure(
            BENCH, "baseline: form post -> run page -> first line, median", median(two_pages), "ms"
        ),  # fmt: skip
        Figure(
            BENCH,
            "baseline: form post -> run page -> first line, p90",
            percentile(two_pages, 90),
            "ms",
        ),  # fmt: skip
    ]


def sign_in(page) -> None:
    page.goto("/accounts/login/")
    page.get_by_label("User name").fill("admin")
    page.get_by_label("Password").fill(ADMIN_PASSWORD)
    page.get_by_role("button", name="Sign in").click()
    page.wait_for_selector("text=Sign out")


def load_to_editable(page, program: int) -> float:
    """ms from the navigation's start to the editor taking keys, by the page's own clock."""
    page.goto(f"/programs/{program}/", wait_until="commit")
    page.wait_for_function("window.robotideEditor && document.getElementById('save-state')")
    page.evaluate("window.robotideEditor.focus()")
    return page.evaluate("performance.now()")


def press_to_line(page, press) -> float:
    started = time.monotonic()
    press()
    page.wait_for_selector(FIRST_LINE)
    return (time.monotonic() - started) * 1000.0


def wait_finished(page) -> None:
    page.wait_for_selector("#run-status[data-state=finished]")


if __name__ == "__main__":
    from benchmarks.common import print_table

    print_table(run())
