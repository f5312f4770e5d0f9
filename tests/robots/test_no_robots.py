"""A student whose classes have no robot (issue 29, item 5): every page and answer says why and
what to ask for (robots.availability), where it said "No robots yet." though robots exist,
showed an empty robot list, and answered Run with a 404. Staff, where there is no robot at
all, are told how to add one."""

import html

import pytest
from django.contrib.auth.models import Group, User
from django.test import Client
from django.urls import reverse

from programs.models import Program
from robots.models import Robot
from tests.robots.test_run_queue import api

pytestmark = pytest.mark.django_db

WHY = "none of your classes has one"
ASK = "Ask your teacher to add a robot to your class."


@pytest.fixture(autouse=True)
def _no_personal_sims(settings):
    """As a server with personal sims switched off: a student whose classes have no robot has
    none at all (with them on, "My sim" is hers: tests/robots/test_sims.py)."""
    settings.SIMS_PER_USER = 0


@pytest.fixture
def nora():
    """A student of class-a; the one robot belongs to class-b."""
    student = User.objects.create_user("nora")
    student.groups.add(Group.objects.create(name="class-a"))
    robot = Robot.objects.create(name="sim", url="sim://")
    robot.groups.add(Group.objects.create(name="class-b"))
    return student


def client_of(user) -> Client:
    client = Client()
    client.force_login(user)
    return client


def program_of(user) -> Program:
    program = Program.objects.create(owner=user, name="Hello", language="python")
    program.save_source("print('hello')\n", user)
    return program


def page(client, url) -> str:
    response = client.get(url)
    assert response.status_code == 200
    return html.unescape(response.content.decode())


def test_the_robot_list_says_why_it_is_empty(nora):
    listing = page(client_of(nora), "/robots/")
    assert WHY in listing and ASK in listing and "No robots yet." not in listing


def test_the_reason_in_portuguese(nora):
    client = Client(HTTP_ACCEPT_LANGUAGE="pt-br")
    client.force_login(nora)
    listing = html.unescape(client.get("/robots/").content.decode())
    assert "nenhuma das suas turmas tem um" in listing and "Peça ao seu professor" in listing


def test_the_workbench_disables_run_and_says_why(nora):
    program = program_of(nora)
    editor = page(client_of(nora), reverse("program-edit", args=[program.pk]))
    assert 'id="no-robot"' in editor and WHY in editor
    start = editor.index('value="run"')
    run_button = editor[start : editor.index("</button>", start)]
    assert "disabled" in run_button and 'title="No robot is open to you yet' in run_button
    select = editor[editor.index('id="bench-robot-choice"') :]
    assert select[: select.index(">")].count("disabled") == 1
    assert "none open to you" in select[: select.index("</select>")]
    estop = editor[editor.index('id="bench-estop"') :]
    assert "disabled" in estop[: estop.index(">")]  # no robot to stop


def test_run_answers_why_not_a_404(nora):
    program = program_of(nora)
    client = client_of(nora)
    # The workbench (scripts on): its console answer is the reason, which the page says.
    started = client.post(
        reverse("program-start", args=[program.pk]),
        {"source": program.source, "language": "python", "robot": ""},
    )
    assert started.status_code == 400 and WHY in started.json()["error"]
    # Scripts off: the form's Run is a page with the reason.
    ran = client.post(
        reverse("program-edit", args=[program.pk]),
        {"source": program.source, "language": "python", "action": "run"},
        follow=True,
    )
    assert ran.status_code == 200 and WHY in html.unescape(ran.content.decode())
    # The program list's Run, and the robot named by hand.
    ran = client.post(reverse("program-run", args=[program.pk]), {"robot": "sim"}, follow=True)
    assert ran.status_code == 200 and WHY in html.unescape(ran.content.decode())
    # The API: 409 with the reason.
    status, answer = api(nora)("POST", f"/api/programs/{program.pk}/run", {"robot": "sim"})
    assert status == 409 and WHY in answer["detail"] and ASK in answer["detail"]


def test_staff_are_told_there_are_no_robots_and_how_to_add_one():
    teacher = User.objects.create_user("tess", is_staff=True, is_superuser=True)
    listing = page(client_of(teacher), "/robots/")
    assert "There are no robots yet. Add one in the administration" in listing
    assert reverse("admin:robots_robot_changelist") in listing
    status, answer = api(teacher)(
        "POST", f"/api/programs/{program_of(teacher).pk}/run", {"robot": "sim"}
    )
    assert status == 409 and "There are no robots yet" in answer["detail"]


def test_a_robot_not_there_is_still_a_404_to_one_who_has_robots(nora):
    Robot.objects.create(name="open", url="sim://")  # no class: open to everyone
    program = program_of(nora)
    status, _ = api(nora)("POST", f"/api/programs/{program.pk}/run", {"robot": "sim"})
    assert status == 404
