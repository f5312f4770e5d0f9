import functools
import os
import re
import threading
from pathlib import Path

import pytest
from django.utils import translation
from hypothesis import HealthCheck, settings

from tests.appliance import Appliance

# Hypothesis's 200 ms deadline for an example, and its health check of slow data generation,
# are timings: on a busy machine (a load of 10-20 on two cores) they fail correct code.
settings.register_profile("robotide", deadline=None, suppress_health_check=[HealthCheck.too_slow])
settings.load_profile("robotide")

# The `agent` fixture: a real Robot API server for tests of the API and its clients.
pytest_plugins = ["tests.robot_api_server"]


@pytest.fixture
def keep_umask():
    """robotide.cli.main() tightens the process' umask for what the server writes: put back
    for the other tests."""
    umask = os.umask(0o022)
    os.umask(umask)
    yield
    os.umask(umask)


@pytest.fixture(autouse=True)
def _test_settings(settings, tmp_path):
    # A data folder of its own: what the agent names after it (its runs' accounts, its
    # cgroups) is not another test process's, whose run 3 is not this one's.
    settings.DATA_DIR = tmp_path
    settings.RUNS_DIR = tmp_path / "runs"
    settings.PASSWORD_HASHERS = ["django.contrib.auth.hashers.MD5PasswordHasher"]
    # Any free port: tests run side by side, and never listen beyond loopback.
    settings.GATEWAY_DEFAULTS = {"gcs": "127.0.0.1:0", "programs": "127.0.0.1:0"}
    # Fair shares (robots.fair_shares) off for tests of other things, which run a user's
    # programs side by side as they please; tests of the shares set their own limits.
    settings.RUNS_PER_USER = settings.RUNS_PER_STAFF = 0
    yield
    # A page asked in Portuguese leaves the language active in this thread's context, which
    # the next async test's tasks copy (an in-process agent's run reasons then said in pt-BR).
    translation.deactivate()


@pytest.fixture
def held_claim(monkeypatch):
    """An in-process agent's Run.claim waits until the test sets this event, then asks the
    database as it would have: its program is up before the answer."""
    from programs.models import Run

    let_go = threading.Event()
    claim = Run.claim

    def held(run_id, **how):
        let_go.wait(30)
        return claim(run_id, **how)

    monkeypatch.setattr(Run, "claim", held)
    yield let_go
    let_go.set()


@pytest.fixture(scope="module")
def appliance(tmp_path_factory):
    app = Appliance(tmp_path_factory.mktemp("appliance")).start()
    yield app
    app.stop()


@pytest.fixture(scope="module", params=["embedded", "split"])
def any_appliance(request, tmp_path_factory):
    """The same end-to-end tests, once per deployment mode."""
    app = Appliance(tmp_path_factory.mktemp(request.param), mode=request.param)
    app.start()
    yield app
    app.stop()


# How the suite splits over several test processes (`make test`: pytest-xdist). A module whose
# tests share an appliance (a module-scoped server, 4-25 s to start) goes whole to one process:
# split, each process would start its own. So do the modules that share something of the
# machine's (one OS account and its clone, a fleet's servers made once for the module). Every
# other test goes wherever a process is free. pytest-xdist's own xdist_group marks do nothing
# with pytest 9.2 (its node ids changed), hence this.
TOGETHER = {
    "tests/e2e/test_ordinary_user.py",
    "tests/fleet/test_fleet.py",
    "tests/fleet/test_passwords.py",
}
SHARES_A_SERVER = re.compile(r"\b(any_)?appliance\b|\bAppliance\(")


@functools.cache
def kept_together(module: str) -> bool:
    if module in TOGETHER:
        return True
    path = Path(__file__).parent.parent / module
    return path.is_file() and bool(SHARES_A_SERVER.search(path.read_text()))


@pytest.hookimpl(optionalhook=True)
def pytest_xdist_make_scheduler(config, log):
    from xdist.scheduler import LoadScopeScheduling

    class SomeModulesTogether(LoadScopeScheduling):
        def _split_scope(self, nodeid: str) -> str:
            module = nodeid.split("::", 1)[0]
            return module if kept_together(module) else nodeid

    return SomeModulesTogether(config, log)


def in_ci() -> bool:
    return os.environ.get("CI", "").lower() in ("1", "true", "yes")


@pytest.fixture
def tun_as_debian_has_it():
    """slirp4netns, run by an agent that is not root, opens /dev/net/tun: Debian's udev
    makes it 0666 (50-udev-default.rules), this machine's came 0600. Made as Debian has it,
    and left so: another test process may be using it meanwhile."""
    tun = Path("/dev/net/tun")
    if tun.stat().st_mode & 0o666 != 0o666:
        tun.chmod(0o666)
