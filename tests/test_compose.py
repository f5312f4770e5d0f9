"""docker-compose.yml checked against the project itself (Docker is not on these machines):
every robotide service's command and health check parse as the robotide command does, every
environment variable is one the code reads and the README documents, published ports match
what the command binds, health URLs resolve, dependencies and volumes exist. The commented
block for a real robot is checked too: it is what people copy."""

import re
from pathlib import Path

import pytest
import yaml
from django.urls import resolve

from robotide.cli import build_parser
from robotide.fleet import load, robotide_services

ROOT = Path(__file__).resolve().parent.parent
COMPOSE = ROOT / "docker-compose.yml"
# Read by the libraries we configure (dj-database-url, uvicorn), documented in the README.
READ_ELSEWHERE = {"DATABASE_URL", "FORWARDED_ALLOW_IPS"}


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
    data = load([COMPOSE])
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
