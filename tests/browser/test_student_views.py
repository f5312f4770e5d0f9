"""What a student sees of robots in a real browser (issue 29, items 5, 11, 12).

- A student whose classes have no robot is told why and what to ask for: on the robot list,
  beside a disabled Run on the workbench, and when Run is asked anyway (Ctrl+Enter).
- "Shown by programs": another student's values while their run runs, never after it ended;
  one's own card goes a while (ROBOTIDE_SHOWS_KEEP_SECONDS) after the run ended.
- The robot page's isolation line: one plain sentence for a student, the whole line (cgroup
  paths and names) for staff.
"""

import re

import pytest
from playwright.sync_api import Page, expect

from tests.appliance import ADMIN_PASSWORD, DEADLINE, Appliance
from tests.browser.test_pages import sign_in

PASSWORD = "user-pass-1234"
SHOWS = """\
import time
import robot

bot = robot.Robot()
bot.show("{name}", {value})
print("shown", flush=True)
while True:
    time.sleep(0.2)
"""
CLASSES = """\
from django.contrib.auth.models import Group, User
from robots.models import Robot
a, b = Group.objects.create(name="class-a"), Group.objects.create(name="class-b")
Robot.objects.get(name="sim").groups.add(b)
User.objects.get(username="nora").groups.add(a)
for name in ("ann", "ben"):
    User.objects.get(username=name).groups.add(b)
"""
WHY = "none of your classes has one"
SIZES = {"phone": (390, 844), "desktop": (1366, 860)}


@pytest.fixture(scope="module")
def appliance(tmp_path_factory):
    """Its own appliance: a shown value leaves 2 s after its run ended; nora's class has no
    robot, ann's and ben's has sim; no personal sims (with them, nora runs on her own "My
    sim": tests/browser/test_my_sim.py, tests/robots/test_sims.py)."""
    env = {"ROBOTIDE_SHOWS_KEEP_SECONDS": "2", "ROBOTIDE_SIMS_PER_USER": "0"}
    app = Appliance(tmp_path_factory.mktemp("students"), extra_env=env).start()
    app.tokens = {name: app.new_user(name, PASSWORD) for name in ("nora", "ann", "ben")}
    app.cli("manage", "shell", "-c", CLASSES)
    yield app
    app.stop()


def signed_in(new_page, username: str) -> Page:
    page = new_page()
    sign_in(page, username, PASSWORD)
    return page


def shot(page: Page, screenshot, name: str) -> None:
    """The page at a phone's width and a desktop's, saved for a person to look at."""
    for size, (width, height) in SIZES.items():
        page.set_viewport_size({"width": width, "height": height})
        screenshot(page, f"{name}-{size}")


def run_as(appliance, who: str, name: str, source: str) -> int:
    token = appliance.tokens[who]
    program = appliance.create_program(name, source, token=token)
    return appliance.run_program(program["id"], token=token)["id"]


def stop(appliance, who: str, run_id: int) -> None:
    response = appliance.api("POST", f"/api/runs/{run_id}/stop", token=appliance.tokens[who])
    assert response.status_code in (200, 202), response.text
    appliance.wait_run(run_id)


def test_a_student_without_a_robot_is_told_why(appliance, new_page, screenshot):
    page = signed_in(new_page, "nora")
    page.goto("/robots/")
    expect(page.locator("#no-robot")).to_contain_text(WHY)
    expect(page.locator("#no-robot")).to_contain_text("Ask your teacher")
    expect(page.get_by_text("No robots yet.")).to_have_count(0)
    shot(page, screenshot, "student-no-robot-list")

    program = appliance.create_program("Hello", "print('hi')\n", token=appliance.tokens["nora"])
    page.goto(f"/programs/{program['id']}/")
    page.wait_for_function("window.robotideEditor !== undefined")
    run = page.get_by_role("button", name="Save and run")
    expect(run).to_be_disabled()
    expect(run).to_have_attribute("title", re.compile(WHY))
    expect(page.locator("#no-robot")).to_be_visible()
    expect(page.locator("#no-robot")).to_contain_text(WHY)
    expect(page.locator("#bench-robot-choice")).to_be_disabled()
    expect(page.locator("#bench-robot-choice")).to_contain_text("none open to you")
    # Ctrl+Enter asks anyway: the answer is the reason, not "The server answered 404".
    page.locator(".CodeMirror").click()
    page.keyboard.press("Control+Enter")
    expect(page.locator("#save-state")).to_contain_text(WHY)
    shot(page, screenshot, "student-no-robot-workbench")


def test_another_students_values_only_while_their_run_runs(appliance, new_page, screenshot):
    ann = signed_in(new_page, "ann")
    ann.goto("/robots/sim/")
    bens = run_as(appliance, "ben", "Ben shows", SHOWS.format(name="ben_secret", value=4242))
    card = ann.locator("#shows .show", has_text="ben_secret")
    expect(card).to_contain_text("4242", timeout=DEADLINE * 1000)  # a running run's: seen
    shot(ann, screenshot, "student-shows-running")
    stop(appliance, "ben", bens)
    expect(card).to_have_count(0)  # ended: ben's alone now (and his teachers')


def test_ones_own_card_goes_a_while_after_the_run_ended(appliance, new_page):
    ann = signed_in(new_page, "ann")
    ann.goto("/robots/sim/")
    mine = run_as(appliance, "ann", "Ann shows", SHOWS.format(name="ann_value", value=777))
    card = ann.locator("#shows .show", has_text="ann_value")
    expect(card).to_contain_text("777", timeout=DEADLINE * 1000)
    stop(appliance, "ann", mine)
    expect(card).to_have_count(0, timeout=DEADLINE * 1000)


def test_a_student_sees_a_plain_sentence_and_staff_the_isolation_line(
    appliance, new_page, screenshot
):
    raw = appliance.api("GET", "/api/robots/sim").json()["isolation"]  # admin: as runbox says
    assert raw
    ann = signed_in(new_page, "ann")
    ann.goto("/robots/sim/")
    line = ann.locator(".isolation")
    expect(line).to_have_text(
        re.compile(r"^Programs (run in a sandbox|cannot run on this robot now)")
    )
    body = ann.content()
    assert "/sys/fs/cgroup" not in body and "robotide-runs-" not in body and raw not in body
    shot(ann, screenshot, "student-robot-page")

    admin = new_page()
    sign_in(admin)
    admin.goto("/robots/sim/")
    words = "seccomp" if "seccomp" in raw else raw[:20]
    expect(admin.locator(".isolation")).to_contain_text(words)
    expect(admin.locator(".isolation")).to_contain_text("Programs run:")
    shot(admin, screenshot, "staff-robot-page")

    # In Portuguese: said from its parts, no path translated (what the line holds depends on
    # the machine; tests/robots/test_isolation_line.py covers each kind of line).
    admin_pt = new_page(locale="pt-BR")
    admin_pt.goto("/accounts/login/")
    admin_pt.locator('input[name="username"]').fill("admin")
    admin_pt.locator('input[name="password"]').fill(ADMIN_PASSWORD)
    admin_pt.locator('input[name="password"]').press("Enter")
    expect(admin_pt).not_to_have_url(re.compile("/accounts/login/"))
    admin_pt.goto("/robots/sim/")
    expect(admin_pt.locator(".isolation")).to_contain_text("Os programas rodam:")
    assert "memória/" not in admin_pt.locator(".isolation").inner_text()
    shot(admin_pt, screenshot, "staff-robot-page-pt")
