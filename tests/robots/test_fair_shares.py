"""Fair shares in the web tier and the database: the admission's decision, what the robot's
page and the API say is in force, the robot setting checked when saved (tests/e2e/
test_fair_shares.py has real agents and runs; test_fair_shares_fleet.py agents in processes of
their own deciding at once on PostgreSQL)."""

import pytest
from asgiref.sync import async_to_sync
from channels.layers import get_channel_layer
from django.contrib.auth.models import User
from django.test import Client
from django.utils import timezone

from programs.models import Program, Run
from robotide.models import ApiToken
from robots import fair_shares
from robots.fair_shares import Admission, admit
from robots.models import Robot

pytestmark = pytest.mark.django_db


@pytest.fixture(autouse=True)
def _limits(settings):
    settings.RUNS_PER_USER = 2
    settings.RUNS_PER_STAFF = 5
    async_to_sync(get_channel_layer().flush)()


@pytest.fixture
def lab():
    users = {name: User.objects.create_user(name) for name in ("alice", "bob")}
    users["staff"] = User.objects.create_user("staff", is_staff=True)
    robots = [Robot.objects.create(name=name, url="sim://") for name in ("arm", "rover")]
    return users, robots


def asked(user, robot) -> Run:
    program, _ = Program.objects.get_or_create(owner=user, name="p", language="python")
    return Run.create_for(program, robot, user)


def running(user, robot) -> Run:
    run = asked(user, robot)
    Run.objects.filter(pk=run.pk).update(state=Run.State.RUNNING, pid=1, started=timezone.now())
    return run


def api(user):
    _, token = ApiToken.issue(user)
    return Client(HTTP_AUTHORIZATION=f"Bearer {token}")


def test_a_run_beyond_its_owners_limit_is_queued_saying_why(lab):
    users, (arm, rover) = lab
    running(users["alice"], arm)
    assert admit(asked(users["alice"], rover).pk).outcome is Admission.ADMITTED
    third = asked(users["alice"], arm)
    decision = admit(third.pk)
    assert decision.outcome is Admission.QUEUED and decision.rank == 1
    third.refresh_from_db()
    assert third.state == "queued" and third.started is None
    assert third.reason == "waiting: you already have 2 runs going (your limit is 2)"
    # Another user's run, and the same robot: not held up.
    assert admit(asked(users["bob"], arm).pk).outcome is Admission.ADMITTED
    # From the queue, once a share is free: admitted and unqueued in the same write.
    Run.objects.filter(owner=users["alice"], state=Run.State.RUNNING).update(state="finished")
    assert admit(third.pk).outcome is Admission.ADMITTED
    third.refresh_from_db()
    assert (third.state, third.reason, third.queue_position) == ("starting", "", None)
    assert third.started is not None and third.pid is None  # its agent's claim is next


def test_a_second_admission_of_one_run_is_not_counted_twice(lab):
    users, (arm, _) = lab
    run = asked(users["alice"], arm)
    assert admit(run.pk).outcome is Admission.ADMITTED
    assert admit(run.pk).outcome is Admission.ADMITTED  # its start asked twice
    assert admit(asked(users["alice"], arm).pk).outcome is Admission.ADMITTED
    Run.objects.filter(pk=run.pk).update(state=Run.State.STOPPED)
    assert admit(run.pk).outcome is Admission.GONE


def test_a_robots_limit_is_the_lower_of_its_setting_and_its_isolation(lab):
    users, (arm, _) = lab
    arm.settings = {"runs_at_once": 3}
    arm.save()
    running(users["alice"], arm)
    assert admit(asked(users["bob"], arm).pk, box_cap=None).outcome is Admission.ADMITTED
    late = asked(users["staff"], arm)
    decision = admit(late.pk, box_cap=2)  # a rootless box without a run-wide cgroup says 1
    assert decision.outcome is Admission.QUEUED and decision.robot_full
    assert decision.reason == "waiting: the robot runs at most 2 programs at once"
    Robot.objects.filter(pk=arm.pk).update(isolation_runs_at_once=1)
    arm.refresh_from_db()
    assert fair_shares.robot_limit(arm) == 1


def test_the_robot_page_and_the_api_say_what_is_in_force(lab):
    users, (arm, _) = lab
    arm.settings = {"runs_at_once": 1}
    arm.isolation_runs_at_once = None
    arm.save()
    running(users["alice"], arm)
    waiting = asked(users["alice"], arm)
    Run.enqueue(waiting.pk, fair_shares.user_reason(2, 2))

    body = api(users["alice"]).get("/api/robots/arm").json()
    assert (body["runs_per_user"], body["your_runs_going"]) == (2, 1), body
    assert (body["runs_at_once"], body["runs_going"]) == (1, 1), body
    staff = api(users["staff"]).get("/api/robots").json()
    assert {r["name"]: r["runs_per_user"] for r in staff} == {"arm": 5, "rover": 5}
    assert next(r for r in staff if r["name"] == "rover")["runs_at_once"] is None
    queued = api(users["alice"]).get(f"/api/runs/{waiting.pk}").json()
    assert queued["reason"] == "waiting: you already have 2 runs going (your limit is 2)"

    alice = Client()
    alice.force_login(users["alice"])
    page = alice.get("/robots/arm/").content.decode()  # no agent: 1 s
    assert "You may have 2 runs going at once, on all robots; more wait in line." in page
    assert "This robot runs at most 1 program at once, whoever&#x27;s." in page
    line = alice.get("/robots/arm/queue").content.decode()
    assert "— waiting: you already have 2 runs going (your limit is 2)" in line
    teacher = Client()
    teacher.force_login(users["staff"])
    line = teacher.get("/robots/arm/queue").content.decode()
    assert "— waiting: its owner already has 2 runs going (their limit is 2)" in line


@pytest.mark.parametrize("value", [-1, 1.5, "2", True])
def test_a_robots_runs_at_once_must_be_a_whole_number(lab, value):
    users, _ = lab
    response = api(users["staff"]).patch(
        "/api/robots/arm", {"settings": {"runs_at_once": value}}, content_type="application/json"
    )
    assert response.status_code == 422, response.content
    assert "runs_at_once must be a whole number" in response.json()["detail"]
    assert Robot.objects.get(name="arm").settings == {}


def test_no_limit_is_no_limit(lab, settings):
    settings.RUNS_PER_USER = 0
    users, (arm, _) = lab
    for _ in range(4):
        assert admit(asked(users["alice"], arm).pk).outcome is Admission.ADMITTED
    assert fair_shares.in_force(users["alice"], arm).runs_per_user is None
