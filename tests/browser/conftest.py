"""A real Chromium (Debian's, never a downloaded one) driven by Playwright's sync API."""

import os
from pathlib import Path

import pytest
from playwright.sync_api import Error as PlaywrightError
from playwright.sync_api import expect, sync_playwright

from tests.appliance import ROOT
from tests.conftest import in_ci

CHROMIUM = os.environ.get("ROBOTIDE_TEST_CHROMIUM", "/usr/bin/chromium")
CHROMIUM_ARGS = [
    "--no-sandbox",
    "--disable-gpu",
    "--disable-background-networking",
    "--disable-component-update",
    "--disable-sync",
    "--no-first-run",
]
SCREENSHOTS = ROOT / "test-artifacts" / "screenshots"
TIMEOUT_MS = 15_000


# Module scope: Playwright's sync API keeps an event loop running in this thread while it is
# open, which the async tests collected after these could not run beside.
@pytest.fixture(scope="module")
def browser():
    if not Path(CHROMIUM).exists():
        message = f"no Chromium at {CHROMIUM}: apt-get install chromium"
        if in_ci():
            pytest.fail(message, pytrace=False)  # nothing is skipped in CI
        pytest.skip(message)
    expect.set_options(timeout=TIMEOUT_MS)
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=CHROMIUM, headless=True, args=CHROMIUM_ARGS)
        yield browser
        browser.close()


@pytest.fixture
def new_page(browser, appliance):
    """Opens pages in fresh browser contexts (own cookies), closed after the test."""
    contexts = []

    def open_page(**context_options):
        context = browser.new_context(
            base_url=appliance.url, viewport={"width": 1280, "height": 860}, **context_options
        )
        context.set_default_timeout(TIMEOUT_MS)
        contexts.append(context)
        return context.new_page()

    yield open_page
    for context in contexts:
        context.close()


@pytest.fixture
def screenshot():
    """Saves a full-page screenshot to test-artifacts/screenshots/NAME.png."""
    SCREENSHOTS.mkdir(parents=True, exist_ok=True)

    def save(page, name: str) -> None:
        # Chromium now and then answers "Unable to capture screenshot" on a busy machine (its
        # compositor had no frame ready): asked again, it has one. Anything else is raised.
        for attempt in range(3):
            try:
                page.screenshot(path=str(SCREENSHOTS / f"{name}.png"), full_page=True)
                return
            except PlaywrightError as exc:
                if "Unable to capture screenshot" not in str(exc) or attempt == 2:
                    raise

    return save
