"""The exercise editor in Chromium: a teacher fills in the form, previews the text, adds a
hidden start pose by clicking (and dragging) on the drawn world, adds checks of two kinds,
saves, and finds it all again when the page is opened anew; an error is shown by its field.
The list and a class's grid at a desktop's width and a phone's (the grid scrolls sideways
with the students' column in view)."""

import json
import re

import pytest
from playwright.sync_api import Page, expect

from tests.browser.test_accessibility import AXE, AXE_URL, axe_violations
from tests.browser.test_pages import sign_in

PASSWORD = "teach-pass-1234"
EDIT_URL = re.compile(r"/classroom/exercises/(\d+)/edit$")

SETUP = """
from django.contrib.auth.models import Group, User
from robotide.models import ClassTeacher
tess = User.objects.create_user("tess", password=%(password)r)
group = Group.objects.create(name="Robotics 7B")
ClassTeacher.objects.create(group=group, user=tess)
for name in ("ana", "bruno", "carla-maria-dos-santos"):
    student = User.objects.create_user(name, first_name=name.title(), password="x-pass-1234")
    group.user_set.add(student)
print(group.pk)
"""


@pytest.fixture(scope="module")
def class_id(appliance) -> int:
    out = appliance.cli("manage", "shell", "-c", SETUP % {"password": PASSWORD})
    return int(out.split()[-1])  # after what the shell says it imported


@pytest.fixture
def page(new_page, class_id):
    """Signed in as the teacher; no script error or CSP refusal on the page by the end."""
    page = new_page()
    errors = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))

    def console(message) -> None:
        if message.type == "error" and not message.text.startswith("Failed to load resource"):
            errors.append(message.text)

    page.on("console", console)
    page.route(f"**{AXE_URL}", lambda r: r.fulfill(path=AXE, content_type="text/javascript"))
    sign_in(page, "tess", PASSWORD)
    yield page
    assert not errors, errors


def screen(page: Page, x: float, y: float) -> tuple[float, float]:
    """Where the world's point (x, y) m is on the screen (the map's y is flipped)."""
    return tuple(
        page.evaluate(
            """([x, y]) => {
                const svg = document.getElementById("ex-map");
                const p = new DOMPoint(x, -y).matrixTransform(svg.getScreenCTM());
                return [p.x, p.y];
            }""",
            [x, y],
        )
    )


def variant(page: Page, n: int):
    return page.locator("#ex-variants > li").nth(n)


def check(page: Page, n: int):
    return page.locator("#ex-checks > li").nth(n)


def test_a_teacher_writes_an_exercise_with_the_form(page, appliance, class_id, screenshot):
    page.goto("/classroom/exercises/new")
    page.get_by_label("Title").fill("Reach the kitchen without touching anything")
    page.get_by_label("Text for students").fill("Drive to the **kitchen**.\n\n- do not touch")
    page.get_by_role("button", name="Preview").click()
    expect(page.locator("#ex-preview strong")).to_have_text("kitchen")
    # The only class she teaches is chosen already.
    expect(page.get_by_label("Class", exact=True)).to_have_value(str(class_id))

    # The world is drawn; the first start pose is the world's own.
    expect(page.locator("#ex-map .ex-floor")).to_have_count(1)
    expect(page.locator("#ex-map .ex-pose")).to_have_count(1)
    # A hidden start pose: pressed at (0.5, -1.0), dragged east (heading 0°).
    page.get_by_label("new ones hidden").check()
    page.locator("#ex-map").scroll_into_view_if_needed()
    page.mouse.move(*screen(page, 0.5, -1.0))
    page.mouse.down()
    page.mouse.move(*screen(page, 0.9, -1.0), steps=6)
    page.mouse.up()
    expect(page.locator("#ex-variants > li")).to_have_count(2)
    second = variant(page, 1)
    expect(second.get_by_label("x (m)")).to_have_value("0.5")
    expect(second.get_by_label("y (m)")).to_have_value("-1")
    expect(second.get_by_label("heading (°)")).to_have_value("0")
    expect(second.get_by_label("hidden from students")).to_be_checked()
    expect(page.locator("#ex-map .ex-pose.hidden")).to_have_count(1)
    expect(page.locator("#ex-map-state")).to_contain_text("Hidden start pose 2 added")
    # The first one dragged from (0, 0) to (0, -0.5).
    page.mouse.move(*screen(page, 0.0, 0.0))
    page.mouse.down()
    page.mouse.move(*screen(page, 0.0, -0.5), steps=6)
    page.mouse.up()
    expect(variant(page, 0).get_by_label("y (m)")).to_have_value("-0.5")
    expect(page.locator("#ex-variants > li")).to_have_count(2)

    # Checks: reach the kitchen (its zone offered from the world), never touch anything.
    page.get_by_role("button", name="Add a check").click()
    first = check(page, 0)
    expect(first.get_by_label("Zone", exact=True)).to_be_visible()
    first.get_by_label("Zone", exact=True).fill("kitchen")
    first.get_by_label("within (s)", exact=True).fill("25")
    first.get_by_label("Points").fill("2")
    first.get_by_label("Message students see").fill("Find the kitchen: follow the wall.")
    page.get_by_role("button", name="Add a check").click()
    other = check(page, 1)
    other.get_by_label("What").select_option("no_contact")
    expect(other.get_by_label("Zone", exact=True)).to_be_hidden()
    page.get_by_label("Time limit of a run").fill("40")
    screenshot(page, "exercise-editor-1280")
    found = axe_violations(page)
    assert not found, found

    page.get_by_role("button", name="Save").first.click()
    expect(page).to_have_url(EDIT_URL)
    expect(page.locator(".messages")).to_contain_text("Saved")
    exercise_id = int(EDIT_URL.search(page.url).group(1))

    # Opened anew: all of it is there.
    page.goto(f"/classroom/exercises/{exercise_id}/edit")
    expect(page.get_by_label("Title")).to_have_value("Reach the kitchen without touching anything")
    expect(page.locator("#ex-variants > li")).to_have_count(2)
    expect(variant(page, 1).get_by_label("hidden from students")).to_be_checked()
    expect(variant(page, 1).get_by_label("heading (°)")).to_have_value("0")
    expect(page.locator("#ex-map .ex-pose.hidden")).to_have_count(1)
    expect(page.locator("#ex-checks > li")).to_have_count(2)
    expect(check(page, 0).get_by_label("What")).to_have_value("reach_zone")
    expect(check(page, 0).get_by_label("Zone", exact=True)).to_have_value("kitchen")
    expect(check(page, 1).get_by_label("What")).to_have_value("no_contact")
    expect(page.get_by_label("Time limit of a run")).to_have_value("40")
    # Its document, as the JSON view has it: theta in radians, the hidden pose's too.
    page.get_by_role("link", name="Edit as JSON").click()
    document = json.loads(page.locator("#ex-document").input_value())
    screenshot(page, "exercise-json-1280")
    assert document["variants"][0]["y"] == -0.5
    assert document["variants"][1] == {"x": 0.5, "y": -1.0, "theta": 0.0, "hidden": True}
    assert [c["kind"] for c in document["checks"]] == ["reach_zone", "no_contact"]
    assert document["checks"][0]["within_s"] == 25 and document["time_limit_s"] == 40

    # A zone the world does not have: refused, said beside the field, the rest kept.
    page.goto(f"/classroom/exercises/{exercise_id}/edit")
    check(page, 0).get_by_label("Zone", exact=True).fill("attic")
    page.get_by_role("button", name="Save").first.click()
    expect(page.locator("#ex-errors")).to_contain_text("Not saved")
    zone = check(page, 0).get_by_label("Zone", exact=True)
    expect(zone).to_have_attribute("aria-invalid", "true")
    expect(page.locator("#checks-0-zone-error")).to_contain_text("attic")
    expect(zone).to_be_focused()  # where the teacher goes on
    expect(variant(page, 1).get_by_label("hidden from students")).to_be_checked()
    screenshot(page, "exercise-editor-error-1280")


def test_the_editor_list_and_grid_on_a_phone(page, appliance, class_id, screenshot):
    page.set_viewport_size({"width": 390, "height": 844})
    page.goto("/classroom/exercises/new")
    page.get_by_label("Title").fill("Stop near the wall")
    page.get_by_role("button", name="Add a check").click()
    check(page, 0).get_by_label("What").select_option("stop_near_wall")
    check(page, 0).get_by_label("gap from (m)").fill("0,2")
    check(page, 0).get_by_label("gap to (m)").fill("0.4")
    # A tap on the map adds a start pose (heading 90° when not dragged).
    page.locator("#ex-map").scroll_into_view_if_needed()
    page.mouse.click(*screen(page, -0.5, 0.5))
    expect(page.locator("#ex-variants > li")).to_have_count(2)
    expect(variant(page, 1).get_by_label("heading (°)")).to_have_value("90")
    assert page.evaluate("document.documentElement.scrollWidth") <= 390
    screenshot(page, "exercise-editor-390")
    page.get_by_role("button", name="Save").first.click()
    expect(page).to_have_url(EDIT_URL)
    exercise_id = int(EDIT_URL.search(page.url).group(1))

    page.goto("/classroom/exercises/")
    expect(page.get_by_role("link", name="Stop near the wall").first).to_be_visible()
    assert page.evaluate("document.documentElement.scrollWidth") <= 390
    screenshot(page, "exercise-list-390")
    found = axe_violations(page)
    assert not found, found

    appliance.cli("manage", "shell", "-c", ATTEMPTS % {"exercise": exercise_id})
    page.goto(f"/classroom/{class_id}/grid")
    expect(page.get_by_role("link", name="Download CSV")).to_have_attribute(
        "href", f"/api/classes/{class_id}/grades.csv"
    )
    cell = page.locator("tr", has_text="Ana").locator("td.grid-cell").last
    expect(cell).to_contain_text("✔")
    expect(cell.get_by_role("link")).to_have_attribute("href", re.compile(r"^/attempts/\d+/$"))
    # The page does not widen: the grid scrolls in its box, the names' column stays.
    assert page.evaluate("document.documentElement.scrollWidth") <= 390
    box = page.locator(".grid-scroll")
    box.evaluate("el => { el.scrollLeft = el.scrollWidth; }")
    name = page.locator("tbody th.grid-student").first
    expect(name).to_be_in_viewport()
    assert name.bounding_box()["x"] < 40
    screenshot(page, "exercise-grid-390")
    found = axe_violations(page)
    assert not found, found
    page.set_viewport_size({"width": 1280, "height": 800})
    box.evaluate("el => { el.scrollLeft = 0; }")
    screenshot(page, "exercise-grid-1280")
    page.goto("/classroom/exercises/")
    screenshot(page, "exercise-list-1280")


# Attempts of the class's students on its exercises (a grid to look at): made directly, as
# the pipeline would have recorded them.
ATTEMPTS = """
from classroom.models import Attempt, Exercise
from django.contrib.auth.models import User
exercise = Exercise.objects.get(pk=%(exercise)s)
for title in ("Find the landmark", "Zones in order", "Three corners"):
    Exercise.objects.create(owner=exercise.owner, group=exercise.group, title=title,
                            world="boxes", checks=[{"kind": "no_contact", "points": 2}])
for other in Exercise.objects.filter(group=exercise.group):
    for n, name in enumerate(("ana", "bruno")):
        Attempt.objects.create(exercise=other, student=User.objects.get(username=name),
                               number=1, language="python", state="done",
                               score=other.max_score if name == "ana" else 0,
                               max_score=other.max_score, passed=name == "ana", late=n == 1)
"""
