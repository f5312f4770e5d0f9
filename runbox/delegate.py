"""A cgroup for a robotide that is not root: systemd's user manager delegates one (no Django).

An ordinary user cannot write the machine's cgroups, so its runs are bounded per process only,
one at a time (runbox.isolation says so on the robot page). Where the user's own systemd runs
(a desktop session, or `loginctl enable-linger`), it hands out a cgroup v2 subtree: the server
(or agent) starts itself again in a transient scope with Delegate=yes, and
runbox.cgroups.detect() there finds its own cgroup writable, with the controllers the user
manager has (Debian: memory, pids, cpu), as under a system unit with Delegate=yes. Each run
then gets its cgroup, and all runs their parent (runbox.share).

    argv = delegated_command()   # None: root, delegated already, or no user manager answers
    if argv:
        os.execve(argv[0], argv, {**os.environ, DELEGATED: "1"})
"""

import os
import pwd
import shutil
import subprocess
import sys
from pathlib import Path

from runbox import SYSTEM_PATH
from runbox.cgroups import detect

DELEGATED = "ROBOTIDE_DELEGATED"  # set in the scope: never a scope within a scope
PROBE_TIMEOUT = 10.0


def outlives_the_session(env) -> bool:
    """A scope of the user's systemd ends with their last session unless they linger: a
    `make run` left running over ssh would die at logout. Moved there only then, or when
    asked (ROBOTIDE_DELEGATE=1)."""
    if env.get("ROBOTIDE_DELEGATE") == "1":
        return True
    return Path("/var/lib/systemd/linger", pwd.getpwuid(os.geteuid()).pw_name).exists()


def delegated_command(env: dict | None = None) -> list[str] | None:
    """This process's command line, run in a scope of the user's systemd with a cgroup
    delegated to it; None where that is not needed or not to be had."""
    env = os.environ if env is None else env
    if os.geteuid() == 0 or env.get(DELEGATED) or detect().available:
        return None
    systemd_run = shutil.which("systemd-run", path=SYSTEM_PATH)
    if systemd_run is None or not outlives_the_session(env):
        return None
    scope = [systemd_run, "--user", "--scope", "--quiet", "-p", "Delegate=yes", "--"]
    try:  # without a user manager (no session, a container) it says so at once
        probe = subprocess.run([*scope, "/bin/true"], capture_output=True, timeout=PROBE_TIMEOUT)
    except (OSError, subprocess.TimeoutExpired):
        return None
    if probe.returncode != 0:
        return None
    return [*scope, sys.executable, *sys.orig_argv[1:]]
