"""The world editor in Chromium: drawing with the mouse and a finger, undo, saving through the
worlds API, the API's refusal shown beside the item it names, and a sim in the drawn world
that stops at the drawn wall."""

import re
import time

import pytest
from playwright.sync_api import Page, expect

from tests.appliance import wait_for
from tests.browser.test_accessibility import AXE, AXE_URL, axe_violations
from tests.browser.test_pages import sign_in

WALL_EXAMPLE = "programs/examples/wall.py"
EDIT_URL = re.compile(r"/worlds/(\d+)/edit$")


@pytest.fixture
def page(new_page):
    """Signed in as admin, at 1366 px; no script error or CSP refusal on it by the end (the
    API's 422s, which the console reports as failed loads, are expected)."""
    page = new_page()
    page.set_viewport_size({"width": 1366, "height": 900})
    errors = []
    page.on("pageerror", lambda exc: errors.append(str(exc)))

    def console(message) -> None:
        if message.type == "error" and not message.text.startswith("Failed to load resource"):
            errors.append(message.text)

    page.on("console", console)
    sign_in(page)
    yield page
    assert not errors, errors


def screen(page: Page, x: float, y: float) -> tuple[float, float]:
    """Where the world's point (x, y) m is on the screen (the drawing's y is flipped)."""
    return tuple(
        page.evaluate(
            """([x, y]) => {
                const svg = document.getElementById("we-canvas");
                const p = new DOMPoint(x, -y).matrixTransform(svg.getScreenCTM());
                return [p.x, p.y];
            }""",
            [x, y],
        )
    )


def drag(page: Page, a: tuple[float, float], b: tuple[float, float]) -> None:
    page.locator("#we-canvas").scroll_into_view_if_needed()
    page.mouse.move(*screen(page, *a))
    page.mouse.down()
    page.mouse.move(*screen(page, *b), steps=8)
    page.mouse.up()


def touch_drag(page: Page, a: tuple[float, float], b: tuple[float, float]) -> None:
    """A finger's drag: touch events, which Chromium turns into pointer events of a touch.
    Timed as a finger's, which rests before it lifts: a drag of events without times looked
    like a fling to Chromium, and the next tap only stopped the fling (no click)."""
    page.locator("#we-canvas").scroll_into_view_if_needed()
    start, end = screen(page, *a), screen(page, *b)
    cdp = page.context.new_cdp_session(page)
    t0 = time.time()

    def touch(kind: str, points: list, at: float) -> None:
        event = {"type": kind, "touchPoints": points, "timestamp": t0 + at}
        cdp.send("Input.dispatchTouchEvent", event)

    touch("touchStart", [{"x": start[0], "y": start[1]}], 0)
    for i in range(1, 9):
        x = start[0] + (end[0] - start[0]) * i / 8
        y = start[1] + (end[1] - start[1]) * i / 8
        touch("touchMove", [{"x": x, "y": y}], i * 0.016)
    touch("touchMove", [{"x": end[0], "y": end[1]}], 0.3)
    touch("touchEnd", [], 0.32)
    cdp.detach()


def button(page: Page, name: str):
    return page.get_by_role("button", name=name, exact=True)


def drawn(page: Page, kind: str):
    return page.locator(f"#we-canvas .we-{kind} > [data-kind]")


def new_world(page: Page, title: str) -> None:
    page.goto("/worlds/new")
    page.get_by_label("Title").fill(title)
    page.get_by_label("Title").press("Tab")


def save(page: Page) -> int:
    button(page, "Save").click()
    expect(page.locator("#we-state")).to_have_text("Saved")
    expect(page).to_have_url(EDIT_URL)
    return int(EDIT_URL.search(page.url).group(1))


def test_a_wall_drawn_with_the_mouse_is_saved(page, appliance, screenshot):
    new_world(page, "One wall")
    button(page, "Wall").click()
    expect(button(page, "Wall")).to_have_attribute("aria-pressed", "true")
    drag(page, (-1.0, 1.0), (1.0, 1.0))
    expect(drawn(page, "walls")).to_have_count(1)
    expect(page.locator("#we-form-title")).to_have_text("Wall 1")  # the new wall is selected
    expect(page.locator("#we-state")).to_have_text("Unsaved changes")
    world_id = save(page)
    document = appliance.api("GET", f"/api/worlds/{world_id}").json()["document"]
    assert [(w["from"], w["to"]) for w in document["walls"]] == [([-1.0, 1.0], [1.0, 1.0])]
    assert document["title"] == "One wall"
    screenshot(page, "world-editor-saved")
    # Opened again, the page draws what is stored.
    page.goto(f"/worlds/{world_id}/edit")
    expect(drawn(page, "walls")).to_have_count(1)


def test_a_wall_drawn_outside_the_arena_is_refused_beside_it(page, appliance, screenshot):
    new_world(page, "Outside")
    button(page, "Wall").click()
    drag(page, (-1.0, -1.0), (0.0, -1.0))
    drag(page, (1.0, 0.5), (2.3, 0.5))  # the arena's east wall is at x 2
    button(page, "Save").click()
    # The message names the second wall, which is selected, with the message by its end.
    expect(page.locator("#we-state")).to_contain_text("outside the arena")
    expect(page.locator("#we-form-title")).to_have_text("Wall 2")
    field = page.locator('#we-form .we-field[data-key="to"]')
    expect(field.locator(".we-error")).to_contain_text("outside the arena")
    expect(field.locator("input").first).to_have_attribute("aria-invalid", "true")
    second = page.locator('#we-canvas [data-kind="walls"][data-index="1"]')
    expect(second).to_have_class(re.compile(r"\binvalid\b"))
    expect(page).to_have_url(re.compile(r"/worlds/new$"))  # nothing stored
    screenshot(page, "world-editor-refused")
    # Mended in the form, it saves.
    page.locator("#we-f-to-x").fill("1.9")
    page.locator("#we-f-to-x").press("Enter")
    save(page)


def test_a_start_pose_a_box_covers_and_a_line_off_the_floor_are_refused(page, appliance):
    """Refusals naming an item without a field of the form: said at the top of its form."""
    new_world(page, "Covered")
    button(page, "Box").click()
    drag(page, (-0.2, -0.2), (0.2, 0.2))  # over the start pose at the centre
    button(page, "Save").click()
    expect(page.locator("#we-form-title")).to_have_text("Start pose 1 (where the robot starts)")
    expect(page.locator("#we-form > .we-error")).to_contain_text("overlaps box 1")
    page.locator("#we-canvas").focus()
    page.keyboard.press("Control+z")
    button(page, "Line").click()
    drag(page, (1.0, 1.5), (2.4, 1.5))
    button(page, "Save").click()
    expect(page.locator("#we-form-title")).to_have_text("Line 1")
    expect(page.locator("#we-form > .we-error")).to_contain_text("outside the arena")


def test_the_worlds_robot_is_set_in_the_worlds_form(page, appliance):
    """A line-following world wants its robot's floor sensor: the world's form sets it (and
    a sonar ring), saved in the document's robot."""
    new_world(page, "Track")
    page.get_by_label("Floor sensor (colour and lines, 0.1 m ahead)").check()
    page.get_by_label("Sonar ring", exact=False).fill("90, 0, -90")
    page.get_by_label("Sonar ring", exact=False).press("Tab")
    page.get_by_label("Radius (m)").fill("0.2")
    page.get_by_label("Radius (m)").press("Tab")
    world_id = save(page)
    robot = appliance.api("GET", f"/api/worlds/{world_id}").json()["document"]["robot"]
    assert robot["floor_sensor"] is True and robot["sonar"] == [90, 0, -90], robot
    assert robot["radius"] == 0.2, robot


def test_undo_removes_the_last_drawn_item_and_redo_brings_it_back(page, appliance):
    page.goto("/worlds/new")
    button(page, "Box").click()
    drag(page, (-1.0, -1.0), (-0.5, -0.5))
    button(page, "Wall").click()
    drag(page, (0.0, 1.0), (1.0, 1.0))
    expect(drawn(page, "walls")).to_have_count(1)
    page.locator("#we-canvas").focus()
    page.keyboard.press("Control+z")
    expect(drawn(page, "walls")).to_have_count(0)
    expect(drawn(page, "boxes")).to_have_count(1)
    page.keyboard.press("Control+Shift+z")
    expect(drawn(page, "walls")).to_have_count(1)
    page.get_by_role("button", name="Undo").click()
    expect(drawn(page, "walls")).to_have_count(0)
    page.get_by_role("button", name="Undo").click()
    expect(drawn(page, "boxes")).to_have_count(0)
    expect(page.get_by_role("button", name="Undo")).to_be_disabled()


def test_select_move_and_delete(page, appliance):
    page.goto("/worlds/new")
    page.keyboard.press("z")  # the zone tool, by its key
    expect(button(page, "Zone")).to_have_attribute("aria-pressed", "true")
    drag(page, (-1.0, -1.0), (0.0, -0.5))
    page.get_by_label("Name", exact=True).fill("kitchen")
    page.get_by_label("Name", exact=True).press("Tab")
    expect(page.locator("#we-canvas .we-zone-name")).to_have_text("kitchen")
    button(page, "Select").click()
    drag(page, (-0.5, -0.8), (0.5, 0.2))  # moved by (1, 1)
    expect(page.get_by_label("Centre x (m)")).to_have_value("0.5")
    expect(page.get_by_label("Centre y (m)")).to_have_value("0.25")
    page.locator("#we-canvas").focus()
    page.keyboard.press("ArrowRight")  # one grid step
    expect(page.get_by_label("Centre x (m)")).to_have_value("0.6")
    page.keyboard.press("Delete")
    expect(drawn(page, "zones")).to_have_count(0)
    expect(page.locator("#we-form-title")).to_have_text("The world")


VIEW = "document.getElementById('we-canvas').viewBox.baseVal"


def test_zoomed_in_the_drawing_is_still_where_the_pointer_is(page, appliance):
    page.goto("/worlds/new")
    whole = page.evaluate(f"() => {VIEW}.width")
    page.locator("#we-canvas").focus()
    page.keyboard.press("+")
    page.keyboard.press("+")
    page.wait_for_function(f"w => {VIEW}.width < w", arg=whole / 2)
    # Looking around: the floor dragged to the left shows what is east of the centre.
    drag(page, (0.5, -0.5), (-0.1, -0.5))
    page.wait_for_function(f"() => {VIEW}.x > -1")
    button(page, "Wall").click()
    drag(page, (0.5, 0.3), (1.2, 0.3))
    expect(page.locator("#we-f-from-x")).to_have_value("0.5")
    expect(page.locator("#we-f-to-x")).to_have_value("1.2")
    button(page, "Whole arena").click()
    page.wait_for_function(f"w => {VIEW}.width === w", arg=whole)


@pytest.mark.parametrize("width", [390, 1366])
def test_the_editor_fits_and_draws_by_touch(new_page, appliance, width, screenshot):
    height = 844 if width == 390 else 900
    page = new_page(has_touch=True, is_mobile=width == 390)
    page.set_viewport_size({"width": width, "height": height})
    sign_in(page)
    page.goto("/worlds/new")
    button(page, "Wall").tap()
    touch_drag(page, (-1.5, 0.5), (1.0, 0.5))
    expect(drawn(page, "walls")).to_have_count(1)
    button(page, "Landmark").tap()
    touch_drag(page, (0.0, 0.3), (0.0, 0.3))
    expect(drawn(page, "landmarks")).to_have_count(1)
    facing = float(page.get_by_label("Facing (°)").input_value())
    assert facing == -90  # on the wall's south face, facing the robot's side
    button(page, "Start pose").tap()
    touch_drag(page, (0.0, -1.2), (1.0, -1.2))  # a second start pose, facing east
    expect(drawn(page, "start")).to_have_count(2)
    expect(page.get_by_label("Heading (°, 0 = east, 90 = north)")).to_have_value("0")
    button(page, "Line").tap()
    touch_drag(page, (-1.5, -1.6), (1.5, -1.0))
    expect(drawn(page, "lines")).to_have_count(1)
    overflow = page.evaluate("document.documentElement.scrollWidth - window.innerWidth")
    assert overflow <= 0, f"{overflow} px wider than the screen"
    toolbar = page.get_by_role("toolbar").bounding_box()
    assert toolbar["x"] + toolbar["width"] <= width
    screenshot(page, f"world-editor-{width}")


def test_a_builtin_world_is_shown_to_read_and_copied_to_edit(page, appliance):
    page.goto("/worlds/builtin/boxes")
    expect(drawn(page, "boxes")).not_to_have_count(0)
    expect(button(page, "Save")).to_be_hidden()
    expect(button(page, "Wall")).to_be_hidden()
    page.get_by_role("button", name="Copy to edit").click()
    button(page, "Wall").click()
    drag(page, (-1.8, 1.8), (-1.2, 1.8))
    world_id = save(page)
    stored = appliance.api("GET", f"/api/worlds/{world_id}").json()
    assert stored["name"] != "boxes" and len(stored["document"]["boxes"]) > 0


def test_a_sim_in_the_drawn_world_stops_before_the_drawn_wall(page, appliance, screenshot):
    """The issue's end to end: the teacher draws a wall across the arena 1 m ahead of the
    start pose and saves; a sim in that world runs *Stop before the wall* from its start pose
    and stops before that wall (the arena's own wall ahead is 2.5 m further)."""
    new_world(page, "Wall ahead")
    button(page, "Wall").click()
    drag(page, (-1.5, 0.5), (1.5, 0.5))
    # The start pose: 1 m south of the centre, facing north (the drawn wall).
    button(page, "Select").click()
    page.mouse.click(*screen(page, 0.0, 0.0))
    expect(page.locator("#we-form-title")).to_contain_text("Start pose 1")
    page.get_by_label("y (m)", exact=True).fill("-1")
    page.get_by_label("y (m)", exact=True).press("Tab")
    expect(page.get_by_label("Heading (°, 0 = east, 90 = north)")).to_have_value("90")
    world_id = save(page)
    screenshot(page, "world-editor-wall-ahead")

    # "Try it in a sim": a sim of one's own in that world (POST /api/sims {world}), its page.
    button(page, "Try it in a sim").click()
    expect(page).to_have_url(re.compile(r"/robots/[\w-]+/$"))
    robot = page.url.rstrip("/").rsplit("/", 1)[1]
    assert appliance.api("GET", f"/api/robots/{robot}").json()["url"] == f"sim://?world={world_id}"
    wait_for(lambda: appliance.api("GET", f"/api/robots/{robot}/sensors").status_code == 200,
             what="the new sim's agent")  # fmt: skip
    start = appliance.api("GET", f"/api/robots/{robot}/sensors").json()["position"]
    assert abs(start["y"] + 1.0) < 0.01, start
    with open(WALL_EXAMPLE) as source:
        program = appliance.create_program("Stop before the drawn wall", source.read())
    run = appliance.wait_run(appliance.run_program(program["id"], robot=robot)["id"])
    log = appliance.api("GET", f"/api/runs/{run['id']}/log").text
    assert run["state"] == "finished", log
    end = appliance.api("GET", f"/api/robots/{robot}/sensors").json()["position"]
    # Short of the drawn wall's south face (y 0.475), having moved towards it.
    assert -0.5 < end["y"] < 0.475 - 0.15, (end, log)
    assert abs(end["x"]) < 0.05, end
    distance = float(re.search(r"Stopped (\d\.\d+) m before the wall", log).group(1))
    assert 0.3 < distance <= 0.5


def test_the_editor_passes_axe_and_works_from_the_keyboard(page, appliance):
    """No serious axe-core violation with an item selected and refused; a wall added, moved
    and deleted with the keyboard alone."""
    page.route(f"**{AXE_URL}", lambda r: r.fulfill(path=AXE, content_type="text/javascript"))
    new_world(page, "By keys")
    button(page, "Select").focus()
    page.keyboard.press("ArrowRight")  # the toolbar's arrows: to Wall
    expect(button(page, "Wall")).to_be_focused()
    page.keyboard.press("Enter")
    expect(button(page, "Wall")).to_have_attribute("aria-pressed", "true")
    page.locator("#we-canvas").focus()
    page.keyboard.press("Enter")  # a wall in the middle, its first field focused
    expect(drawn(page, "walls")).to_have_count(1)
    expect(page.locator("#we-f-from-x")).to_be_focused()
    page.locator("#we-f-to-x").fill("2.5")
    page.locator("#we-f-to-x").press("Enter")
    button(page, "Save").click()
    expect(page.locator('#we-form .we-field[data-key="to"] .we-error')).to_be_visible()
    found = axe_violations(page)
    assert not found, found
    page.locator("#we-canvas").focus()
    page.keyboard.press("ArrowUp")
    expect(page.locator("#we-f-from-y")).to_have_value("0.1")
    page.keyboard.press("Delete")
    expect(drawn(page, "walls")).to_have_count(0)


def test_a_world_shared_to_read_is_copied_to_edit_and_hidden_from_others(new_page, appliance):
    doc = {"format": 1, "name": "shared-one", "title": "Shared one",
           "size": {"width": 3, "height": 3}, "walls": [{"from": [-1, 1], "to": [1, 1]}],
           "start": [{"x": 0, "y": 0, "theta": 0}]}  # fmt: skip
    appliance.new_user("bobw")
    appliance.new_user("carolw")
    world = appliance.api("POST", "/api/worlds", doc).json()
    shared = appliance.api("POST", f"/api/worlds/{world['id']}/shares", {"user": "bobw"})
    assert shared.status_code == 201, shared.text
    carol = new_page()
    sign_in(carol, "carolw", "user-pass-1234")
    assert carol.goto(f"/worlds/{world['id']}/edit").status == 404
    bob = new_page()
    sign_in(bob, "bobw", "user-pass-1234")
    bob.goto(f"/worlds/{world['id']}/edit")
    expect(drawn(bob, "walls")).to_have_count(1)
    expect(button(bob, "Save")).to_be_hidden()
    button(bob, "Copy to edit").click()
    copy_id = save(bob)
    assert copy_id != world["id"]
    copy = appliance.api("GET", f"/api/worlds/{copy_id}").json()
    assert copy["owner"] == "bobw" and len(copy["document"]["walls"]) == 1
    original = appliance.api("GET", f"/api/worlds/{world['id']}").json()
    assert original["owner"] == "admin" and original["revision"] == 1
