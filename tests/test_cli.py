"""The robotide command: first start, second start, tokens."""

import getpass
import io
import os
import re
import shutil
import signal
import socket
import subprocess
import sys

import httpx
import pytest

from tests.appliance import (
    ROBOTIDE,
    SQLITE,
    START_TIMEOUT,
    free_port,
    migrated_sqlite,
    wait_for,
)

pytestmark = pytest.mark.usefixtures("keep_umask")


def start(data_dir, port, **env):
    environ = {k: v for k, v in os.environ.items() if k not in ("REDIS_URL", "DATABASE_URL")}
    environ.update(ROBOTIDE_DATA=str(data_dir), **env)
    if "ROBOTIDE_ADMIN_PASSWORD" not in env:
        environ.pop("ROBOTIDE_ADMIN_PASSWORD", None)
    return subprocess.Popen(
        [ROBOTIDE, "up", "--bind", f"127.0.0.1:{port}"],
        env=environ, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
    )  # fmt: skip


def serve_then_stop(data_dir, **env) -> str:
    port = free_port()
    proc = start(data_dir, port, **env)
    try:
        # A first start migrates a database from nothing: seconds when quiet, far more on a
        # busy machine. Only a start that fails waits out the deadline; one that ended says so.
        wait_for(lambda: httpx.get(f"http://127.0.0.1:{port}/accounts/login/").status_code == 200,
                 timeout=START_TIMEOUT, what="the first start's server",
                 gone=lambda: proc.poll() is not None)  # fmt: skip
        login = httpx.get(f"http://127.0.0.1:{port}/programs/")
        assert login.status_code == 302
    finally:
        proc.send_signal(signal.SIGTERM)
        output, _ = proc.communicate(timeout=START_TIMEOUT)
    assert proc.returncode == 0, output
    return output


def test_first_start_sets_up_everything_and_prints_the_password_once(tmp_path):
    first = serve_then_stop(tmp_path)
    password = re.search(r"password '([^']+)'", first).group(1)
    assert "user 'admin'" in first and "serving on http://127.0.0.1:" in first
    assert "robotide user password admin" in first  # how to set a new one when it is lost
    assert (tmp_path / "robotide.sqlite3").exists() and (tmp_path / "secret_key").exists()
    assert oct((tmp_path / "secret_key").stat().st_mode)[-3:] == "600"
    second = serve_then_stop(tmp_path)
    assert "password" not in second
    env = {**os.environ, "ROBOTIDE_DATA": str(tmp_path)}
    env.pop("REDIS_URL", None)
    env.pop("DATABASE_URL", None)
    token = subprocess.run([ROBOTIDE, "token", "admin"], env=env, capture_output=True, text=True)
    assert token.returncode == 0 and token.stdout.startswith("rt_")
    check = subprocess.run(
        [ROBOTIDE, "manage", "shell", "-c",
         "from django.contrib.auth import authenticate;"
         f"print(authenticate(username='admin', password={password!r}) is not None)"],
        env=env, capture_output=True, text=True,
    )  # fmt: skip
    assert check.stdout.splitlines()[-1] == "True"


def test_admin_password_from_the_environment(tmp_path):
    output = serve_then_stop(tmp_path, ROBOTIDE_ADMIN_PASSWORD="from-env-pass-1")
    assert "from-env-pass-1" not in output and "password" not in output


def test_token_for_an_unknown_user_fails_clearly(tmp_path):
    env = {**os.environ, "ROBOTIDE_DATA": str(tmp_path)}
    env.pop("REDIS_URL", None)
    env.pop("DATABASE_URL", None)
    shutil.copy(migrated_sqlite(), tmp_path / SQLITE)
    result = subprocess.run([ROBOTIDE, "token", "nobody"], env=env, capture_output=True, text=True)
    assert result.returncode == 2 and "no user named 'nobody'" in result.stderr


def test_bad_bind_is_refused(tmp_path):
    proc = start(tmp_path, "x")
    proc.wait(timeout=30)
    assert proc.returncode != 0 and "HOST:PORT" in proc.stdout.read()


def test_a_busy_port_is_said_with_how_to_choose_another(tmp_path):
    with socket.socket() as taken:  # another robotide, or another program
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        proc = start(tmp_path, port)
        output, _ = proc.communicate(timeout=START_TIMEOUT)
    assert proc.returncode == 1, output
    assert f"port {port} on 127.0.0.1 is already in use" in output, output
    assert f"make run BIND=127.0.0.1:{port + 1}" in output and "--bind" in output, output
    for noise in ("serving on", "Traceback", "Errno", "password"):
        assert noise not in output, output
    assert not (tmp_path / SQLITE).exists()  # said before anything is set up


@pytest.mark.django_db
def test_user_password_sets_a_password_a_login_then_accepts(monkeypatch, capsys):
    from django.contrib.auth.models import User

    from robotide.cli import main

    User.objects.create_user("admin", password="the-lost-one-123", is_superuser=True)
    monkeypatch.setattr(sys, "stdin", io.StringIO("found-again-4567\n"))
    assert main(["user", "password", "admin", "--password-stdin"]) == 0
    assert capsys.readouterr().out == "New password of 'admin' set\n"
    assert signed_in("admin", "found-again-4567") and not signed_in("admin", "the-lost-one-123")

    assert main(["user", "password", "admin", "--generate"]) == 0
    said = capsys.readouterr().out
    password = re.fullmatch(r"New password of 'admin': '(\S+)' \(shown once\)\n", said).group(1)
    assert signed_in("admin", password)

    typed = iter(["typed-at-the-terminal-1", "typed-at-the-terminal-1"])
    monkeypatch.setattr(getpass, "getpass", lambda prompt: next(typed))
    assert main(["user", "password", "admin"]) == 0
    assert signed_in("admin", "typed-at-the-terminal-1")

    typed = iter(["one-password-1234", "another-one-1234"])  # mistyped: nothing set
    assert main(["user", "password", "admin"]) == 2
    assert "differ" in capsys.readouterr().err
    assert signed_in("admin", "typed-at-the-terminal-1")
    assert main(["user", "password", "nobody", "--generate"]) == 2


def signed_in(username: str, password: str) -> bool:
    from django.test import Client

    client = Client()
    page = client.post("/accounts/login/", {"username": username, "password": password})
    return page.status_code == 302 and "_auth_user_id" in client.session


def test_the_server_raises_its_open_files_limit_to_what_the_system_allows():
    """systemd starts services with a soft limit of 1024 open files; every connection of every
    run and viewer is one of them."""
    code = (
        "import resource; from robotide.cli import open_files_as_allowed;"
        "open_files_as_allowed(); print(*resource.getrlimit(resource.RLIMIT_NOFILE))"
    )
    done = subprocess.run(
        ["prlimit", "--nofile=1024:4096", sys.executable, "-c", code],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    assert done.stdout.split() == ["4096", "4096"]
