"""`make fleet` (python -m robotide.fleet) on servers that ask for passwords: its own
PostgreSQL and Redis, on 127.0.0.1, with passwords generated once into FLEET_DATA/secrets.env
(0600), never the machine's password-less servers. Whoever reaches them without the password
(another user on the machine, a program that got to the network) is refused: in fleet mode
Redis is the channel layer, and whoever writes to it can command the agents.

The fleet is run as `make fleet` runs it, with one service of our own that prints the
DATABASE_URL and REDIS_URL the robotide services get.
"""

import os
import signal
import socket
import subprocess
import sys
import uuid
from pathlib import Path
from urllib.parse import urlsplit

import psycopg
import pytest
import redis
import yaml
from redis.backoff import NoBackoff
from redis.retry import Retry

from tests.appliance import POSTGRES, REDIS, ROOT, claim_redis_db, release_redis_db, wait_for

PROBE = (
    "import os, time\n"
    "print('DATABASE_URL=' + os.environ['DATABASE_URL'])\n"
    "print('REDIS_URL=' + os.environ['REDIS_URL'], flush=True)\n"
    "time.sleep(600)\n"
)


class FleetRun:
    """`python -m robotide.fleet -f probe.yml` in FLEET_DATA ``data``."""

    def __init__(self, data: Path, **env: str) -> None:
        self.data = data
        self.env = {k: v for k, v in os.environ.items() if not k.startswith("FLEET_")}
        self.env.update(FLEET_DATA=str(data), PYTHONUNBUFFERED="1", **env)
        self.process = None
        probe = {"command": ["robotide", "manage", "shell", "-c", PROBE]}
        self.file = data / "probe.yml"
        self.file.write_text(yaml.safe_dump({"services": {"probe": probe}}))

    def start(self) -> dict[str, str]:
        """The URLs the fleet's services got."""
        (self.data / "probe.log").unlink(missing_ok=True)
        with open(self.data / "fleet.out", "a") as out:
            self.process = subprocess.Popen(
                [sys.executable, "-m", "robotide.fleet", "-f", str(self.file)],
                env=self.env, cwd=ROOT, stdout=out, stderr=subprocess.STDOUT,
            )  # fmt: skip

        def urls():
            assert self.process.poll() is None, (self.data / "fleet.out").read_text()
            lines = (self.data / "probe.log").read_text().splitlines()
            found = dict(line.split("=", 1) for line in lines if "_URL=" in line)
            return found if len(found) == 2 else None

        return wait_for(urls, timeout=60, interval=0.1, what="the fleet's services")

    def stop(self) -> int | None:
        if self.process is None or self.process.poll() is not None:
            return self.process and self.process.returncode
        self.process.send_signal(signal.SIGTERM)
        try:
            return self.process.wait(30)
        except subprocess.TimeoutExpired:
            self.process.kill()
            return self.process.wait()


@pytest.fixture(scope="module")
def fleet(fleet_data):
    run = FleetRun(fleet_data)
    try:
        urls = run.start()
        yield run, urls
    finally:
        run.stop()
        print((fleet_data / "fleet.out").read_text()[-3000:])


def without_password(url: str) -> str:
    parts = urlsplit(url)
    user = f"{parts.username}@" if parts.username else ""
    return parts._replace(netloc=f"{user}{parts.hostname}:{parts.port}").geturl()


def with_password(url: str, password: str) -> str:
    parts = urlsplit(url)
    netloc = f"{parts.username or ''}:{password}@{parts.hostname}:{parts.port}"
    return parts._replace(netloc=netloc).geturl()


def test_postgres_refuses_a_connection_without_the_password(fleet):
    _, urls = fleet
    database = urls["DATABASE_URL"]
    with pytest.raises(psycopg.OperationalError, match="password"):
        psycopg.connect(without_password(database), connect_timeout=5).close()
    with pytest.raises(psycopg.OperationalError, match="password authentication failed"):
        psycopg.connect(with_password(database, "robotide"), connect_timeout=5).close()
    with psycopg.connect(database, connect_timeout=5) as conn:
        assert conn.execute("SELECT current_user").fetchone() == ("robotide",)


def test_redis_refuses_a_client_without_the_password(fleet):
    _, urls = fleet
    url = urls["REDIS_URL"]
    for wrong in (without_password(url), with_password(url, "robotide")):
        client = redis.Redis.from_url(wrong, socket_timeout=5, retry=Retry(NoBackoff(), 0))
        with pytest.raises(redis.AuthenticationError):
            client.ping()
        with pytest.raises(redis.AuthenticationError):  # no forged agent commands
            client.publish("robots", '{"type": "estop"}')
    assert redis.Redis.from_url(url, socket_timeout=5).ping()


def test_passwords_are_generated_once_into_a_file_only_its_owner_reads(fleet, fleet_data):
    _, urls = fleet
    secrets = fleet_data / "secrets.env"
    assert secrets.exists(), "no secrets file in FLEET_DATA"
    status = secrets.stat()
    assert status.st_mode & 0o777 == 0o600 and status.st_uid == os.geteuid()
    values = dict(
        line.split("=", 1) for line in secrets.read_text().splitlines() if "=" in line
    )  # fmt: skip
    assert urlsplit(urls["DATABASE_URL"]).password == values["POSTGRES_PASSWORD"]
    assert urlsplit(urls["REDIS_URL"]).password == values["REDIS_PASSWORD"]
    for value in values.values():
        assert len(value) >= 32


def test_the_servers_are_its_own_on_loopback(fleet, fleet_data):
    _, urls = fleet
    database, channels = urlsplit(urls["DATABASE_URL"]), urlsplit(urls["REDIS_URL"])
    assert database.hostname == channels.hostname == "127.0.0.1"
    assert database.port != 5432 and channels.port != 6379, "the machine's servers"
    postmaster = fleet_data / "postgres" / "postmaster.pid"
    assert postmaster.exists(), "no PostgreSQL cluster in FLEET_DATA"
    if os.geteuid() == 0:  # PostgreSQL refuses root; Redis does not need it
        import pwd

        pid = int(postmaster.read_text().split()[0])
        assert owner(pid) == pwd.getpwnam("postgres").pw_uid
        assert owner(listener(channels.port)) != 0


def owner(pid: int) -> int:
    status = Path(f"/proc/{pid}/status").read_text()
    return int(next(line for line in status.splitlines() if line.startswith("Uid:")).split()[1])


def listener(port: int) -> int:
    """The redis-server on ``port`` (its process title says where it listens)."""
    for proc in Path("/proc").glob("[0-9]*"):
        try:
            title = (proc / "cmdline").read_bytes().replace(b"\0", b" ").decode()
        except OSError:
            continue
        if title.startswith(("redis-server ", "/usr/bin/redis-server ")) and (
            title.rstrip().endswith(f"127.0.0.1:{port}")
        ):
            return int(proc.name)
    raise LookupError(f"no redis-server on port {port}")


def test_servers_of_your_own_are_used_as_given(tmp_path_factory):
    """FLEET_DATABASE_URL and FLEET_REDIS_URL: no servers of the fleet's own are started
    (their passwords, if any, are the operator's). Here, the test machine's."""
    data = tmp_path_factory.mktemp("own")
    name = f"robotide_fleet_{uuid.uuid4().hex[:8]}"
    redis_db = claim_redis_db()
    database, channels = f"{POSTGRES}/{name}", f"{REDIS}/{redis_db[0]}"
    run = FleetRun(data, FLEET_DATABASE_URL=database, FLEET_REDIS_URL=channels)
    try:
        assert run.start() == {"DATABASE_URL": database, "REDIS_URL": channels}
        assert not (data / "postgres").exists() and not (data / "redis").exists()
    finally:
        run.stop()
        release_redis_db(*redis_db)
        with psycopg.connect(f"{POSTGRES}/postgres", autocommit=True) as conn:
            conn.execute(f'DROP DATABASE IF EXISTS "{name}" WITH (FORCE)')


def test_stopped_its_servers_are_gone_started_again_the_passwords_are_the_same(fleet):
    run, urls = fleet
    assert run.stop() == 0
    database, channels = urls["DATABASE_URL"], urls["REDIS_URL"]
    with pytest.raises(psycopg.OperationalError):
        psycopg.connect(database, connect_timeout=5).close()
    with pytest.raises(ConnectionRefusedError):
        socket.create_connection(("127.0.0.1", urlsplit(channels).port), timeout=5)
    again = run.start()
    try:
        for key, url in again.items():
            assert urlsplit(url).password == urlsplit(urls[key]).password
        with psycopg.connect(again["DATABASE_URL"], connect_timeout=5) as conn:
            conn.execute("SELECT 1")
        assert redis.Redis.from_url(again["REDIS_URL"], socket_timeout=5).ping()
    finally:
        assert run.stop() == 0
