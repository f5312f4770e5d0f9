"""The Robot API help: the editor's JSON per language and the help page, both from
programs/robot_api_spec.py."""

import html

import pytest
from django.contrib.auth.models import User

from programs.robot_api_spec import CALLS, CLIENTS

pytestmark = pytest.mark.django_db


@pytest.fixture
def alice(client):
    user = User.objects.create_user("alice", password="pw-alice-123")
    client.force_login(user)
    return user


@pytest.mark.parametrize("language", list(CLIENTS))
def test_it_gives_each_languages_calls_as_json(client, alice, language):
    response = client.get(f"/help/robot-api/{language}.json")
    assert response.status_code == 200 and response["Content-Type"] == "application/json"
    help_ = response.json()
    assert help_["language"] == language and help_["label"] == CLIENTS[language].label
    names = [call["name"] for call in help_["calls"]]
    assert names == [call.name for call in CALLS if language in call.forms]
    for call in help_["calls"]:
        assert call["page"] == f"/help/robot-api/#{call['name']}"
        assert call["signature"] and call["summary"] and call["doc"] and call["example"]


def test_it_says_the_units_and_the_form_the_client_takes(client, alice):
    calls = {c["name"]: c for c in client.get("/help/robot-api/perl.json").json()["calls"]}
    drive = calls["drive"]
    assert drive["signature"] == "$bot->drive($linear, $angular)"
    assert [(p["name"], p["unit"]) for p in drive["params"]] == [
        ("$linear", "m/s"),
        ("$angular", "rad/s"),
    ]


def test_a_language_without_a_client_is_not_found(client, alice):
    assert client.get("/help/robot-api/cobol.json").status_code == 404
    assert client.get("/help/robot-api/blocks.json").status_code == 404


def test_it_requires_sign_in(client):
    for url in ("/help/robot-api/python.json", "/help/robot-api/"):
        response = client.get(url)
        assert response.status_code == 302 and "/accounts/login/" in response["Location"]


def test_the_page_has_a_section_per_call_with_every_languages_form(client, alice):
    page = html.unescape(client.get("/help/robot-api/").content.decode())
    for call in CALLS:
        assert f'id="{call.name}"' in page
        for language, client_ in CLIENTS.items():
            if language in call.forms:
                assert client_.display(call.forms[language]) in page, (call.name, language)
                assert client_.example(call) in page, (call.name, language)
            else:
                assert call.absent[language] in page
    assert "robot drive LINEAR [ANGULAR]" in page and "m/s" in page and "rad/s" in page
