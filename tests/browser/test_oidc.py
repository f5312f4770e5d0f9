"""Sign-in with an OpenID Connect provider in a real browser: the appliance (`robotide up`) set
by ROBOTIDE_OIDC_* for a real provider (node's oidc-provider, tests/oidc_provider.py), both on
free ports. The sign-in page's button, the provider's form and back; classes and teaching from
claims and the example programs; sign-out at the provider; a disabled account; a forged state.
Screenshots: test-artifacts/screenshots/oidc-*.png.
"""

import json
import re

import httpx
import pytest
from playwright.sync_api import Page, expect

from tests.appliance import Appliance
from tests.browser.test_accessibility import AXE, AXE_URL, axe_violations
from tests.oidc_provider import ACCOUNTS, Provider

BUTTON = "Sign in with Uni Login"


@pytest.fixture(scope="module")
def appliance(tmp_path_factory):
    """The appliance, signing in at its own provider (``appliance.provider``)."""
    app = Appliance(tmp_path_factory.mktemp("appliance"))
    provider = Provider(
        tmp_path_factory.mktemp("oidc"),
        [f"{app.url}/accounts/oidc/callback/"],
        [f"{app.url}/accounts/login/"],
    ).start()
    app.env.update(provider.env())
    app.provider = provider
    try:
        yield app.start()
        app.stop()
    finally:
        provider.stop()


@pytest.fixture
def provider(appliance):
    provider = appliance.provider
    provider.accounts = json.loads(json.dumps(ACCOUNTS))
    provider.save_accounts()
    return provider


def at_provider(page: Page, provider, login: str) -> None:
    """The sign-in page's button, then the provider's own form."""
    page.goto("/accounts/login/")
    page.get_by_role("link", name=BUTTON).click()
    expect(page).to_have_url(re.compile(re.escape(provider.issuer) + "/interaction/"))
    page.locator("input[name=login]").fill(login)
    page.locator("input[name=password]").fill(ACCOUNTS[login]["password"])
    page.get_by_role("button", name="Sign-in").click()


def with_axe(page: Page) -> None:
    """axe-core at AXE_URL, answered by the test (tests/browser/test_accessibility.py)."""
    page.route(f"**{AXE_URL}", lambda r: r.fulfill(path=AXE, content_type="text/javascript"))


def test_the_sign_in_page_with_the_button_passes_axe(new_page, screenshot):
    page = new_page()
    with_axe(page)
    page.goto("/accounts/login/")
    expect(page.get_by_role("link", name=BUTTON)).to_be_visible()
    screenshot(page, "oidc-sign-in")
    assert axe_violations(page) == []


def test_a_teacher_signs_in_at_the_provider_and_out_again(
    appliance, provider, new_page, screenshot
):
    page = new_page()
    at_provider(page, provider, "tom")
    expect(page).to_have_url(f"{appliance.url}/programs/")
    expect(page.get_by_role("button", name="Sign out")).to_be_visible()
    expect(page.get_by_role("link", name="tom")).to_be_visible()
    expect(page.get_by_text("Stop before the wall", exact=True)).to_be_visible()  # the examples
    screenshot(page, "oidc-signed-in")
    taught = appliance.cli(
        "manage", "shell", "-c",
        "from robotide.models import ClassTeacher as T; "
        "print([t.group.name for t in T.objects.filter(user__username='tom')])",
    )  # fmt: skip
    assert taught.strip().splitlines()[-1] == "['class-robotics1']"

    page.get_by_role("button", name="Sign out").click()  # here, then at the provider
    expect(page).to_have_url(re.compile(re.escape(provider.issuer) + "/session/end"))
    page.get_by_role("button", name="Yes, sign me out").click()
    expect(page).to_have_url(re.compile(re.escape(f"{appliance.url}/accounts/login/")))
    page.get_by_role("link", name=BUTTON).click()
    expect(page.locator("input[name=password]")).to_be_visible()  # asked again: signed out there


def test_an_account_disabled_at_the_provider_cannot_sign_in(appliance, provider, new_page):
    provider.accounts["dora"]["disabled"] = True
    provider.save_accounts()
    page = new_page()
    at_provider(page, provider, "dora")
    expect(page).to_have_url(re.compile(re.escape(provider.issuer) + "/interaction/"))
    expect(page.locator("input[name=password]")).to_be_visible()  # refused: the form again
    page.goto("/programs/")
    expect(page).to_have_url(re.compile("/accounts/login/"))


def test_a_callback_this_browser_did_not_ask_for_is_refused(
    appliance, provider, new_page, screenshot
):
    """A forged state, and a genuine code and state sent to someone else's browser (to sign
    them in as the attacker): each is the sign-in page saying why, and nobody signed in."""
    with httpx.Client(base_url=appliance.url) as attacker:
        start = attacker.get("/accounts/oidc/login/").headers["location"]
        back = provider.sign_in_elsewhere(start, "ana", ACCOUNTS["ana"]["password"])
    forged = re.sub(r"state=[^&]+", "state=forged", back)
    page = new_page()
    page.goto("/accounts/login/")
    page.get_by_role("link", name=BUTTON).click()  # a sign-in of its own, with its own state
    expect(page.locator("input[name=login]")).to_be_visible()
    for url in (forged, back):
        response = page.goto(url)
        assert response.status == 400
        refusal = "does not belong to a sign-in started in this browser"
        expect(page.get_by_text(refusal)).to_be_visible()
        expect(page.get_by_role("button", name="Sign out")).to_have_count(0)
    screenshot(page, "oidc-refused")
    with_axe(page)
    assert axe_violations(page) == []
    page.goto("/programs/")
    expect(page).to_have_url(re.compile("/accounts/login/"))
