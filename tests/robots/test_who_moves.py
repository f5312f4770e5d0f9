"""Who may move a robot, and who may stop it: robot settings besides who may see it (its
classes). Refusals come before anything reaches the robot's agent (none runs here)."""

import pytest
from asgiref.sync import async_to_sync
from channels.layers import get_channel_layer
from django.contrib.auth.models import Group, User
from django.test import Client

from programs.models import Program, Run
from robotide.models import ClassTeacher
from robots.models import Robot, RobotStop
from tests.robots.test_run_queue import api

pytestmark = pytest.mark.django_db


@pytest.fixture(autouse=True)
def _quiet_layer():
    async_to_sync(get_channel_layer().flush)()


@pytest.fixture
def lab():
    """A class's robot: olga owns it (and sees it as its owner), tina teaches the class,
    sam is a student in it."""
    users = {n: User.objects.create_user(n) for n in ("olga", "tina", "sam")}
    users["staff"] = User.objects.create_superuser("staff")
    group = Group.objects.create(name="class-a")
    users["sam"].groups.add(group)
    ClassTeacher.objects.create(group=group, user=users["tina"])
    robot = Robot.objects.create(name="arm", url="sim://", owner=users["olga"])
    robot.groups.add(group)
    return users, robot


def program_of(user) -> Program:
    program = Program.objects.create(owner=user, name="p", language="python")
    program.save_source("print(1)\n", user)
    return program


@pytest.mark.parametrize(
    ("drive_by", "allowed"),
    [
        ("everyone", {"sam", "tina", "olga", "staff"}),
        ("teachers", {"tina", "olga", "staff"}),
        ("owner", {"olga", "staff"}),
    ],
)
def test_who_may_run_programs_on_it(lab, drive_by, allowed):
    users, robot = lab
    Robot.objects.filter(pk=robot.pk).update(drive_by=drive_by)
    for name, user in users.items():
        status, body = api(user)("POST", f"/api/programs/{program_of(user).pk}/run",
                                 {"robot": "arm"})  # fmt: skip
        if name in allowed:
            assert status == 201, (name, body)
        else:
            assert status == 403, (name, body)
            assert (
                body["detail"] == f"Only {Robot(drive_by=drive_by).get_drive_by_display()}"
                " may run programs on arm."
            )
    assert not Run.objects.filter(owner=users["sam"]).exists() or "sam" in allowed


def test_a_student_who_may_not_drive_is_told_so_on_the_pages(lab):
    users, robot = lab
    Robot.objects.filter(pk=robot.pk).update(drive_by="owner")
    client = Client()
    client.force_login(users["sam"])
    response = client.post("/robots/arm/run", {"program": program_of(users["sam"]).pk},
                           follow=True)  # fmt: skip
    assert "Only its owner and staff may run programs on arm." in response.content.decode()
    assert not Run.objects.exists()
    page = client.get("/robots/arm/").content.decode()
    assert "Drives it: its owner and staff (not you)" in page


def test_who_may_press_its_emergency_stop(lab):
    users, robot = lab
    Robot.objects.filter(pk=robot.pk).update(estop_by="owner")
    status, body = api(users["sam"])("POST", "/api/robots/arm/estop")
    assert status == 403 and "Only its owner and staff may press" in body["detail"], body
    assert not RobotStop.objects.exists()  # refused: nothing was pressed
    client = Client()
    client.force_login(users["sam"])
    page = client.get("/robots/arm/").content.decode()
    assert 'disabled title="Only its owner and staff may press it"' in page
    # The workbench's button (htmx): told why in words, not an error page.
    response = client.post("/robots/arm/estop", {"via": "workbench"}, HTTP_HX_REQUEST="true")
    assert response.status_code == 403
    assert response.content.decode() == "Only its owner and staff may press arm's emergency stop."
    assert not RobotStop.objects.exists()


def test_a_press_its_agent_misses_is_recorded_all_the_same(lab, settings):
    """Safety first: everyone who sees it may press it, and a press is never lost."""
    users, robot = lab
    status, body = api(users["sam"])("POST", "/api/robots/arm/estop")
    assert status == 503, body  # no agent runs here
    stop = RobotStop.objects.get()
    assert (stop.kind, stop.username, stop.via) == ("estop", "sam", "the API")
    assert stop.note.startswith("its agent was not reached")
    assert RobotStop.pressed(robot.pk) == stop


def test_who_may_resume_and_the_record_of_it(lab):
    users, robot = lab
    ran = [{"run": 7, "owner": "sam", "program": "p"}]
    RobotStop.objects.create(robot=robot, kind="estop", user=users["sam"], username="sam",
                             via="the API", runs=ran)  # fmt: skip
    other = User.objects.create_user("eve")
    other.groups.add(robot.groups.first())
    status, body = api(other)("POST", "/api/robots/arm/resume")
    assert status == 403, body
    assert RobotStop.pressed(robot.pk) is not None
    status, body = api(users["sam"])("POST", "/api/robots/arm/resume")  # who pressed it
    assert status == 200 and body == {"robot": "arm", "waiting": 0}, body
    assert RobotStop.pressed(robot.pk) is None
    assert list(RobotStop.objects.values_list("kind", "username")) == [
        ("resume", "sam"), ("estop", "sam"),
    ]  # fmt: skip
    staff = Client()
    staff.force_login(users["staff"])
    listing = staff.get("/admin/robots/robotstop/").content.decode()
    assert "#7 p (sam)" in listing and "resumed" in listing
    assert staff.get("/admin/robots/robotstop/add/").status_code == 403


def test_a_student_cannot_lift_a_teachers_stop_by_pressing_it_again(lab):
    """Whoever pressed a stop may lift it only while every press in force is theirs (else
    it takes staff or the robot's owner): a student pressing after the teacher did became
    "whoever pressed it", resumed the robot, and the queue the stop held moved."""
    users, robot = lab
    for who in ("tina", "sam"):  # the teacher's stop, then the student's press on top of it
        RobotStop.objects.create(robot=robot, kind="estop", user=users[who], username=who,
                                 via="the API")  # fmt: skip
    for who in ("sam", "tina"):
        status, body = api(users[who])("POST", "/api/robots/arm/resume")
        assert status == 403, (who, body)
    assert RobotStop.pressed(robot.pk) is not None  # still stopped
    status, body = api(users["olga"])("POST", "/api/robots/arm/resume")  # its owner may
    assert status == 200, body
    # After a resume, a stop only the student pressed is the student's to lift.
    RobotStop.objects.create(robot=robot, kind="estop", user=users["sam"], username="sam",
                             via="the API")  # fmt: skip
    status, body = api(users["sam"])("POST", "/api/robots/arm/resume")
    assert status == 200, body


def test_the_robot_page_says_it_is_stopped_and_who_may_resume(lab):
    users, robot = lab
    RobotStop.objects.create(robot=robot, kind="estop", user=users["sam"], username="sam",
                             via="the robot's page")  # fmt: skip
    for name, may in (("sam", True), ("olga", True), ("tina", False)):
        client = Client()
        client.force_login(users[name])
        page = client.get("/robots/arm/").content.decode()
        assert 'class="estopped" role="alert"' in page and "pressed by sam" in page
        assert ("Resume: let it move again" in page) == may, name
