"""The pages in a real browser against a real appliance: sign in, edit, run, watch, stop.

Every page visited is saved to test-artifacts/screenshots/ for a person to look at.
"""

import re

import pytest
from playwright.sync_api import Page, expect

from tests.appliance import ADMIN_PASSWORD, free_port

EXAMPLES = ["Compass", "Drive a square", "Stop before the wall", "Hello from the shell"]

GREETER = """\
import sys

for i in range(3):
    print(f"out line {i}")
print("oops on stderr", file=sys.stderr)
"""

FOREVER = """\
import time

i = 0
while True:
    print(i)
    i += 1
    time.sleep(0.1)
"""


def sign_in(page: Page, username: str = "admin", password: str = ADMIN_PASSWORD) -> None:
    page.goto("/accounts/login/")
    page.get_by_label("User name").fill(username)
    page.get_by_label("Password").fill(password)
    page.get_by_role("button", name="Sign in").click()
    expect(page.get_by_role("button", name="Sign out")).to_be_visible()


@pytest.fixture
def page(new_page) -> Page:
    """A browser signed in as admin."""
    page = new_page()
    sign_in(page)
    return page


def active_runs(appliance) -> list[int]:
    states = ("starting", "running")
    return [r["id"] for s in states for r in appliance.api("GET", f"/api/runs?state={s}").json()]


@pytest.fixture(autouse=True)
def _no_runs_left(appliance):
    """A failed test leaves no never-ending program behind to confuse the next one."""
    before = set(active_runs(appliance))
    yield
    left = [run_id for run_id in active_runs(appliance) if run_id not in before]
    for run_id in left:
        appliance.api("POST", f"/api/runs/{run_id}/stop")
    for run_id in left:
        appliance.wait_run(run_id)


def editor_text(page: Page) -> str:
    # A page just shown (its heading) may not have made its editor yet on a busy machine.
    page.wait_for_function("window.robotideEditor !== undefined")
    return page.evaluate("window.robotideEditor.getValue()")


def set_editor_text(page: Page, text: str) -> None:
    page.evaluate("text => window.robotideEditor.setValue(text)", text)


def run_id_of(page: Page) -> int:
    expect(page).to_have_url(re.compile(r"/runs/\d+/$"))
    return int(re.search(r"/runs/(\d+)/$", page.url).group(1))


def mark_page(page: Page) -> None:
    """Tags the loaded document; a reload or navigation loses the tag."""
    page.evaluate("window.notReloaded = true")


def assert_not_reloaded(page: Page) -> None:
    assert page.evaluate("window.notReloaded === true"), "the page was reloaded"


def program_row(page: Page, name: str):
    return page.locator("#programs tbody tr").filter(
        has=page.get_by_role("link", name=name, exact=True)
    )


def running_table(page: Page):
    return page.locator("#run-tables h2:has-text('Running now') + table")


def finished_table(page: Page):
    return page.locator("#run-tables h2:has-text('Finished') + table")


def test_signing_in_shows_the_example_programs(new_page, screenshot):
    page = new_page()
    page.goto("/")
    expect(page).to_have_url(re.compile(r"/accounts/login/"))
    page.get_by_label("User name").fill("admin")
    page.get_by_label("Password").fill("not the password")
    page.get_by_role("button", name="Sign in").click()
    expect(page.locator(".errorlist")).to_be_visible()
    screenshot(page, "login")

    page.get_by_label("Password").fill(ADMIN_PASSWORD)
    page.get_by_role("button", name="Sign in").click()
    expect(page).to_have_url(re.compile(r"/programs/$"))
    expect(page.locator("header")).to_contain_text("admin")
    for name in EXAMPLES:
        expect(page.locator("#programs").get_by_role("link", name=name, exact=True)).to_be_visible()
    expect(program_row(page, "Hello from the shell")).to_contain_text("Shell")
    expect(program_row(page, "Compass")).to_contain_text("Python")
    screenshot(page, "programs-list")


def test_write_save_and_run_a_program(page, screenshot):
    page.goto("/programs/")
    new = page.locator("section", has=page.get_by_role("heading", name="New program"))
    new.get_by_label("Name").fill("Greeter")
    new.get_by_label("Language").select_option("python")
    new.get_by_role("button", name="Create").click()

    expect(page).to_have_url(re.compile(r"/programs/\d+/$"))
    expect(page.get_by_role("heading", name="Greeter")).to_be_visible()
    expect(page.locator(".CodeMirror")).to_be_visible()
    expect(page.locator("#source")).to_be_hidden()  # CodeMirror took the textarea's place
    assert "import robot" in editor_text(page)  # a new program starts from the template

    set_editor_text(page, GREETER)
    # And a line typed by hand, as a user would.
    page.locator(".CodeMirror").click()
    page.keyboard.press("Control+End")
    page.keyboard.type('print("typed in the editor")')
    source = GREETER + 'print("typed in the editor")'
    screenshot(page, "editor")

    page.get_by_role("button", name="Save", exact=True).click()
    expect(page.locator("#save-state")).to_contain_text("Saved (revision 2)")
    page.reload()
    expect(page.locator(".CodeMirror")).to_be_visible()
    assert editor_text(page) == source
    assert page.locator("#source").input_value() == source

    page.get_by_role("button", name="Save and run").click()  # the console, on this page
    console = page.locator("#console")
    expect(console.locator("#log-lines .ln.o")).to_have_text(
        ["out line 0", "out line 1", "out line 2", "typed in the editor"]
    )
    expect(console.locator("#run-status .state")).to_have_text("finished")
    console.get_by_role("link", name=re.compile(r"Run #\d+")).click()  # and its own page
    run_id = run_id_of(page)
    expect(page.get_by_role("heading", name=f"Run #{run_id}: Greeter")).to_be_visible()
    expect(page.locator("#log-lines .ln.o")).to_have_text(
        ["out line 0", "out line 1", "out line 2", "typed in the editor"]
    )
    expect(page.locator("#log-lines .ln.e")).to_have_text(["oops on stderr"])
    expect(page.locator("#run-status .state")).to_have_text("finished")
    expect(page.locator("#run-status")).to_contain_text("exit code 0")
    expect(page.get_by_role("button", name="Stop")).to_have_count(0)
    screenshot(page, "run-finished")


def test_output_streams_live_and_stop_ends_the_run(page, appliance, screenshot):
    appliance.create_program("Counter", FOREVER)
    page.goto("/programs/")
    program_row(page, "Counter").get_by_role("button", name="Run").click()
    run_id = run_id_of(page)
    expect(page.locator("#run-status .state")).to_have_text("running")
    mark_page(page)
    # The page's websocket opens on the pass it was rendered with (programs.watch_pass).
    assert "pass=" in page.locator("[ws-connect]").first.get_attribute("ws-connect")

    lines = page.locator("#log-lines .ln.o")
    expect(lines.nth(2)).to_be_visible()
    seen = lines.count()
    # More lines arrive on the same page: streamed, not reloaded.
    page.wait_for_function(
        "n => document.querySelectorAll('#log-lines .ln.o').length >= n + 5", arg=seen
    )
    assert_not_reloaded(page)
    numbers = [int(text) for text in lines.all_inner_texts()]
    assert numbers == list(range(len(numbers))), "lines lost, repeated or out of order"
    screenshot(page, "run-streaming")

    page.get_by_role("button", name="Stop").click()
    expect(page.locator("#run-status .state")).to_have_text("stopped")
    expect(page.get_by_role("button", name="Stop")).to_have_count(0)
    assert appliance.api("GET", f"/api/runs/{run_id}").json()["state"] == "stopped"
    screenshot(page, "run-stopped")

    page.get_by_role("navigation").get_by_role("link", name="Runs").click()
    expect(page).to_have_url(re.compile(r"/runs/$"))
    row = finished_table(page).locator(f"#run-row-{run_id}")
    expect(row).to_contain_text("Counter")
    expect(row.locator(".state")).to_have_text("stopped")
    expect(running_table(page)).to_have_count(0)
    expect(page.locator("#run-tables")).to_contain_text("Nothing is running.")


def test_runs_page_lists_several_runs_and_updates_live(page, appliance, screenshot):
    first = appliance.create_program("Forever A", FOREVER)
    second = appliance.create_program("Forever B", FOREVER)
    run_a = appliance.run_program(first["id"])["id"]
    run_b = appliance.run_program(second["id"])["id"]
    appliance.wait_run(run_a, states=("running",))
    appliance.wait_run(run_b, states=("running",))

    page.goto("/runs/")
    running = running_table(page)
    expect(running.locator(f"#run-row-{run_a}")).to_contain_text("Forever A")
    expect(running.locator(f"#run-row-{run_b}")).to_contain_text("Forever B")
    expect(running.locator(".state")).to_have_text(["running", "running"])
    expect(page.locator("#run-tables h2 .count")).to_have_text("2")
    screenshot(page, "runs-list")

    mark_page(page)
    running.locator(f"#run-row-{run_a}").get_by_role("button", name="Stop").click()
    row_a = finished_table(page).locator(f"#run-row-{run_a}")
    expect(row_a.locator(".state")).to_have_text("stopped")
    expect(running_table(page).locator("tbody tr")).to_have_count(1)
    expect(running_table(page).locator(f"#run-row-{run_b}")).to_be_visible()
    expect(page.locator("#run-tables h2 .count")).to_have_text("1")
    assert_not_reloaded(page)

    # A run ending elsewhere (here: through the API) shows up too.
    appliance.api("POST", f"/api/runs/{run_b}/stop")
    expect(finished_table(page).locator(f"#run-row-{run_b} .state")).to_have_text("stopped")
    expect(page.locator("#run-tables")).to_contain_text("Nothing is running.")
    assert_not_reloaded(page)
    screenshot(page, "runs-list-after-stop")


def test_revisions_copy_download_and_delete(page, appliance, screenshot):
    one = "print('one')\nprint('same')\n"
    two = "print('two')\nprint('same')\n"
    three = "print('same')\nprint('three')\n"
    program = appliance.create_program("Revised", one)
    page.goto(f"/programs/{program['id']}/")
    for number, text in [(2, two), (3, three)]:
        expect(page.locator(".CodeMirror")).to_be_visible()
        set_editor_text(page, text)
        page.get_by_role("button", name="Save", exact=True).click()
        expect(page.locator("#save-state")).to_contain_text(f"Saved (revision {number})")

    page.get_by_role("link", name="Revisions").click()
    rows = page.locator("table.list tbody tr")
    expect(rows).to_have_count(3)
    expect(rows.locator("td:first-child")).to_have_text(["3 current", "2", "1"])
    screenshot(page, "revisions")

    rows.nth(2).get_by_role("link", name="Compare with current").click()
    expect(page.get_by_role("heading", name="Revision 1 of Revised")).to_be_visible()
    expect(page.locator("pre.diff .del")).to_have_text(["-print('one')"])
    expect(page.locator("pre.diff .add")).to_have_text(["+print('three')"])
    expect(page.locator("pre.code")).to_have_text(one)
    screenshot(page, "diff")

    page.get_by_role("button", name="Restore this revision").click()
    expect(page).to_have_url(re.compile(rf"/programs/{program['id']}/$"))
    expect(page.locator(".messages")).to_contain_text("Restored revision 1 as revision 4")
    expect(page.locator(".CodeMirror")).to_be_visible()
    assert editor_text(page) == one

    page.get_by_label("Save as").fill("Revised copy")
    page.get_by_role("button", name="Save as").click()
    expect(page.get_by_role("heading", name="Revised copy")).to_be_visible()
    expect(page.locator(".messages")).to_contain_text("Saved a copy as Revised copy")
    copy_id = int(re.search(r"/programs/(\d+)/$", page.url).group(1))
    assert copy_id != program["id"]
    assert editor_text(page) == one

    with page.expect_download() as download_info:
        page.get_by_role("link", name="Download").click()
    download = download_info.value
    assert download.suggested_filename == "revised-copy.py"
    assert open(download.path()).read() == one

    page.get_by_role("link", name="Delete").click()
    expect(page.get_by_role("heading", name="Delete Revised copy?")).to_be_visible()
    screenshot(page, "delete")
    assert appliance.api("GET", f"/api/programs/{copy_id}").status_code == 200  # not yet
    page.get_by_role("button", name="Delete").click()
    expect(page).to_have_url(re.compile(r"/programs/$"))
    expect(page.locator(".messages")).to_contain_text("Deleted Revised copy")
    expect(program_row(page, "Revised copy")).to_have_count(0)
    expect(program_row(page, "Revised")).to_have_count(1)
    assert appliance.api("GET", f"/api/programs/{copy_id}").status_code == 404


def test_upload_a_shell_script(page, tmp_path, screenshot):
    script = tmp_path / "wave.sh"
    script.write_text('#!/bin/sh\necho "waving from the shell"\n')
    page.goto("/programs/")
    upload = page.locator("section", has=page.get_by_role("heading", name="Upload a file"))
    upload.get_by_label("File", exact=True).set_input_files(script)
    expect(upload.locator("select[name=language]")).to_have_value("")  # from the file name
    upload.get_by_role("button", name="Upload").click()

    expect(page.get_by_role("heading", name="wave", exact=True)).to_be_visible()
    expect(page.locator(".messages")).to_contain_text("Uploaded wave.")
    expect(page.get_by_label("Language")).to_have_value("shell")
    expect(page.locator(".CodeMirror")).to_be_visible()
    assert editor_text(page) == script.read_text()
    assert page.evaluate("window.robotideEditor.getOption('mode')") == "shell"
    screenshot(page, "uploaded")

    page.get_by_role("button", name="Save and run").click()
    expect(page.locator("#console #log-lines .ln.o")).to_have_text(["waving from the shell"])
    expect(page.locator("#console #run-status .state")).to_have_text("finished")


def test_pages_work_with_scripts_off(new_page, appliance, screenshot):
    page = new_page(java_script_enabled=False)
    sign_in(page)
    program = appliance.create_program("Plain", "print('old')\n")
    page.goto(f"/programs/{program['id']}/")
    expect(page.locator(".CodeMirror")).to_have_count(0)
    source = page.locator("textarea#source")
    expect(source).to_be_visible()
    expect(source).to_have_value("print('old')\n")

    text = "import time\nprint('plain one')\ntime.sleep(2)\nprint('plain two')\n"
    source.fill(text)
    page.get_by_role("button", name="Save", exact=True).click()
    expect(page.locator(".messages")).to_contain_text("Saved (revision 2)")
    page.reload()
    expect(page.locator("textarea#source")).to_have_value(text)
    screenshot(page, "editor-no-scripts")

    page.get_by_role("button", name="Save and run").click()
    run_id = run_id_of(page)
    expect(page.locator("#run-status .state")).to_have_text(re.compile("starting|running"))
    # No websocket: the page refreshes itself while the run is active.
    expect(page.locator('meta[http-equiv="refresh"]')).to_have_count(1)
    screenshot(page, "run-no-scripts-live")
    expect(page.locator("#run-status .state")).to_have_text("finished", timeout=20_000)
    expect(page.locator("#log-lines .ln.o")).to_have_text(["plain one", "plain two"])
    expect(page.locator("#run-status")).to_contain_text("exit code 0")
    expect(page.locator('meta[http-equiv="refresh"]')).to_have_count(0)
    assert appliance.api("GET", f"/api/runs/{run_id}").json()["state"] == "finished"
    screenshot(page, "run-no-scripts-finished")


def test_robot_page_shows_sensors_camera_and_program_drawings(page, appliance, screenshot):
    page.goto("/robots/sim/")
    sensors = page.locator("#sensors")
    expect(sensors.locator("th", has_text=re.compile(r"^heading$"))).to_be_visible()
    expect(sensors.locator("th", has_text=re.compile(r"^range$"))).to_be_visible()
    # The sim drawn by the page itself (its JPEG stream is for pages without scripts).
    expect(page.locator("canvas.simview-canvas")).to_be_visible()
    expect(page.locator("canvas.simview-canvas")).to_have_attribute("data-pose", re.compile(r"\S"))
    expect(page.locator("#shows .show")).to_have_count(0)

    compass = next(
        p
        for p in appliance.api("GET", "/api/programs").json()
        if p["name"] == "Compass" and p["owner"] == "admin"
    )
    page.get_by_label("Program").select_option(str(compass["id"]))
    page.get_by_role("button", name="Run").click()
    run_id = run_id_of(page)
    expect(page.locator("#log-lines .ln.o").first).to_contain_text("My heading is")
    page.get_by_role("link", name="sim").first.click()  # the run's robot (its panel names it too)

    expect(page.locator("#robot-running")).to_contain_text(f"#{run_id} Compass")
    shows = page.locator("#shows")
    drawing = shows.locator(".show", has_text="compass").locator("img")
    expect(drawing).to_be_visible()
    expect(drawing).to_have_attribute("src", re.compile(r"^data:image/svg\+xml;base64,"))
    page.wait_for_function(
        "() => { const img = document.querySelector('#shows img');"
        " return img && img.complete && img.naturalWidth > 0; }"
    )
    expect(shows.locator(".show", has_text="heading").locator("output")).to_have_text(
        re.compile(r"^\d+$")
    )
    screenshot(page, "robot")

    page.get_by_role("button", name="EMERGENCY STOP").click()
    expect(page.locator(".messages")).to_contain_text(re.compile(r"\d+ program\(s\) ended"))
    assert appliance.wait_run(run_id)["state"] == "stopped"
    expect(page.locator("#robot-running")).to_contain_text("No program is running.")
    screenshot(page, "robot-after-estop")
    appliance.resume()


def test_other_users_cannot_open_my_programs_or_runs(new_page, appliance):
    program = appliance.create_program("Mine alone", "print('mine')\n")
    run_id = appliance.run_program(program["id"])["id"]
    appliance.wait_run(run_id)
    appliance.new_user("bob", password="bob-pass-1234")

    page = new_page()
    sign_in(page, "bob", "bob-pass-1234")
    expect(page.locator("#programs").get_by_role("link", name="Compass")).to_be_visible()
    expect(program_row(page, "Mine alone")).to_have_count(0)
    for path in [
        f"/programs/{program['id']}/",
        f"/programs/{program['id']}/revisions/",
        f"/programs/{program['id']}/revisions/1/",
        f"/programs/{program['id']}/download",
        f"/runs/{run_id}/",
        f"/runs/{run_id}/log",
    ]:
        assert page.goto(path).status == 404, path
    page.goto("/runs/")
    expect(page.locator(f"#run-row-{run_id}")).to_have_count(0)
    # Bob's own program opens: the 404s above are about whose it is.
    page.goto("/programs/")
    page.get_by_role("link", name="Compass").click()
    expect(page.locator(".CodeMirror")).to_be_visible()


def test_staff_change_a_robots_options_and_it_reopens_with_them(page, appliance, screenshot):
    page.goto("/robots/sim/")
    page.get_by_role("link", name="edit").click()
    expect(page.get_by_role("heading", name="Driver options")).to_be_visible()
    page.get_by_label("max_linear").fill("-1")
    page.get_by_role("button", name="Save and reopen").click()
    expect(page.locator(".errorlist")).to_contain_text("max_linear must be greater than 0")
    page.get_by_label("max_linear").fill("0.3")
    page.get_by_label("arena").select_option("square")
    screenshot(page, "robot-settings")
    page.get_by_role("button", name="Save and reopen").click()
    expect(page.locator(".messages")).to_contain_text("Settings saved")
    options = page.locator("table.options")
    expect(options.locator("tr", has_text="max_linear")).to_contain_text("0.3set here")
    expect(options.locator("tr", has_text="arena")).to_contain_text("squareset here")
    screenshot(page, "robot-with-settings")
    assert appliance.api("GET", "/api/robots/sim").json()["settings"] == {
        "arena": "square",
        "max_linear": 0.3,
    }
    # Back as it was, for the other tests on this appliance.
    response = appliance.api("PATCH", "/api/robots/sim", {"settings": {}})
    assert response.status_code == 200


def test_a_robot_that_is_away_says_why_on_its_page(page, appliance, screenshot):
    port = free_port()  # nothing listens there: a Pioneer that is switched off
    response = appliance.api(
        "POST", "/api/robots",
        {"name": "away", "url": f"pioneer+tcp://127.0.0.1:{port}", "settings": {"timeout": 0.5}},
    )  # fmt: skip
    assert response.status_code == 201, response.text
    page.goto("/robots/away/")
    alert = page.locator("#sensors").get_by_role("alert")
    expect(alert).to_contain_text("Robot not reachable")
    expect(alert).to_contain_text(f"127.0.0.1:{port}")
    screenshot(page, "robot-away")
