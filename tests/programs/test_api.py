"""The REST API through Django's test client, with bearer tokens and sessions."""

import pytest
from django.contrib.auth.models import User
from django.test import Client

from programs.models import Program
from robotide.models import ApiToken
from robots.models import Robot

pytestmark = pytest.mark.django_db


@pytest.fixture
def alice():
    return User.objects.create_user("alice", password="pw-alice-123")


@pytest.fixture
def api(alice):
    _, token = ApiToken.issue(alice)
    client = Client(HTTP_AUTHORIZATION=f"Bearer {token}")

    def call(method, path, body=None):
        return getattr(client, method.lower())(path, body, content_type="application/json")

    return call


def test_openapi_is_published(client):
    spec = client.get("/api/openapi.json").json()
    assert "/api/programs" in spec["paths"] and "/api/runs/{run_id}/stop" in spec["paths"]


def test_create_read_update_delete(api, alice):
    created = api("POST", "/api/programs", {"name": "p", "language": "python", "source": "1\n"})
    assert created.status_code == 201
    program = created.json()
    assert program["owner"] == "alice" and program["revisions"] == 1
    updated = api("PUT", f"/api/programs/{program['id']}", {"source": "2\n"})
    assert updated.json()["source"] == "2\n" and updated.json()["revisions"] == 2
    assert api("GET", f"/api/programs/{program['id']}").json()["name"] == "p"
    assert api("DELETE", f"/api/programs/{program['id']}").status_code == 204
    assert api("GET", f"/api/programs/{program['id']}").status_code == 404


def test_validation_errors_are_clear(api):
    missing = api("POST", "/api/programs", {"language": "python"})
    assert missing.status_code == 422 and "name" in missing.text
    blank = api("POST", "/api/programs", {"name": "   ", "language": "python"})
    assert blank.status_code == 422
    too_long = "#" * 600_000
    huge = api("POST", "/api/programs", {"name": "x", "language": "python", "source": too_long})
    assert huge.status_code == 422 and "KB" in huge.text
    rename = api("POST", "/api/programs", {"name": "y", "language": "python"})
    clash = api("PUT", f"/api/programs/{rename.json()['id']}", {"name": "Compass"})
    assert clash.status_code == 409


def test_malformed_json_is_a_client_error(alice):
    _, token = ApiToken.issue(alice)
    response = Client().post(
        "/api/programs", "{nope", content_type="application/json",
        HTTP_AUTHORIZATION=f"Bearer {token}",
    )  # fmt: skip
    assert 400 <= response.status_code < 500


@pytest.mark.parametrize("body", ['"x"', "3", "[1]", "null"])
def test_a_body_that_is_not_an_object_is_refused(api, body):
    program = api("POST", "/api/programs", {"name": "b", "language": "python"}).json()
    # Every field of these is optional: without the check any JSON would do as {}.
    for method, path in [
        ("POST", f"/api/programs/{program['id']}/copy"),
        ("PUT", f"/api/programs/{program['id']}"),
        ("POST", f"/api/programs/{program['id']}/shares"),
    ]:
        response = api(method, path, body)
        assert response.status_code == 422, (path, response.content)
        assert "must be a JSON object" in response.text


def test_no_or_wrong_credentials(client):
    assert client.get("/api/programs").status_code == 401
    wrong = Client(HTTP_AUTHORIZATION="Bearer rt_nope").get("/api/programs")
    assert wrong.status_code == 401 and "Bearer" in wrong.json()["detail"]


def test_session_auth_needs_csrf_for_changes(alice):
    client = Client(enforce_csrf_checks=True)
    client.force_login(alice)
    assert client.get("/api/programs").status_code == 200
    body = {"name": "z", "language": "python"}
    response = client.post("/api/programs", body, content_type="application/json")
    assert response.status_code in (401, 403)
    assert not Program.objects.filter(name="z").exists()


def test_a_disabled_user_token_stops_working(api, alice):
    assert api("GET", "/api/programs").status_code == 200
    alice.is_active = False
    alice.save()
    assert api("GET", "/api/programs").status_code == 401


def test_only_staff_add_robots(api, alice):
    body = {"name": "r2", "url": "sim://"}
    assert api("POST", "/api/robots", body).status_code == 403
    alice.is_staff = True
    alice.save()
    bad = api("POST", "/api/robots", {"name": "r3", "url": "teleport://x"})
    assert bad.status_code == 422 and "sim://" in bad.text


def test_run_on_an_unknown_robot(api):
    program = api("POST", "/api/programs", {"name": "p", "language": "python"}).json()
    # No robot open to alice at all: she is told why, not that "ghost" is missing.
    response = api("POST", f"/api/programs/{program['id']}/run", {"robot": "ghost"})
    assert response.status_code == 409 and "Ask your teacher" in response.json()["detail"]
    Robot.objects.create(name="arm", url="sim://")  # open to everyone
    response = api("POST", f"/api/programs/{program['id']}/run", {"robot": "ghost"})
    assert response.status_code == 404 and "ghost" in response.json()["detail"]


def test_robot_settings_that_cannot_work_are_refused(api, alice):
    alice.is_staff = True
    alice.save()
    for settings in [
        {"max_linear": "fast"},
        {"limits": {"cpu_seconds": "lots"}},
        {"network": "wifi"},
        {"isolation": "none"},
        {"wheels": 6},
    ]:
        body = {"name": "r4", "url": "sim://", "settings": settings}
        response = api("POST", "/api/robots", body)
        assert response.status_code == 422, (settings, response.text)
    ok = api(
        "POST", "/api/robots", {"name": "r4", "url": "sim://", "settings": {"network": "none"}}
    )
    assert ok.status_code == 201
