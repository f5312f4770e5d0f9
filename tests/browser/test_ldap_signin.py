"""Directory sign-in in a real browser: an appliance started with ROBOTIDE_LDAP_* pointing at a
real slapd (tests/ldap_server.py), and Chromium on its sign-in page.

Screenshots: test-artifacts/screenshots/ldap-*.png.
"""

import re

import pytest
from playwright.sync_api import Page, expect

from tests.appliance import Appliance
from tests.browser.test_pages import EXAMPLES, sign_in
from tests.ldap_server import (
    PEOPLE,
    add_entries,
    as_directory_admin,
    ldap_env,
    person,
    running_slapd,
)

REFUSED = "Please enter a correct username and password"


@pytest.fixture(scope="module")
def directory(tmp_path_factory):
    with running_slapd(tmp_path_factory.mktemp("slapd")) as uri:
        yield uri


@pytest.fixture(scope="module")
def appliance(directory, tmp_path_factory):
    """This module's appliance: its accounts come from the directory (and its local admin)."""
    app = Appliance(tmp_path_factory.mktemp("ldap-appliance"), extra_env=ldap_env(directory))
    app.start()
    yield app
    app.stop()


def refused(page: Page, username: str, password: str) -> None:
    page.goto("/accounts/login/")
    page.get_by_label("User name").fill(username)
    page.get_by_label("Password").fill(password)
    page.get_by_role("button", name="Sign in").click()
    expect(page.locator(".errorlist")).to_contain_text(REFUSED)
    expect(page).to_have_url(re.compile(r"/accounts/login/$"))
    expect(page.get_by_role("button", name="Sign out")).to_have_count(0)


def test_a_student_signs_in_with_the_directory_password(new_page, screenshot):
    page = new_page()
    sign_in(page, "stu", "stu-pass-1")
    expect(page).to_have_url(re.compile(r"/programs/$"))
    expect(page.locator("header")).to_contain_text("stu")
    for name in EXAMPLES:
        expect(page.locator("#programs").get_by_role("link", name=name, exact=True)).to_be_visible()
    screenshot(page, "ldap-student-programs")
    page.goto("/accounts/")
    expect(page.locator("#account-classes")).to_have_text("Your classes: class-robotics1")
    screenshot(page, "ldap-student-account")


def test_the_teacher_sees_the_class_programs(appliance, new_page, screenshot):
    appliance.session("stu", "stu-pass-1").close()  # the student exists, with the examples
    page = new_page()
    sign_in(page, "tea", "tea-pass-1")
    others = page.locator("#programs tbody.others")
    expect(others).to_contain_text("your classes' programs")
    for name in EXAMPLES:
        row = others.locator("tr").filter(has=page.get_by_role("link", name=name, exact=True))
        expect(row).to_contain_text("stu")
    screenshot(page, "ldap-teacher-programs")
    page.goto("/accounts/")
    expect(page.locator("#account-teaching")).to_have_text("You teach: class-robotics1")


def test_a_wrong_directory_password_is_refused(new_page, screenshot):
    page = new_page()
    refused(page, "stu", "not-the-password")
    screenshot(page, "ldap-wrong-password")


def test_a_user_removed_from_the_directory_is_refused(directory, new_page):
    with as_directory_admin(directory) as conn:
        add_entries(conn, person("leaver", "Lee", "Leaver", "leaver-pass-1"))
    sign_in(new_page(), "leaver", "leaver-pass-1")
    with as_directory_admin(directory) as conn:
        conn.delete_s(f"uid=leaver,{PEOPLE}")
    refused(new_page(), "leaver", "leaver-pass-1")
