"""The README's first promise, kept for an ordinary user: the whole appliance set up and served
by `make run` under an unprivileged OS account, its runs in the rootless box.

An account of its own (``robotide-newcomer``, with a home) gets a fresh clone of this
repository (its committed HEAD) and runs ``make run`` with Debian's python3, as a newcomer
would. Through the HTTP API the example *Stop before the wall* then runs on ``sim``, and probe
programs check what the box keeps from them although the run's processes belong, outside
their user namespace, to the very account that owns the server, its database and its secret
key: PostgreSQL, Redis and the web server's port refuse them, /proc/net/tcp shows nothing of
the host, and the clone with its data folder is not there.

The test needs root (to make the account and become it); in CI it runs, elsewhere it is
skipped when not root. pip reaches the package registry as root's pip does: its configuration
(``pip config list``: every file and PIP_* variable) is handed to the account as PIP_*
variables. The account (and so its pip cache) is kept between runs; the clone is deleted, and no
process of the account may outlive the test.
"""

import ast
import os
import pwd
import re
import shutil
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import httpx
import pytest

from tests.appliance import free_port, wait_for
from tests.conftest import in_ci
from tests.net_probes import DNS_ANSWERED, DNS_PROBE, udp_service

REPO = Path(__file__).resolve().parents[2]  # the repository this file lives in
ACCOUNT = "robotide-newcomer"
PASSWORD = "newcomer-admin-pass-1234"
SYSTEM_PYTHON = "/usr/bin/python3"
USER_PATH = "/usr/local/bin:/usr/bin:/bin"  # an ordinary Debian account's PATH
SBIN_PATH = f"/usr/local/sbin:/usr/sbin:/sbin:{USER_PATH}"
SETUP_TIMEOUT = 900  # a cold pip install of everything, on a slow network
PASSED_ON = ("http_proxy", "https_proxy", "no_proxy", "all_proxy", "SSL_CERT_FILE",
             "SSL_CERT_DIR", "REQUESTS_CA_BUNDLE", "LANG")  # fmt: skip


def tool(name: str) -> str:
    found = shutil.which(name, path=SBIN_PATH)
    assert found, f"{name} is needed for this test"
    return found


@pytest.fixture(scope="module")
def newcomer():
    """The unprivileged account, made if missing; none of its processes left from before."""
    if os.geteuid() != 0:
        why = "it makes an OS account and becomes it: run the tests as root"
        if in_ci():
            pytest.fail(f"the ordinary-user appliance test must run in CI, and {why}")
        pytest.skip(f"the ordinary-user appliance test is skipped: {why}")
    assert os.path.exists(SYSTEM_PYTHON), f"{SYSTEM_PYTHON} (Debian's python3) is needed"
    try:
        account = pwd.getpwnam(ACCOUNT)
    except KeyError:
        subprocess.run([tool("useradd"), "--create-home", "--shell", "/bin/sh", ACCOUNT],
                       check=True)  # fmt: skip
        account = pwd.getpwnam(ACCOUNT)
    _end_leftovers(account)
    return account


def pip_settings() -> dict[str, str]:
    """Root's pip configuration as PIP_* variables: its files (user files in root's home
    apply to root only) and its environment, so the account's pip reaches the same registry."""
    env: dict[str, str] = {}
    listed = subprocess.run([sys.executable, "-m", "pip", "config", "list"],
                            capture_output=True, text=True)  # fmt: skip
    for line in listed.stdout.splitlines() if listed.returncode == 0 else ():
        key, sep, value = line.partition("=")
        section, _, name = key.rpartition(".")
        if sep and section != ":env:":  # those are os.environ's, passed on below
            env["PIP_" + name.upper().replace("-", "_")] = ast.literal_eval(value)
    env |= {k: v for k, v in os.environ.items() if k.startswith("PIP_")}
    env |= {k: v for name in PASSED_ON for k in (name, name.upper()) if (v := os.environ.get(k))}
    return env


class UserAppliance:
    """`make run` in a clone in the account's home, as the account."""

    def __init__(self, account: pwd.struct_passwd, logs: Path):
        self.account = account
        self.home = Path(account.pw_dir)
        self.clone = self.home / "robotide"
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.log_path = logs / "make-run.log"
        self.env = {
            "HOME": str(self.home), "USER": account.pw_name, "LOGNAME": account.pw_name,
            "SHELL": account.pw_shell or "/bin/sh", "PATH": USER_PATH,
            **pip_settings(), "ROBOTIDE_ADMIN_PASSWORD": PASSWORD, "PYTHONUNBUFFERED": "1",
        }  # fmt: skip
        self.server: subprocess.Popen | None = None

    def as_user(self) -> list[str]:
        a = self.account
        return [tool("setpriv"), f"--reuid={a.pw_uid}", f"--regid={a.pw_gid}", "--init-groups",
                "--"]  # fmt: skip

    def start(self) -> "UserAppliance":
        shutil.rmtree(self.clone, ignore_errors=True)
        # --no-hardlinks: the clone's files are given to the account, not the repository's.
        subprocess.run(
            ["git", "-c", f"safe.directory={REPO}", "clone", "--quiet", "--no-hardlinks",
             str(REPO), str(self.clone)], check=True,
        )  # fmt: skip
        subprocess.run(["chown", "-R", f"{self.account.pw_uid}:{self.account.pw_gid}",
                        str(self.clone)], check=True)  # fmt: skip
        command = ["make", "run", f"PYTHON={SYSTEM_PYTHON}", f"BIND=127.0.0.1:{self.port}"]
        with open(self.log_path, "w") as log:
            self.server = subprocess.Popen(
                [*self.as_user(), *command], cwd=self.clone, env=self.env, stdout=log,
                stderr=subprocess.STDOUT, stdin=subprocess.DEVNULL, start_new_session=True,
            )  # fmt: skip
        deadline = time.monotonic() + SETUP_TIMEOUT
        while not self._serving():
            if self.server.poll() is not None:
                raise AssertionError(f"`make run` ended ({self.server.returncode})")
            if time.monotonic() > deadline:
                raise TimeoutError(f"`make run` not serving after {SETUP_TIMEOUT} s")
            time.sleep(0.5)
        self.token = self.cli("token", "admin").strip()
        wait_for(lambda: self.api("GET", "/api/robots/sim/sensors").status_code == 200,
                 timeout=30, what="the sim robot's agent")  # fmt: skip
        return self

    def _serving(self) -> bool:
        try:
            return httpx.get(f"{self.url}/accounts/login/", timeout=5).status_code == 200
        except httpx.HTTPError:
            return False

    def cli(self, *args) -> str:
        done = subprocess.run([*self.as_user(), ".venv/bin/robotide", *args], cwd=self.clone,
                              env=self.env, capture_output=True, text=True)  # fmt: skip
        assert done.returncode == 0, done.stderr
        return done.stdout

    def api(self, method: str, path: str, body=None) -> httpx.Response:
        headers = {"Authorization": f"Bearer {self.token}"}
        return httpx.request(method, self.url + path, json=body, headers=headers, timeout=10)

    def run(self, program_id: int, timeout: float = 60, robot="sim") -> tuple[dict, str]:
        started = self.api("POST", f"/api/programs/{program_id}/run", {"robot": robot})
        assert started.status_code == 201, started.text
        run_id = started.json()["id"]

        def ended():
            run = self.api("GET", f"/api/runs/{run_id}").json()
            return run if run["state"] not in ("queued", "starting", "running") else None

        run = wait_for(ended, timeout=timeout, interval=0.2, what=f"run {run_id} to end")
        return run, self.api("GET", f"/api/runs/{run_id}/log").text

    def run_source(self, name: str, source: str, robot="sim") -> tuple[dict, str]:
        body = {"name": name, "language": "python", "source": source}
        created = self.api("POST", "/api/programs", body)
        assert created.status_code == 201, created.text
        return self.run(created.json()["id"], robot=robot)

    def logs(self) -> str:
        return self.log_path.read_text() if self.log_path.exists() else ""

    def stop(self) -> list[str]:
        """SIGTERM to the server's process group, SIGKILL after a grace; then the account's
        processes still alive after a while (`pgrep -u`), which must be none."""
        if self.server is not None and self.server.poll() is None:
            os.killpg(self.server.pid, signal.SIGTERM)
            try:
                self.server.wait(timeout=20)
            except subprocess.TimeoutExpired:
                os.killpg(self.server.pid, signal.SIGKILL)
                self.server.wait(timeout=10)
        deadline = time.monotonic() + 10
        while (left := processes_of(self.account)) and time.monotonic() < deadline:
            time.sleep(0.2)
        return left

    def remove(self) -> None:
        shutil.rmtree(self.clone, ignore_errors=True)


def processes_of(account: pwd.struct_passwd) -> list[str]:
    found = subprocess.run(["pgrep", "-a", "-u", str(account.pw_uid)], capture_output=True,
                           text=True)  # fmt: skip
    return found.stdout.splitlines()


def _end_leftovers(account: pwd.struct_passwd) -> None:
    """The account is this test's own: what runs under it is left from an interrupted run."""
    for line in processes_of(account):
        pid = int(line.split()[0])
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            pass


@pytest.fixture(scope="module")
def app(newcomer, tmp_path_factory):
    app = UserAppliance(newcomer, tmp_path_factory.mktemp("ordinary-user"))
    try:
        app.start()
    except BaseException:
        print(app.logs())
        _clean_up(app)
        raise
    yield app
    _clean_up(app)


def _clean_up(app: UserAppliance) -> None:
    if app.stop():  # reported by the last test; ended here so that nothing outlives the test
        _end_leftovers(app.account)
    app.remove()


def programs_by_name(app) -> dict:
    return {p["name"]: p for p in app.api("GET", "/api/programs").json()}


def test_the_admin_signs_in_with_the_password_make_run_was_given(app):
    client = httpx.Client(base_url=app.url, follow_redirects=True, timeout=10)
    page = client.get("/accounts/login/")
    csrf = re.search(r'name="csrfmiddlewaretoken" value="([^"]+)"', page.text).group(1)
    signed_in = client.post("/accounts/login/", data={
        "username": "admin", "password": PASSWORD, "csrfmiddlewaretoken": csrf,
    })  # fmt: skip
    assert "Sign out" in signed_in.text, "the admin could not sign in"
    assert "Stop before the wall" in client.get("/").text


def test_the_server_and_its_data_belong_to_the_ordinary_user(app, newcomer):
    server = [line.split()[0] for line in processes_of(newcomer) if "robotide up" in line]
    assert server, processes_of(newcomer)
    status = dict(line.split(":", 1) for line in Path(f"/proc/{server[0]}/status").open())
    assert status["Uid"].split() == [str(newcomer.pw_uid)] * 4  # real, effective, saved, fs
    assert int(status["CapEff"], 16) == 0  # no privilege of any kind
    assert (app.clone / "var" / "secret_key").stat().st_uid == newcomer.pw_uid


def test_the_robot_says_its_runs_are_in_the_rootless_box(app):
    robots = {r["name"]: r for r in app.api("GET", "/api/robots").json()}
    isolation = robots["sim"]["isolation"]
    assert "rootless box" in isolation and "user namespace" in isolation, isolation


def test_stop_before_the_wall_runs_in_its_box(app):
    run, log = app.run(programs_by_name(app)["Stop before the wall"]["id"])
    assert run["state"] == "finished" and run["exit_code"] == 0, f"{run['reason']}: {log}"
    distance = float(re.search(r"Stopped (\d\.\d+) m before the wall", log).group(1))
    assert 0.3 < distance <= 0.5, log
    assert "[robotide] finished: exit status 0" in log


LOOPBACKS = ("127.0.0.1", "::1")
PROBE = """
import os, socket
print("UIDMAP", open("/proc/self/uid_map").read().split())
print("API", os.environ.get("ROBOT_API_TCP"))
for port in {ports!r}:
    for host in {hosts!r}:
        try:
            socket.create_connection((host, port), timeout=3).close()
            print("CONNECTED", host, port)
        except OSError as e:
            print("REFUSED", host, port, type(e).__name__)
for table in ("tcp", "tcp6", "udp", "udp6"):
    for line in open("/proc/net/" + table).read().splitlines()[1:]:
        print("SOCKET", table, *line.split()[1:3])
for path in {paths!r}:
    try:
        if os.path.isdir(path):
            print("LISTED", path, os.listdir(path))
        else:
            print("READ", path, open(path, "rb").read())
    except OSError as e:
        print("DENIED", path, type(e).__name__)
"""


def host_listening_ports() -> set[int]:
    ports = set()
    for table in ("tcp", "tcp6"):
        for line in Path(f"/proc/net/{table}").read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] == "0A":  # LISTEN
                ports.add(int(fields[1].rsplit(":", 1)[1], 16))
    return ports


def test_a_run_reaches_neither_the_hosts_services_nor_the_servers_port(app, newcomer):
    services = [5432, 6379, app.port]  # PostgreSQL, Redis, the web server itself
    listening = host_listening_ports()
    assert app.port in listening  # the control: the host's table has the server
    source = PROBE.format(ports=services, hosts=LOOPBACKS, paths=[])
    run, log = app.run_source("probe network", source)
    assert run["state"] == "finished", f"{run['reason']}: {log}"
    assert "CONNECTED" not in log, log
    assert log.count("REFUSED") == 2 * len(services), log
    # Its own user namespace, where one id is mapped (to the account's, levels up), not root.
    uid_map = re.search(r"UIDMAP \[(.*)\]", log).group(1).replace("'", "").split(", ")
    assert len(uid_map) == 3 and uid_map[0] != "0" and uid_map[2] == "1", log
    # Its own network namespace: only what its robot gives programs, the Robot API's relay.
    api_port = int(re.search(r"API 127\.0\.0\.1:(\d+)", log).group(1))
    sockets = re.findall(r"SOCKET (\w+) (\S+) (\S+)", log)
    assert sockets and all(t == "tcp" and local == f"0100007F:{api_port:04X}"
                           for t, local, _ in sockets), log  # fmt: skip
    assert not {int(local.rsplit(":", 1)[1], 16) for _, local, _ in sockets} & set(services)


# A full run's probe: its resolver and its way out, then the host's services both on its
# own loopback and behind the NAT's gateway (the host's loopback, were it open).
FULL_PROBE = (
    DNS_PROBE
    + """
routes = [line.split() for line in open("/proc/net/route").read().splitlines()[1:]]
print("DEFAULT", [r[0] for r in routes if r[1] == "00000000" and r[7] == "00000000"])
"""
    + PROBE
)


UDP_AND_ABSTRACT = """
import socket
u = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
u.settimeout(2)
try:
    u.sendto(b"ping", ("127.0.0.1", {udp}))
    print("UDP ANSWERED", u.recv(100))
except OSError as e:
    print("UDP unanswered", type(e).__name__)
a = socket.socket(socket.AF_UNIX)
try:
    a.connect({abstract!r})
    print("ABSTRACT CONNECTED")
except OSError as e:
    print("ABSTRACT refused", type(e).__name__)
"""


def test_a_run_reaches_no_udp_listener_nor_abstract_socket_of_the_host(app):
    """A UDP echo on the host's 127.0.0.1 and an abstract Unix socket (one per network
    namespace, whoever binds it): both answer the host, neither the rootless run."""
    abstract = socket.socket(socket.AF_UNIX)
    abstract.bind(f"\0robotide-newcomer-{os.getpid()}")
    abstract.listen()
    with udp_service() as udp, abstract:
        control = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        control.settimeout(2)
        control.sendto(b"ping", udp)
        assert control.recv(100) == b"ping"  # the controls: both answer the host
        socket.socket(socket.AF_UNIX).connect(abstract.getsockname())
        source = UDP_AND_ABSTRACT.format(udp=udp[1], abstract=abstract.getsockname())
        run, log = app.run_source("probe udp and abstract", source)
    assert run["state"] == "finished", f"{run['reason']}: {log}"
    assert "UDP unanswered" in log and "ABSTRACT refused" in log, log


def test_a_full_run_of_the_ordinary_user_has_the_nat_and_nothing_of_the_host(
    app, tun_as_debian_has_it
):
    """A robot with network `full` in the ordinary user's appliance: its run looks names up
    through the NAT, goes out through its own tap device, and reaches neither the host's
    loopback behind the NAT's gateway nor the host's services."""
    body = {"name": "open", "url": "sim://", "settings": {"network": "full"}}
    assert app.api("POST", "/api/robots", body).status_code == 201
    wait_for(lambda: app.api("GET", "/api/robots/open/sensors").status_code == 200)
    services = [5432, 6379, app.port]
    source = FULL_PROBE.format(ports=services, hosts=("127.0.0.1", "10.0.2.2"), paths=[])
    run, log = app.run_source("probe full", source, robot="open")
    assert run["state"] == "finished", f"{run['reason']}: {log}"
    assert "SERVERS ['10.0.2.3']" in log and DNS_ANSWERED in log, log
    assert "DEFAULT ['tap0']" in log, log
    assert "CONNECTED" not in log and log.count("REFUSED") == 2 * len(services), log


def test_a_run_cannot_see_the_users_own_files(app, newcomer):
    data = app.clone / "var"
    secret = (data / "secret_key").read_bytes().strip()
    paths = [str(p) for p in (data / "secret_key", data / "robotide.sqlite3", data / "runs",
                              data, app.clone / "pyproject.toml", app.clone, app.home,
                              app.home / ".profile")]  # fmt: skip
    assert all(os.path.exists(p) for p in paths)  # the control: they are there, outside
    run, log = app.run_source("probe files", PROBE.format(ports=[], hosts=LOOPBACKS, paths=paths))
    assert run["state"] == "finished", f"{run['reason']}: {log}"
    assert log.count("DENIED") == len(paths) and "READ" not in log and "LISTED" not in log, log
    assert secret.decode() not in log


def test_the_robot_says_what_the_rootless_box_cannot_give(app):
    """Runs as an ordinary user get per-process limits, not a cgroup across the run (see
    scripts/install-run-deps.sh): the robot's isolation must say so."""
    isolation = {r["name"]: r for r in app.api("GET", "/api/robots").json()}["sim"]["isolation"]
    assert "no cgroups" in isolation and "per-process rlimits only" in isolation, isolation


def test_stopping_the_server_leaves_no_process_of_the_user(app, newcomer):
    left = app.stop()
    assert app.server.returncode is not None
    assert not left, f"still running as {newcomer.pw_name} after the server stopped: {left}"
    assert not [p for p in Path("/tmp").glob("robotide-*") if owner(p) == newcomer.pw_uid]


def owner(path: Path) -> int | None:
    try:
        return path.stat().st_uid
    except FileNotFoundError:  # another test's, gone meanwhile
        return None
