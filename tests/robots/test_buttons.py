"""Manual commands on the robot page: set up by the robot's owner or staff, one click runs."""

import pytest
from django.contrib.auth.models import Group, User

from programs.models import Program, Run
from robotide.models import ClassTeacher
from robots.models import Robot, RobotButton

pytestmark = pytest.mark.django_db


@pytest.fixture
def owner():
    return User.objects.create_user("owner")


@pytest.fixture
def robot(owner):
    return Robot.objects.create(name="rover", url="sim://", owner=owner)


@pytest.fixture
def program(owner):
    return Program.objects.create(owner=owner, name="Dock", language="python", source="print(1)")


def test_the_owner_adds_a_button_with_arguments(client, owner, robot, program):
    client.force_login(owner)
    response = client.post(
        f"/robots/{robot.name}/buttons/",
        {"label": "Dock slowly", "program": program.pk, "arguments": '0.1 "bay two"',
         "position": 1},
    )  # fmt: skip
    assert response.status_code == 302, response.content.decode()
    button = RobotButton.objects.get()
    assert (button.label, button.args, button.program) == ("Dock slowly", ["0.1", "bay two"],
                                                           program)  # fmt: skip
    page = client.get(f"/robots/{robot.name}/buttons/?edit={button.pk}").content.decode()
    assert "0.1 &#x27;bay two&#x27;" in page  # shown again as it would be typed


def test_a_bad_argument_line_and_a_taken_label_are_refused(client, owner, robot, program):
    client.force_login(owner)
    RobotButton.objects.create(robot=robot, label="Dock", program=program)
    page = client.post(
        f"/robots/{robot.name}/buttons/",
        {"label": "Dock", "program": program.pk, "arguments": '"open', "position": 0},
    ).content.decode()
    assert "a button with that label already" in page
    assert "No closing quotation" in page
    assert RobotButton.objects.count() == 1


def test_only_the_owner_and_staff_set_up_buttons(client, robot, program):
    student = User.objects.create_user("student")
    client.force_login(student)
    assert client.get(f"/robots/{robot.name}/buttons/").status_code == 403
    other = Program.objects.create(owner=student, name="Mine", language="python")
    teacher = User.objects.create_user("teacher", is_staff=True)
    group = Group.objects.create(name="class-a")
    student.groups.add(group)
    ClassTeacher.objects.create(group=group, user=teacher)
    client.force_login(teacher)
    response = client.post(
        f"/robots/{robot.name}/buttons/",
        {"label": "Student's", "program": other.pk, "arguments": "", "position": 0},
    )
    assert response.status_code == 302  # a teacher may use their students' programs


def test_one_may_only_pick_ones_own_programs(client, owner, robot):
    client.force_login(owner)
    theirs = Program.objects.create(
        owner=User.objects.create_user("someone"), name="Theirs", language="python"
    )
    page = client.post(
        f"/robots/{robot.name}/buttons/",
        {"label": "X", "program": theirs.pk, "arguments": "", "position": 0},
    ).content.decode()
    assert "Select a valid choice" in page


def test_a_click_runs_the_program_with_its_arguments_as_the_clicker(
    client, robot, program, django_capture_on_commit_callbacks
):
    button = RobotButton.objects.create(robot=robot, label="Dock", program=program, args=["2"])
    student = User.objects.create_user("student")
    client.force_login(student)
    with django_capture_on_commit_callbacks():
        response = client.post(
            f"/robots/{robot.name}/buttons/{button.pk}/press", headers={"HX-Request": "true"}
        )
    run = Run.objects.get()
    assert (run.owner, run.program, run.robot, run.args) == (student, program, robot, ["2"])
    assert f"run #{run.pk}</a> started" in response.content.decode()
    assert client.get(f"/robots/{robot.name}/").status_code == 200
    client.logout()
    assert client.post(f"/robots/{robot.name}/buttons/{button.pk}/press").status_code == 302
    assert Run.objects.count() == 1
