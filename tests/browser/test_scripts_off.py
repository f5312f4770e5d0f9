"""Pages with JavaScript turned off: the robot page shows its camera once and no drive pad that
cannot work; a failed run's page links its error lines to the program's lines."""

from playwright.sync_api import expect

from tests.browser.test_pages import sign_in

FAILS = """\
x = 1
y = 2
raise ValueError("boom")
"""


def test_the_robot_page_without_scripts(new_page, screenshot):
    page = new_page(java_script_enabled=False)
    sign_in(page)
    page.goto("/robots/sim/")
    expect(page.locator("img.camera")).to_have_count(1)
    expect(page.locator("img.camera")).to_be_visible()
    pad = page.locator("#control .pad")
    expect(pad).to_be_hidden()  # held buttons over a websocket: nothing without scripts
    said = page.locator("#control .no-scripts")
    expect(said).to_have_text("Driving by hand needs JavaScript.", use_inner_text=True)
    expect(said).to_be_visible()
    for width, height in ((390, 844), (1366, 900)):
        page.set_viewport_size({"width": width, "height": height})
        screenshot(page, f"robot-page-no-scripts-{width}")


def test_a_failed_runs_error_links_to_its_line_without_scripts(appliance, new_page, screenshot):
    program = appliance.create_program("Fails on line 3", FAILS)
    run = appliance.run_program(program["id"])["id"]
    assert appliance.wait_run(run)["state"] == "failed"
    page = new_page(java_script_enabled=False)
    sign_in(page)
    page.goto(f"/runs/{run}/")
    link = page.locator('#log a[href="#line-3"]')
    expect(link).to_have_count(1)
    expect(link).to_contain_text("line 3")
    link.click()
    line = page.locator("#line-3")
    expect(line).to_be_visible()  # its listing opened, at the line
    expect(line).to_contain_text('raise ValueError("boom")')
    for width, height in ((390, 844), (1366, 900)):
        page.set_viewport_size({"width": width, "height": height})
        screenshot(page, f"run-failed-no-scripts-{width}")
