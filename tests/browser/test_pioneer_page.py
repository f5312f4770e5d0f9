"""A classic P3-AT's page, in a real browser: the model it named, where its units come from,
and a unit set in its settings.

A real appliance drives the ARCOS emulator (tests/rhal/arcos_emulator.py) started as a P3-AT,
on an event loop of its own in this process.
"""

import pytest
from playwright.sync_api import expect

from tests.browser.test_pages import sign_in
from tests.peers import peer_in_thread

ROBOT = "p3at"


@pytest.fixture(scope="module")
def pioneer(tmp_path_factory):
    with peer_in_thread("pioneer", tmp_path_factory.mktemp("pioneer"), model="p3at") as peer:
        yield peer


@pytest.fixture(scope="module")
def p3at(appliance, pioneer):
    response = appliance.api("POST", "/api/robots", {"name": ROBOT, "url": pioneer.url})
    assert response.status_code == 201, response.text
    yield ROBOT
    appliance.api("DELETE", f"/api/robots/{ROBOT}")


def test_the_robot_page_names_the_model_and_where_each_unit_comes_from(new_page, p3at, screenshot):
    page = new_page()
    sign_in(page)
    page.goto(f"/robots/{p3at}/")
    card = page.locator(".model-card")
    expect(card).to_contain_text("Pioneer p3at", timeout=20_000)  # once the agent is up
    expect(card).to_contain_text("ARIA params/p3at.p")
    expect(card).to_contain_text("SYNC2 subclass 'p3at'")
    dist = card.locator("tr", has_text="dist_conv")
    expect(dist).to_contain_text("0.465 mm")
    expect(dist).to_contain_text("model")
    screenshot(page, "robot-pioneer-model")

    page.goto(f"/robots/{p3at}/settings")
    page.locator("[name=option_dist_conv]").fill("0.47")
    page.get_by_role("button", name="Save and reopen").click()
    page.goto(f"/robots/{p3at}/")
    dist = page.locator(".model-card tr", has_text="dist_conv")
    expect(dist).to_contain_text("0.47 mm", timeout=20_000)  # the agent reopened the robot
    expect(dist).to_contain_text("settings")
