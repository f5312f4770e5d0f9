# The browser tests' Chromium fixtures, for the pages' Content Security Policy check.
from tests.browser.conftest import browser, new_page  # noqa: F401
