"""How a robot's programs are boxed (issue 29, items 9 and 12): the administrator's line, with
the machine's cgroup paths and names, for the robot's owner and staff only; one plain sentence
for students, on the page and in the API. In pt-BR the line is said again from its parts: no
path translated word by word, no English left of the English line."""

import re
from pathlib import Path

import pytest
from django.contrib.auth.models import User
from django.test import Client
from django.utils import translation

from robots.isolation_words import isolation_shown
from robots.models import Robot
from runbox.cgroups import CgroupSupport
from runbox.isolation import InForce, Policy
from runbox.launcher import Limits
from runbox.share import RunsParent
from tests.robots.test_run_queue import api

pytestmark = pytest.mark.django_db

PATH = "/sys/fs/cgroup/memory/user.slice/robotide-runs-1a2b3c4d"
ROOTLESS = (
    "rootless box (user namespaces), own user namespace, seccomp, network loopback;"
    f" no cgroups: robotide is not root and cannot write to {PATH}"
    " (run it in a systemd unit with Delegate=yes) — per-process rlimits only: each process at"
    " most 1024 MB, at most 64 processes, one run at a time; no run-wide memory limit: no"
    " delegated cgroup"
)
ROOTED = (
    "sandbox (bubblewrap), own OS account, seccomp, network full; no cgroups: the runs' parent"
    " cgroup robotide-runs-1a2b3c4d could not be made: [Errno 30] Read-only file system —"
    " per-process rlimits only: one run at a time; no run-wide memory limit"
)
# Technical names a pt-BR reader meets as they are (a tool, a kernel feature, a unit).
TERMS = {
    "sandbox", "bubblewrap", "seccomp", "cgroup", "cgroups", "rlimits", "loopback", "swap",
    "cpu", "mb", "root", "robotide", "systemd", "delegate", "yes", "namespace", "namespaces",
}  # fmt: skip
PT = {"HTTP_ACCEPT_LANGUAGE": "pt-br"}


@pytest.fixture
def lab():
    users = {
        "olga": User.objects.create_user("olga"),  # owns the robot
        "sam": User.objects.create_user("sam"),  # a student: may use it
        "staff": User.objects.create_user("staff", is_staff=True),
    }
    Robot.objects.create(name="arm", url="sim://", owner=users["olga"], isolation=ROOTLESS)
    return users


def robot_page(user, **headers) -> str:
    client = Client(**headers)
    client.force_login(user)
    response = client.get("/robots/arm/")
    assert response.status_code == 200
    return response.content.decode()


def isolation_span(page: str) -> str:
    return re.search(r'<span class="isolation"[^>]*>(.*?)</span>', page, re.S).group(1)


def test_a_student_sees_one_plain_sentence_and_no_path_or_cgroup_name(lab):
    sentences = (({}, "Programs run in a sandbox"), (PT, "Os programas rodam numa sandbox"))
    for headers, sentence in sentences:
        page = robot_page(lab["sam"], **headers)
        assert sentence in isolation_span(page)
        assert "/sys/fs/cgroup" not in page and "1a2b3c4d" not in page, isolation_span(page)
        assert "rlimits" not in page
    status, robot = api(lab["sam"])("GET", "/api/robots/arm")
    assert status == 200 and robot["isolation"].startswith("Programs run in a sandbox")
    assert "/sys/fs/cgroup" not in robot["isolation"]


@pytest.mark.parametrize("who", ["olga", "staff"])
def test_its_owner_and_staff_see_the_whole_line(lab, who):
    assert PATH in isolation_span(robot_page(lab[who]))
    status, robot = api(lab[who])("GET", "/api/robots/arm")
    assert status == 200 and robot["isolation"] == ROOTLESS  # as runbox wrote it


def test_a_student_is_not_told_why_runs_cannot_start_here(lab):
    Robot.objects.filter(name="arm").update(isolation=f"cannot write to {PATH}")
    span = isolation_span(robot_page(lab["sam"]))
    assert PATH not in span and "its owner or staff can see why" in span


@pytest.mark.parametrize("line", [ROOTLESS, ROOTED])
def test_the_portuguese_line_keeps_paths_and_leaves_no_english(line):
    with translation.override("en"):
        english = isolation_shown(line)
    with translation.override("pt-br"):
        portuguese = isolation_shown(line)
    # Paths, cgroup names and numbers as they are, never a word inside them translated.
    for kept in (PATH, "robotide-runs-1a2b3c4d", "1024", "64"):
        assert (kept in portuguese) == (kept in line), kept
    assert "memória/" not in portuguese and "memória" in portuguese

    # No English word of the English line in the Portuguese one (paths and names aside).
    def words(text: str) -> set[str]:
        text = re.sub(r"\S*/\S*|robotide-runs-\w+|\[Errno \d+\][^—]*", " ", text)
        return {w.lower() for w in re.findall(r"[A-Za-z][A-Za-z+]+", text)}

    left = (words(portuguese) & words(english)) - TERMS - {"de", "a", "no"}
    assert not left, (left, portuguese)


def test_every_line_runbox_writes_is_read_back_whole():
    """runbox's phrases and these patterns agree: a line of each kind parses, part by part."""
    from robots.isolation_words import parts  # new with the line said from its parts

    parent = RunsParent("robotide-runs-1a2b3c4d", 3 * 1024**3, 2048, 50)
    supports = [
        None,
        CgroupSupport("v2", ("memory", "swap", "pids", "cpu", "kill"), parent=parent),
        CgroupSupport("v1", ("memory", "swap", "pids", "cpu", "cpuacct", "freezer")),
        CgroupSupport(None, why="no memory cgroup controller is mounted"),
        CgroupSupport(None, why=f"robotide is not root and cannot write to {PATH}"),
        CgroupSupport(None, why="cannot read /proc/self/cgroup: No such file or directory"),
    ]
    for rootless in (False, True):
        for network in ("none", "loopback", "full"):
            for support in supports:
                in_force = InForce(Policy(network=network), Path("/c"), rootless, support)
                for limits in (None, Limits()):
                    line = in_force.describe(limits)
                    parts(line)  # Unknown if any part were not read
                    with translation.override("pt-br"):
                        assert isolation_shown(line) != line
