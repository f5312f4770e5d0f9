"""Every page passes axe-core with no serious or critical violation, as a student and as staff;
and the robot page works from the keyboard and speaks its changes (live regions).

axe-core is test-only (tests/vendor/axe-core/): the appliance never serves it. The browser asks
for it at a same-origin address that the test answers itself, so the page's strict
Content-Security-Policy (script-src 'self') stays on while axe looks at it.
Screenshots: test-artifacts/screenshots/a11y-*.png.
"""

from pathlib import Path

import pytest
from playwright.sync_api import Page, expect

from tests.browser.test_pages import sign_in

AXE = Path(__file__).resolve().parents[1] / "vendor" / "axe-core" / "axe.min.js"
AXE_URL = "/__test__/axe.min.js"  # answered by page.route below, never by the appliance
STUDENT = ("a11y-student", "a11y-pass-1234")
FINISHES = "print('hello')\n"

# Third-party widgets whose own markup we do not write: (axe rule, CSS selector, why). Only
# that rule on those nodes is let through, not the subtree: every other rule still checks them.
KNOWN_THIRD_PARTY = [
    # Blockly 12 labels its workspace <g> (aria-label="Blockly Workspace", tabindex=0) without
    # a role; the node is Blockly's own and re-rendered by it, so a role set from our script
    # could fight Blockly's keyboard navigation, which manages the workspace's ARIA.
    ("aria-prohibited-attr", "#blocks-area g.blocklyWorkspace", "Blockly's workspace"),
]


def axe_violations(page: Page, also: tuple[str, ...] = ()) -> list[dict]:
    """axe-core's serious and critical violations on the page as it is now, and those of the
    rules in `also` whatever their impact."""
    page.add_script_tag(url=AXE_URL)
    return page.evaluate(
        """async ([known, also]) => {
          const isKnown = (rule, node) => node.target.length === 1 && known.some(([id, css]) =>
            id === rule && document.querySelector(node.target[0])?.matches(css));
          const result = await axe.run(document, {resultTypes: ["violations"]});
          return result.violations
            .filter(v => v.impact === "serious" || v.impact === "critical" || also.includes(v.id))
            .map(v => ({id: v.id, impact: v.impact, help: v.help,
                        targets: v.nodes.filter(n => !isKnown(v.id, n))
                                        .map(n => n.target.join(" "))}))
            .filter(v => v.targets.length);
        }""",
        [[[rule, css] for rule, css, _ in KNOWN_THIRD_PARTY], list(also)],
    )


def check(page: Page, screenshot, name: str, also: tuple[str, ...] = ()) -> None:
    screenshot(page, f"a11y-{name}")
    found = axe_violations(page, also)
    report = "\n".join(
        f"  {v['id']} ({v['impact']}): {v['help']}\n" + "".join(f"    {t}\n" for t in v["targets"])
        for v in found
    )
    assert not found, f"axe-core on {name} ({page.url}):\n{report}"


@pytest.fixture(scope="module")
def student(appliance) -> str:
    """The student's API token."""
    return appliance.new_user(STUDENT[0], password=STUDENT[1])


@pytest.fixture
def as_who(new_page, student):
    """A signed-in page for "student" or "staff" (the appliance's admin), or "nobody"; axe is
    on hand at AXE_URL."""

    def open_page(who: str) -> Page:
        page = new_page()
        page.route(
            f"**{AXE_URL}",
            lambda route: route.fulfill(path=AXE, content_type="text/javascript"),
        )
        if who == "student":
            sign_in(page, *STUDENT)
        elif who == "staff":
            sign_in(page)
        return page

    return open_page


def token_of(who: str, student: str):
    return student if who == "student" else None  # None: the appliance's admin token


ROLES = ["student", "staff"]


def test_sign_in_page(as_who, screenshot):
    page = as_who("nobody")
    page.goto("/accounts/login/")
    expect(page.get_by_label("User name")).to_be_visible()
    check(page, screenshot, "sign-in")


@pytest.mark.parametrize("who", ROLES)
def test_program_list(as_who, screenshot, who):
    page = as_who(who)
    page.goto("/programs/")
    expect(page.locator("#programs")).to_be_visible()
    check(page, screenshot, f"programs-{who}")


@pytest.mark.parametrize("who", ROLES)
def test_workbench_with_a_finished_run(as_who, appliance, student, screenshot, who):
    program = appliance.create_program(f"A11y bench {who}", FINISHES, token=token_of(who, student))
    appliance.resume()  # whatever an earlier test pressed
    page = as_who(who)
    page.goto(f"/programs/{program['id']}/")
    expect(page.locator(".CodeMirror")).to_be_visible()
    expect(page.locator("#bench-panel #sensors")).to_be_visible()
    page.locator(".CodeMirror").click()
    page.keyboard.press("Control+Enter")
    expect(page.locator("#console #run-status .state")).to_have_text("finished", timeout=30_000)
    check(page, screenshot, f"workbench-{who}")


@pytest.mark.parametrize("who", ROLES)
def test_blocks_program(as_who, appliance, student, screenshot, who):
    program = appliance.create_program(
        f"A11y blocks {who}", "", language="blocks", token=token_of(who, student)
    )
    page = as_who(who)
    page.goto(f"/programs/{program['id']}/")
    expect(page.locator("#blocks-area .blocklySvg")).to_be_visible()
    check(page, screenshot, f"blocks-{who}")


@pytest.mark.parametrize("who", ROLES)
def test_runs_list_and_a_run(as_who, appliance, student, screenshot, who):
    token = token_of(who, student)
    program = appliance.create_program(f"A11y run {who}", FINISHES, token=token)
    appliance.resume()
    run = appliance.run_program(program["id"], token=token)
    appliance.wait_run(run["id"])
    page = as_who(who)
    page.goto("/runs/")
    expect(page.locator("#run-tables")).to_be_visible()
    check(page, screenshot, f"runs-{who}")
    page.goto(f"/runs/{run['id']}/")
    expect(page.locator(".state").first).to_be_visible()
    check(page, screenshot, f"run-{who}")


@pytest.mark.parametrize("who", ROLES)
def test_robot_page(as_who, appliance, screenshot, who):
    appliance.resume()
    page = as_who(who)
    page.goto("/robots/sim/")
    page.wait_for_function("() => document.querySelector('#robot-status.connected')")
    expect(page.locator("#sensors")).to_be_visible()
    check(page, screenshot, f"robot-{who}")


def test_robot_page_emergency_stopped(as_who, appliance, screenshot):
    page = as_who("staff")
    try:
        response = appliance.api("POST", "/api/robots/sim/estop")
        assert response.status_code == 200, response.text
        page.goto("/robots/sim/")
        banner = page.locator(".estopped")
        expect(banner).to_be_visible()
        assert banner.get_attribute("role") == "alert"
        check(page, screenshot, "robot-estopped")
    finally:
        appliance.resume()


def test_robot_settings(as_who, screenshot):
    page = as_who("staff")
    page.goto("/robots/sim/settings")
    expect(page.locator("form").last).to_be_visible()
    check(page, screenshot, "robot-settings-staff")


@pytest.mark.parametrize("who", ROLES)
def test_sharing(as_who, appliance, student, screenshot, who):
    program = appliance.create_program(f"A11y shared {who}", FINISHES, token=token_of(who, student))
    page = as_who(who)
    page.goto(f"/programs/{program['id']}/")
    card = page.locator("section.shares")
    card.get_by_label("Share with").fill("everyone")
    card.get_by_label("may edit").check()
    card.get_by_role("button", name="Share", exact=True).click()
    expect(card.locator(".share-list")).to_contain_text("may edit")
    expect(page.locator(".CodeMirror")).to_be_visible()
    check(page, screenshot, f"sharing-{who}")


@pytest.mark.parametrize("who", ROLES)
@pytest.mark.parametrize(
    ("name", "url"),
    [("account", "/accounts/"), ("robot-api", "/help/robot-api/"), ("languages", "/languages/")],
)
def test_simple_pages(as_who, screenshot, who, name, url):
    page = as_who(who)
    page.goto(url)
    expect(page.locator("h1").first).to_be_visible()
    check(page, screenshot, f"{name}-{who}")


@pytest.mark.parametrize("who", ROLES)
def test_admin(as_who, screenshot, who):
    page = as_who(who)
    page.goto("/admin/")  # a student gets the admin's sign-in page, saying they may not
    expect(page.locator("main")).to_be_visible()
    check(page, screenshot, f"admin-{who}")


def test_admin_sign_in_page(as_who, screenshot):
    # Django's own page: its missing level-one heading is only "moderate" to axe, so asked for.
    page = as_who("nobody")
    page.goto("/admin/login/")
    expect(page.get_by_label("Username")).to_be_visible()
    check(page, screenshot, "admin-sign-in", also=("page-has-heading-one",))
    page.get_by_label("Username").fill("admin")
    page.get_by_label("Password").fill("not the password")
    page.get_by_role("button", name="Log in").click()
    expect(page.locator(".errornote")).to_be_visible()
    check(page, screenshot, "admin-sign-in-refused", also=("page-has-heading-one",))


# -- The robot page by keyboard ----------------------------------------------------------------


def tab_to(page: Page, name: str, limit: int = 80) -> dict:
    """Presses Tab until the element named `name` has focus; returns what the browser says of it."""
    for _ in range(limit):
        page.keyboard.press("Tab")
        focused = page.evaluate(
            """() => {
              const el = document.activeElement;
              const style = getComputedStyle(el);
              return {name: el.getAttribute("aria-label") || el.textContent.trim(),
                      tag: el.tagName, outlineStyle: style.outlineStyle,
                      outlineWidth: parseFloat(style.outlineWidth)};
            }"""
        )
        if focused["name"] == name:
            return focused
    raise AssertionError(f"{name!r} not reached in {limit} presses of Tab")


@pytest.mark.parametrize("who", ROLES)
def test_the_robot_page_by_keyboard(as_who, appliance, who):
    appliance.resume()
    page = as_who(who)
    page.goto("/robots/sim/")
    page.wait_for_function("() => document.querySelector('#robot-status.connected')")
    names = ["EMERGENCY STOP", "Forward", "Turn left", "Stop", "Turn right", "Back"]
    # A robot whose settings do not let this user press its e-stop shows it disabled, and a
    # disabled button is rightly not in the Tab order.
    if page.get_by_role("button", name="EMERGENCY STOP").is_disabled():
        assert who == "student"
        names.remove("EMERGENCY STOP")
    for name in names:
        page.locator("body").focus()
        page.evaluate("document.activeElement.blur()")
        focused = tab_to(page, name)
        assert focused["tag"] == "BUTTON", focused
        assert focused["outlineStyle"] not in ("none", "") and focused["outlineWidth"] >= 2, (
            f"no visible focus outline on {name}: {focused}"
        )


def test_the_robot_page_speaks_its_changes(as_who, appliance):
    page = as_who("staff")
    appliance.resume()
    page.goto("/robots/sim/")
    page.wait_for_function("() => document.querySelector('#robot-status.connected')")

    def live(selector: str) -> bool:
        return page.evaluate(
            """s => { const el = document.querySelector(s);
                      return !!el.closest('[role=status], [role=alert], [aria-live]'); }""",
            selector,
        )

    assert live("#robot-status"), "the robot's status is not a live region"
    assert live("#control .lease"), "who controls the robot is not a live region"
    assert live("#teleop-status"), "the driving errors are not a live region"
