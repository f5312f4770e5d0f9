"""A websocket's user and language through the whole application (robotide.asgi): read from the
session in the consumer's own first trip to a worker thread (robotide.ws_user), checked as
Django checks a page's, and in the account's language."""

import asgiref.sync
import pytest
from channels.db import database_sync_to_async
from channels.testing import WebsocketCommunicator
from django.contrib.auth.models import User
from django.test import Client

from programs.models import Program, Run
from robotide.asgi import application
from robotide.models import LanguagePreference
from robots.models import Robot

pytestmark = pytest.mark.django_db(transaction=True)


@database_sync_to_async
def signed_in(name: str, language: str | None = None) -> tuple[User, bytes]:
    """A user with (optionally) a stored language, signed in: their session cookie."""
    user = User.objects.create_user(name)
    if language:
        LanguagePreference.objects.create(user=user, language=language)
    client = Client()
    client.force_login(user)  # sign-in keeps the account's language in the session
    return user, f"sessionid={client.cookies['sessionid'].value}".encode()


@database_sync_to_async
def run_of(user, log: bytes = b"o hello\n") -> Run:
    robot, _ = Robot.objects.get_or_create(name="sim", defaults={"url": "sim://"})
    program = Program.objects.create(owner=user, name=f"p{Program.objects.count()}")
    run = Run.create_for(program, robot, user)
    run.log_path.parent.mkdir(parents=True, exist_ok=True)
    run.log_path.write_bytes(log)
    return run


def page(path: str, cookie: bytes | None = None, language: bytes = b"en"):
    headers = [(b"host", b"testserver"), (b"origin", b"http://testserver")]
    headers += [(b"accept-language", language)] + ([(b"cookie", cookie)] if cookie else [])
    return WebsocketCommunicator(application, path, headers=headers)


async def status_of(comm) -> str:
    connected, code = await comm.connect()
    assert connected, code
    lines = await comm.receive_from()
    status = await comm.receive_from()
    await comm.disconnect()
    assert 'id="log-lines"' in lines and 'id="run-status"' in status
    return status


async def test_a_run_page_gets_its_first_lines_after_one_trip_to_a_worker_thread(monkeypatch):
    """Fails with channels' AuthMiddlewareStack: it reads the user in a trip of its own."""
    alice, cookie = await signed_in("alice")
    run = await run_of(alice)
    trips = []
    real = asgiref.sync.SyncToAsync.__call__

    async def counted(self, *args, **kwargs):
        trips.append(getattr(self.func, "__name__", repr(self.func)))
        return await real(self, *args, **kwargs)

    monkeypatch.setattr(asgiref.sync.SyncToAsync, "__call__", counted)
    comm = page(f"/ws/runs/{run.pk}/", cookie)
    assert (await comm.connect())[0]
    assert "hello" in await comm.receive_from()
    # Before the lines: the consumer's own trip alone (no_op is the test harness's).
    before_lines = trips[: trips.index("seen") + 1] if "seen" in trips else trips
    assert [name for name in before_lines if name != "no_op"] == ["seen"], trips
    await comm.disconnect()


async def test_the_accounts_language_wins_over_the_browsers():
    bia, cookie = await signed_in("bia", language="pt-br")
    run = await run_of(bia)
    assert ">iniciando<" in await status_of(page(f"/ws/runs/{run.pk}/", cookie, b"en"))


async def test_without_an_accounts_language_the_browsers_is_used():
    caio, cookie = await signed_in("caio")
    run = await run_of(caio)
    assert ">iniciando<" in await status_of(page(f"/ws/runs/{run.pk}/", cookie, b"pt-BR"))
    assert ">starting<" in await status_of(page(f"/ws/runs/{run.pk}/", cookie, b"en"))


async def test_no_session_or_someone_elses_run_is_refused():
    dora, _ = await signed_in("dora")
    _, eve_cookie = await signed_in("eve")
    run = await run_of(dora)
    for cookie in (None, eve_cookie, b"sessionid=forged"):
        comm = page(f"/ws/runs/{run.pk}/", cookie)
        connected, code = await comm.connect()
        assert (connected, code) == (False, 4404), cookie
    connected, code = await page("/ws/runs/").connect()
    assert (connected, code) == (False, 4401)


async def test_a_session_from_before_a_password_change_is_no_longer_signed_in():
    """As Django checks a page's session: its hash of the password no longer matches."""
    fay, cookie = await signed_in("fay")
    run = await run_of(fay)
    assert (await page(f"/ws/runs/{run.pk}/", cookie).connect())[0]

    @database_sync_to_async
    def change_password():
        fay.set_password("a-new-secret-123")
        fay.save()

    await change_password()
    connected, code = await page(f"/ws/runs/{run.pk}/", cookie).connect()
    assert (connected, code) == (False, 4404)


async def test_every_page_websocket_reads_its_user():
    """Each consumer reads the lazy user in a worker thread (on the event loop Django would
    refuse the query), and speaks the account's language."""
    gil, cookie = await signed_in("gil", language="pt-br")
    run = await run_of(gil)
    for path in ("/ws/runs/", f"/ws/programs/{run.program_id}/console/"):
        comm = page(path, cookie)
        connected, code = await comm.connect()
        assert connected, (path, code)
        await comm.disconnect()
    comm = page("/ws/robots/sim/", cookie)
    assert (await comm.connect())[0]
    running = await comm.receive_from()  # the robot's running programs: gil's, starting
    assert f"#{run.pk}" in running and ">iniciando<" in running
    await comm.disconnect()
