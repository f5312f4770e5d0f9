"""A robot's settings and URL (device paths, hosts, credentials) are shown to its owner and
staff only: in the API's list and detail, on the robot list and on the robot's page. A student
who may use the robot sees the kind of robot it is, no settings (issue 28, item 7)."""

import pytest
from django.contrib.auth.models import User

from robots.models import Robot
from tests.robots.test_run_queue import api, signed_in

pytestmark = pytest.mark.django_db

# What a real robot's setup holds, that only those who look after it may read.
PRIVATE = ("/dev/ttyUSB7", "/dev/video3", "hunter2", "10.0.0.5")


@pytest.fixture
def lab():
    users = {
        "olga": User.objects.create_user("olga"),  # owns the robots
        "sam": User.objects.create_user("sam"),  # a student: may use them
        "staff": User.objects.create_user("staff", is_staff=True),
    }
    Robot.objects.create(
        name="arm", url="pioneer:///dev/ttyUSB7?baud=9600", owner=users["olga"],
        settings={"max_linear": 0.4, "camera": {"device": "/dev/video3"}},
    )  # fmt: skip
    Robot.objects.create(
        name="drone", url="mavlink+tcp://pilot:hunter2@10.0.0.5:5760", owner=users["olga"]
    )
    return users


def robots_in_api(user) -> tuple[dict, str]:
    """Each robot of GET /api/robots, by name, with its GET /api/robots/{name} besides."""
    call = api(user)
    status, listed = call("GET", "/api/robots")
    assert status == 200, listed
    robots = {robot["name"]: robot for robot in listed}
    for name in ("arm", "drone"):
        status, robots[f"{name} alone"] = call("GET", f"/api/robots/{name}")
        assert status == 200
    return robots, repr(robots)


def test_a_student_sees_no_settings_and_only_the_driver_of_a_url(lab):
    robots, text = robots_in_api(lab["sam"])
    for key in ("arm", "arm alone"):
        assert robots[key]["settings"] == {} and robots[key]["url"] == "pioneer://"
    for key in ("drone", "drone alone"):
        assert robots[key]["url"] == "mavlink+tcp://"
    assert not [secret for secret in PRIVATE if secret in text], text


@pytest.mark.parametrize("who", ["olga", "staff"])
def test_its_owner_and_staff_see_its_settings_but_never_a_password(lab, who):
    robots, text = robots_in_api(lab[who])
    for key in ("arm", "arm alone"):
        assert robots[key]["url"] == "pioneer:///dev/ttyUSB7?baud=9600"
        assert robots[key]["settings"] == {
            "max_linear": 0.4,
            "camera": {"device": "/dev/video3"},
        }
    for key in ("drone", "drone alone"):
        assert robots[key]["url"] == "mavlink+tcp://pilot:***@10.0.0.5:5760"
    assert "hunter2" not in text


def test_the_pages_show_a_student_no_settings(lab):
    client = signed_in(lab["sam"])
    listing = client.get("/robots/").content.decode()
    page = client.get("/robots/arm/").content.decode()
    assert "<code>pioneer://</code>" in listing and "<code>pioneer://</code>" in page
    assert "Shown to its owner and staff only." in page
    assert not [secret for secret in PRIVATE if secret in listing + page]


def test_the_pages_show_its_owner_its_settings(lab):
    client = signed_in(lab["olga"])
    listing = client.get("/robots/").content.decode()
    page = client.get("/robots/arm/").content.decode()
    assert "pioneer:///dev/ttyUSB7?baud=9600" in listing and "10.0.0.5" in listing
    assert "pioneer:///dev/ttyUSB7?baud=9600" in page
    assert "<code>max_linear</code></th><td>0.4</td>" in page
    assert "hunter2" not in listing + page
