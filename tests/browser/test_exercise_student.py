"""A student's exercise in a real browser (issue 31): the list, the exercise (its world drawn
with the visible start only), Start making the program and opening the workbench with its
Check, and an attempt's checklist and replay (scrubbed, played)."""

import json
import math
import re

import pytest
from playwright.sync_api import Page, expect

from tests.appliance import Appliance
from tests.browser.test_accessibility import AXE, AXE_URL, axe_violations
from tests.browser.test_pages import set_editor_text, sign_in

PASSWORD = "user-pass-1234"
SIZES = {"desktop": (1280, 800), "phone": (390, 844)}
VISIBLE = {"x": -1.1, "y": -1.4, "theta": 1.3}
HIDDEN = {"x": 1.2345, "y": -0.6789, "theta": 2.3456}
KITCHEN = (-0.5, 1.7)
END_T = 10.0
SETUP = (
    f"VISIBLE = {VISIBLE!r}\nHIDDEN = {HIDDEN!r}\n"
    + """\
from django.contrib.auth.models import Group, User
from classroom.models import Exercise
from robotide.models import ClassTeacher
from worlds.documents import builtin_worlds
group = Group.objects.create(name="class-a")
User.objects.get(username="alice").groups.add(group)
ClassTeacher.objects.create(group=group, user=User.objects.get(username="tina"))
Exercise.objects.create(
    owner=User.objects.get(username="tina"), group=group, title="Reach the kitchen",
    text="Drive to the **kitchen**: never touch a wall or a box.\\n\\n- the range sensor helps",
    world="boxes", world_document=builtin_worlds()["boxes"], languages=["python"],
    variants=[{**VISIBLE, "hidden": False}, {**HIDDEN, "hidden": True}],
    checks=[{"kind": "reach_zone", "zone": "kitchen", "within_s": 30, "points": 2, "message": ""},
            {"kind": "no_contact", "points": 1, "message": "Look before you drive!"}],
    starter="import robot\\n\\nbot = robot.Robot()\\n", starter_language="python",
)
"""
)


def path_poses() -> list:
    """A straight drive from the visible start into the kitchen, END_T sim s long."""
    steps = int(END_T / 0.05)
    theta = math.atan2(KITCHEN[1] - VISIBLE["y"], KITCHEN[0] - VISIBLE["x"])
    return [
        [round(i * 0.05, 3),
         round(VISIBLE["x"] + (KITCHEN[0] - VISIBLE["x"]) * i / steps, 4),
         round(VISIBLE["y"] + (KITCHEN[1] - VISIBLE["y"]) * i / steps, 4),
         round(theta, 4)]
        for i in range(steps + 1)
    ]  # fmt: skip


#: An attempt of alice's as classroom.checking leaves one: done, a run and trace per variant.
ATTEMPT = """\
import json
from django.contrib.auth.models import User
from django.utils import timezone
from classroom.models import Attempt, AttemptRun, Exercise
from programs.models import Program, Run
from robots.models import Robot
alice = User.objects.get(username="alice")
exercise = Exercise.objects.get(title="Reach the kitchen")
program = Program.objects.create(owner=alice, name="attempted", language="python")
revision = program.save_source("print('hi')\\n", alice)
sim = Robot.objects.create(name="check-sim-1", url="sim://", personal=True, owner=alice,
                           checking=True, reaped=timezone.now())
results = [
    {"check": 0, "variant": 0, "passed": True, "why": "reached kitchen at 9.5 s", "points": 2},
    {"check": 0, "variant": 1, "passed": False,
     "why": "hidden variant 2: never reached kitchen", "points": 2},
    {"check": 1, "variant": 0, "passed": False, "why": "touched a box at 4.0 s", "points": 1},
    {"check": 1, "variant": 1, "passed": True, "why": "hidden variant 2: no contact",
     "points": 1},
]
attempt = Attempt.objects.create(
    exercise=exercise, student=alice, program=program, revision=revision, language="python",
    source=revision.source, revision_number=revision.number, number=1, state="done", score=0,
    max_score=3, passed=False, finished=timezone.now(), results=results)
trace = json.loads(TRACE)
for index, variant in enumerate(exercise.variants):
    pose = {k: variant[k] for k in ("x", "y", "theta")}
    run = Run.create_for(program, sim, alice, sealed=index == 1)
    Run.objects.filter(pk=run.pk).update(state="finished", exit_code=0)
    run.directory.mkdir(parents=True, exist_ok=True)
    (run.directory / "trace.json").write_text(json.dumps({**trace, "start": pose}))
    AttemptRun.objects.create(attempt=attempt, variant=index, hidden=variant["hidden"],
                              pose=pose, run=run, checked=True)
print(attempt.pk)
"""


def trace() -> dict:
    poses = path_poses()
    touch = poses[80]  # at 4.0 s
    return {
        "version": 1, "speed": 5.0, "radius": 0.15, "start": VISIBLE, "poses": poses,
        "contacts": [[4.0, touch[1], touch[2]]], "commands": [[0.0, 0.3, 0.0]],
        "said": [[9.5, "kitchen"]], "output": [[0.1, "off I go"]],
        "end": {"t": END_T, "state": "finished", "exit_code": 0, "reason": "exit status 0",
                "time_limit": False},
        "truncated": False,
    }  # fmt: skip


@pytest.fixture(scope="module")
def appliance(tmp_path_factory):
    app = Appliance(tmp_path_factory.mktemp("exercises")).start()
    for name in ("alice", "tina"):
        app.new_user(name, PASSWORD)
    app.cli("manage", "shell", "-c", SETUP)
    yield app
    app.stop()


def signed_in(new_page, username: str) -> Page:
    page = new_page()
    page.route(
        f"**{AXE_URL}", lambda route: route.fulfill(path=AXE, content_type="text/javascript")
    )
    sign_in(page, username, PASSWORD)
    return page


def accessible(page: Page, name: str) -> None:
    """axe-core finds no serious or critical violation on the page as it is now."""
    found = axe_violations(page)
    assert not found, f"axe-core on {name}: {found}"


def shot(page: Page, screenshot, name: str) -> None:
    for size, (width, height) in SIZES.items():
        page.set_viewport_size({"width": width, "height": height})
        screenshot(page, f"{name}-{size}")
    page.set_viewport_size({"width": 1280, "height": 800})


def test_open_an_exercise_start_it_and_the_workbench_has_check(appliance, new_page, screenshot):
    page = signed_in(new_page, "alice")
    page.get_by_role("link", name="Exercises").click()
    expect(page.get_by_role("heading", name="Exercises")).to_be_visible()
    shot(page, screenshot, "exercise-student-list")
    accessible(page, "the exercise list")
    page.get_by_role("link", name="Reach the kitchen").first.click()
    expect(page.get_by_role("heading", name="Reach the kitchen")).to_be_visible()
    expect(page.locator("#exercise-text strong")).to_have_text("kitchen")
    expect(page.locator("#hidden-count")).to_have_text("and 1 hidden start pose")
    expect(page.locator("#exercise-checks")).to_contain_text("Reach the zone “kitchen” within 30 s")
    canvas = page.locator("canvas.replay-canvas")
    expect(canvas).to_be_visible()
    # Drawn: the world's floor and the start, not the dark background only.
    page.wait_for_function(
        """() => { const c = document.querySelector('canvas.replay-canvas');
          if (!c || c.width < 100) return false;
          const d = c.getContext('2d').getImageData(c.width / 2, c.height / 2, 1, 1).data;
          return d[0] > 200 && d[1] > 200; }"""
    )
    assert str(HIDDEN["x"]) not in page.content()
    shot(page, screenshot, "exercise-student-exercise")
    accessible(page, "an exercise")

    page.get_by_role("button", name="Start").click()
    page.wait_for_url("**/programs/*/")
    expect(page.locator("#exercise-bench")).to_contain_text("Reach the kitchen")
    check = page.get_by_role("button", name="Check")
    expect(check).to_be_visible()
    expect(page.locator("#exercise-checklist")).to_contain_text("Not checked yet")
    shot(page, screenshot, "exercise-student-workbench")
    accessible(page, "an exercise's workbench")
    # Back on the exercise: its program opens.
    page.goto(page.locator("#exercise-bench h2 a").get_attribute("href"))
    expect(page.get_by_role("link", name="Open my program")).to_be_visible()


def test_an_attempts_checklist_and_replay(appliance, new_page, screenshot):
    code = f"TRACE = {json.dumps(trace())!r}\n" + ATTEMPT
    attempt_id = int(appliance.cli("manage", "shell", "-c", code).strip().splitlines()[-1])
    page = signed_in(new_page, "alice")
    page.goto(f"/attempts/{attempt_id}/")
    checklist = page.locator(".checklist")
    expect(checklist).to_contain_text("not passed")
    expect(checklist).to_contain_text("0 of 3 points")
    expect(checklist.locator("li.check.failed")).to_have_count(2)
    expect(checklist).to_contain_text("hidden start 2: never reached kitchen")
    expect(checklist).to_contain_text("Look before you drive!")
    # One replay (the visible start's); the hidden one's is not offered.
    expect(page.locator("figure.replay")).to_have_count(1)
    canvas = page.locator("#replay-0 canvas")
    expect(canvas).to_have_attribute("data-t", f"{END_T:.2f}")  # the whole path first
    scrub = page.locator("#replay-0 .replay-scrub")
    scrub.fill("0")
    expect(canvas).to_have_attribute("data-t", "0.00")
    heading = round(math.atan2(KITCHEN[1] - VISIBLE["y"], KITCHEN[0] - VISIBLE["x"]), 4)
    expect(canvas).to_have_attribute(
        "data-pose", f"{VISIBLE['x']:.3f} {VISIBLE['y']:.3f} {heading:.3f}"
    )
    expect(page.locator("#replay-0 .replay-time")).to_have_text("0.0 s of 10.0 s")
    scrub.fill("500")
    expect(canvas).to_have_attribute("data-t", "5.00")
    mid_x = (VISIBLE["x"] + KITCHEN[0]) / 2
    mid_y = (VISIBLE["y"] + KITCHEN[1]) / 2
    expect(canvas).to_have_attribute("data-pose", f"{mid_x:.3f} {mid_y:.3f} {heading:.3f}")
    expect(page.locator("#replay-0 .replay-note")).to_contain_text("1 contact so far")
    shot(page, screenshot, "exercise-student-attempt")
    accessible(page, "an attempt")
    # Played from there, it goes on to the end, and the time shown follows it.
    page.locator("#replay-0 .replay-play").click()
    expect(canvas).to_have_attribute("data-t", f"{END_T:.2f}")
    expect(page.locator("#replay-0 .replay-time")).to_have_text("10.0 s of 10.0 s")
    expect(page.locator("#replay-0 .replay-note")).to_contain_text("said at 9.5 s: kitchen")
    # The hidden variant's replay is not the student's to read.
    hidden = page.request.get(f"/attempts/{attempt_id}/replay/1.json")
    assert hidden.status == 404
    # Its teacher sees both.
    teacher = signed_in(new_page, "tina")
    teacher.goto(f"/attempts/{attempt_id}/")
    expect(teacher.locator("figure.replay")).to_have_count(2)
    expect(teacher.locator("#replay-1 canvas")).to_have_attribute("data-t", f"{END_T:.2f}")


HELLO_SETUP = """\
from django.contrib.auth.models import Group, User
from classroom.models import Exercise
from worlds.documents import builtin_worlds
Exercise.objects.create(
    owner=User.objects.get(username="tina"), group=Group.objects.get(name="class-a"),
    title="Say hello", text="Print **hello**, drive a little, end.", world="boxes",
    world_document=builtin_worlds()["boxes"], languages=["python"],
    variants=[{"x": 0.0, "y": -0.8, "theta": 1.5708, "hidden": False},
              {"x": -0.8, "y": 0.8, "theta": 0.0, "hidden": True}],
    checks=[{"kind": "output_matches", "pattern": "hello", "points": 1, "message": ""},
            {"kind": "ends_within", "seconds": 20, "points": 1, "message": "End it!"}],
    starter="import robot\\n\\nbot = robot.Robot()\\n", starter_language="python",
)
"""
HELLO = """\
import time

import robot

bot = robot.Robot()
print("hello")
bot.drive(0.2, 0.0)
time.sleep(2)
bot.stop()
"""


def test_check_on_the_workbench_runs_every_start_and_the_checklist_follows(
    appliance, new_page, screenshot
):
    """A real Check (classroom.checking): one run per start on fresh check sims; the
    workbench's checklist follows the attempt until it is done, then its replay plays."""
    appliance.cli("manage", "shell", "-c", HELLO_SETUP)
    page = signed_in(new_page, "alice")
    page.goto("/exercises/")
    page.get_by_role("link", name="Say hello").click()
    page.get_by_role("button", name="Start").click()
    page.wait_for_url("**/programs/*/")
    expect(page.locator(".CodeMirror")).to_be_visible()
    set_editor_text(page, HELLO)
    expect(page.locator("#save-state")).to_have_text("Unsaved changes")
    page.get_by_role("button", name="Check").click()
    # Saved first, as Save does, then checked: the checklist comes, and follows the attempt.
    expect(page.locator("#save-state")).to_contain_text("Saved (revision 2)")
    checklist = page.locator("#exercise-checklist .checklist")
    expect(checklist).to_be_visible()
    expect(checklist).to_have_attribute("data-state", "done", timeout=180_000)
    expect(checklist).to_contain_text("passed")
    expect(checklist).to_contain_text("2 of 2 points")
    expect(checklist.locator("li.check.passed")).to_have_count(2)
    expect(checklist).to_contain_text("hidden start 2")
    expect(page.locator("#check-state")).to_have_text("Checked")
    shot(page, screenshot, "exercise-student-checked")
    checklist.get_by_role("link", name="Attempt 1").click()
    expect(page.locator("figure.replay")).to_have_count(1)
    canvas = page.locator("#replay-0 canvas")
    expect(canvas).to_have_attribute("data-t", re.compile(r"^\d+\.\d\d$"))
    page.locator("#replay-0 .replay-scrub").fill("0")
    expect(canvas).to_have_attribute("data-pose", "0.000 -0.800 1.571")
    expect(page.locator("#attempt-runs")).to_contain_text("its run is not shown")
