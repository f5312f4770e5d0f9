"""A teacher's classroom in Chromium (issue 31): a staff teacher without model permissions finds
Classroom in the menu and no Admin link; makes a class; adds three students from a pasted
list; sees their sheet of one-time passwords and prints it (print media: the menu and buttons
gone, the cards kept; an A4 PDF); a student signs in with the one-time password and must
choose their own before anything else. Pages saved at 1280 and 390 px wide for a person to
look at (test-artifacts/screenshots/classroom-*.png)."""

import re

import pytest
from playwright.sync_api import expect

from tests.browser.test_accessibility import AXE, AXE_URL, axe_violations
from tests.browser.test_fit import measure, small_targets
from tests.browser.test_pages import sign_in

PASSWORD = "a long enough passphrase"
NAMES = ["Ana Maria Silva", "Bruno Costa", "Célia Dias"]
WIDTHS = {"wide": (1280, 800), "phone": (390, 844)}


@pytest.fixture(scope="module")
def teacher(appliance):
    appliance.new_user("tereza", PASSWORD, staff=True)  # staff, but no model permissions
    return "tereza"


def with_axe(page):
    """axe-core on hand at AXE_URL (answered here, never by the appliance)."""
    page.route(
        f"**{AXE_URL}", lambda route: route.fulfill(path=AXE, content_type="text/javascript")
    )
    return page


def shots(page, screenshot, name: str) -> None:
    """The page at both widths, each checked not to scroll sideways, its targets big enough
    for a finger on a phone, and no serious or critical axe-core violation."""
    found = axe_violations(page)
    assert not found, (name, found)
    for label, (width, height) in WIDTHS.items():
        page.set_viewport_size({"width": width, "height": height})
        fit = measure(page)
        assert fit["scroll"] <= fit["client"] and not fit["wide"], (name, label, fit)
        if width < 600:
            assert not small_targets(page), (name, small_targets(page))
        screenshot(page, f"classroom-{name}-{label}")
    page.set_viewport_size({"width": 1280, "height": 800})


def test_class_of_three_sheet_printed_and_first_sign_in(
    new_page, appliance, teacher, screenshot, tmp_path
):
    page = with_axe(new_page())
    sign_in(page, teacher, PASSWORD)
    menu = page.locator("header.top nav")
    expect(menu.get_by_role("link", name="Exercises")).to_be_visible()
    expect(menu.get_by_role("link", name="Admin")).to_have_count(0)
    menu.get_by_role("link", name="Classroom").click()
    expect(page.locator("h1")).to_have_text("Classroom")

    page.get_by_label("Name").fill("Robotics 7B")
    page.get_by_role("button", name="Make the class").click()
    expect(page.locator("h1")).to_have_text("Robotics 7B")
    expect(page.locator("#join-code")).to_have_text(re.compile(r"^[A-Z2-9]{8}$"))

    page.get_by_label("Names, one a line").fill("\n".join(NAMES))
    page.get_by_role("button", name="Add to the class").click()
    expect(page.locator("h1")).to_have_text("Sign-in sheet: Robotics 7B")
    cards = page.locator(".sheet-card")
    expect(cards).to_have_count(3)
    expect(page.locator(".messages")).to_contain_text("Made 3 accounts")
    username = cards.nth(0).locator(".sheet-username").inner_text()
    password = cards.nth(0).locator(".sheet-password").inner_text()
    assert username == "ana-maria-silva" and re.fullmatch(r"[A-Z2-9]{10}", password)
    expect(cards.nth(2)).to_contain_text("Célia Dias")
    expect(cards.nth(0).locator(".sheet-url")).to_have_text(f"{appliance.url}/accounts/login/")
    shots(page, screenshot, "sheet")

    # Printed: the menu, the note and the buttons are not on paper; the cards are, two a row.
    page.emulate_media(media="print")
    expect(page.locator("header.top")).to_be_hidden()
    expect(page.locator("#sheet-print")).to_be_hidden()
    expect(cards.nth(2)).to_be_visible()
    first, second = cards.nth(0).bounding_box(), cards.nth(1).bounding_box()
    assert abs(first["y"] - second["y"]) < 1 and second["x"] > first["x"]  # side by side
    screenshot(page, "classroom-sheet-print")
    pdf = tmp_path / "sheet.pdf"
    page.pdf(path=str(pdf), prefer_css_page_size=True)
    data = pdf.read_bytes()
    # A4 (595 x 842 pt), as the sheet's @page asks; three cards on one page
    assert re.search(rb"/MediaBox \[0 0 59[45](\.\d+)? 84[12](\.\d+)?\]", data), data[:400]
    assert len(re.findall(rb"/Type /Page[^s]", data)) == 1
    page.emulate_media(media="screen")

    # Shown once: back on it, the passwords are gone.
    page.reload()
    expect(page.locator(".sheet-card")).to_have_count(0)
    expect(page.locator("#sheet-gone")).to_contain_text("shown once")

    page.get_by_role("link", name="Back to the class").click()
    expect(page.locator("#students tbody tr")).to_have_count(3)
    expect(page.locator("#students")).to_contain_text("one-time password")
    shots(page, screenshot, "class")
    page.goto("/classroom/")
    expect(page.locator("#classes-mine")).to_contain_text("3 students")
    shots(page, screenshot, "list")

    # The student's first sign-in: their own password before anything else.
    student = with_axe(new_page())
    sign_in(student, username, password)
    expect(student).to_have_url(re.compile(r"/accounts/password/$"))
    expect(student.locator(".messages")).to_contain_text("Choose a password of your own")
    student.goto("/programs/")
    expect(student).to_have_url(re.compile(r"/accounts/password/$"))
    student.locator("#id_old_password").fill(password)
    student.locator("#id_new_password1").fill(PASSWORD)
    student.locator("#id_new_password2").fill(PASSWORD)
    student.get_by_role("button", name="Change password").click()
    expect(student.locator("h1")).to_have_text("Password changed")
    student.goto("/programs/")
    expect(student).to_have_url(re.compile(r"/programs/$"))
    expect(student.locator("header.top nav").get_by_role("link", name="Classroom")).to_have_count(0)

    # The teacher sees it on the class's page, and opens the student.
    page.get_by_role("link", name="Robotics 7B").click()
    ana = page.locator("#students tbody tr", has_text="Ana Maria Silva")
    expect(ana).not_to_contain_text("one-time password")
    expect(ana).to_contain_text("minutes ago")
    expect(page.locator("#students tbody tr", has_text="Bruno Costa")).to_contain_text("one-time")
    page.locator("#students").get_by_role("link", name="Ana Maria Silva").click()
    expect(page.locator("h1")).to_have_text("Ana Maria Silva")
    expect(page.locator("#hidden-examples")).to_contain_text("never touched")
    shots(page, screenshot, "student")


def test_join_with_the_code(new_page, appliance, teacher, screenshot):
    """A student makes their own account with the class's join code, as read off a board."""
    page = with_axe(new_page())
    sign_in(page, teacher, PASSWORD)
    page.goto("/classroom/")
    page.get_by_label("Name").fill("Robotics 8C")
    page.get_by_role("button", name="Make the class").click()
    code = page.locator("#join-code").inner_text()

    student = with_axe(new_page())
    student.goto("/accounts/join/")
    shots(student, screenshot, "join")
    student.get_by_label("Join code").fill("WRONG-CODE")
    student.get_by_label("Username").fill("dani")
    student.get_by_label("Your name").fill("Dani Prado")
    student.get_by_label("Password", exact=True).fill(PASSWORD)
    student.get_by_label("Password confirmation").fill(PASSWORD)
    student.get_by_role("button", name="Make my account").click()
    expect(student.locator("#join")).to_contain_text("No class has this join code")
    student.get_by_label("Join code").fill(code[:4].lower() + " " + code[4:].lower())
    student.get_by_label("Password", exact=True).fill(PASSWORD)
    student.get_by_label("Password confirmation").fill(PASSWORD)
    student.get_by_role("button", name="Make my account").click()
    expect(student.locator(".messages")).to_contain_text("you are in Robotics 8C")
    expect(student.get_by_role("button", name="Sign out")).to_be_visible()
    page.reload()
    expect(page.locator("#students")).to_contain_text("Dani Prado")
