"""`make run`'s first step on a fresh Debian machine, whose python3 has no venv module until
python3-venv is installed: as root scripts/install-run-deps.sh installs it (and what runs
need), as an ordinary user it says what to ask for and stops before the virtualenv fails.

The machine is made fresh in a bubblewrap sandbox: /usr/bin/python3 is a stand-in that cannot
import ensurepip until apt-get has installed python3-venv, and apt-get a stand-in that notes
what it was asked to install (nothing reaches Debian's archive).
"""

import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

from tests.conftest import in_ci

SCRIPT = Path(__file__).resolve().parents[1] / "scripts" / "install-run-deps.sh"
NOBODY = 65534

FAKE_PYTHON = """#!/bin/sh
# Debian's python3 without python3-venv: ensurepip and venv appear once it is "installed".
case "$*" in
*ensurepip*) [ -e "{state}/python3-venv" ] || exit 1 ;;
esac
exit 0
"""
FAKE_APT = """#!/bin/sh
echo "$@" >> "{state}/apt-get.log"
case "$*" in *install*python3-venv*) touch "{state}/python3-venv" ;; esac
exit 0
"""


@pytest.fixture
def fresh():
    if os.geteuid() != 0:
        if in_ci():
            pytest.fail("the fresh-machine test must run in CI, as root (bubblewrap)")
        pytest.skip("the fresh machine is made with bubblewrap as root")
    folder = Path(tempfile.mkdtemp(prefix="robotide-fresh-"))  # open to nobody, unlike pytest's
    state = folder / "state"
    state.mkdir()
    state.chmod(0o777)
    for name, text in (("python3", FAKE_PYTHON), ("apt-get", FAKE_APT)):
        (folder / name).write_text(text.format(state="/fresh-state"))
        (folder / name).chmod(0o755)
    shutil.copy(SCRIPT, folder / "install-run-deps.sh")
    folder.chmod(0o755)
    yield folder, state
    shutil.rmtree(folder)


def run_fresh(folder: Path, state: Path, *account: str) -> subprocess.CompletedProcess:
    bwrap = shutil.which("bwrap")
    assert bwrap, "bubblewrap is needed (scripts/install-test-deps.sh installs it)"
    argv = [
        bwrap, "--dev-bind", "/", "/",
        "--ro-bind", str(folder / "python3"), "/usr/bin/python3",
        "--ro-bind", str(folder / "apt-get"), "/usr/bin/apt-get",
        "--bind", str(state), "/fresh-state",
        "--", *account, "/bin/sh", str(folder / "install-run-deps.sh"), "/usr/bin/python3",
    ]  # fmt: skip
    env = {"PATH": "/usr/local/bin:/usr/bin:/bin", "HOME": "/"}
    return subprocess.run(argv, capture_output=True, text=True, timeout=60, env=env, cwd="/")


def test_as_root_the_venv_module_is_installed_first(fresh):
    folder, state = fresh
    done = run_fresh(folder, state)
    assert done.returncode == 0, done.stderr
    asked = (state / "apt-get.log").read_text()
    assert "install" in asked and "python3-venv" in asked, asked


def test_as_an_ordinary_user_it_says_what_to_ask_for_and_stops(fresh):
    folder, state = fresh
    nobody = ["setpriv", f"--reuid={NOBODY}", f"--regid={NOBODY}", "--clear-groups"]
    done = run_fresh(folder, state, *nobody)
    assert done.returncode == 1, done.stderr
    assert "apt-get install python3-venv" in done.stderr, done.stderr
    assert not (state / "apt-get.log").exists()  # not root: nothing installed


def test_as_an_ordinary_user_with_the_venv_module_it_says_a_few_lines_and_goes_on(fresh):
    """make run's one note to an ordinary user: a few plain lines, then the install goes on."""
    folder, state = fresh
    (state / "python3-venv").touch()  # the venv module there: nothing to ask for
    nobody = ["setpriv", f"--reuid={NOBODY}", f"--regid={NOBODY}", "--clear-groups"]
    done = run_fresh(folder, state, *nobody)
    assert done.returncode == 0, done.stderr
    lines = done.stderr.splitlines()
    assert lines[0].startswith("robotide: running as nobody, not root"), done.stderr
    assert len(lines) <= 3 and "make run' as root" in done.stderr, done.stderr
    assert not (state / "apt-get.log").exists()
