"""Issue 31's scenario in a real browser, through the pages: a teacher makes a class of three
from a pasted list and prints its sheet of one-time passwords; sets an exercise, "reach the
kitchen without touching anything" on the boxes world, with one visible and two hidden start
poses; student A signs in with her one-time password, chooses her own, and checks a program
that stops by its range sensor: it passes every variant. Student B's "drive 3 s, then turn"
passes the visible variant and fails a hidden one, and his checklist says why without giving
the hidden pose away. The teacher's grid shows both, and its CSV has both rows.

The programs were chosen on an in-process sim (rhal.connect("sim://?world=boxes")) from these
poses: the kitchen zone is x in [-1, 0], y in [1.4, 2.0], its wall at y = 2 (the robot's radius
is 0.15 m: it touches the wall with its centre at 1.85). B drives 0.2 m/s for 3 s of his
clock: from y = 0.82 (the visible start and hidden start 3) he ends in the kitchen if his
drive lasts 3 to 5.15 s (it cannot be shorter: his sleep begins once the drive answered), so
a check sim's clock at speed 2 may be late by a whole real second and he still passes; from
y = -1.15 (hidden start 2) he ends at y = -0.55, nowhere near it. A drives north until her
range sensor reads 0.45 m (slowly for the last 0.45 m) and stops, her centre at y = 1.55:
the same wherever she starts facing north, a stop 0.3 m (2 s of her slow speed) before a
touch.
"""

import csv
import math
import re

import pytest
from playwright.sync_api import Page, expect

from tests.browser.test_pages import set_editor_text, sign_in

TEACHER, TEACHER_PASSWORD = "tess", "teacher-pass-1234"
NAMES = ["Ana Souza", "Bruno Lima", "Carla Dias"]
NEW_PASSWORDS = {"A": "ana-chose-this-9081", "B": "bruno-chose-this-4410"}
TITLE = "Reach the kitchen without touching anything"
TEXT = "Drive to the **kitchen** and stop there. Do not touch a wall or a box."
NORTH = round(math.pi / 2, 4)
VISIBLE = {"x": -0.5, "y": 0.82, "theta": NORTH, "hidden": False}
HIDDEN = [
    {"x": -0.45, "y": -1.15, "theta": NORTH, "hidden": True},  # B ends far short of it
    {"x": -0.75, "y": 0.82, "theta": NORTH, "hidden": True},  # B gets there too
]
SPEED = "2"  # the check sims' clock, x real time: B's 3 s may be a second late and still pass
# What would give a hidden pose away, in any page a student is shown
HIDDEN_GIVEAWAYS = ["-0.45", "-1.15", "-0.75"]
CHECK_DEADLINE_MS = 180_000  # the attempt's state: a deadline for the event, not its time

PROGRAM_A = """\
import time

import robot

bot = robot.Robot()
# Fast while the wall is far, slowly near it, and stop 0.45 m before it: in the kitchen.
while True:
    distance = bot.sensors()["range"]
    if distance < 0.45:
        break
    bot.drive(0.4 if distance > 0.9 else 0.15, 0.0)
    time.sleep(0.02)
bot.stop()
print(f"stopped {distance:.2f} m before the wall")
"""
PROGRAM_B = """\
import time

import robot

bot = robot.Robot()
bot.drive(0.2, 0.0)
time.sleep(3)
bot.drive(0.0, 1.0)
time.sleep(1.5)
bot.stop()
print("there, I think")
"""
SHOTS = "/work/notes/shots"


@pytest.fixture(scope="module")
def teacher(appliance):
    appliance.new_user(TEACHER, TEACHER_PASSWORD, staff=True)  # staff, no model permissions
    return TEACHER


def create_class(page: Page) -> tuple[int, dict[str, tuple[str, str]]]:
    """The classroom page: a class, then three students from a pasted list. Returns its id
    and each name's (username, one-time password) read off the sheet."""
    page.goto("/classroom/")
    page.get_by_label("Name").fill("Robotics 7B")
    page.get_by_role("button", name="Make the class").click()
    expect(page.locator("h1")).to_have_text("Robotics 7B")
    group = int(re.search(r"/classroom/(\d+)/", page.url).group(1))
    page.get_by_label("Names, one a line").fill("\n".join(NAMES))
    page.get_by_role("button", name="Add to the class").click()
    expect(page.locator("h1")).to_have_text("Sign-in sheet: Robotics 7B")
    cards = page.locator(".sheet-card")
    expect(cards).to_have_count(3)
    accounts = {}
    for name in NAMES:
        card = cards.filter(has_text=name)
        username = card.locator(".sheet-username").inner_text().strip()
        password = card.locator(".sheet-password").inner_text().strip()
        accounts[name] = (username, password)
    return group, accounts


def print_sheet(page: Page) -> None:
    """The sheet as printed: the menu and the buttons gone, every card there; and a PDF."""
    page.emulate_media(media="print")
    expect(page.locator("header.top")).to_be_hidden()
    expect(page.locator("#sheet-print")).to_be_hidden()
    for name in NAMES:
        expect(page.locator(".sheet-card").filter(has_text=name)).to_be_visible()
    pdf = page.pdf(path=f"{SHOTS}/classroom-e2e-sheet.pdf", prefer_css_page_size=True)
    assert pdf.startswith(b"%PDF"), pdf[:20]
    page.emulate_media(media="screen")


def variant_row(page: Page, n: int):
    return page.locator("#ex-variants > li").nth(n)


def check_row(page: Page, n: int):
    return page.locator("#ex-checks > li").nth(n)


def set_pose(row, pose: dict) -> None:
    row.get_by_label("x (m)").fill(str(pose["x"]))
    row.get_by_label("y (m)").fill(str(pose["y"]))
    row.get_by_label("heading (°)").fill("90")
    hidden = row.get_by_label("hidden from students")
    if pose["hidden"]:
        hidden.check()
    else:
        hidden.uncheck()


def create_exercise(page: Page, group: int) -> int:
    """The exercise editor's form: text, the boxes world, three start poses (the first
    visible), two checks; saved. Returns the exercise's id."""
    page.goto("/classroom/exercises/new")
    page.get_by_label("Title").fill(TITLE)
    page.get_by_label("Text for students").fill(TEXT)
    page.locator("#ex-world").select_option("boxes")
    page.get_by_label("Class", exact=True).select_option(str(group))
    expect(page.locator("#ex-variants > li")).to_have_count(1)  # the world's own start
    set_pose(variant_row(page, 0), VISIBLE)
    for number, pose in enumerate(HIDDEN, 1):
        page.get_by_role("button", name="Add a start pose").click()
        expect(page.locator("#ex-variants > li")).to_have_count(number + 1)
        set_pose(variant_row(page, number), pose)
    page.get_by_role("button", name="Add a check").click()
    reach = check_row(page, 0)
    reach.get_by_label("What").select_option("reach_zone")
    reach.get_by_label("Zone", exact=True).fill("kitchen")
    reach.get_by_label("Message students see").fill("Find the kitchen: its wall is north.")
    page.get_by_role("button", name="Add a check").click()
    untouched = check_row(page, 1)
    untouched.get_by_label("What").select_option("no_contact")
    untouched.get_by_label("Message students see").fill("Slow down before the wall.")
    page.get_by_label("Check speed").fill(SPEED)
    page.get_by_label("Time limit of a run").fill("30")
    page.get_by_role("button", name="Save").first.click()
    expect(page).to_have_url(re.compile(r"/classroom/exercises/\d+/edit$"))
    expect(page.locator(".messages")).to_contain_text("Saved")
    page.screenshot(path=f"{SHOTS}/classroom-e2e-exercise.png", full_page=True)
    html = page.content()  # the teacher's: what a leak would look like, so its absence counts
    assert all(giveaway in html for giveaway in HIDDEN_GIVEAWAYS), HIDDEN_GIVEAWAYS
    return int(re.search(r"/exercises/(\d+)/edit$", page.url).group(1))


def sign_in_first_time(page: Page, username: str, one_time: str, chosen: str) -> None:
    """Signs in with the sheet's password, and must choose one before anything else."""
    sign_in(page, username, one_time)
    expect(page).to_have_url(re.compile(r"/accounts/password/$"))
    page.locator("#id_old_password").fill(one_time)
    page.locator("#id_new_password1").fill(chosen)
    page.locator("#id_new_password2").fill(chosen)
    page.get_by_role("button", name="Change password").click()
    expect(page.locator("h1")).to_have_text("Password changed")


def check_program(page: Page, exercise: int, source: str):
    """From the student's list of exercises: open it, Start (the workbench opens), write the
    program, press Check; waits until the attempt is done. Returns the checklist and the
    attempt's id."""
    page.goto("/exercises/")
    page.get_by_role("link", name=TITLE).first.click()
    expect(page).to_have_url(re.compile(rf"/exercises/{exercise}/$"))
    expect(page.locator("h1")).to_have_text(TITLE)
    expect(page.locator("#hidden-count")).to_contain_text("2 hidden start poses")
    assert_no_hidden_pose(page, "the exercise's page")
    page.locator("#start").click()
    expect(page).to_have_url(re.compile(r"/programs/\d+/$"))
    expect(page.locator("#exercise-bench")).to_contain_text(TITLE)
    page.wait_for_function("() => window.robotideEditor !== undefined")
    set_editor_text(page, source)
    page.locator("#check-button").click()
    checklist = page.locator("#exercise-checklist .checklist")
    expect(checklist).to_have_attribute(
        "data-state", re.compile("^(done|error)$"), timeout=CHECK_DEADLINE_MS
    )
    expect(checklist).to_have_attribute("data-state", "done")  # not error: its why else
    return checklist, int(checklist.get_attribute("data-attempt"))


def assert_no_hidden_pose(page: Page, where: str) -> None:
    html = page.content()
    for giveaway in HIDDEN_GIVEAWAYS:
        assert giveaway not in html, f"{giveaway} (a hidden pose) on {where}"


def test_a_class_an_exercise_and_two_students(new_page, appliance, teacher):
    page = new_page()
    sign_in(page, TEACHER, TEACHER_PASSWORD)
    group, accounts = create_class(page)
    page.screenshot(path=f"{SHOTS}/classroom-e2e-sheet.png", full_page=True)
    print_sheet(page)
    exercise = create_exercise(page, group)

    # A: her program stops by the range sensor, wherever it starts: every variant passes.
    (a_user, a_once), (b_user, b_once) = accounts[NAMES[0]], accounts[NAMES[1]]
    ana = new_page()
    sign_in_first_time(ana, a_user, a_once, NEW_PASSWORDS["A"])
    checklist, attempt_a = check_program(ana, exercise, PROGRAM_A)
    expect(checklist.locator(".verdict")).to_have_text("passed")
    expect(checklist.locator(".score")).to_have_text("2 of 2 points")
    expect(checklist.locator(".check.passed")).to_have_count(2)
    expect(checklist.locator(".variants li.failed")).to_have_count(0)
    ana.screenshot(path=f"{SHOTS}/classroom-e2e-ana.png", full_page=True)

    # B: 3 s ahead, then a turn: the visible start passes; hidden start 1 is too far back.
    bruno = new_page()
    sign_in_first_time(bruno, b_user, b_once, NEW_PASSWORDS["B"])
    checklist, attempt_b = check_program(bruno, exercise, PROGRAM_B)
    expect(checklist.locator(".verdict")).to_have_text("not passed")
    expect(checklist.locator(".score")).to_have_text("1 of 2 points")
    reach, untouched = checklist.locator(".check").nth(0), checklist.locator(".check").nth(1)
    expect(reach).to_have_class(re.compile(r"\bfailed\b"))
    expect(untouched).to_have_class(re.compile(r"\bpassed\b"))
    expect(reach.locator(".teacher-message")).to_have_text("Find the kitchen: its wall is north.")
    entries = reach.locator(".variants > li")
    expect(entries).to_have_count(3)
    expect(entries.nth(0)).to_have_class(re.compile(r"\bpassed\b"))  # the visible start
    failed = reach.locator(".variants > li.failed")
    expect(failed).to_have_count(1)
    expect(failed).to_have_class(re.compile(r"\bhidden-variant\b"))
    expect(failed.locator(".why")).to_contain_text("kitchen")  # why, in words
    bruno.screenshot(path=f"{SHOTS}/classroom-e2e-bruno-bench.png", full_page=True)
    assert_no_hidden_pose(bruno, "the workbench")

    # His attempt's page: the checklist again, the visible start's replay, nothing hidden.
    bruno.goto(f"/attempts/{attempt_b}/")
    expect(bruno.locator(".checklist")).to_have_attribute("data-state", "done")
    expect(bruno.locator("#replay-0")).to_be_visible()
    expect(bruno.locator("#replays figure.replay")).to_have_count(1)
    expect(bruno.locator("#attempt-runs")).to_contain_text("secret")
    assert_no_hidden_pose(bruno, "the attempt's page")
    bruno.screenshot(path=f"{SHOTS}/classroom-e2e-bruno-attempt.png", full_page=True)
    for hidden in (1, 2):
        answer = bruno.request.get(f"/attempts/{attempt_b}/replay/{hidden}.json")
        assert answer.status == 404, (hidden, answer.status)
    assert bruno.request.get(f"/attempts/{attempt_a}/").status == 404  # not his

    # The teacher's grid: both, with their scores; and its CSV.
    page.goto(f"/classroom/{group}/grid")
    cells = page.locator("#grades td.grid-cell")
    ana_cell = cells.and_(page.locator(f'[data-student="{a_user}"]'))
    bruno_cell = cells.and_(page.locator(f'[data-student="{b_user}"]'))
    expect(ana_cell).to_contain_text("✔")
    expect(ana_cell).to_contain_text("2/2")
    expect(ana_cell.get_by_role("link")).to_have_attribute("href", f"/attempts/{attempt_a}/")
    expect(bruno_cell).to_contain_text("1/2")
    expect(bruno_cell).to_contain_text("1 attempt")
    expect(bruno_cell).not_to_contain_text("✔")
    page.screenshot(path=f"{SHOTS}/classroom-e2e-grid.png", full_page=True)
    with page.expect_download() as download:
        page.get_by_role("link", name="Download CSV").click()
    with open(download.value.path(), encoding="utf-8-sig") as f:
        rows = list(csv.reader(f))
    column = rows[0].index(TITLE)
    by_user = {row[0]: row for row in rows[1:]}
    assert float(by_user[a_user][column]) == 2, rows
    assert float(by_user[b_user][column]) == 1, rows
