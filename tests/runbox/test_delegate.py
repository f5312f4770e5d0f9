"""runbox.delegate: a robotide that is not root asks the user's systemd for a cgroup of its own.

Here (a container: no systemd, no user manager) an ordinary user's robotide is given none and
stays where it is, its runs bounded per process (tests/runbox/test_rootless_bounds.py). The
path where the user's systemd answers is not tested: no machine this suite runs on has one,
and a test that can only be skipped here would be skipped in CI.
"""

import json
import os
import subprocess

import pytest

from runbox.delegate import DELEGATED, delegated_command
from tests.runbox.test_box import NOBODY, ROOT, readable_copy  # noqa: F401 (a fixture)

ASK = """
import json, sys
sys.path.insert(0, {code!r})
from runbox.cgroups import detect
from runbox.delegate import delegated_command
print(json.dumps({{"command": delegated_command(), "cgroups": detect().available,
                   "why": detect().why}}))
"""


def ask(code, *, as_nobody: bool) -> dict:
    argv = ["/usr/bin/python3", "-c", ASK.format(code=str(code))]
    if as_nobody:
        argv = ["setpriv", f"--reuid={NOBODY}", f"--regid={NOBODY}", "--clear-groups", *argv]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=60, cwd="/")
    assert done.returncode == 0, done.stderr
    return json.loads(done.stdout)


def user_manager_answers() -> bool:
    probe = ["systemd-run", "--user", "--scope", "--quiet", "-p", "Delegate=yes", "/bin/true"]
    try:
        return subprocess.run(probe, capture_output=True, timeout=10).returncode == 0
    except OSError:
        return False


@pytest.mark.skipif(os.geteuid() != 0, reason="becomes `nobody`: run as root")
def test_root_and_a_user_without_a_user_manager_stay_where_they_are(readable_copy):  # noqa: F811
    assert ask(readable_copy, as_nobody=False)["command"] is None  # root makes its cgroups
    if user_manager_answers():
        pytest.fail("this machine's systemd answers: this test is for machines without one")
    said = ask(readable_copy, as_nobody=True)
    assert said["command"] is None and not said["cgroups"], said
    assert said["why"].startswith("robotide is not root and cannot write to"), said
    assert delegated_command({DELEGATED: "1"}) is None  # in its scope: never again
