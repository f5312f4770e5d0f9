"""A run websocket's pass: given with what showed the viewer the run, good for that browser
session, that run and ACCESS_STANDS_SECONDS only."""

from urllib.parse import parse_qs, urlsplit

import pytest
from django.contrib.auth.models import User
from django.test import Client

from programs import watch_pass
from programs.models import Program, Run
from robotide.models import ApiToken
from robots.models import Robot

pytestmark = pytest.mark.django_db


@pytest.fixture
def run():
    alice = User.objects.create_user("alice", password="pw-alice-123")
    robot = Robot.objects.create(name="sim", url="sim://")
    program = Program.objects.create(owner=alice, name="Stop at the wall", language="python")
    return Run.create_for(program, robot, alice)


def signed_in(user) -> Client:
    client = Client(enforce_csrf_checks=True)
    client.force_login(user)
    return client


def pass_of(live: str) -> str | None:
    return parse_qs(urlsplit(live).query).get("pass", [None])[0]


def test_a_pass_names_its_run_and_how_its_lines_are_shown(run):
    given = watch_pass.read(watch_pass.give(run, "session-a"), run.pk, "session-a")
    assert (given.run_id, given.language, given.program_name) == (
        run.pk,
        "python",
        run.program_name,
    )
    assert 0 <= given.age < 1


def test_a_pass_is_for_its_session_and_its_run_only(run):
    text = watch_pass.give(run, "session-a")
    assert watch_pass.read(text, run.pk, "session-b") is None
    assert watch_pass.read(text, run.pk + 1, "session-a") is None
    assert watch_pass.read(text, run.pk, None) is None


def test_a_pass_names_no_session_key(run):
    assert "session-a" not in str(watch_pass.signing.loads(watch_pass.give(run, "session-a"),
                                                           salt=watch_pass.SALT))  # fmt: skip


def test_a_changed_or_made_up_pass_is_none(run):
    text = watch_pass.give(run, "session-a")
    payload, _, signature = text.rpartition(":")
    assert watch_pass.read(payload + ":" + signature[::-1], run.pk, "session-a") is None
    other = watch_pass.signing.dumps([run.pk, "python", "p", "x", 0.0], salt="another")
    assert watch_pass.read(other, run.pk, "session-a") is None
    assert watch_pass.read("garbage", run.pk, "session-a") is None


def test_a_pass_stands_as_long_as_any_access_read(run, monkeypatch):
    text = watch_pass.give(run, "session-a")
    now = watch_pass.time.time()
    later = now + watch_pass.ACCESS_STANDS_SECONDS + 0.01
    monkeypatch.setattr(watch_pass.time, "time", lambda: later)
    assert watch_pass.read(text, run.pk, "session-a") is None
    monkeypatch.setattr(watch_pass.time, "time", lambda: now - 60)  # from the future
    assert watch_pass.read(text, run.pk, "session-a") is None


def test_the_api_gives_a_signed_in_session_its_pass(run):
    alice = run.owner
    client = signed_in(alice)
    live = client.get(f"/api/runs/{run.pk}").json()["live"]
    assert live.startswith(f"/ws/runs/{run.pk}/?pass=")
    assert watch_pass.read(pass_of(live), run.pk, client.session.session_key) is not None


def test_a_token_gets_no_pass_even_with_another_users_cookie(run):
    """A token's request with somebody's session cookie: a pass for that session would let
    its holder watch what only the token's user may."""
    bob = User.objects.create_user("bob")
    client = signed_in(bob)
    _, token = ApiToken.issue(run.owner)
    answer = client.get(f"/api/runs/{run.pk}", HTTP_AUTHORIZATION=f"Bearer {token}").json()
    assert answer["live"] == f"/ws/runs/{run.pk}/"


def test_the_run_page_opens_its_websocket_with_its_pass_and_offset(run):
    run.log_path.parent.mkdir(parents=True)
    run.log_path.write_bytes(b"o hello\n")
    client = signed_in(run.owner)
    page = client.get(f"/runs/{run.pk}/").content.decode()
    live = page.split('ws-connect="', 1)[1].split('"', 1)[0].replace("&amp;", "&")
    query = parse_qs(urlsplit(live).query)
    assert query["from"] == ["8"]
    assert watch_pass.read(query["pass"][0], run.pk, client.session.session_key) is not None
