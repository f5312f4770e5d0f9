"""Programs sent out: by e-mail (Django's locmem outbox) and pushed to a second, real robotide
over HTTP on 127.0.0.1, through the API and the program page's forms."""

import smtplib
import socket
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer

import pytest
from django.contrib.auth.models import User
from django.core import mail
from django.core.cache import cache
from django.core.mail.backends.base import BaseEmailBackend
from django.template.loader import render_to_string
from django.test import Client

from programs import outbound
from programs.models import Program
from robotide.models import ApiToken
from tests.appliance import Appliance, free_port

pytestmark = pytest.mark.django_db

SOURCE = "print('hello')\n"


@pytest.fixture(autouse=True)
def _fresh_counters():
    cache.clear()  # the hourly allowances
    yield
    cache.clear()


@pytest.fixture(autouse=True)
def _lab_on_loopback(settings):
    # The second robotide and the servers here listen on 127.0.0.1: a lab's own, allowed.
    settings.PUSH_ALLOW = ["127.0.0.1"]


@pytest.fixture
def alice():
    return User.objects.create_user(
        "alice", email="alice@example.org", password="pw-alice-123", first_name="Alice"
    )


@pytest.fixture
def bob():
    return User.objects.create_user("bob", password="pw-bob-123")


@pytest.fixture
def program(alice):
    program = Program.objects.create(owner=alice, name="hello", language="python")
    program.save_source(SOURCE, alice)
    return program


def api_for(user):
    _, token = ApiToken.issue(user)
    client = Client(HTTP_AUTHORIZATION=f"Bearer {token}")

    def call(method, path, body=None):
        return getattr(client, method.lower())(path, body, content_type="application/json")

    return call


@pytest.fixture
def api(alice):
    return api_for(alice)


def email(api, program, to="b@example.org"):
    return api("POST", f"/api/programs/{program.pk}/email", {"to": to})


# -- e-mail ---------------------------------------------------------------------------------------


def test_it_mails_the_source_attached_saying_who_sent_it_from_where(api, program, settings):
    settings.DEFAULT_FROM_EMAIL = "lab@example.org"
    response = api("POST", f"/api/programs/{program.pk}/email", {"to": " bob@example.org "})
    assert response.status_code == 200, response.content
    assert response.json() == {"to": "bob@example.org", "attachment": "hello.py"}
    [sent] = mail.outbox
    assert sent.to == ["bob@example.org"] and sent.from_email == "lab@example.org"
    assert sent.reply_to == ["alice@example.org"]
    assert "hello" in sent.subject and "alice" in sent.subject
    assert "Alice (alice) <alice@example.org>" in sent.body
    assert "http://testserver/" in sent.body and "hello.py" in sent.body
    assert sent.attachments == [("hello.py", SOURCE, "text/plain")]


def test_the_attachment_has_the_languages_extension(api, alice):
    shell = Program.objects.create(owner=alice, name="Wall & turn", language="shell")
    shell.save_source("robot stop\n", alice)
    assert email(api, shell).status_code == 200
    assert mail.outbox[0].attachments == [("wall-turn.sh", "robot stop\n", "text/plain")]


@pytest.mark.parametrize(
    "to", ["not an address", "a@b", "bob@example.org, eve@example.org", "x@example.org\nBcc: e@f.g"]
)
def test_it_refuses_what_is_not_one_address(api, program, to):
    response = api("POST", f"/api/programs/{program.pk}/email", {"to": to})
    assert response.status_code == 422 and "not an e-mail address" in response.json()["detail"]
    assert mail.outbox == []


def test_it_limits_mails_per_user_and_hour(api, program, bob, settings):
    settings.EMAIL_PER_HOUR = 2
    for _ in range(2):
        assert email(api, program).status_code == 200
    third = email(api, program)
    assert third.status_code == 429 and "at most 2 e-mails an hour" in third.json()["detail"]
    assert len(mail.outbox) == 2
    bobs = Program.objects.create(owner=bob, name="bobs", language="python")
    assert email(api_for(bob), bobs).status_code == 200


def test_it_can_be_turned_off(api, program, settings):
    settings.EMAIL_PER_HOUR = 0
    response = email(api, program)
    assert response.status_code == 403 and "turned off" in response.json()["detail"]


def test_a_mail_server_that_is_down_is_a_clear_503(api, program, settings):
    port = free_port()  # nothing listens there
    settings.EMAIL_BACKEND = "django.core.mail.backends.smtp.EmailBackend"
    settings.EMAIL_HOST, settings.EMAIL_PORT, settings.EMAIL_PER_HOUR = "127.0.0.1", port, 1
    response = email(api, program)
    assert response.status_code == 503
    assert f"mail server (127.0.0.1:{port}) cannot be reached" in response.json()["detail"]
    # A mail that did not go does not count against the hour's allowance.
    again = email(api, program)
    assert again.status_code == 503


class RefusingBackend(BaseEmailBackend):
    def send_messages(self, messages):
        to = messages[0].to[0]
        raise smtplib.SMTPRecipientsRefused({to: (550, b"5.1.1 no such mailbox")})


def test_a_mail_server_that_refuses_is_a_clear_502(api, program, settings):
    settings.EMAIL_BACKEND = f"{__name__}.RefusingBackend"
    response = email(api, program)
    assert response.status_code == 502
    assert response.json()["detail"] == (
        "The mail server refused the mail: 550 5.1.1 no such mailbox."
    )


def test_only_programs_one_may_see_are_mailed(program, bob):
    response = email(api_for(bob), program)
    assert response.status_code == 404 and mail.outbox == []


def test_the_page_form_mails_and_says_so(client, alice, program):
    client.force_login(alice)
    response = client.post(f"/programs/{program.pk}/email", {"to": "bob@example.org"}, follow=True)
    assert "Sent hello to bob@example.org." in response.content.decode()
    assert mail.outbox[0].attachments[0][0] == "hello.py"
    refused = client.post(f"/programs/{program.pk}/email", {"to": "nope"}, follow=True)
    assert "is not an e-mail address" in refused.content.decode() and len(mail.outbox) == 1


def test_the_forms_render_with_their_actions(rf, alice, program):
    request = rf.get("/")
    request.user = alice
    email = render_to_string("programs/_email.html", {"program": program}, request)
    push = render_to_string("programs/_push.html", {"program": program}, request)
    assert f'action="/programs/{program.pk}/email"' in email and "csrfmiddlewaretoken" in email
    assert f'action="/programs/{program.pk}/push"' in push and 'type="password"' in push


# -- origin, as a receiver records it ------------------------------------------------------------


def test_a_created_program_keeps_its_origin_on_one_line(api, alice):
    origin = "pushed from http://a:8000\n by \x1b[31mmallory\x00 " + "x" * 500
    body = {"name": "o", "language": "python", "origin": origin}
    assert api("POST", "/api/programs", body).status_code == 201
    stored = Program.objects.get(owner=alice, name="o").origin
    assert stored.startswith("pushed from http://a:8000 by [31mmallory x") and len(stored) == 300
    assert api("POST", "/api/programs", {"name": "p", "language": "python"}).status_code == 201
    assert Program.objects.get(owner=alice, name="p").origin == ""


# -- push to a second robotide --------------------------------------------------------------------


@pytest.fixture(scope="module")
def remote(tmp_path_factory):
    """Another robotide on 127.0.0.1 that takes requests of at most 16 KB."""
    app = Appliance(tmp_path_factory.mktemp("remote"), extra_env={"ROBOTIDE_MAX_REQUEST_KB": "16"})
    app.start()
    app.carol = app.new_user("carol")
    yield app
    app.stop()


def remote_origin(remote, program_id: int) -> str:
    code = f"from programs.models import Program as P; print(P.objects.get(pk={program_id}).origin)"
    return remote.cli("manage", "shell", "--no-imports", "-c", code).strip()


def test_a_pushed_program_arrives_with_its_origin_under_the_tokens_account(api, program, remote):
    body = {"url": remote.url + "/", "token": remote.carol}
    response = api("POST", f"/api/programs/{program.pk}/push", body)
    assert response.status_code == 200, response.content
    arrived = response.json()
    assert arrived["url"] == remote.url and arrived["owner"] == "carol"
    assert arrived["name"] == "hello"
    there = remote.api("GET", f"/api/programs/{arrived['id']}", token=remote.carol).json()
    assert there["source"] == SOURCE and there["language"] == "python"
    assert remote_origin(remote, arrived["id"]) == "pushed from http://testserver by alice"
    # The same name again: it arrives as "hello (2)", the first one untouched.
    again = api("POST", f"/api/programs/{program.pk}/push", body).json()
    assert again["name"] == "hello (2)" and again["id"] != arrived["id"]


def test_a_wrong_token_is_refused_by_the_remote(api, program, remote):
    body = {"url": remote.url, "token": "rt_not-a-token"}
    response = api("POST", f"/api/programs/{program.pk}/push", body)
    assert response.status_code == 502
    assert response.json()["detail"].startswith(f"The token was refused by {remote.url}:")


def test_a_program_too_large_for_the_remote(api, alice, remote):
    big = Program.objects.create(owner=alice, name="big", language="python")
    big.save_source("# " + "x" * 20_000 + "\n", alice)
    response = api("POST", f"/api/programs/{big.pk}/push", {"url": remote.url, "token": "t"})
    assert response.status_code == 502
    too_large = f"The program is too large for the robotide at {remote.url}."
    assert response.json()["detail"] == too_large


def test_an_unreachable_robotide(api, program):
    url = f"http://127.0.0.1:{free_port()}"
    response = api("POST", f"/api/programs/{program.pk}/push", {"url": url, "token": "t"})
    assert response.status_code == 502
    assert response.json()["detail"] == f"{url} is not reachable."


def test_a_robotide_that_does_not_answer_in_time(api, program, monkeypatch):
    monkeypatch.setattr(outbound, "PUSH_TIMEOUT", 0.3)
    with socket.socket() as silent:  # takes connections into its backlog, never answers
        silent.bind(("127.0.0.1", 0))
        silent.listen()
        url = f"http://127.0.0.1:{silent.getsockname()[1]}"
        response = api("POST", f"/api/programs/{program.pk}/push", {"url": url, "token": "t"})
    assert response.status_code == 504
    assert response.json()["detail"] == f"{url} is not reachable: no answer within 0.3 s."


@pytest.fixture
def stranger():
    """A web server that is no robotide: it redirects /api/programs and knows nothing else."""
    seen = []

    class Handler(BaseHTTPRequestHandler):
        def do_POST(self):
            seen.append((self.path, self.headers.get("Authorization")))
            self.rfile.read(int(self.headers.get("Content-Length") or 0))
            if self.path.startswith("/moved"):
                self.send_response(307)
                self.send_header("Location", f"http://127.0.0.1:{port}/elsewhere/api/programs")
            else:
                self.send_response(404)
            self.send_header("Content-Length", "0")
            self.end_headers()

        def log_message(self, *args):
            pass

    server = ThreadingHTTPServer(("127.0.0.1", 0), Handler)
    port = server.server_address[1]
    threading.Thread(target=server.serve_forever, args=(0.05,), daemon=True).start()
    server.seen, server.url = seen, f"http://127.0.0.1:{port}"
    yield server
    server.shutdown()
    server.server_close()


def test_a_redirect_is_not_followed_and_the_token_not_sent_on(api, program, stranger):
    url = stranger.url + "/moved"
    response = api("POST", f"/api/programs/{program.pk}/push", {"url": url, "token": "secret"})
    assert response.status_code == 502
    # Where it points is not told: an answer that is not a robotide's says nothing of itself.
    detail = response.json()["detail"]
    assert detail.startswith(f"{url} is not a robotide") and "elsewhere" not in detail
    assert stranger.seen == [("/moved/api/programs", "Bearer secret")]


def test_a_server_that_is_no_robotide(api, program, stranger):
    body = {"url": stranger.url, "token": "t"}
    response = api("POST", f"/api/programs/{program.pk}/push", body)
    assert response.status_code == 502
    assert response.json()["detail"].startswith(f"{stranger.url} is not a robotide")


@pytest.mark.parametrize(
    "url", ["ftp://127.0.0.1/", "file:///etc/passwd", "127.0.0.1:8000", "http://", "http://a b",
            "http://127.0.0.1:port", "http://user:pw@127.0.0.1:8000"],
)  # fmt: skip
def test_only_http_addresses(api, program, url):
    response = api("POST", f"/api/programs/{program.pk}/push", {"url": url, "token": "t"})
    assert response.status_code == 422, response.content


def test_pushes_are_limited_per_hour(api, program, monkeypatch):
    monkeypatch.setattr(outbound, "PUSHES_PER_HOUR", 1)
    body = {"url": f"http://127.0.0.1:{free_port()}", "token": "t"}
    assert api("POST", f"/api/programs/{program.pk}/push", body).status_code == 502
    assert api("POST", f"/api/programs/{program.pk}/push", body).status_code == 429


def test_the_page_form_pushes_and_says_where_it_went(client, alice, program, remote):
    client.force_login(alice)
    form = {"url": remote.url, "token": remote.carol}
    page = client.post(f"/programs/{program.pk}/push", form, follow=True).content.decode()
    assert f"Pushed hello to {remote.url}:" in page and "of carol there" in page
    form["token"] = "wrong"
    page = client.post(f"/programs/{program.pk}/push", form, follow=True).content.decode()
    assert "The token was refused by" in page
