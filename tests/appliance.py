"""A real robotide appliance in subprocesses, for end-to-end tests and benchmarks.

Embedded: `robotide up` alone (SQLite, in-memory layer, agent in the server process).
Split: `robotide up` with REDIS_URL and DATABASE_URL (a fresh PostgreSQL database) plus
`robotide agent sim` as its own process.
"""

import atexit
import contextlib
import os
import re
import shutil
import signal
import socket
import sqlite3
import subprocess
import sys
import tempfile
import time
import uuid
from pathlib import Path

import httpx

ROOT = Path(__file__).resolve().parent.parent
ROBOTIDE = str(Path(sys.executable).parent / "robotide")
ADMIN_PASSWORD = "admin-pass-1234"
POSTGRES = os.environ.get("ROBOTIDE_TEST_POSTGRES", "postgresql://postgres@127.0.0.1:5432")
REDIS = os.environ.get("ROBOTIDE_TEST_REDIS", "redis://127.0.0.1:6379")


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


# s an appliance may take to come up: under two test processes' load a split one (a fresh
# PostgreSQL database migrated, collectstatic) took over 20 s. Only a failing start waits it.
START_TIMEOUT = 120.0
# s for anything else asked of an appliance (an agent up, a run ended): a deadline for the
# event, not how long it takes. 20 s ran out at a load of 10-20 on two cores.
DEADLINE = 60.0


def wait_for(predicate, timeout=DEADLINE, interval=0.05, what="condition", gone=None):
    """Wait for ``predicate``; ``gone``: says when waiting longer is pointless (a process
    that ended)."""
    deadline = time.monotonic() + timeout
    last = None
    while time.monotonic() < deadline:
        if gone is not None and gone():
            raise RuntimeError(f"gave up waiting for {what}: it ended (last: {last!r})")
        try:
            last = predicate()
            if last:
                return last
        except Exception as exc:  # not up yet
            last = exc
        time.sleep(interval)
    raise TimeoutError(f"timed out waiting for {what} (last: {last!r})")


class Appliance:
    def __init__(self, data_dir: Path, mode: str = "embedded", extra_env: dict | None = None):
        self.data_dir = data_dir
        self.mode = mode
        self.port = free_port()
        self.url = f"http://127.0.0.1:{self.port}"
        self.processes: list[subprocess.Popen] = []
        self.env = {
            **os.environ,
            "ROBOTIDE_DATA": str(data_dir),
            "ROBOTIDE_ADMIN_PASSWORD": ADMIN_PASSWORD,
            "PYTHONUNBUFFERED": "1",
            **(extra_env or {}),
        }
        if mode == "embedded":
            self.env.pop("REDIS_URL", None)
            self.env.pop("DATABASE_URL", None)
        self.database = None
        self.redis_db: tuple[int, str] | None = None

    # -- life cycle ---------------------------------------------------------------------------

    def start(self) -> "Appliance":
        """Started, or stopped again with its logs printed: a fixture has nothing to clean."""
        try:
            return self._start()
        except Exception:
            print(self.logs())
            self.stop()
            raise

    def _start(self) -> "Appliance":
        if self.mode == "split":
            self._create_database()
            self.redis_db = claim_redis_db()
            self.env["REDIS_URL"] = f"{REDIS}/{self.redis_db[0]}"
        elif not (self.data_dir / SQLITE).exists():
            shutil.copy(migrated_sqlite(), self.data_dir / SQLITE)
        self.server = self._spawn("up", "--bind", f"127.0.0.1:{self.port}")
        wait_for(lambda: httpx.get(f"{self.url}/accounts/login/").status_code == 200,
                 timeout=START_TIMEOUT, what="the web server", gone=self._ended)  # fmt: skip
        if self.mode == "split":
            self.agent = self._spawn("agent", "sim")
        self.token = self.cli("token", "admin").strip()
        wait_for(lambda: self.api("GET", "/api/robots/sim/sensors").status_code == 200,
                 timeout=START_TIMEOUT, what="the sim robot's agent", gone=self._ended)  # fmt: skip
        return self

    def _ended(self) -> bool:
        return any(proc.poll() is not None for proc in self.processes)

    def _spawn(self, *args) -> subprocess.Popen:
        log = open(self.data_dir / f"{args[0]}-{len(self.processes)}.log", "w")  # noqa: SIM115
        proc = subprocess.Popen(
            [ROBOTIDE, *args], env=self.env, stdout=log, stderr=subprocess.STDOUT, cwd=ROOT
        )
        self.processes.append(proc)
        return proc

    def cli(self, *args) -> str:
        return subprocess.run([ROBOTIDE, *args], env=self.env, check=True, capture_output=True,
                              text=True, cwd=ROOT).stdout  # fmt: skip

    def stop(self) -> None:
        for proc in reversed(self.processes):
            if proc.poll() is None:
                proc.send_signal(signal.SIGTERM)
        for proc in self.processes:
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
        if self.database:
            self._drop_database()
        if self.redis_db:
            release_redis_db(*self.redis_db)
            self.redis_db = None

    def logs(self) -> str:
        return "\n".join(p.read_text() for p in sorted(self.data_dir.glob("*.log")))

    # -- PostgreSQL ---------------------------------------------------------------------------

    def _create_database(self) -> None:
        import psycopg

        self.database = f"robotide_test_{uuid.uuid4().hex[:10]}"
        template = migrated_postgres()
        with psycopg.connect(f"{POSTGRES}/postgres", autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{self.database}" TEMPLATE "{template}"')
        self.env["DATABASE_URL"] = f"{POSTGRES}/{self.database}"

    def _drop_database(self) -> None:
        _drop(self.database)

    # -- HTTP ---------------------------------------------------------------------------------

    def api(self, method: str, path: str, body=None, token: str | None = None) -> httpx.Response:
        headers = {"Authorization": f"Bearer {token or self.token}"}
        return httpx.request(method, self.url + path, json=body, headers=headers, timeout=10)

    def new_user(self, username: str, password: str = "user-pass-1234", staff: bool = False) -> str:
        """Create a user; returns an API token for them."""
        code = (
            "from django.contrib.auth import get_user_model;"
            f"get_user_model().objects.create_user({username!r}, password={password!r},"
            f" is_staff={staff!r})"
        )
        self.cli("manage", "shell", "-c", code)
        return self.cli("token", username).strip()

    def session(self, username: str = "admin", password: str = ADMIN_PASSWORD) -> httpx.Client:
        """A browser-like signed-in client (session cookie + CSRF)."""
        client = httpx.Client(base_url=self.url, follow_redirects=True, timeout=10)
        page = client.get("/accounts/login/")
        csrf = re.search(r'name="csrfmiddlewaretoken" value="([^"]+)"', page.text).group(1)
        response = client.post(
            "/accounts/login/", data={"username": username, "password": password,
                                      "csrfmiddlewaretoken": csrf},
        )  # fmt: skip
        assert "Sign out" in response.text, "login failed"
        return client

    def wait_run(
        self, run_id: int, states=("finished", "failed", "stopped", "lost"), timeout=2 * DEADLINE
    ):
        def done():
            run = self.api("GET", f"/api/runs/{run_id}").json()
            return run if run["state"] in states else None

        return wait_for(done, timeout=timeout, what=f"run {run_id} in {states}")

    def resume(self, robot: str = "sim") -> None:
        """After a test's emergency stop: the robot may move again for the tests after it."""
        response = self.api("POST", f"/api/robots/{robot}/resume")
        assert response.status_code == 200, response.text

    def create_program(self, name: str, source: str, language: str = "python", token=None) -> dict:
        body = {"name": name, "language": language, "source": source}
        response = self.api("POST", "/api/programs", body, token=token)
        assert response.status_code == 201, response.text
        return response.json()

    def run_program(self, program_id: int, robot: str = "sim", token=None) -> dict:
        response = self.api(
            "POST", f"/api/programs/{program_id}/run", {"robot": robot}, token=token
        )
        assert response.status_code == 201, response.text
        return response.json()


# -- migrated once per test process -------------------------------------------------------------
# Migrating a fresh database takes 4 s of the 6 s an embedded server needs to come up, and the
# suite starts dozens. An appliance starts on a copy of one migrated here (`robotide up` still
# runs migrate: nothing to do); the admin, the sim robot and the rest are made by `up` as on a
# fresh install. `make run`'s own first start is tested from nothing (test_cli,
# test_ordinary_user).

SQLITE = "robotide.sqlite3"
_migrated: dict[str, str] = {}


def migrated_sqlite() -> str:
    if "sqlite" not in _migrated:
        folder = Path(tempfile.mkdtemp(prefix="robotide-migrated-"))
        atexit.register(shutil.rmtree, folder, ignore_errors=True)
        _migrate({"ROBOTIDE_DATA": str(folder)})
        # All of it in the one file a copy takes: what the write-ahead log may still hold goes
        # in, and the last connection closed removes the log.
        with contextlib.closing(sqlite3.connect(folder / SQLITE)) as db:
            db.execute("PRAGMA wal_checkpoint(TRUNCATE)")
        _migrated["sqlite"] = str(folder / SQLITE)
    return _migrated["sqlite"]


def migrated_postgres() -> str:
    """A database to copy (CREATE DATABASE ... TEMPLATE), this process's own: a template
    being copied must have no other session on it."""
    if "postgres" not in _migrated:
        import psycopg

        name = f"robotide_template_{uuid.uuid4().hex[:10]}"
        with psycopg.connect(f"{POSTGRES}/postgres", autocommit=True) as conn:
            conn.execute(f'CREATE DATABASE "{name}"')
        atexit.register(_drop, name)
        with tempfile.TemporaryDirectory() as folder:
            _migrate({"ROBOTIDE_DATA": folder, "DATABASE_URL": f"{POSTGRES}/{name}"})
        _migrated["postgres"] = name
    return _migrated["postgres"]


def _migrate(settings: dict) -> None:
    env = {k: v for k, v in os.environ.items() if k not in ("REDIS_URL", "DATABASE_URL")}
    command = [ROBOTIDE, "manage", "migrate", "-v0"]
    subprocess.run(command, env={**env, **settings}, check=True, cwd=ROOT, capture_output=True)


def _drop(database: str) -> None:
    import psycopg

    with psycopg.connect(f"{POSTGRES}/postgres", autocommit=True) as conn:
        conn.execute(f'DROP DATABASE IF EXISTS "{database}" WITH (FORCE)')


REDIS_DBS = range(7, 16)  # Redis's default 16 databases; 0-6 are left to others
REDIS_CLAIM_SECONDS = 3600  # a claim a killed test session left behind lapses


def claim_redis_db() -> tuple[int, str]:
    """A Redis database of its own, flushed: split appliances of parallel test workers and
    sessions never share one (two agents named sim would take each other's messages).
    Claimed by a key in database 0; returns it and the claim's token (release_redis_db)."""
    import redis

    token = uuid.uuid4().hex
    claims = redis.Redis.from_url(f"{REDIS}/0")
    for db in REDIS_DBS:
        if claims.set(f"robotide-test-db:{db}", token, nx=True, ex=REDIS_CLAIM_SECONDS):
            redis.Redis.from_url(f"{REDIS}/{db}").flushdb()
            return db, token
    raise RuntimeError(f"every Redis database {REDIS_DBS[0]}-{REDIS_DBS[-1]} is claimed")


def release_redis_db(db: int, token: str) -> None:
    import redis

    claims = redis.Redis.from_url(f"{REDIS}/0")
    if claims.get(f"robotide-test-db:{db}") == token.encode():
        claims.delete(f"robotide-test-db:{db}")


def cookie_header(client: httpx.Client) -> str:
    return "; ".join(f"{k}={v}" for k, v in client.cookies.items())
