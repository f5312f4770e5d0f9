"""The compose file's robotide services, run natively: `make fleet` (python -m robotide.fleet).

Where Docker is not at hand, this starts the same commands with the same environment as
docker-compose.yml, on this machine: the local PostgreSQL and Redis stand in for the postgres
and redis services (FLEET_DATABASE_URL, FLEET_REDIS_URL), ROBOTIDE_DATA is one folder for all
(FLEET_DATA, default var/fleet: the volumes), and published ports go to loopback (FLEET_HOST).
Services start in dependency order, each once the ones it depends on are healthy by their own
health check; one that exits is started again if its ``restart`` says so. Ctrl-C stops all.

    .venv/bin/python -m robotide.fleet [-f docker-compose.yml] [-f more.yml]
"""

from __future__ import annotations

import argparse
import os
import re
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlsplit, urlunsplit

import yaml

ROOT = Path(__file__).resolve().parent.parent
BACKING = ("postgres", "redis")  # compose services the machine's own servers stand in for
_VARIABLE = re.compile(r"\$\{(\w+)(?::?-([^}]*))?\}")


def load(files: list[Path], variables: dict | None = None) -> dict[str, dict]:
    """The services of the compose files, later files overriding earlier ones, with
    ``${VAR:-default}`` replaced from ``variables`` (default: this environment)."""
    variables = os.environ if variables is None else variables
    services: dict[str, dict] = {}
    for path in files:
        data = yaml.safe_load(path.read_text()) or {}
        for name, service in (data.get("services") or {}).items():
            services[name] = {**services.get(name, {}), **(service or {})}
    return _interpolate(services, variables)


def _interpolate(value, variables):
    if isinstance(value, str):
        return _VARIABLE.sub(lambda m: variables.get(m.group(1)) or (m.group(2) or ""), value)
    if isinstance(value, list):
        return [_interpolate(item, variables) for item in value]
    if isinstance(value, dict):
        return {key: _interpolate(item, variables) for key, item in value.items()}
    return value


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
    parser = argparse.ArgumentParser(prog="python -m robotide.fleet", description=__doc__)
    parser.add_argument("-f", "--file", action="append", type=Path, dest="files")
    args = parser.parse_args(argv)
    database = os.environ.get(
        "FLEET_DATABASE_URL", "postgresql://postgres@127.0.0.1:5432/robotide_fleet"
    )
    ensure_database(database)
    fleet = Fleet(
        args.files or [ROOT / "docker-compose.yml"],
        data=Path(os.environ.get("FLEET_DATA", ROOT / "var" / "fleet")).resolve(),
        database=database,
        redis=os.environ.get("FLEET_REDIS_URL", "redis://127.0.0.1:6379/1"),
        host=os.environ.get("FLEET_HOST", "127.0.0.1"),
    )
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    try:
        fleet.start()
        for service in fleet.services.values():
            print(f"fleet: {service.name} up ({' '.join(service.argv[1:])}); "
                  f"log {fleet.data / (service.name + '.log')}", flush=True)  # fmt: skip
        stop.wait()
    finally:
        fleet.stop()
    return 0


if __name__ == "__main__":
    sys.exit(main())
