"""A robot's run queue in the web tier: its order, who may reorder and cancel, the API, the
pages, and what the presence watch and a restarted agent leave alone (tests/e2e/test_run_queue.py
has the agent's side, with a real agent on the sim robot)."""

from datetime import timedelta

import pytest
from asgiref.sync import async_to_sync
from channels.layers import get_channel_layer
from django.contrib.auth.models import Group, User
from django.template.loader import render_to_string
from django.test import Client
from django.utils import timezone

from programs.models import Program, Run, ordinal
from robotide.models import ApiToken
from robots import run_queue
from robots.models import Robot, agent_channel
from robots.presence import sweep_lost

pytestmark = pytest.mark.django_db


@pytest.fixture(autouse=True)
def _quiet_layer():
    async_to_sync(get_channel_layer().flush)()


@pytest.fixture
def lab():
    users = {name: User.objects.create_user(name) for name in ("alice", "bob", "carol", "olga")}
    users["staff"] = User.objects.create_user("staff", is_staff=True)
    robot = Robot.objects.create(name="arm", url="sim://", owner=users["olga"])
    return users, robot


def run_of(user, robot, state=None) -> Run:
    program, _ = Program.objects.get_or_create(owner=user, name="p", language="python")
    run = Run.create_for(program, robot, user)
    if state is not None:
        Run.objects.filter(pk=run.pk).update(state=state)
    return run


def queued(user, robot) -> Run:
    run = run_of(user, robot)
    assert Run.enqueue(run.pk) is not None
    run.refresh_from_db()
    return run


def ranks(*runs: Run) -> list:
    for run in runs:
        run.refresh_from_db()
    return [run.queue_rank for run in runs]


def api(user):
    _, token = ApiToken.issue(user)
    client = Client(HTTP_AUTHORIZATION=f"Bearer {token}")

    def call(method, path, body=None):
        response = getattr(client, method.lower())(path, body, content_type="application/json")
        return response.status_code, response.json()

    return call


def signed_in(user) -> Client:
    client = Client()
    client.force_login(user)
    return client


def agent_messages(robot) -> list[str]:
    layer = get_channel_layer()
    channel = agent_channel(robot.name)
    kinds = []
    while layer.channels.get(channel):
        kinds.append(async_to_sync(layer.receive)(channel)["type"])
    return kinds


def test_ordinals():
    assert [ordinal(n) for n in (1, 2, 3, 4, 11, 12, 13, 21, 22, 101, 111)] == [
        "1st", "2nd", "3rd", "4th", "11th", "12th", "13th", "21st", "22nd", "101st", "111th",
    ]  # fmt: skip


def test_the_line_keeps_its_order_and_is_reordered(lab):
    users, robot = lab
    a, b, c = (queued(users[n], robot) for n in ("alice", "bob", "carol"))
    assert ranks(a, b, c) == [1, 2, 3] and c.queue_place == "3rd in line"
    assert Run.move_in_queue(c.pk, 1) == 1
    assert ranks(a, b, c) == [2, 3, 1]
    assert Run.move_in_queue(c.pk, 99) == 3  # past the end: last
    assert ranks(a, b, c) == [1, 2, 3]
    assert Run.move_in_queue(a.pk, 2) == 2 and ranks(a, b, c) == [2, 1, 3]
    # Another robot's line is its own.
    other = Robot.objects.create(name="other", url="sim://")
    elsewhere = queued(users["alice"], other)
    assert elsewhere.queue_rank == 1
    # Cancelled: out of the line, which closes up.
    assert Run.cancel_queued(b.pk)
    b.refresh_from_db()
    assert (b.state, b.reason, b.queue_rank) == ("stopped", "cancelled while queued", None)
    assert b.ended is not None and b.started is None
    assert ranks(a, c) == [1, 2]
    assert not Run.cancel_queued(b.pk) and Run.move_in_queue(b.pk, 1) is None
    # Its turn: starting again, as a run the agent then claims.
    assert Run.unqueue(a.pk) and Run.claim(a.pk)
    assert ranks(c) == [1]
    # Only a run not yet started may be queued.
    running = run_of(users["bob"], robot, Run.State.RUNNING)
    assert Run.enqueue(running.pk) is None


def test_a_queued_run_starts_from_its_row_as_it_would_have(lab):
    users, robot = lab
    run = queued(users["alice"], robot)
    Run.objects.filter(pk=run.pk).update(program_name="Drive a Square!", args=[1, "two"])
    run.refresh_from_db()
    assert run.start_message() == {
        "run_id": run.pk, "language": "python", "source": "", "filename": "drive-a-square.py",
        "args": ["1", "two"], "user": "alice",
    }  # fmt: skip


def test_the_api_gives_places_and_only_staff_or_the_robots_owner_reorder(lab):
    users, robot = lab
    a, b, c = (queued(users[n], robot) for n in ("alice", "bob", "carol"))
    status, body = api(users["carol"])("GET", f"/api/runs/{c.pk}")
    assert status == 200 and body["state"] == "queued" and body["queue_position"] == 3
    # The owner of a run may not jump the line; others do not even see it.
    status, body = api(users["carol"])("POST", f"/api/runs/{c.pk}/queue", {"position": 1})
    assert status == 403 and "staff" in body["detail"]
    assert api(users["bob"])("POST", f"/api/runs/{c.pk}/queue", {"position": 1})[0] == 404
    assert api(users["staff"])("POST", f"/api/runs/{c.pk}/queue", {"position": 0})[0] == 422
    # The robot's owner (not staff) reorders it.
    status, body = api(users["olga"])("POST", f"/api/runs/{c.pk}/queue", {"position": 2})
    assert status == 200 and body["queue_position"] == 2, body
    assert ranks(a, b, c) == [1, 3, 2]
    assert "run.queue_changed" in agent_messages(robot)  # its agent reads the new order
    status, body = api(users["staff"])("POST", f"/api/runs/{a.pk}/queue", {"position": 3})
    assert status == 200 and ranks(a, b, c) == [3, 2, 1]
    # Not queued (any more): 409.
    mine = run_of(users["olga"], robot, Run.State.FINISHED)
    status, body = api(users["olga"])("POST", f"/api/runs/{mine.pk}/queue", {"position": 1})
    assert status == 409 and "finished" in body["detail"]


def test_staff_and_the_robots_owner_see_what_waits_students_their_own(lab):
    users, robot = lab
    a, b = queued(users["alice"], robot), queued(users["bob"], robot)
    running = run_of(users["bob"], robot, Run.State.RUNNING)

    def listed(user, query=""):
        status, body = api(user)("GET", f"/api/runs{query}")
        assert status == 200
        return {(r["id"], r["queue_position"]) for r in body}

    assert listed(users["alice"]) == {(a.pk, 1)}
    assert listed(users["olga"], "?state=queued&robot=arm") == {(a.pk, 1), (b.pk, 2)}
    assert listed(users["staff"]) == {(a.pk, 1), (b.pk, 2)}  # not bob's running one
    assert running.pk not in {r for r, _ in listed(users["olga"])}


def test_the_stop_action_cancels_a_queued_run_without_its_agent(lab):
    users, robot = lab
    a, b, c = (queued(users[n], robot) for n in ("alice", "bob", "carol"))
    status, body = api(users["alice"])("POST", f"/api/runs/{a.pk}/stop")
    assert status == 200 and (body["state"], body["reason"]) == (
        "stopped",
        "cancelled while queued",
    )
    assert api(users["alice"])("POST", f"/api/runs/{b.pk}/stop")[0] == 404  # not hers
    assert "run.queue_changed" in agent_messages(robot)
    # The robot's owner cancels anyone's, from the robot's page (scripts off: a redirect).
    response = signed_in(users["olga"]).post(f"/runs/{b.pk}/stop", {"next": "/robots/arm/"})
    assert response.status_code == 302 and response["Location"] == "/robots/arm/"
    b.refresh_from_db()
    assert b.state == "stopped" and b.reason == "cancelled while queued"
    # A teacher cancels a student's, as they may stop it.
    teacher = User.objects.create_user("teacher")
    klass = Group.objects.create(name="class-a")
    users["carol"].groups.add(klass)
    klass.teachers.create(user=teacher)
    response = signed_in(teacher).post(f"/runs/{c.pk}/stop", HTTP_HX_REQUEST="true")
    assert response.status_code == 204
    c.refresh_from_db()
    assert c.state == "stopped"


def test_the_pages_say_the_place_in_line(lab):
    users, robot = lab
    queued(users["bob"], robot)
    mine = queued(users["alice"], robot)
    alice = signed_in(users["alice"])
    page = alice.get(f"/runs/{mine.pk}/").content.decode()
    assert 'data-state="queued"' in page and 'data-queue-position="2"' in page
    assert 'queued</span> <span class="queue-place">— 2nd in line' in page
    assert "✕ Cancel" in page and "■ Stop" not in page
    listing = alice.get("/runs/").content.decode()
    running_now = listing.split("Finished")[0]
    assert f"#{mine.pk}" in running_now and "— 2nd in line" in running_now


def test_the_robots_queue_as_a_student_and_as_its_manager_see_it(lab):
    users, robot = lab
    a, b = queued(users["alice"], robot), queued(users["bob"], robot)
    as_alice = signed_in(users["alice"]).get("/robots/arm/queue").content.decode()
    assert f"#{a.pk} p" in as_alice and "yours" in as_alice
    assert "another user's program" in as_alice and "bob" not in as_alice
    assert "Move up" not in as_alice and as_alice.count("Cancel run") == 1
    as_olga = signed_in(users["olga"]).get("/robots/arm/queue").content.decode()
    assert f"#{b.pk} p" in as_olga and "bob" in as_olga and as_olga.count("Cancel run") == 2
    assert 'title="Move to the front"' in as_olga and 'title="Move down"' in as_olga
    # The page moves one with a form (scripts off) or htmx.
    olga = signed_in(users["olga"])
    response = olga.post("/robots/arm/queue/move", {"run": b.pk, "to": 1})
    assert response.status_code == 302 and ranks(a, b) == [2, 1]
    response = olga.post("/robots/arm/queue/move", {"run": b.pk, "to": 2}, HTTP_HX_REQUEST="true")
    assert response.status_code == 204 and ranks(a, b) == [1, 2]
    alice = signed_in(users["alice"])
    assert alice.post("/robots/arm/queue/move", {"run": a.pk, "to": 2}).status_code == 403
    # What the robot's websocket sends has no queue: it makes the page fetch it.
    oob = render_to_string("robots/_running.html", {"running": [], "oob": True})
    assert 'id="robot-queue-refresh"' in oob and 'hx-get="queue"' in oob
    assert 'id="robot-queue"' not in oob


def test_the_robot_page_shows_the_line_in_its_running_card(lab):
    users, robot = lab
    queued(users["bob"], robot)
    queued(users["alice"], robot)
    page = signed_in(users["alice"]).get("/robots/arm/").content.decode()  # no agent: 1 s
    card = page.split("<h2>Running here</h2>")[1].split("<h2>")[0]
    assert 'id="robot-queue"' in card and 'id="robot-queue-refresh"' in card
    assert "— 1st in line" in card and "— 2nd in line" in card


def test_a_held_queue_says_so_and_its_manager_resumes_it(lab):
    users, robot = lab
    a, b = queued(users["alice"], robot), queued(users["bob"], robot)
    Run.objects.filter(pk__in=[a.pk, b.pk]).update(reason=Run.HELD)
    as_alice = signed_in(users["alice"]).get("/robots/arm/queue").content.decode()
    # Once the stop is resumed, held runs wait until started again: staff or the robot's
    # owner start them all (each run's owner starts theirs: tests/robots/test_resume_holds.py).
    assert "After an emergency stop" in as_alice and "Start every held run" not in as_alice
    assert api(users["alice"])("POST", "/api/runs/queue/resume", {"robot": "arm"})[0] == 403
    olga = signed_in(users["olga"])
    assert "Start every held run" in olga.get("/robots/arm/queue").content.decode()
    response = olga.post("/robots/arm/queue/resume")
    assert response.status_code == 302
    assert set(Run.objects.filter(pk__in=[a.pk, b.pk]).values_list("reason", flat=True)) == {""}
    assert run_queue.CHANGED in agent_messages(robot)
    assert not run_queue.held(robot)


def test_queued_runs_are_not_lost_with_their_agent(lab):
    users, robot = lab
    waiting = queued(users["alice"], robot)
    running = run_of(users["bob"], robot, Run.State.RUNNING)
    long_ago = timezone.now() - timedelta(minutes=5)
    Run.objects.filter(pk__in=[waiting.pk, running.pk]).update(created=long_ago)
    Robot.objects.filter(pk=robot.pk).update(last_seen=long_ago)
    assert sweep_lost() == [(running.pk, "arm")]
    assert Run.mark_lost("arm") == []
    waiting.refresh_from_db()
    assert waiting.state == "queued" and waiting.queue_rank == 1


def test_the_turn_setting_is_a_run_setting_with_a_default(lab, settings):
    users, robot = lab
    settings.QUEUE_TURN_SECONDS = 300
    robot.settings = {"queue_turn_seconds": 45, "max_linear": 0.3}
    assert robot.driver_options() == {"max_linear": 0.3}  # not the driver's
    assert run_queue.turn_seconds(robot.settings) == 45
    assert run_queue.turn_seconds({}) == 300
    assert run_queue.turn_seconds({"queue_turn_seconds": 0}) == 0  # no limit
    assert run_queue.turn_seconds({"queue_turn_seconds": "soon"}) == 300
