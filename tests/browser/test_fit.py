"""Every page fits a phone (360 and 390 px wide) and still looks as it did on a laptop (1366 px).

For each page a student and a teacher open: the page never scrolls sideways (a wide table
scrolls inside its own box or becomes cards) and no table runs past its column; the emergency
stop is on screen on the workbench and the robot's page (at every width, also after scrolling
down); on a phone every button, field, summary and menu link is at least 44 px tall (a
finger's width). Also a student reading Portuguese (longer words) at 360 px, and a tablet's
820 px. Each page is saved at 390, 820 and 1366 px (and the Portuguese 360) to
test-artifacts/screenshots/fit-*.png for a person to look at.
"""

import pytest
from playwright.sync_api import Page, expect

from tests.browser.test_pages import sign_in

PASSWORD = "a long enough passphrase"
PHONES = (360, 390)
WIDTHS = (*PHONES, 1366)
TABLET = 820  # one column, as on a narrow window: the emergency stop floats there too
HEIGHT = {360: 740, 390: 844, TABLET: 1180, 1366: 860}
SHOT_AT = (390, TABLET, 1366)
TOUCH = 44  # px: the smallest target a finger hits (WCAG 2.5.5, Apple's and Google's guides)

# What a finger must hit: the menu, buttons, links drawn as buttons or beside a button (Cancel),
# summaries, and form fields (a checkbox through its label).
TARGETS = (
    "header.top a, header.top button, header.top select, summary, button, a.button, "
    ":is(form, p) > button ~ a, select, textarea, "
    "input:not([type=hidden]):not([type=checkbox]):not([type=radio]), "
    "label:has(> input[type=checkbox]), label:has(> input[type=radio])"
)
# Exceptions, on purpose: the editors' own insides (CodeMirror's hidden input, Blockly's
# drawing) are not ours to size, and a link inside a sentence or a table cell is text, not a
# button (WCAG 2.5.5 exempts inline targets).
NOT_TARGETS = ".CodeMirror, .blocklySvg, .blocklyWidgetDiv, .blocklyToolboxDiv, .visually-hidden"

UNBROKEN = "a_long_name_with_no_spaces_" * 3  # what students name things; and a path, a hash…
LONG_LINE = "/sys/fs/cgroup/robotide/" + "0123456789abcdef" * 12

PYTHON = f"""\
import robot
print({LONG_LINE!r})
print("short line")
"""


def measure(page: Page) -> dict:
    """The page's width against its window's, and what sticks out past the right edge."""
    return page.evaluate(
        """() => {
        const root = document.documentElement, width = root.clientWidth;
        const wide = [];
        for (const el of document.body.querySelectorAll("*")) {
          const box = el.getBoundingClientRect();
          if (box.width && box.right > width + 0.5 && el.checkVisibility()) {
            let parent = el.parentElement, inner = false;  // a scrolling box holds it: fine
            for (; parent && parent !== document.body; parent = parent.parentElement) {
              const overflow = getComputedStyle(parent).overflowX;
              if (overflow === "auto" || overflow === "scroll" || overflow === "hidden") {
                inner = true; break;
              }
            }
            if (!inner) wide.push(el.tagName.toLowerCase() + (el.id ? "#" + el.id : "")
              + (el.className && typeof el.className === "string"
                 ? "." + el.className.trim().split(/\\s+/).join(".") : "")
              + " " + Math.round(box.right) + "px");
          }
        }
        // A table wider than its box, where no scrolling box holds it, runs under what is
        // beside it (the page's width does not show that).
        for (const table of document.querySelectorAll("main table")) {
          const box = table.parentElement;
          if (!table.checkVisibility() || getComputedStyle(box).overflowX !== "visible") continue;
          const over = table.getBoundingClientRect().right - box.getBoundingClientRect().right;
          const name = "table" + (table.id ? "#" + table.id : "");
          if (over > 1) wide.push(`${name} ${Math.round(over)}px past its box`);
        }
        return {scroll: root.scrollWidth, client: width, wide: wide.slice(0, 8)};
    }"""
    )


def small_targets(page: Page) -> list[str]:
    return page.evaluate(
        """([targets, exempt, least]) => {
        const small = [];
        for (const el of document.querySelectorAll(targets)) {
          if (el.closest(exempt) || !el.checkVisibility({visibilityProperty: true})) continue;
          const box = el.getBoundingClientRect();
          if (!box.width || !box.height) continue;
          if (box.height < least - 0.5) {
            const name = (el.innerText || el.value || el.name || el.getAttribute("aria-label")
                          || "").trim().slice(0, 30);
            small.push(`${el.tagName.toLowerCase()} "${name}" ${Math.round(box.height)}px`);
          }
        }
        return small;
    }""",
        [TARGETS, NOT_TARGETS, TOUCH],
    )


def inside_viewport(page: Page, selector: str) -> bool:
    box = page.locator(selector).bounding_box()
    view = page.viewport_size
    return (
        box is not None
        and box["x"] >= 0
        and box["y"] >= 0
        and box["x"] + box["width"] <= view["width"]
        and box["y"] + box["height"] <= view["height"]
    )


@pytest.fixture(scope="module")
def people(appliance):
    """A student and a teacher (staff), each with a Python program of two revisions, a blocks
    program, a finished run that printed a long unbroken line, and an API token."""
    made = {}
    for role, staff in (("student", False), ("teacher", True), ("aluno", False)):
        username = f"fit-{role}"
        token = appliance.new_user(username, PASSWORD, staff=staff)
        program = appliance.create_program(f"{UNBROKEN}{role}", "print(1)\n", token=token)
        appliance.api("PUT", f"/api/programs/{program['id']}", {"source": PYTHON}, token=token)
        blocks = appliance.create_program(f"Blocks {role}", "", language="blocks", token=token)
        run = appliance.run_program(program["id"], token=token)
        appliance.wait_run(run["id"])
        short = appliance.create_program(f"Wave {role}", "print('hi')\n", token=token)
        appliance.wait_run(appliance.run_program(short["id"], token=token)["id"])
        made[role] = {
            "username": username,
            "program": program["id"],
            "blocks": blocks["id"],
            "run": run["id"],
        }
    # The robot page's gateway card: a serial bridge whose device is not there (an error row).
    bridge = {"device": "/dev/ttyUSB-robotide-fit-test-not-there", "address": "127.0.0.1:0"}
    response = appliance.api("POST", "/api/robots/sim/bridges", bridge)
    assert response.status_code == 201, response.text
    return made


def pages_of(who: dict, staff: bool) -> list[tuple[str, str, str]]:
    """(name, address, what shows the page is ready) of every page this person opens."""
    program, blocks, run = who["program"], who["blocks"], who["run"]
    pages = [
        ("programs", "/programs/", "#programs"),
        ("workbench", f"/programs/{program}/", "#bench-panel #sensors"),
        ("workbench-blocks", f"/programs/{blocks}/", "#blocks-area .blocklySvg"),
        ("revisions", f"/programs/{program}/revisions/", "h1"),
        ("compare", f"/programs/{program}/revisions/1/", "pre.diff"),
        ("current-revision", f"/programs/{program}/revisions/2/", "p.empty"),
        ("delete", f"/programs/{program}/delete", "h1"),
        ("languages", "/languages/", "h1"),
        ("robot-api", "/help/robot-api/", "h1"),
        ("robots", "/robots/", "h1"),
        ("robot", "/robots/sim/", ".gateway"),
        ("runs", "/runs/", "#run-tables"),
        ("run", f"/runs/{run}/", "#log-lines .ln"),
        ("account", "/accounts/", "h1"),
        ("password", "/accounts/password/", "h1"),
    ]
    if staff:
        pages += [
            ("robot-settings", "/robots/sim/settings", "h1"),
            ("robot-buttons", "/robots/sim/buttons/", "h1"),
        ]
    return pages


def check(page: Page, name: str, width: int, screenshot, problems: list[str]) -> None:
    fit = measure(page)
    if fit["scroll"] > fit["client"] or any("past its box" in w for w in fit["wide"]):
        problems.append(f"{name}: {fit['scroll']} px wide in {fit['client']}: {fit['wide']}")
    if width in PHONES:
        small = small_targets(page)
        if small:
            problems.append(f"{name}: under {TOUCH} px tall: {small}")
    if name.split("-", 1)[1] in ("workbench", "workbench-blocks", "workbench-ran", "robot"):
        estop = "button.estop"
        expect(page.locator(estop)).to_be_visible()
        if not inside_viewport(page, estop):
            problems.append(f"{name}: the emergency stop is off screen")
        page.evaluate("window.scrollTo(0, document.documentElement.scrollHeight)")
        if not inside_viewport(page, estop):
            problems.append(f"{name}: the emergency stop is gone after scrolling down")
        page.evaluate("window.scrollTo(0, 0)")
    if width in SHOT_AT or name.startswith("aluno"):  # and the Portuguese phone
        screenshot(page, f"fit-{name}-{width}")


def open_at(new_page, width: int) -> Page:
    page = new_page()  # a window this wide (the fixture's context options fix the viewport)
    page.set_viewport_size({"width": width, "height": HEIGHT[width]})
    return page


@pytest.mark.parametrize(
    "role, width",
    [(role, width) for role in ("student", "teacher") for width in WIDTHS]
    + [("aluno", 360), ("student", TABLET)],
)
def test_every_page_fits(new_page, people, role, width, screenshot):
    """Each page as a student and a teacher see it; and as a student reading Portuguese (its
    words are longer) on the narrowest phone."""
    who = people[role]
    page = open_at(new_page, width)
    sign_in(page, who["username"], PASSWORD)
    if role == "aluno":
        page.locator("header.top .language-switcher select").select_option("pt-br")
        page.locator("header.top .language-switcher button").click()
        expect(page.locator("html")).to_have_attribute("lang", "pt-br")
    problems: list[str] = []
    for name, address, ready in pages_of(who, staff=role == "teacher"):
        page.goto(address)
        expect(page.locator(ready).first).to_be_visible()
        check(page, f"{role}-{name}", width, screenshot, problems)
    # The workbench once its program ran: the console's status line and output under the editor.
    page.goto(f"/programs/{who['program']}/")
    expect(page.locator("#bench-panel #sensors")).to_be_visible()
    page.locator(".CodeMirror").click()
    page.keyboard.press("Control+Enter")  # save and run
    expect(page.locator("#console #run-status .state.finished")).to_be_visible()
    check(page, f"{role}-workbench-ran", width, screenshot, problems)
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("width", WIDTHS)
def test_the_sign_in_page_fits(new_page, appliance, width, screenshot):
    page = open_at(new_page, width)
    page.goto("/accounts/login/")
    page.get_by_label("User name").fill("nobody")
    page.get_by_label("Password").fill("not the password")
    page.get_by_role("button", name="Sign in").click()
    expect(page.locator(".errorlist")).to_be_visible()  # with its error, the longer page
    problems: list[str] = []
    check(page, "sign-in", width, screenshot, problems)
    assert not problems, "\n".join(problems)
