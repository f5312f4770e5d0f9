"""The admin site of a lab: its pages, searches and filters, and its actions."""

import pytest
from django.contrib.admin.helpers import ACTION_CHECKBOX_NAME
from django.contrib.auth.models import Group, User

from programs.models import Program, Run, Share
from robotide.models import ClassTeacher
from robots.models import Robot, robots_for_user
from tests.admin_inlines import no_inline_rows

pytestmark = pytest.mark.django_db


@pytest.fixture
def admin_user(client):
    user = User.objects.create_superuser("boss", password="pw")
    client.force_login(user)
    return user


@pytest.fixture
def lab(admin_user):
    alice = User.objects.create_user("alice", password="pw")
    bob = User.objects.create_user("bob", password="pw")
    carol = User.objects.create_user("carol", password="pw")
    klass = Group.objects.create(name="5b")
    klass.user_set.add(alice, bob)
    ClassTeacher.objects.create(group=klass, user=carol)
    robot = Robot.objects.create(name="rover", url="sim://")
    program = Program.objects.create(owner=alice, name="square", language="python")
    program.save_source("print('square')\n", alice)
    other = Program.objects.create(owner=bob, name="circle", language="python")
    run = Run.create_for(program, robot, alice)
    Run.objects.filter(pk=run.pk).update(state=Run.State.RUNNING)
    done = Run.create_for(other, robot, bob)
    Run.objects.filter(pk=done.pk).update(state=Run.State.FINISHED)
    return {
        "alice": alice, "bob": bob, "carol": carol, "klass": klass, "robot": robot,
        "program": program, "other": other, "run": run, "done": done,
    }  # fmt: skip


@pytest.mark.parametrize(
    "url",
    [
        "/admin/",
        "/admin/auth/user/",
        "/admin/auth/user/?q=ali&teaching__group__id__exact=1",
        "/admin/auth/group/",
        "/admin/auth/group/?q=5b",
        "/admin/robots/robot/",
        "/admin/robots/robot/?q=rov",
        "/admin/programs/program/",
        "/admin/programs/program/?q=square&language__exact=python",
        "/admin/programs/program/?owner__groups__id__exact=1",
        "/admin/programs/revision/",
        "/admin/programs/revision/?q=square",
        "/admin/programs/share/",
        "/admin/programs/share/?q=square&can_edit__exact=0",
        "/admin/programs/run/",
        "/admin/programs/run/?state__exact=running&q=alice",
        "/admin/robotide/apitoken/",
    ],
)
def test_admin_pages_load(client, lab, url):
    response = client.get(url)
    assert response.status_code == 200, url


def test_change_pages_load(client, lab):
    for url in [
        f"/admin/auth/user/{lab['carol'].pk}/change/",
        f"/admin/auth/group/{lab['klass'].pk}/change/",
        f"/admin/programs/program/{lab['program'].pk}/change/",
        f"/admin/programs/run/{lab['run'].pk}/change/",
        f"/admin/robots/robot/{lab['robot'].pk}/change/",
    ]:
        response = client.get(url)
        assert response.status_code == 200, url
    # The user's page lists the classes they teach, the class's page its teachers.
    user_page = client.get(f"/admin/auth/user/{lab['carol'].pk}/change/").content.lower()
    assert b"classes taught" in user_page
    group_page = client.get(f"/admin/auth/group/{lab['klass'].pk}/change/").content.lower()
    assert b"teachers" in group_page and b"carol" in group_page


def test_program_list_counts_shares_and_groups_list_members(client, lab):
    Share.objects.create(program=lab["program"], group=lab["klass"])
    Share.objects.create(program=lab["program"], everyone=True)
    programs = client.get("/admin/programs/program/")
    square = next(p for p in programs.context["cl"].result_list if p.name == "square")
    assert square._shares == 2
    groups = client.get("/admin/auth/group/")
    assert groups.context["cl"].result_list[0]._members == 2


def test_share_with_a_group_asks_then_shares(client, lab):
    selected = [lab["program"].pk, lab["other"].pk]
    data = {"action": "share_with_group", ACTION_CHECKBOX_NAME: selected}
    asked = client.post("/admin/programs/program/", data)
    assert asked.status_code == 200 and b"Share programs with a group" in asked.content
    assert not Share.objects.exists()
    done = client.post(
        "/admin/programs/program/",
        {**data, "apply": "1", "group": lab["klass"].pk, "can_edit": "on"},
        follow=True,
    )
    assert b"Shared 2 program(s) with 5b" in done.content
    shares = Share.objects.filter(group=lab["klass"])
    assert {s.program_id for s in shares} == set(selected)
    assert all(s.can_edit and s.created_by.username == "boss" for s in shares)


def test_share_with_a_group_needs_a_group(client, lab):
    data = {"action": "share_with_group", ACTION_CHECKBOX_NAME: [lab["program"].pk], "apply": "1"}
    again = client.post("/admin/programs/program/", data)
    assert again.status_code == 200 and again.context["form"].errors
    assert not Share.objects.exists()


def test_stop_selected_runs_asks_the_active_ones(client, lab, monkeypatch):
    asked = []
    monkeypatch.setattr("programs.admin.request_stop", lambda run: asked.append(run.pk))
    data = {"action": "stop_runs", ACTION_CHECKBOX_NAME: [lab["run"].pk, lab["done"].pk]}
    response = client.post("/admin/programs/run/", data, follow=True)
    assert asked == [lab["run"].pk]
    assert b"Asked 1 run(s) to stop (1 had already ended)" in response.content


def test_stop_selected_runs_without_an_agent_does_not_crash(client, lab):
    """No agent reads the robot's channel: the stop is queued for it, the run left as is."""
    data = {"action": "stop_runs", ACTION_CHECKBOX_NAME: [lab["run"].pk]}
    response = client.post("/admin/programs/run/", data, follow=True)
    assert response.status_code == 200
    assert b"Asked 1 run(s) to stop" in response.content
    lab["run"].refresh_from_db()
    assert lab["run"].state == Run.State.RUNNING


def test_stop_selected_runs_reports_an_unreachable_agent(client, lab, monkeypatch):
    from robots.runs import AgentUnreachable

    def unreachable(run):
        raise AgentUnreachable("the agent of robot 'rover' cannot be reached")

    monkeypatch.setattr("programs.admin.request_stop", unreachable)
    data = {"action": "stop_runs", ACTION_CHECKBOX_NAME: [lab["run"].pk]}
    response = client.post("/admin/programs/run/", data, follow=True)
    assert b"cannot be reached" in response.content
    assert b"Asked 0 run(s) to stop" in response.content


def _take(client, users, robot, apply=True):
    data = {"action": "take_robot_access", ACTION_CHECKBOX_NAME: [u.pk for u in users]}
    if apply:
        data.update(apply="1", robot=robot.pk)
    return client.post("/admin/auth/user/", data, follow=True)


def test_take_away_access_to_a_robot_of_a_class(client, lab):
    robot, klass = lab["robot"], lab["klass"]
    robot.groups.set([klass])
    assert robot in robots_for_user(lab["alice"]) and robot in robots_for_user(lab["carol"])
    page = _take(client, [lab["alice"], lab["carol"]], robot, apply=False)
    assert b"open to everyone" in page.content and b"&lt;robot&gt;-users" in page.content
    response = _take(client, [lab["alice"], lab["carol"]], robot)
    assert b"out of rover&#x27;s classes (5b)" in response.content
    assert robot not in robots_for_user(lab["alice"])
    assert robot not in robots_for_user(lab["carol"])  # no longer its teacher either
    assert robot in robots_for_user(lab["bob"])
    assert list(robot.groups.all()) == [klass]


def test_take_away_access_to_a_robot_open_to_everyone(client, lab, admin_user):
    robot = lab["robot"]
    assert robot in robots_for_user(lab["bob"])
    response = _take(client, [lab["bob"]], robot)
    assert b"now for the class rover-users" in response.content
    group = Group.objects.get(name="rover-users")
    assert list(robot.groups.all()) == [group]
    assert set(group.user_set.all()) == {lab["alice"], lab["carol"], admin_user}
    assert robot not in robots_for_user(lab["bob"])
    assert robot in robots_for_user(lab["alice"])
    # Bob keeps his class: only the robot is taken away.
    assert lab["klass"] in lab["bob"].groups.all()


def test_the_robot_admin_edits_its_classes(client, lab):
    robot = lab["robot"]
    page = client.get(f"/admin/robots/robot/{robot.pk}/change/")
    form = page.context["adminform"].form
    data = {k: v for k, v in form.initial.items() if v is not None and k != "groups"}
    data.update(name="rover", url="sim://", groups=[lab["klass"].pk], run_settings="{}")
    for name, field in form.fields.items():
        if name.startswith("option_") and name not in data:
            value = form.initial.get(name, field.initial)
            if value is not None and value is not False:
                data[name] = value
    data = {k: v for k, v in data.items() if k in form.fields or k == "groups"}
    data.update(no_inline_rows())
    response = client.post(f"/admin/robots/robot/{robot.pk}/change/", data)
    assert response.status_code == 302, response.context["adminform"].form.errors
    assert list(robot.groups.all()) == [lab["klass"]]


def test_the_robot_admin_adds_gateway_endpoints_checked_as_the_api_checks_them(client, lab):
    robot = lab["robot"]
    robot.url = "mavlink+udp://127.0.0.1:14555"
    robot.save()
    page = client.get(f"/admin/robots/robot/{robot.pk}/change/")
    assert "MAVLink gateway endpoint" in page.text
    form = page.context["adminform"].form
    base = {k: v for k, v in form.initial.items() if v is not None and k in form.fields}
    base.update(run_settings="{}", groups=[])
    for name, field in form.fields.items():
        if name.startswith("option_") and name not in base:
            value = form.initial.get(name, field.initial)
            if value is not None and value is not False:
                base[name] = value
    bad = {"type": "udp", "mode": "server", "address": "nowhere", "block": "[]"}
    response = client.post(
        f"/admin/robots/robot/{robot.pk}/change/", {**base, **no_inline_rows(endpoints=bad)}
    )
    assert response.status_code == 200 and "not HOST:PORT" in response.text
    good = {**bad, "address": "127.0.0.1:14560", "allow": "[0, 76]", "read_only": "on"}
    response = client.post(
        f"/admin/robots/robot/{robot.pk}/change/", {**base, **no_inline_rows(endpoints=good)}
    )
    assert response.status_code == 302, [
        response.context["adminform"].form.errors,
        [f.errors for f in response.context["inline_admin_formsets"][0].formset.forms],
    ]
    row = robot.endpoints.get()
    assert (row.address, row.allow, row.read_only) == ("127.0.0.1:14560", [0, 76], True)


@pytest.mark.parametrize("of_a_class", [True, False])
def test_taking_a_robot_from_a_superuser_says_they_keep_every_robot(
    client, lab, admin_user, of_a_class
):
    robot = lab["robot"]
    if of_a_class:
        robot.groups.set([lab["klass"]])
    response = _take(client, [lab["bob"], admin_user], robot)
    assert response.status_code == 200
    assert b"Superusers among them still use every robot." in response.content


def test_a_local_accounts_page_shows_no_directory_or_provider_block(client, lab):
    from robotide.models import DirectoryAccount

    page = client.get(f"/admin/auth/user/{lab['alice'].pk}/change/").content.decode()
    assert "From the directory (LDAP)" not in page
    assert "From the OpenID Connect provider" not in page
    assert "Classes taught" in page  # the inlines every account has stay
    DirectoryAccount.objects.create(user=lab["bob"], dn="uid=bob,ou=people,dc=lab")
    page = client.get(f"/admin/auth/user/{lab['bob'].pk}/change/").content.decode()
    assert "From the directory (LDAP)" in page and "uid=bob,ou=people,dc=lab" in page
    assert "From the OpenID Connect provider" not in page
