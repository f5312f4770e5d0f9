"""Names may not hold control or text-direction characters (robotide.names): every API call
that takes a name answers 422 saying which character, and the pages' forms say so too
(issue 28, item 6). On PostgreSQL too: tests/e2e/test_names_databases.py."""

import io
import json
import zipfile

import pytest
from django.contrib.auth.models import Group, User
from django.core.files.uploadedfile import SimpleUploadedFile
from django.test import Client

from programs.models import Program
from robotide.models import ApiToken
from robots.models import Robot, RobotButton

pytestmark = pytest.mark.django_db

BAD = "x\u0000y"


def calls(program_id: int, bad: str = BAD) -> list[tuple[str, str, dict | None]]:
    """Every API call that takes a name, with ``bad`` as that name: (method, path, body).
    ``program_id``: a program of the caller's; the robot "sim" and the class "class-a" exist."""
    path_bad = bad.replace("\u0000", "%00")
    robot_gets = ["", "/sensors", "/endpoints", "/recordings", "/bridges"]
    return [
        ("POST", "/api/programs", {"name": bad, "language": "python", "source": ""}),
        ("PUT", f"/api/programs/{program_id}", {"name": bad}),
        ("POST", f"/api/programs/{program_id}/copy", {"name": bad}),
        ("POST", f"/api/programs/{program_id}/shares", {"user": bad}),
        ("POST", f"/api/programs/{program_id}/shares", {"group": bad}),
        ("POST", f"/api/programs/{program_id}/run", {"robot": bad}),
        ("POST", "/api/runs/queue/resume", {"robot": bad}),
        ("GET", f"/api/runs?robot={path_bad}", None),
        ("POST", "/api/robots", {"name": bad, "url": "sim://"}),
        *[("GET", f"/api/robots/{path_bad}{tail}", None) for tail in robot_gets],
        ("POST", f"/api/robots/{path_bad}/estop", None),
        ("POST", f"/api/robots/{path_bad}/resume", None),
        ("PATCH", f"/api/robots/{path_bad}", {"description": "d"}),
        ("POST", f"/api/robots/{path_bad}/endpoints", {"type": "udp"}),
        ("GET", f"/api/robots/sim/recordings/{path_bad}.tlog", None),
        ("POST", "/api/groups", {"name": bad}),
        ("POST", f"/api/groups/{path_bad}/members", {"user": "staff"}),
        ("POST", "/api/groups/class-a/members", {"user": bad}),
        ("POST", "/api/tokens", {"name": bad}),
    ]


def says_which_character(body: dict, bad: str = BAD) -> bool:
    char = next(c for c in bad if c not in "xy")
    return f"U+{ord(char):04X}" in str(body["detail"])


@pytest.fixture
def staff():
    user = User.objects.create_user("staff", password="pw-staff-123", is_staff=True)
    Robot.objects.create(name="sim", url="sim://")
    Group.objects.create(name="class-a")
    return user


def program_of(user) -> Program:
    program = Program.objects.create(owner=user, name="p", language="python")
    program.save_source("print(1)\n", user)
    return program


@pytest.mark.parametrize("bad", [BAD, "x\u202ey", "x\u2028y", "x\u001by"])
def test_every_api_call_taking_a_name_refuses_one_with_a_control_character(staff, bad):
    _, token = ApiToken.issue(staff)
    client = Client(HTTP_AUTHORIZATION=f"Bearer {token}")
    session = Client()
    session.force_login(staff)  # /api/tokens: a session's only
    program = program_of(staff)
    programs = set(Program.objects.values_list("name", flat=True))
    wrong = []
    for method, path, body in calls(program.pk, bad):
        caller = session if path == "/api/tokens" else client
        response = getattr(caller, method.lower())(path, body, content_type="application/json")
        if response.status_code != 422 or not says_which_character(response.json(), bad):
            wrong.append((method, path, response.status_code, response.content[:200]))
    assert not wrong, wrong
    assert set(Program.objects.values_list("name", flat=True)) == programs
    assert not ApiToken.objects.exclude(name="").exists()


def test_a_name_with_spaces_around_it_or_in_it_is_still_taken(staff):
    _, token = ApiToken.issue(staff)
    client = Client(HTTP_AUTHORIZATION=f"Bearer {token}")
    body = {"name": " my  robot\u00a0walk ", "language": "python", "source": ""}
    response = client.post("/api/programs", body, content_type="application/json")
    assert response.status_code == 201 and response.json()["name"] == "my  robot\u00a0walk"


def test_the_pages_forms_say_why_a_name_is_refused(staff):
    client = Client()
    client.force_login(staff)
    page = client.post("/programs/new", {"name": "x\u202ey", "language": "python"})
    assert page.status_code == 400 and "U+202E" in page.content.decode()
    program = program_of(staff)
    programs = set(Program.objects.values_list("name", flat=True))
    page = client.post(
        f"/programs/{program.pk}/",
        {"action": "save_as", "save_as": "x\u0007y", "source": "", "language": "python"},
    )
    assert "U+0007" in page.content.decode()
    page = client.post("/accounts/", {"name": "x\u001by"})
    assert "U+001B" in page.content.decode()
    page = client.post(
        "/robots/sim/buttons/", {"label": "go\u2028now", "program": program.pk, "position": 0}
    )
    assert "U+2028" in page.content.decode()
    assert set(Program.objects.values_list("name", flat=True)) == programs
    assert not RobotButton.objects.exists() and not ApiToken.objects.exists()


def test_an_imported_programs_name_loses_the_characters_a_name_may_not_hold(staff):
    """A zip's manifest was never checked as names are: its names are cleaned, not refused
    (the rest of the zip would be lost with them)."""
    manifest = {"format": "robotide-programs", "version": 1, "programs": [
        {"name": "dri\u202eve\u0000r", "language": "python", "file": "d.py"}]}  # fmt: skip
    data = io.BytesIO()
    with zipfile.ZipFile(data, "w") as zf:
        zf.writestr("manifest.json", json.dumps(manifest))
        zf.writestr("d.py", "print(1)\n")
    _, token = ApiToken.issue(staff)
    client = Client(HTTP_AUTHORIZATION=f"Bearer {token}")
    upload = SimpleUploadedFile("programs.zip", data.getvalue(), "application/zip")
    for replace in ("false", "true"):  # the latter looks its name up among the user's
        response = client.post("/api/programs/import", {"file": upload, "replace": replace})
        assert response.status_code == 200, response.content
        upload.seek(0)
    assert Program.objects.filter(owner=staff, name="driver").count() == 1


@pytest.mark.parametrize("model", ["programs/program", "auth/group"])
def test_the_admin_says_why_a_name_is_refused(staff, model):
    staff.is_superuser = True
    staff.save()
    client = Client()
    client.force_login(staff)
    before = Program.objects.count(), Group.objects.count()
    page = client.post(f"/admin/{model}/add/", {"name": "x\u202ey", "language": "python"})
    assert page.status_code == 200 and "U+202E" in page.content.decode()
    assert (Program.objects.count(), Group.objects.count()) == before
