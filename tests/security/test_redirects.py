"""A form's ``next`` (run stop, robot queue, say box: robotide.redirects.back) leads back
within this site only: never an open redirect."""

import pytest
from django.test import RequestFactory

from robotide.redirects import back


@pytest.mark.parametrize(
    "next_url, lands",
    [
        ("/programs/3/", "/programs/3/"),
        ("https://evil.example/phish", "/runs/7/"),
        ("//evil.example/phish", "/runs/7/"),
        ("javascript:alert(1)", "/runs/7/"),
        ("", "/runs/7/"),
    ],
)
def test_back_goes_to_next_on_this_site_only(next_url, lands):
    request = RequestFactory().post("/runs/7/stop", {"next": next_url})
    assert back(request, "run-detail", 7)["Location"] == lands
