"""`make run` as a newcomer does it: a fresh clone of this repository (its committed HEAD), run
by an ordinary user, not root. What it installs is the appliance alone (nothing of the tests),
what it says is a few plain lines, and a port already in use is said as such, naming BIND=.

The clone's own Makefile and pyproject.toml install it, with pip from the package index as a
newcomer's would (the machine's pip configuration, not root's own). Most of the time is
unpacking ~400 MB of wheels (pymavlink, numpy, Django...): measured on two cores at a load of
12-17, 40-90 s; the test prints its own. The account is its own (not tests/e2e's
robotide-newcomer, whose test ends that account's processes when it starts).
"""

import os
import pwd
import shutil
import signal
import socket
import subprocess
import tempfile
import time
from pathlib import Path

import httpx
import pytest

from tests.appliance import START_TIMEOUT, free_port, wait_for

ROOT = Path(__file__).resolve().parents[1]
NEWCOMER = "robotide-first-run"
# How this machine reaches the package index, if through a proxy: a login would have it too.
PASSED_ON = ("http_proxy", "https_proxy", "no_proxy", "all_proxy", "HTTP_PROXY", "HTTPS_PROXY",
             "NO_PROXY", "SSL_CERT_FILE", "PIP_CERT", "PIP_INDEX_URL")  # fmt: skip
TEST_TOOLS = {"playwright", "pytest", "ruff", "schemathesis", "hypothesis", "daphne", "twisted"}
INSTALL_TIMEOUT = 900  # s: a cold install on a loaded machine; only a hung one waits it out


@pytest.fixture
def newcomer():
    """How to run a command as an ordinary user (as root: an account made for it, kept between
    runs) and that user's home."""
    if os.geteuid() != 0:
        return [], Path.home()
    try:
        account = pwd.getpwnam(NEWCOMER)
    except KeyError:
        subprocess.run(["useradd", "--create-home", "--shell", "/bin/sh", NEWCOMER], check=True)
        account = pwd.getpwnam(NEWCOMER)
    return ["runuser", "-u", NEWCOMER, "--"], Path(account.pw_dir)


@pytest.fixture
def clone(newcomer):
    runner, home = newcomer
    folder = Path(tempfile.mkdtemp(prefix="make-run-", dir=home))
    repo = folder / "robotide"
    # --no-hardlinks: the clone is given to the newcomer, and must share no file with this one.
    subprocess.run(["git", "clone", "-q", "--no-hardlinks", str(ROOT), str(repo)], check=True)
    if runner:
        subprocess.run(["chown", "-R", f"{NEWCOMER}:{NEWCOMER}", str(folder)], check=True)
    yield repo
    shutil.rmtree(folder, ignore_errors=True)


def as_newcomer(newcomer, repo: Path, *argv: str) -> list[str]:
    runner, home = newcomer
    # A login's environment, not this test process' (no venv, no CI's or pytest's variables).
    environment = ["PATH=/usr/local/bin:/usr/bin:/bin", f"HOME={home}", "LANG=C.UTF-8"]
    environment += [f"{name}={os.environ[name]}" for name in PASSED_ON if name in os.environ]
    return [*runner, "env", "-i", *environment, *argv]


def test_make_run_in_a_fresh_clone_as_an_ordinary_user(newcomer, clone):
    with socket.socket() as taken:  # another program on the port
        taken.bind(("127.0.0.1", 0))
        taken.listen()
        port = taken.getsockname()[1]
        started = time.monotonic()
        first = subprocess.run(
            as_newcomer(newcomer, clone, "make", "run", f"BIND=127.0.0.1:{port}"),
            cwd=clone, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
            timeout=INSTALL_TIMEOUT,
        )  # fmt: skip
        print(f"make run, fresh clone, installing: {time.monotonic() - started:.0f} s")
    said = first.stdout
    assert first.returncode != 0, said
    assert f"port {port} on 127.0.0.1 is already in use" in said, said
    assert "make run BIND=127.0.0.1:" in said, said
    for noise in ("serving on", "Traceback", "Errno", "BuildBackendWarning", "Editable install"):
        assert noise not in said, said
    # What it does, one line each (virtualenv, install), the rootless box's note (three), the
    # busy port (two) and make's own error line.
    assert len(said.splitlines()) <= 9, said
    assert "runtime only" in said, said

    names = subprocess.run(
        [str(clone / ".venv/bin/python"), "-c",
         "import importlib.metadata as m;"
         "print('\\n'.join(d.metadata['Name'].lower() for d in m.distributions()))"],
        capture_output=True, text=True, check=True,
    ).stdout.split()  # fmt: skip
    assert {"robotide", "django", "uvicorn"} <= set(names)
    assert not TEST_TOOLS & set(names), TEST_TOOLS & set(names)

    # Again on a free port: nothing more to install, the server up, and the admin's password
    # line says how to set a new one.
    port = free_port()
    started = time.monotonic()
    server = subprocess.Popen(
        as_newcomer(newcomer, clone, "make", "run", f"BIND=127.0.0.1:{port}"),
        cwd=clone, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
        start_new_session=True,
    )  # fmt: skip
    try:
        wait_for(
            lambda: httpx.get(f"http://127.0.0.1:{port}/accounts/login/").status_code == 200,
            timeout=START_TIMEOUT, what="make run's server", gone=lambda: server.poll() is not None,
        )  # fmt: skip
        print(f"make run again, installed: serving after {time.monotonic() - started:.0f} s")
    finally:
        os.killpg(server.pid, signal.SIGTERM)
        said, _ = server.communicate(timeout=START_TIMEOUT)
    assert "installing" not in said and "creating" not in said, said
    assert f"robotide serving on http://127.0.0.1:{port}/" in said, said
    assert "user password admin" in said, said
