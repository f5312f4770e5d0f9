"""The compose file's robotide services, run natively: `make fleet` (python -m robotide.fleet).

Where Docker is not at hand, this starts the same commands with the same environment as
docker-compose.yml, on this machine. ROBOTIDE_DATA is one folder for all (FLEET_DATA, default
var/fleet: the volumes), and published ports go to loopback (FLEET_HOST). The postgres and
redis services are the fleet's own servers, started here (PrivateServers): a PostgreSQL cluster
in FLEET_DATA/postgres and a redis-server, both on 127.0.0.1 on a free port, both asking for
the passwords generated once into FLEET_DATA/secrets.env (mode 0600); never the machine's
password-less ones. FLEET_DATABASE_URL or FLEET_REDIS_URL use servers of your own instead.
Services start in dependency order, each once the ones it depends on are healthy by their own
health check; one that exits is started again if its ``restart`` says so. Ctrl-C stops all.

    .venv/bin/python -m robotide.fleet [-f docker-compose.yml] [-f more.yml]
    python3 -m robotide.fleet secrets [--env-file .env]   # for docker compose: its passwords
"""

from __future__ import annotations

import argparse
import os
import re
import secrets as _random
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit, urlunsplit

ROOT = Path(__file__).resolve().parent.parent
BACKING = ("postgres", "redis")  # compose services PrivateServers (or yours) stand in for
SECRETS = ("POSTGRES_PASSWORD", "REDIS_PASSWORD")  # what `secrets` generates
# $$, ${VAR}, ${VAR:-default}, ${VAR-default}, ${VAR:?error}, ${VAR?error}: as compose reads them
_VARIABLE = re.compile(r"\$(?:\$|\{(\w+)(?:(:?)([-?])([^}]*))?\})")


class MissingVariable(SystemExit):
    """A ``${VAR:?message}`` whose VAR is not set: compose stops with the message; so do we."""


def load(files: list[Path], variables: dict | None = None) -> dict[str, dict]:
    """The services of the compose files, later files overriding earlier ones, with
    ``${VAR:-default}`` and the like replaced from ``variables`` (default: this environment)."""
    import yaml

    variables = os.environ if variables is None else variables
    services: dict[str, dict] = {}
    for path in files:
        data = yaml.safe_load(path.read_text()) or {}
        for name, service in (data.get("services") or {}).items():
            services[name] = {**services.get(name, {}), **(service or {})}
    return _interpolate(services, variables)


def _interpolate(value, variables):
    if isinstance(value, str):
        return _VARIABLE.sub(lambda m: _variable(m, variables), value)
    if isinstance(value, list):
        return [_interpolate(item, variables) for item in value]
    if isinstance(value, dict):
        return {key: _interpolate(item, variables) for key, item in value.items()}
    return value


def _variable(match: re.Match, variables) -> str:
    name, colon, kind, word = match.groups()
    if name is None:
        return "$"
    value = variables.get(name)
    missing = value is None or (colon == ":" and value == "")
    if not missing:
        return value
    if kind == "?":
        raise MissingVariable(f"fleet: {name} is not set: {word or 'required'}")
    return word or ""


def robotide_services(services: dict[str, dict]) -> dict[str, dict]:
    return {
        name: service for name, service in services.items()
        if (service.get("command") or [None])[0] == "robotide"
    }  # fmt: skip


@dataclass
class Service:
    name: str
    argv: list[str]
    env: dict[str, str]
    depends: list[str]
    health: list[str] | str | None  # a command, or a URL to GET
    restart: bool
    process: subprocess.Popen | None = None
    restarts: int = 0
    held: bool = False  # killed on purpose: not started again until restart()


class Fleet:
    def __init__(
        self, files: list[Path], *, data: Path, database: str, redis: str, host: str,
        only: list[str] | None = None, variables: dict | None = None,
    ) -> None:  # fmt: skip
        self.data, self.database, self.redis, self.host = data, database, redis, host
        # The backing servers' passwords only make the URLs replaced here (database, redis)
        # and the services not run here: callers that bring their own servers need not give them.
        variables = {
            **dict.fromkeys(SECRETS, "unused"),
            **(os.environ if variables is None else variables),
        }
        found = robotide_services(load(files, variables))
        self.services = {
            name: self._service(name, spec)
            for name, spec in found.items()
            if only is None or name in only
        }
        self.stopping = False
        self._lock = threading.Lock()

    # -- what compose says, made local ------------------------------------------------------

    def _service(self, name: str, spec: dict) -> Service:
        env = {key: str(value) for key, value in (spec.get("environment") or {}).items()}
        env.update(DATABASE_URL=self.database, REDIS_URL=self.redis, ROBOTIDE_DATA=str(self.data))
        argv = [self._local(arg, spec) for arg in spec["command"]]
        argv[0] = str(Path(sys.executable).parent / "robotide")
        depends = [d for d in (spec.get("depends_on") or {}) if d not in BACKING]
        test = (spec.get("healthcheck") or {}).get("test")
        return Service(name, argv, env, depends, self._health(test, spec),
                       spec.get("restart", "no") != "no")  # fmt: skip

    def _local(self, arg: str, spec: dict) -> str:
        """A bind address published by ``ports`` listens on FLEET_HOST here."""
        host, _, port = arg.rpartition(":")
        published = _published(spec)
        if host in ("0.0.0.0", "::") and port in published:
            return f"{self.host}:{published[port]}"
        return arg

    def _health(self, test, spec: dict):
        if not test or test[0] != "CMD":
            return None
        if test[1] == "robotide":
            return [str(Path(sys.executable).parent / "robotide"), *test[2:]]
        urls = [u for arg in test[2:] for u in re.findall(r"http://[^'\")\s]+", arg)]
        if urls:  # the service's own port, as published here
            parts = urlsplit(urls[0])
            port = _published(spec).get(str(parts.port), parts.port)
            return urlunsplit(parts._replace(netloc=f"{self.host}:{port}"))
        return None

    # -- running ---------------------------------------------------------------------------

    def start(self, timeout: float = 60.0) -> None:
        self.data.mkdir(parents=True, exist_ok=True)
        started: set[str] = set()
        while len(started) < len(self.services):
            ready = [s for s in self.services.values()
                     if s.name not in started and set(s.depends) <= started]  # fmt: skip
            if not ready:
                raise SystemExit(
                    f"fleet: depends_on has a cycle among {set(self.services) - started}"
                )
            for service in ready:
                self._spawn(service)
            for service in ready:
                self.wait_healthy(service.name, timeout)
                started.add(service.name)
        threading.Thread(target=self._supervise, daemon=True, name="fleet").start()

    def _spawn(self, service: Service) -> None:
        log = open(self.data / f"{service.name}.log", "a")  # noqa: SIM115 - the child's
        service.process = subprocess.Popen(
            service.argv, env={**os.environ, **service.env}, stdout=log,
            stderr=subprocess.STDOUT, cwd=ROOT, start_new_session=True,
        )  # fmt: skip
        log.close()

    def healthy(self, name: str) -> bool:
        service = self.services[name]
        if service.process is None or service.process.poll() is not None:
            return False
        check = service.health
        if check is None:
            return True
        if isinstance(check, str):
            import httpx

            try:
                return httpx.get(check, timeout=2).status_code == 200
            except httpx.HTTPError:
                return False
        env = {**os.environ, **service.env}
        return subprocess.run(check, env=env, capture_output=True, cwd=ROOT).returncode == 0

    def wait_healthy(self, name: str, timeout: float = 60.0) -> None:
        deadline = time.monotonic() + timeout
        while not self.healthy(name):
            process = self.services[name].process
            if (
                process is not None
                and process.poll() is not None
                and not self.services[name].restart
            ):
                raise RuntimeError(f"fleet: {name} exited ({process.returncode}); see its log")
            if time.monotonic() > deadline:
                raise TimeoutError(f"fleet: {name} not healthy within {timeout:g} s")
            time.sleep(0.2)

    def kill(self, name: str, sig: int = signal.SIGKILL) -> None:
        """As a crash would: the service is not started again until restart(name)."""
        service = self.services[name]
        with self._lock:
            service.held = True
            if service.process is not None:
                os.killpg(service.process.pid, sig)
                service.process.wait()

    def restart(self, name: str) -> None:
        service = self.services[name]
        with self._lock:
            service.held = False
            if service.process is None or service.process.poll() is not None:
                self._spawn(service)

    def _supervise(self) -> None:
        while not self.stopping:
            with self._lock:
                for service in self.services.values():
                    gone = service.process is not None and service.process.poll() is not None
                    if gone and service.restart and not service.held:
                        service.restarts += 1
                        self._spawn(service)
            time.sleep(1.0)

    def stop(self, timeout: float = 15.0) -> None:
        self.stopping = True
        order = list(self.services.values())[::-1]  # agents before the web tier
        for service in order:
            if service.process is not None and service.process.poll() is None:
                os.killpg(service.process.pid, signal.SIGTERM)
        for service in order:
            if service.process is None:
                continue
            try:
                service.process.wait(timeout)
            except subprocess.TimeoutExpired:
                os.killpg(service.process.pid, signal.SIGKILL)
                service.process.wait()


def _published(spec: dict) -> dict[str, str]:
    """``ports: ["8080:8000"]`` -> {"8000": "8080"}: the container's port, as published."""
    found = {}
    for mapping in spec.get("ports", []):
        outside, _, inside = str(mapping).rpartition(":")
        found[inside.split("/")[0]] = outside.rpartition(":")[2] or inside.split("/")[0]
    return found


# -- passwords ------------------------------------------------------------------------------


def secrets(path: Path) -> dict[str, str]:
    """The fleet's passwords, KEY=VALUE lines in ``path``: generated the first time (hex, so
    they go into URLs and config files as they are), read every time after; the ones missing
    from a file that is there are added to it, the rest of it kept. The file is the owner's
    alone (0600), made so if it was not."""
    found: dict[str, str] = {}
    text = ""
    if path.exists():
        os.chmod(path, 0o600)
        text = path.read_text()
        for line in text.splitlines():
            key, sep, value = line.strip().partition("=")
            if sep and not key.startswith("#"):
                found[key.strip()] = value.strip().strip("'\"")
    missing = {key: _random.token_hex(24) for key in SECRETS if not found.get(key)}
    if missing:
        if not text:
            text = (
                "# robotide fleet passwords: generated once, kept here, never committed.\n"
                "# Changing one means changing it in its server too (PostgreSQL keeps the one\n"
                "# it was created with: ALTER ROLE robotide PASSWORD '...').\n"
            )
        elif not text.endswith("\n"):
            text += "\n"
        text += "".join(f"{key}={value}\n" for key, value in missing.items())
        path.parent.mkdir(parents=True, exist_ok=True)
        fresh = path.with_name(path.name + ".new")
        fresh.unlink(missing_ok=True)
        fd = os.open(fresh, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o600)
        with os.fdopen(fd, "w") as file:
            file.write(text)
        os.replace(fresh, path)
        found.update(missing)
    return found


# -- the fleet's own PostgreSQL and Redis ---------------------------------------------------


class PrivateServers:
    """The postgres and redis services of the compose file, as servers of this fleet's own.

    PostgreSQL: a cluster in ``data/postgres`` (initdb the first time, its superuser
    ``robotide`` with POSTGRES_PASSWORD, scram-sha-256 for every connection) listening on
    127.0.0.1 only, on a free port, no Unix socket. Redis: ``redis-server`` with REDIS_PASSWORD
    as requirepass, on 127.0.0.1 only, on a free port, nothing saved; its configuration goes in
    through its stdin, so the password is on no command line. As root, both run as their
    accounts (``postgres``; ``redis``, else ``postgres``): PostgreSQL refuses root, and neither
    needs it. They die with the process that started them (a parent-death signal).
    """

    def __init__(
        self, data: Path, passwords: dict[str, str], *, postgres: bool = True, redis: bool = True
    ) -> None:
        self.data, self.passwords = data, passwords
        self.wanted = {"postgres": postgres, "redis": redis}
        self.processes: dict[str, subprocess.Popen] = {}
        self.ports: dict[str, int] = {}

    @property
    def database_url(self) -> str:
        password = self.passwords["POSTGRES_PASSWORD"]
        return f"postgresql://robotide:{password}@127.0.0.1:{self.ports['postgres']}/robotide"

    @property
    def redis_url(self) -> str:
        password = self.passwords["REDIS_PASSWORD"]
        return f"redis://:{password}@127.0.0.1:{self.ports['redis']}/0"

    def start(self, timeout: float = 60.0) -> PrivateServers:
        try:
            if self.wanted["postgres"]:
                self._start_postgres(timeout)
            if self.wanted["redis"]:
                self._start_redis(timeout)
        except BaseException:
            self.stop()
            raise
        return self

    def stop(self, timeout: float = 15.0) -> None:
        # SIGINT: PostgreSQL's fast shutdown (SIGTERM would wait for every client to leave).
        for name, sig in (("postgres", signal.SIGINT), ("redis", signal.SIGTERM)):
            process = self.processes.pop(name, None)
            if process is None or process.poll() is not None:
                continue
            process.send_signal(sig)
            try:
                process.wait(timeout)
            except subprocess.TimeoutExpired:
                process.kill()
                process.wait()

    # -- PostgreSQL ------------------------------------------------------------------------

    def _start_postgres(self, timeout: float) -> None:
        cluster = self.data / "postgres"
        account = _account("postgres") if os.geteuid() == 0 else None
        made = (cluster / "PG_VERSION").exists()
        bindir = _postgres_bin((cluster / "PG_VERSION").read_text().strip() if made else None)
        self._own_folder(cluster, account)
        if not made:
            self._initdb(bindir, cluster, account)
        port = self.ports["postgres"] = _free_port()
        self._spawn("postgres", [
            bindir / "postgres", "-D", cluster, "-c", "listen_addresses=127.0.0.1",
            "-c", f"port={port}", "-c", "unix_socket_directories=",
            "-c", "password_encryption=scram-sha-256",
        ], account, signal.SIGINT)  # fmt: skip

        def ready():
            import psycopg

            admin = self.database_url.rpartition("/")[0] + "/postgres"
            with psycopg.connect(admin, connect_timeout=2):
                return True

        self._wait("postgres", ready, timeout)
        ensure_database(self.database_url)

    def _initdb(self, bindir: Path, cluster: Path, account) -> None:
        # The password in a file only initdb's account reads (a pipe's /dev/stdin it may not).
        scratch = Path(tempfile.mkdtemp(prefix=".initdb-", dir=self.data))
        try:
            pwfile = scratch / "password"
            pwfile.write_text(self.passwords["POSTGRES_PASSWORD"] + "\n")
            if account is not None:
                for path in (scratch, pwfile):
                    os.chown(path, account.pw_uid, account.pw_gid)
            initdb = subprocess.run(
                [bindir / "initdb", "-D", cluster, "-U", "robotide", f"--pwfile={pwfile}",
                 "--auth=scram-sha-256", "-E", "UTF8", "--locale=C.UTF-8"],
                text=True, capture_output=True, **_as(account),
            )  # fmt: skip
        finally:
            shutil.rmtree(scratch, ignore_errors=True)
        if initdb.returncode != 0:
            for leftover in cluster.iterdir():
                shutil.rmtree(leftover) if leftover.is_dir() else leftover.unlink()
            raise SystemExit(f"fleet: initdb failed:\n{initdb.stdout}{initdb.stderr}")

    # -- Redis -----------------------------------------------------------------------------

    def _start_redis(self, timeout: float) -> None:
        program = shutil.which("redis-server") or "/usr/bin/redis-server"
        if not Path(program).exists():
            raise SystemExit("fleet: redis-server not found: install it, or set FLEET_REDIS_URL")
        folder = self.data / "redis"
        account = _account("redis", "postgres") if os.geteuid() == 0 else None
        self._own_folder(folder, account)
        port = self.ports["redis"] = _free_port()
        config = (
            f"bind 127.0.0.1\nport {port}\nprotected-mode yes\n"
            f"requirepass {self.passwords['REDIS_PASSWORD']}\n"
            f'save ""\nappendonly no\ndir {folder}\ndaemonize no\nlogfile ""\n'
        )
        process = self._spawn("redis", [program, "-"], account, signal.SIGTERM, stdin=True)
        process.stdin.write(config.encode())
        process.stdin.close()

        def ready():
            import redis

            # Listening first: redis-py retries a refused connection for seconds.
            socket.create_connection(("127.0.0.1", port), timeout=2).close()
            return redis.Redis.from_url(self.redis_url, socket_timeout=2).ping()

        self._wait("redis", ready, timeout)

    # -- both ------------------------------------------------------------------------------

    def _own_folder(self, folder: Path, account) -> None:
        """``folder``, the server's alone; as root, its account's, which must reach it."""
        folder.mkdir(mode=0o700, parents=True, exist_ok=True)
        os.chmod(folder, 0o700)
        if account is None:
            return
        os.chown(folder, account.pw_uid, account.pw_gid)
        for above in folder.resolve().parents:
            if not _searchable(above, account):
                raise SystemExit(
                    f"fleet: the {account.pw_name} account, which runs the fleet's "
                    f"{folder.name} server, cannot reach {folder} ({above} is closed to it): "
                    "chmod o+x the folders above, or set FLEET_DATA to a folder it can reach"
                )

    def _spawn(self, name, argv, account, death, stdin=False) -> subprocess.Popen:
        log = open(self.data / f"{name}.log", "a")  # noqa: SIM115 - the child's
        with log:
            self.processes[name] = subprocess.Popen(
                [str(arg) for arg in argv], stdout=log, stderr=subprocess.STDOUT,
                stdin=subprocess.PIPE if stdin else subprocess.DEVNULL,
                start_new_session=True,  # Ctrl-C is for the fleet, which stops it last
                preexec_fn=_die_with_parent(death), **_as(account),
            )  # fmt: skip
        return self.processes[name]

    def _wait(self, name: str, ready, timeout: float) -> None:
        deadline, last = time.monotonic() + timeout, None
        while True:
            process = self.processes[name]
            if process.poll() is not None:
                log = (self.data / f"{name}.log").read_text()[-3000:]
                raise SystemExit(f"fleet: its {name} server exited ({process.returncode}):\n{log}")
            try:
                if ready():
                    return
            except Exception as error:  # not up yet
                last = error
            if time.monotonic() > deadline:
                raise TimeoutError(f"fleet: its {name} server not up within {timeout:g} s: {last}")
            time.sleep(0.1)


def _account(*names: str):
    import pwd

    for name in names:
        try:
            return pwd.getpwnam(name)
        except KeyError:
            continue
    raise SystemExit(
        f"fleet: run as root, it runs its servers as {' or '.join(names)}, and there is no such "
        "account (install the server's package, or run make fleet as an ordinary user)"
    )


def _searchable(folder: Path, account) -> bool:
    """May ``account`` go through ``folder`` (its x bit for owner, group or others)?"""
    status = folder.stat()
    if status.st_uid == account.pw_uid:
        return bool(status.st_mode & 0o100)
    if status.st_gid in os.getgrouplist(account.pw_name, account.pw_gid):
        return bool(status.st_mode & 0o010)
    return bool(status.st_mode & 0o001)


def _as(account) -> dict:
    if account is None:
        return {}
    return {"user": account.pw_uid, "group": account.pw_gid, "extra_groups": []}


def _postgres_bin(version: str | None) -> Path:
    """The newest PostgreSQL's programs (or those of the version the cluster was made by)."""
    found = sorted(
        Path("/usr/lib/postgresql").glob("*/bin/initdb"),
        key=lambda p: [int(n) if n.isdigit() else 0 for n in p.parent.parent.name.split(".")],
    )
    if version:
        found = [p for p in found if p.parent.parent.name == version] or found[-1:]
    if found:
        return found[-1].parent
    on_path = shutil.which("initdb")
    if on_path:
        return Path(on_path).parent
    raise SystemExit(
        "fleet: PostgreSQL's server programs (initdb, postgres) not found under "
        "/usr/lib/postgresql/*/bin nor on PATH: install postgresql, or set FLEET_DATABASE_URL"
    )


def _die_with_parent(sig: int):
    """For preexec_fn: the child gets ``sig`` when the process that started it dies, however
    it dies. Looked up here: the child, already its account, may not read Python's files."""
    import ctypes

    prctl, pr_set_pdeathsig = getattr(ctypes.CDLL(None, use_errno=True), "prctl", None), 1
    return prctl and (lambda: prctl(pr_set_pdeathsig, int(sig), 0, 0, 0))  # Linux only


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def ensure_database(url: str) -> None:
    """The fleet's PostgreSQL database, created if it is not there."""
    import psycopg

    parts = urlsplit(url)
    name = parts.path.lstrip("/")
    admin = urlunsplit(parts._replace(path="/postgres"))
    with psycopg.connect(admin, autocommit=True) as conn:
        if not conn.execute("SELECT 1 FROM pg_database WHERE datname = %s", (name,)).fetchone():
            conn.execute(f'CREATE DATABASE "{name}"')


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(
        prog="python -m robotide.fleet",
        description=__doc__,
        formatter_class=argparse.RawDescriptionHelpFormatter,
    )
    parser.add_argument("-f", "--file", action="append", type=Path, dest="files")
    actions = parser.add_subparsers(dest="action")
    make = actions.add_parser(
        "secrets", help="generate docker compose's passwords into an env file, once"
    )
    make.add_argument(
        "--env-file",
        type=Path,
        default=ROOT / ".env",
        help="default: .env next to docker-compose.yml, which compose reads",
    )
    args = parser.parse_args(argv)
    if args.action == "secrets":
        before = args.env_file.read_text() if args.env_file.exists() else None
        secrets(args.env_file)
        done = "kept" if args.env_file.read_text() == before else "generated"
        print(f"{args.env_file}: {', '.join(SECRETS)} ({done}; "
              "mode 0600; keep it out of version control)")  # fmt: skip
        return 0

    data = Path(os.environ.get("FLEET_DATA", ROOT / "var" / "fleet")).resolve()
    data.mkdir(parents=True, exist_ok=True)
    passwords = secrets(data / "secrets.env")
    database, redis = os.environ.get("FLEET_DATABASE_URL"), os.environ.get("FLEET_REDIS_URL")
    servers = PrivateServers(data, passwords, postgres=not database, redis=not redis)
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    fleet = None
    try:
        servers.start()
        for name, port in servers.ports.items():
            print(f"fleet: its own {name} on 127.0.0.1:{port} (passwords in "
                  f"{data / 'secrets.env'}); log {data / (name + '.log')}", flush=True)  # fmt: skip
        if database:
            ensure_database(database)
        fleet = Fleet(
            args.files or [ROOT / "docker-compose.yml"],
            data=data,
            database=database or servers.database_url,
            redis=redis or servers.redis_url,
            host=os.environ.get("FLEET_HOST", "127.0.0.1"),
            variables={**os.environ, **passwords},
        )
        fleet.start()
        for service in fleet.services.values():
            print(f"fleet: {service.name} up ({' '.join(service.argv[1:])}); "
                  f"log {fleet.data / (service.name + '.log')}", flush=True)  # fmt: skip
        stop.wait()
    finally:
        if fleet is not None:
            fleet.stop()
        servers.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
