"""The worlds list page in Chromium (issue 30): a world imported from a file lands among mine,
its Export gives the same document back, it is shared from its Share page, and another
student then finds it under "Shared with everyone"; the page fits a phone (390 px) and a
laptop (1366 px), saved for a person to look at."""

import json
from pathlib import Path

import pytest
from playwright.sync_api import expect

from tests.browser.test_fit import TOUCH, measure, small_targets
from tests.browser.test_pages import sign_in

SHOTS = Path("/work/notes/shots")
PASSWORD = "a long enough passphrase"
WORLD = {
    "format": 1, "name": "hallway", "title": "The hallway",
    "size": {"width": 5.0, "height": 3.0},
    "walls": [{"from": [-1.0, 0.0], "to": [1.5, 0.0], "thickness": 0.05}],
    "start": [{"x": -2.0, "y": -1.0, "theta": 0.0}],
}  # fmt: skip


@pytest.fixture(scope="module")
def students(appliance):
    return {name: appliance.new_user(name, PASSWORD) for name in ("wanda", "walt")}


def shot(page, name: str) -> None:
    SHOTS.mkdir(parents=True, exist_ok=True)
    page.screenshot(path=str(SHOTS / f"{name}.png"), full_page=True)


def test_import_export_share(new_page, appliance, students, tmp_path):
    page = new_page()
    sign_in(page, "wanda", PASSWORD)
    page.get_by_role("link", name="Worlds").click()
    expect(page.locator("h1")).to_have_text("Worlds")
    expect(page.locator("#worlds-builtin")).to_contain_text("maze")
    upload = tmp_path / "hallway.json"
    upload.write_text(json.dumps(WORLD))
    page.locator("#world-import input[type=file]").set_input_files(str(upload))
    page.get_by_role("button", name="Import", exact=True).click()
    expect(page.locator(".messages")).to_contain_text("Imported hallway.json as hallway")
    row = page.locator("#worlds-mine tr", has_text="The hallway")
    expect(row).to_be_visible()

    with page.expect_download() as download:
        row.get_by_role("link", name="Export").click()
    assert download.value.suggested_filename == "hallway.json"
    exported = json.loads(Path(download.value.path()).read_text())
    assert exported["walls"][0]["from"] == [-1.0, 0.0] and exported["title"] == "The hallway"

    row.get_by_role("link", name="Share").click()
    page.get_by_label("Share with").fill("everyone")
    page.get_by_role("button", name="Share", exact=True).click()
    expect(page.locator(".messages")).to_contain_text("Shared with everyone")

    other = new_page()
    sign_in(other, "walt", PASSWORD)
    other.goto("/worlds/")
    expect(other.locator("#worlds-public")).to_contain_text("The hallway")
    expect(other.locator("#worlds-mine")).not_to_contain_text("The hallway")


@pytest.mark.parametrize(
    "who, width, height", [("walt", 390, 844), ("admin", 390, 844), ("walt", 1366, 860)]
)
def test_list_fits(new_page, appliance, students, who, width, height):
    """A student's page, and an admin's (the menu's longest: Admin too)."""
    page = new_page()
    page.set_viewport_size({"width": width, "height": height})
    if who == "admin":
        sign_in(page)
    else:
        sign_in(page, who, PASSWORD)
    page.goto("/worlds/")
    expect(page.locator("#worlds-builtin")).to_contain_text("maze")
    fit = measure(page)
    assert fit["scroll"] <= fit["client"], fit
    if width < 600:
        assert not small_targets(page), f"under {TOUCH} px: {small_targets(page)}"
    shot(page, f"worlds-list-{who}-{width}")
