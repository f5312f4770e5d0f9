"""Sharing a program between two people, each in their own browser (own cookies).

Alice shares a program with Bob read-only on the program page; Bob finds it in his list,
opens it read-only (no Save) and saves a copy of his own; Alice unshares and the program's
address is a 404 for Bob at once. Screenshots: sharing-card (Alice's "Shared with" card) and
sharing-read-only (Bob's view).
"""

import re

from playwright.sync_api import expect

from tests.browser.test_pages import program_row, sign_in

SOURCE = "print('shared hello')\n"


def test_share_read_only_copy_and_unshare(new_page, appliance, screenshot):
    alice_token = appliance.new_user("alice", password="alice-pass-1234")
    appliance.new_user("bob", password="bob-pass-1234")
    created = appliance.api(
        "POST", "/api/programs",
        {"name": "Alices robot dance", "language": "python", "source": SOURCE},
        token=alice_token,
    )  # fmt: skip
    assert created.status_code == 201, created.text
    url = f"/programs/{created.json()['id']}/"

    alice = new_page()
    sign_in(alice, "alice", "alice-pass-1234")
    bob = new_page()
    sign_in(bob, "bob", "bob-pass-1234")
    # Not shared yet: Bob cannot open it.
    expect(program_row(bob, "Alices robot dance")).to_have_count(0)
    assert bob.goto(url).status == 404

    # Alice shares it with Bob, read-only.
    alice.goto(url)
    card = alice.locator("section.shares")
    expect(card.get_by_role("heading", name="Shared with")).to_be_visible()
    expect(card.locator(".share-list")).to_contain_text("Only you.")
    card.get_by_label("Share with").fill("user:bob")
    expect(card.get_by_label("may edit")).not_to_be_checked()
    card.get_by_role("button", name="Share", exact=True).click()
    expect(alice.locator(".messages")).to_contain_text("Shared with user bob")
    expect(card.locator(".share-list")).to_contain_text("user bob · read-only")
    screenshot(alice, "sharing-card")

    # Bob sees it in his list and opens it: read-only, no Save, but Run and Save as.
    bob.goto("/programs/")
    row = program_row(bob, "Alices robot dance")
    expect(row).to_have_count(1)
    expect(row).to_contain_text("alice")
    expect(bob.locator("#programs tbody.others tr.group")).to_contain_text("Shared with you")
    screenshot(bob, "sharing-list")
    row.get_by_role("link", name="Alices robot dance", exact=True).click()
    expect(bob).to_have_url(re.compile(re.escape(url) + "$"))
    expect(bob.locator(".page-head")).to_contain_text("by alice")
    expect(bob.locator(".badge.read-only")).to_be_visible()
    expect(bob.get_by_role("button", name="Save", exact=True)).to_have_count(0)
    expect(bob.get_by_role("button", name="Save as", exact=True)).to_be_visible()
    expect(bob.locator("section.shares")).to_have_count(0)  # only the owner shares
    expect(bob.locator(".CodeMirror")).to_contain_text("shared hello")
    # It says so where one would type, and typing there changes nothing.
    expect(bob.locator("#read-only-note")).to_contain_text("alice shared this program with you")
    bob.locator(".CodeMirror").click()
    bob.keyboard.type("typed by bob")
    expect(bob.locator(".CodeMirror")).not_to_contain_text("typed by bob")
    expect(bob.locator("#save-state")).not_to_have_text("Unsaved changes")
    screenshot(bob, "sharing-read-only")

    # Bob saves a copy: his own program, which he may edit.
    bob.get_by_label("Save as").fill("Bobs dance")
    bob.get_by_role("button", name="Save as", exact=True).click()
    expect(bob.locator("h1")).to_have_text("Bobs dance")
    expect(bob).not_to_have_url(re.compile(re.escape(url) + "$"))
    expect(bob.locator(".badge.read-only")).to_have_count(0)
    expect(bob.get_by_role("button", name="Save", exact=True)).to_be_visible()
    expect(bob.locator(".CodeMirror")).to_contain_text("shared hello")
    copy_url = bob.url

    # Alice unshares; Bob's next look at the program is a 404, his copy stays.
    card.locator(".share-list li", has_text="user bob").get_by_role(
        "button", name="Unshare"
    ).click()
    expect(alice.locator(".messages")).to_contain_text("No longer shared with user bob")
    expect(card.locator(".share-list")).to_contain_text("Only you.")
    assert bob.goto(url).status == 404
    bob.goto("/programs/")
    expect(program_row(bob, "Alices robot dance")).to_have_count(0)
    expect(program_row(bob, "Bobs dance")).to_have_count(1)
    assert bob.goto(copy_url).status == 200
