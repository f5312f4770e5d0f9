"""docker-compose.yml checked against the project itself (Docker is not on these machines):
every robotide service's command and health check parse as the robotide command does, every
environment variable is one the code reads and the README documents, published ports match
what the command binds, health URLs resolve, dependencies and volumes exist. The commented
block for a real robot is checked too: it is what people copy. PostgreSQL and Redis ask for
the passwords of the generated env file, which nothing commits or builds into the image."""

import os
import re
import shutil
import socket
import subprocess
from pathlib import Path
from urllib.parse import urlsplit

import pytest
import redis
import yaml
from django.urls import resolve
from redis.backoff import NoBackoff
from redis.retry import Retry

from robotide.cli import build_parser
from robotide.fleet import load, robotide_services
from tests.appliance import free_port, wait_for

ROOT = Path(__file__).resolve().parent.parent
COMPOSE = ROOT / "docker-compose.yml"
# Read by the libraries we configure (dj-database-url, uvicorn), documented in the README.
READ_ELSEWHERE = {"DATABASE_URL", "FORWARDED_ALLOW_IPS"}
# What `make fleet-secrets` writes into .env, as compose reads it.
ENV_FILE = {"POSTGRES_PASSWORD": "pg-from-env-file", "REDIS_PASSWORD": "redis-from-env-file"}


def compose() -> dict:
    return yaml.safe_load(COMPOSE.read_text())


def copied_block() -> dict:
    """The commented example of a real robot, as someone uncommenting it gets it."""
    text = COMPOSE.read_text()
    block = re.search(r"^  # (agent-rover:\n(?:  #   .*\n)+)", text, re.M)
    assert block, "the example block for a real robot is gone"
    yaml_text = re.sub(r"^  #   ", "    ", block.group(1), flags=re.M)
    anchors = text[: text.index("services:")]  # the x-robotide anchor it merges
    return yaml.safe_load(anchors + "services:\n  " + yaml_text)["services"]


def services() -> dict:
    data = load([COMPOSE], ENV_FILE)
    return {**robotide_services(data), **copied_block()}


def variables_read_by_the_code() -> set[str]:
    names = set()
    for path in [
        *ROOT.glob("robotide/*.py"),
        *ROOT.glob("robots/*.py"),
        *ROOT.glob("programs/*.py"),
    ]:
        text = path.read_text()
        names |= set(
            re.findall(r"""(?:environ(?:\.get)?[(\[]|env_\w+\()\s*["']([A-Z][A-Z0-9_]+)""", text)
        )
    return names


def documented() -> set[str]:
    readme = (ROOT / "README.md").read_text()
    return set(re.findall(r"`([A-Z][A-Z0-9_]+)`", readme))


@pytest.mark.parametrize("name", sorted(services()))
def test_each_robotide_service_runs_a_real_command(name):
    service = services()[name]
    command = service["command"]
    assert command[0] == "robotide"
    args = build_parser().parse_args(command[1:])  # SystemExit on anything unknown
    if args.command == "up":
        port = args.bind.rpartition(":")[2]
        assert args.bind.startswith("0.0.0.0:"), "a container must listen beyond its loopback"
        assert any(p.split(":")[-1] == port for p in service["ports"]), (port, service["ports"])
    if args.command == "agent":
        assert args.names or args.sim, "an agent serves at least one robot"


@pytest.mark.parametrize("name", sorted(services()))
def test_each_variable_is_read_by_the_code_and_documented(name):
    environment = services()[name].get("environment") or {}
    assert environment, "the robotide services all have the shared environment"
    read, described = variables_read_by_the_code() | READ_ELSEWHERE, documented()
    for variable in environment:
        assert variable in read, f"{variable} is read by nothing in robotide"
        assert variable in described, f"{variable} is not in the README's settings"
    assert {"DATABASE_URL", "REDIS_URL", "ROBOTIDE_DATA"} <= set(environment)


@pytest.mark.parametrize("name", sorted(services()))
def test_health_checks_ask_what_exists(name):
    test = (services()[name].get("healthcheck") or {}).get("test")
    assert test and test[0] == "CMD", "every robotide service says when it is healthy"
    if test[1] == "robotide":
        build_parser().parse_args(test[2:])
    else:
        urls = re.findall(r"http://127\.0\.0\.1:(\d+)(/[^'\")\s]*)", " ".join(test))
        assert urls, test
        port, path = urls[0]
        assert resolve(path).url_name == "healthz"
        bind = services()[name]["command"][-1]
        assert bind.endswith(f":{port}")


def test_dependencies_volumes_and_the_image():
    data = compose()
    names = set(data["services"])
    for name, service in {**data["services"], **copied_block()}.items():
        for dependency, rule in (service.get("depends_on") or {}).items():
            assert dependency in names, f"{name} depends on unknown {dependency}"
            if rule.get("condition") == "service_healthy":
                assert "healthcheck" in data["services"][dependency], dependency
        for volume in service.get("volumes") or []:
            source = volume.split(":")[0]
            if not source.startswith(("/", ".")):
                assert source in data["volumes"], f"{name}: volume {source} is not declared"
    web = data["services"]["web"]
    assert int(web["environment"]["ROBOTIDE_WEB_WORKERS"].split(":-")[1].rstrip("}")) > 1
    dockerfile = (ROOT / "Dockerfile").read_text()
    cmd = re.search(r"^CMD (\[.*\])$", dockerfile, re.M).group(1)
    build_parser().parse_args(yaml.safe_load(cmd)[1:])


def test_a_robot_is_added_by_a_block_or_scaled_by_a_setting():
    agents = [s for s in services().values() if s["command"][1] == "agent"]
    assert any("ROBOTIDE_SIM_ROBOTS" in (s.get("environment") or {}) for s in agents)
    rover = copied_block()["agent-rover"]
    args = build_parser().parse_args(rover["command"][1:])
    assert args.names == ["rover"] and args.url.startswith("mavlink://")
    assert rover["devices"]


# -- passwords ----------------------------------------------------------------------------------


def test_the_servers_and_their_clients_take_the_passwords_from_the_env_file():
    data = load([COMPOSE], ENV_FILE)
    postgres, cache = data["postgres"]["environment"], data["redis"]
    assert postgres["POSTGRES_PASSWORD"] == ENV_FILE["POSTGRES_PASSWORD"]
    assert postgres["POSTGRES_HOST_AUTH_METHOD"] == "scram-sha-256"
    assert cache["environment"]["REDISCLI_AUTH"] == ENV_FILE["REDIS_PASSWORD"]
    assert "requirepass $REDISCLI_AUTH" in cache["command"][-1]  # $$ in the file: for sh
    for name, service in robotide_services(data).items():
        database = urlsplit(service["environment"]["DATABASE_URL"])
        channels = urlsplit(service["environment"]["REDIS_URL"])
        assert database.password == ENV_FILE["POSTGRES_PASSWORD"], name
        assert channels.password == ENV_FILE["REDIS_PASSWORD"], name


def test_no_password_is_written_in_the_file():
    text = COMPOSE.read_text()
    raw = yaml.safe_load(text)
    for name, service in {**raw["services"], "x-robotide": raw["x-robotide"]}.items():
        for key, value in (service.get("environment") or {}).items():
            if "PASSWORD" in key or key.endswith("_AUTH") or key.endswith("_URL"):
                password = urlsplit(value).password if "://" in value else value
                assert password is None or password.startswith("${"), (name, key)
    settings = [line for line in text.splitlines() if not line.lstrip().startswith("#")]
    assert not re.search(r"requirepass\s+[^$\s]", "\n".join(settings))
    assert "robotide:robotide@" not in text


def test_without_the_env_file_compose_stops_and_says_how_to_make_it():
    with pytest.raises(SystemExit, match="make fleet-secrets"):
        load([COMPOSE], {})
    makefile = (ROOT / "Makefile").read_text()
    assert re.search(r"^fleet-secrets:", makefile, re.M)
    assert "make fleet-secrets" in (ROOT / "README.md").read_text()


def test_fleet_secrets_makes_the_env_file_once_for_the_owner_alone(tmp_path):
    """As an operator with only python3 and a checkout: nothing from the venv needed."""
    env_file = tmp_path / ".env"
    command = ["python3", "-m", "robotide.fleet", "secrets", "--env-file", str(env_file)]
    clean = {"PATH": os.environ["PATH"], "HOME": str(tmp_path)}
    subprocess.run(command, cwd=ROOT, env=clean, check=True, capture_output=True)
    first = env_file.read_text()
    assert env_file.stat().st_mode & 0o777 == 0o600
    values = dict(line.split("=", 1) for line in first.splitlines() if not line.startswith("#"))
    assert set(values) == set(ENV_FILE) and all(len(v) >= 32 for v in values.values())
    assert len(set(values.values())) == 2
    subprocess.run(command, cwd=ROOT, env=clean, check=True, capture_output=True)
    assert env_file.read_text() == first, "generated once, then kept"
    theirs = tmp_path / "theirs.env"  # an operator's .env already there: added to, kept
    theirs.write_text("# lab settings\nROBOTIDE_SIM_ROBOTS=3\n")
    command[-1] = str(theirs)
    subprocess.run(command, cwd=ROOT, env=clean, check=True, capture_output=True)
    lines = theirs.read_text().splitlines()
    assert lines[:2] == ["# lab settings", "ROBOTIDE_SIM_ROBOTS=3"] and len(lines) == 4
    assert theirs.stat().st_mode & 0o777 == 0o600
    for ignore in (".gitignore", ".dockerignore"):  # not in git, not in the image
        assert ".env" in (ROOT / ignore).read_text().split(), ignore


def test_the_redis_service_asks_for_its_password_and_its_health_check_gives_it(tmp_path):
    """The compose file's redis command and health check, run here: the image's entrypoint
    stood in for by one that adds a free port."""
    cache = load([COMPOSE], ENV_FILE)["redis"]
    port = free_port()
    entrypoint = tmp_path / "docker-entrypoint.sh"
    entrypoint.write_text(f'#!/bin/sh\nexec "$@" --port {port} --bind 127.0.0.1\n')
    entrypoint.chmod(0o755)
    env = {"PATH": f"{tmp_path}:{os.environ['PATH']}", **cache["environment"]}
    server = subprocess.Popen(cache["command"], env=env, stdout=subprocess.DEVNULL)
    try:
        password = ENV_FILE["REDIS_PASSWORD"]
        wait_for(lambda: socket.create_connection(("127.0.0.1", port)).close() or True,
                 what="redis listening")  # fmt: skip
        assert redis.Redis(port=port, password=password).ping()
        with pytest.raises(redis.AuthenticationError):
            redis.Redis(port=port, retry=Retry(NoBackoff(), 0)).ping()  # at once, not in 4 s
        health = cache["healthcheck"]["test"]
        assert health[0] == "CMD-SHELL" and shutil.which("redis-cli")
        check = health[1].replace("redis-cli", f"redis-cli -p {port}")
        assert subprocess.run(["sh", "-c", check], env=env).returncode == 0
        no_password = {k: v for k, v in env.items() if k != "REDISCLI_AUTH"}
        assert subprocess.run(["sh", "-c", check], env=no_password).returncode != 0
    finally:
        server.terminate()
        server.wait(10)
