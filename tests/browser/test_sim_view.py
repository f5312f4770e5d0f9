"""The sim drawn in the browser (issue 30): the robot page and the workbench's panel draw the
sim's world and robot on a canvas from its pose stream, where the telemetry says it is, without
asking for the server-drawn MJPEG; a page without scripts still gets the JPEG."""

import math
import shutil
from pathlib import Path

import pytest
from playwright.sync_api import Page, expect

from tests.browser.conftest import SCREENSHOTS
from tests.browser.test_pages import sign_in

SHOTS = Path("/work/notes/shots")
ROBOT_RGB = (31, 95, 191)  # simview.js's COLOURS.robot
# An arc to the left, 0.5 m across: from wherever the tests before left it near the centre,
# clear of the boxes world's boxes and walls.
ARC = """\
import robot, time

bot = robot.Robot()
print("moving")
bot.drive(0.25, 0.5)
time.sleep(2.0)
bot.stop()
"""


def telemetry(appliance) -> tuple[float, float, float]:
    position = appliance.api("GET", "/api/robots/sim/sensors").json()["position"]
    return position["x"], position["y"], position["theta"]


def drawn(page: Page) -> tuple[float, float, float]:
    return tuple(
        float(v) for v in page.locator("canvas.simview-canvas").get_attribute("data-pose").split()
    )


def pixel_at(page: Page, x: float, y: float) -> tuple[int, int, int]:
    """The canvas's colour at world point (x, y) m, mapped as the canvas says (data-view)."""
    return tuple(
        page.evaluate(
            """([x, y]) => {
                const canvas = document.querySelector("canvas.simview-canvas");
                const [ox, oy, scale] = canvas.dataset.view.split(" ").map(Number);
                const ratio = canvas.width / canvas.clientWidth;
                const px = Math.round((ox + x * scale) * ratio);
                const py = Math.round((oy - y * scale) * ratio);
                const data = canvas.getContext("2d").getImageData(px, py, 1, 1).data;
                return Array.from(data.slice(0, 3));
            }""",
            [x, y],
        )
    )


def near(colour, target, tolerance=12) -> bool:
    return all(abs(a - b) <= tolerance for a, b in zip(colour, target, strict=True))


def save_shot(page: Page, name: str) -> None:
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)
    path = SCREENSHOTS / f"{name}.png"
    page.screenshot(path=str(path), full_page=True)
    SHOTS.mkdir(parents=True, exist_ok=True)
    shutil.copy(path, SHOTS / path.name)


def watch_requests(page: Page) -> list[str]:
    urls: list[str] = []
    page.on("request", lambda request: urls.append(request.url))
    return urls


def wait_drawn_at(page: Page, pose, tolerance=0.01) -> None:
    """Until the canvas draws the robot at ``pose`` (each frame it says where, in data-pose)."""
    page.wait_for_function(
        """([x, y, theta, tolerance]) => {
            const pose = document.querySelector("canvas.simview-canvas").dataset.pose;
            if (!pose) return false;
            const [px, py, pt] = pose.split(" ").map(Number);
            const turn = Math.abs(Math.atan2(Math.sin(pt - theta), Math.cos(pt - theta)));
            return Math.hypot(px - x, py - y) <= tolerance && turn <= 0.02;
        }""",
        arg=[*pose, tolerance],
    )


# A phone's screen has two device pixels to a CSS pixel: the canvas draws at its resolution.
@pytest.mark.parametrize("width,height,ratio", [(390, 844, 2), (1366, 900, 1)])
def test_the_robot_page_draws_the_sim_where_the_telemetry_says(
    appliance, new_page, width, height, ratio
):
    page = new_page(device_scale_factor=ratio)
    page.set_viewport_size({"width": width, "height": height})
    sign_in(page)
    urls = watch_requests(page)
    page.goto("/robots/sim/")
    canvas = page.locator("canvas.simview-canvas")
    expect(canvas).to_be_visible()
    before = telemetry(appliance)
    wait_drawn_at(page, before)
    box = canvas.bounding_box()
    assert box["width"] <= width and box["x"] >= 0, "the canvas fits the page"
    backing = page.evaluate("() => document.querySelector('canvas.simview-canvas').width")
    assert abs(backing - box["width"] * ratio) <= ratio, "as many pixels as the screen shows"
    assert near(pixel_at(page, *before[:2]), ROBOT_RGB), "the robot is drawn where it is"

    program = appliance.create_program(f"Arc {width}", ARC)
    run = appliance.run_program(program["id"])
    # While it moves, the drawing moves (the pose stream, and frames between its poses).
    page.wait_for_function(
        "([x, y]) => { const p = document.querySelector('canvas.simview-canvas').dataset.pose"
        ".split(' ').map(Number); return Math.hypot(p[0] - x, p[1] - y) > 0.05; }",
        arg=list(before[:2]),
    )
    assert appliance.wait_run(run["id"])["state"] == "finished"
    after = telemetry(appliance)
    assert math.dist(before[:2], after[:2]) > 0.35, "the arc moved it more than its width"
    wait_drawn_at(page, after)
    assert near(pixel_at(page, *after[:2]), ROBOT_RGB), "the robot is drawn where it is now"
    assert not near(pixel_at(page, *before[:2]), ROBOT_RGB), "and no longer where it was"
    save_shot(page, f"sim-view-robot-page-{width}")
    assert not [u for u in urls if "camera.mjpg" in u or "camera.jpg" in u], "no server drawing"
    assert any(u.endswith("/robots/sim/world.json") for u in urls)


def test_the_workbench_panel_draws_the_sim(appliance, new_page):
    page = new_page()
    page.set_viewport_size({"width": 1366, "height": 900})
    sign_in(page)
    urls = watch_requests(page)
    program = appliance.create_program("Arc on the bench", ARC)
    page.goto(f"/programs/{program['id']}/")
    canvas = page.locator("#bench-panel canvas.simview-canvas")
    expect(canvas).to_be_visible()
    wait_drawn_at(page, telemetry(appliance))
    page.locator('button[name="action"][value="run"]').click()
    expect(page.locator("#console #run-status .state")).to_have_text("finished", timeout=60_000)
    after = telemetry(appliance)
    wait_drawn_at(page, after)
    assert near(pixel_at(page, *after[:2]), ROBOT_RGB)
    save_shot(page, "sim-view-workbench-1366")
    page.set_viewport_size({"width": 390, "height": 844})
    canvas.scroll_into_view_if_needed()
    wait_drawn_at(page, after)
    assert near(pixel_at(page, *after[:2]), ROBOT_RGB), "redrawn at its new size"
    save_shot(page, "sim-view-workbench-390")
    assert not [u for u in urls if "camera.mjpg" in u], "no server drawing"


def test_without_scripts_the_page_shows_the_servers_jpeg(appliance, new_page):
    page = new_page(java_script_enabled=False)
    page.set_viewport_size({"width": 390, "height": 844})
    sign_in(page)
    urls = watch_requests(page)
    page.goto("/robots/sim/")
    camera = page.locator("img#camera")
    expect(camera).to_be_visible()
    expect(page.locator("canvas.simview-canvas")).to_be_hidden()
    page.wait_for_function("() => document.getElementById('camera').naturalWidth === 320")
    assert any("camera.mjpg" in u for u in urls)
    save_shot(page, "sim-view-no-scripts-390")


# A world with one of each thing simview.js draws; its robot has a sonar ring and a cone.
WORLD = {
    "world": {
        "format": 1, "name": "every-thing", "title": "Every thing",
        "size": {"width": 4.0, "height": 3.0},
        "walls": [{"from": [-1.0, -1.5], "to": [-1.0, 0.0], "thickness": 0.1}],
        "boxes": [{"x": 1.0, "y": 0.8, "width": 0.6, "height": 0.3, "angle": 0.5}],
        "landmarks": [{"text": "kitchen", "x": 2.0, "y": -1.0, "facing": math.pi,
                       "size": 0.4, "height": 0.3}],
        "lines": [{"points": [[-1.8, 1.2], [0.0, 1.2], [0.5, 0.5]], "width": 0.05,
                   "colour": "#000000"}],
        "zones": [{"name": "kitchen", "x": 1.4, "y": -1.0, "width": 1.0, "height": 0.6,
                   "colour": "#40a0ff"}],
        "start": [{"x": 0.0, "y": 0.0, "theta": math.pi / 2}],
    },
    "robot": {"radius": 0.15, "range": {"cone_deg": 15, "rays": 5, "min": 0.03, "max": 4.0},
              "sonar": [90, 45, 0, -45, -90], "floor_sensor": True},
    "speed": 2,
}  # fmt: skip
HARNESS = """\
<link rel="stylesheet" href="/static/robotide/app.css">
<div id="socket" class="card"><figure class="simview">
<canvas class="simview-canvas" data-world-url="/robots/sim/world.json" width="320" height="240">
</canvas></figure></div>
<script src="/static/robotide/simview.js"></script>
"""
SEND = """(pose) => document.getElementById("socket").dispatchEvent(new CustomEvent(
    "htmx:wsBeforeMessage", {bubbles: true, cancelable: true,
    detail: {message: JSON.stringify({type: "robot.pose", pose: pose})}}))"""


def pose(x, y, theta, linear=0.0, angular=0.0, bumper=False, rng=1.0, t=1.0) -> dict:
    return {"x": x, "y": y, "theta": theta, "linear": linear, "angular": angular,
            "bumper": bumper, "range": rng, "sonar": [0.5, 0.8, 1.0, 0.8, 0.5], "t": t}  # fmt: skip


def test_every_thing_of_a_world_is_drawn_and_the_pose_extrapolated(new_page):
    """The page's drawing on its own (its world and its poses given), for worlds with walls,
    turned boxes, zones, lines and a sonar ring; between poses the robot goes on along its
    speeds (at the sim's speed, 2x here), for a moment only."""
    page = new_page()
    sign_in(page)
    page.route("**/robots/sim/world.json", lambda route: route.fulfill(json=WORLD))
    page.set_viewport_size({"width": 1366, "height": 900})
    page.set_content(HARNESS)
    page.wait_for_function("() => document.querySelector('canvas.simview-canvas').dataset.view")
    page.evaluate(SEND, pose(-0.3, -0.6, 0.0, bumper=True))
    wait_drawn_at(page, (-0.3, -0.6, 0.0))
    assert near(pixel_at(page, -0.3, -0.6), ROBOT_RGB)
    assert near(pixel_at(page, -0.3, -0.6 + 0.14), (214, 32, 32), 40), "the bumper, red"
    assert near(pixel_at(page, 1.0, 0.8), (160, 118, 74)), "the box"
    assert near(pixel_at(page, -1.0, -1.0), (90, 74, 58)), "the wall"
    assert near(pixel_at(page, 0.0, 1.2), (0, 0, 0), 40), "the painted line"
    zone = pixel_at(page, 1.0, -1.2)
    assert zone[2] > zone[0] + 40, f"the zone's blue: {zone}"
    assert not near(pixel_at(page, 1.3, 0.5), (160, 118, 74)), "the box is turned"
    save_shot(page, "sim-view-every-thing-1366")

    page.evaluate(SEND, pose(-0.3, -0.6, 0.0, linear=0.1, t=2.0))
    page.wait_for_function(
        "() => Number(document.querySelector('canvas.simview-canvas').dataset.pose"
        ".split(' ')[0]) > -0.29"
    )  # it goes on east at 0.1 m/s x 2
    # It carries on for the hold (0.3 s) and no further: wait until it has got there (a
    # busy machine's frames come late), then it must be exactly there, not beyond.
    page.wait_for_function(
        "() => Number(document.querySelector('canvas.simview-canvas').dataset.pose"
        ".split(' ')[0]) >= -0.3 + 0.1 * 2 * 0.3 - 0.002"
    )
    # Twenty more of the display's frames (about 0.3 s more at 60 Hz): still there.
    page.evaluate(
        "() => new Promise(done => { let n = 0; const tick = () => ++n >= 20 ? done()"
        " : requestAnimationFrame(tick); requestAnimationFrame(tick); })"
    )
    x, y, theta = drawn(page)
    assert x == pytest.approx(-0.3 + 0.1 * 2 * 0.3, abs=0.002) and y == pytest.approx(-0.6)
