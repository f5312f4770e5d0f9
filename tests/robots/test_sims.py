"""Personal sims (issue 30, "A sim of one's own"; robots.sims, /api/sims): each student makes
one, only they, their teachers and staff see it, and only their programs run on it; a twin of a
Pioneer has its speeds and its sonar ring; idle ones are removed, their runs and logs kept;
per-user and per-server caps refuse with a clear message.

On the code before personal sims there is no /api/sims at all (404): ``make_sim`` then makes
the nearest thing that code had, a robot of no class with the student as its owner, so that the
visibility tests fail on what they are about (another student sees it, and runs on it)."""

import asyncio
import html
from datetime import timedelta

import pytest
from django.contrib.auth.models import Group, User
from django.test import Client
from django.urls import reverse
from django.utils import timezone

from programs.models import Program, Run
from robotide.models import ApiToken, ClassTeacher
from robots.models import Robot
from tests.e2e.conftest import robot_on  # noqa: F401 - a fixture: a real agent on a peer

pytestmark = pytest.mark.django_db

P3DX_RING = [90, 50, 30, 10, -10, -30, -50, -90, -90, -130, -150, -170, 170, 150, 130, 90]
P3AT_FRONT = [90, 50, 30, 10, -10, -30, -50, -90]


@pytest.fixture(autouse=True)
def _caps(settings):
    settings.SIMS_PER_USER = 2
    settings.SIMS_MAX = 40
    settings.SIM_IDLE_MINUTES = 60


@pytest.fixture
def school():
    """alice and bob in class-a, taught by tess; carol in class-b, taught by tom; staff."""
    class_a, class_b = Group.objects.create(name="class-a"), Group.objects.create(name="class-b")
    people = {name: User.objects.create_user(name) for name in ("alice", "bob", "carol")}
    people["alice"].groups.add(class_a)
    people["bob"].groups.add(class_a)
    people["carol"].groups.add(class_b)
    for teacher, group in (("tess", class_a), ("tom", class_b)):
        people[teacher] = User.objects.create_user(teacher)
        ClassTeacher.objects.create(group=group, user=people[teacher])
    people["staff"] = User.objects.create_user("staff", is_staff=True)
    return people


def api(user):
    _, token = ApiToken.issue(user)
    client = Client(HTTP_AUTHORIZATION=f"Bearer {token}")

    def call(method, path, body=None):
        response = getattr(client, method.lower())(path, body, content_type="application/json")
        return response.status_code, (response.json() if response.content else None)

    return call


def signed_in(user) -> Client:
    client = Client()
    client.force_login(user)
    return client


def make_sim(user, **body) -> dict:
    status, answer = api(user)("POST", "/api/sims", body)
    if status == 404 and "twin_of" not in body:  # no /api/sims (the code before it)
        robot = Robot.objects.create(name=f"sim-{user.username}-1", url="sim://", owner=user)
        return api(user)("GET", f"/api/robots/{robot.name}")[1]
    assert status == 201, answer
    return answer


def program_of(user) -> Program:
    program, made = Program.objects.get_or_create(owner=user, name="Hello", language="python")
    if made:
        program.save_source("print('hello')\n", user)
    return program


# -- what it is, and who sees it ---------------------------------------------------------------


def test_a_sim_of_ones_own_is_a_robot_as_the_api_shows_robots(school):
    alice = school["alice"]
    made = make_sim(alice)
    assert made["name"] == "sim-alice-1" and made["personal"] is True, made
    assert made["url"] == "sim://" and made["settings"] == {"start_each_run": True}
    assert api(alice)("GET", f"/api/robots/{made['name']}") == (200, made)
    again = make_sim(alice, world="maze")
    assert again["name"] == "sim-alice-2" and again["url"] == "sim://?world=maze"
    status, mine = api(alice)("GET", "/api/sims")
    assert status == 200 and [s["name"] for s in mine] == ["sim-alice-1", "sim-alice-2"]
    status, answer = api(alice)("POST", "/api/sims", {"world": "atlantis"})
    assert status == 422 and "atlantis" in answer["detail"], answer
    robot = Robot.objects.get(name="sim-alice-1")
    assert robot.owner == alice and robot.used is not None and not robot.groups.exists()


def test_another_student_can_neither_see_nor_drive_nor_stop_nor_run_on_it(school):
    alice, bob = school["alice"], school["bob"]
    sim = make_sim(alice)["name"]
    bob_api = api(bob)
    for method, path in (
        ("GET", f"/api/robots/{sim}"),
        ("GET", f"/api/robots/{sim}/sensors"),
        ("POST", f"/api/robots/{sim}/estop"),
        ("POST", f"/api/robots/{sim}/resume"),
        ("POST", f"/api/robots/{sim}/hear"),
        ("DELETE", f"/api/sims/{sim}"),
    ):
        status, answer = bob_api(method, path, {"text": "hi"} if path.endswith("hear") else None)
        assert status == 404, (method, path, status, answer)
    assert sim not in [r["name"] for r in bob_api("GET", "/api/robots")[1]]
    status, answer = bob_api("POST", f"/api/programs/{program_of(bob).pk}/run", {"robot": sim})
    assert status in (404, 409) and not Run.objects.filter(robot__name=sim).exists(), answer
    pages = signed_in(bob)
    assert pages.get(f"/robots/{sim}/").status_code == 404
    assert sim not in pages.get("/robots/").content.decode()
    editor = pages.get(reverse("program-edit", args=[program_of(bob).pk])).content.decode()
    assert sim not in editor
    ran = pages.post(reverse("program-run", args=[program_of(bob).pk]), {"robot": sim})
    assert ran.status_code in (302, 404) and not Run.objects.filter(robot__name=sim).exists()
    # Its owner sees, drives and stops it; it is hers on her pages.
    robot = Robot.objects.get(name=sim)
    assert robot.drivable_by(alice) and robot.stoppable_by(alice)
    assert not robot.drivable_by(bob) and not robot.stoppable_by(bob)
    assert signed_in(alice).get(f"/robots/{sim}/").status_code == 200


def test_the_teacher_of_the_students_class_and_staff_see_it_others_do_not(school):
    sim = make_sim(school["alice"])["name"]
    robot = Robot.objects.get(name=sim)
    for who in ("tess", "staff"):  # her teacher; staff
        status, answer = api(school[who])("GET", f"/api/robots/{sim}")
        assert status == 200 and answer["personal"], (who, answer)
        assert robot.drivable_by(school[who]) and robot.stoppable_by(school[who])
        assert signed_in(school[who]).get(f"/robots/{sim}/").status_code == 200
    for who in ("tom", "carol"):  # another class's teacher and student
        assert api(school[who])("GET", f"/api/robots/{sim}")[0] == 404, who
        assert not robot.drivable_by(school[who])
    # Only she runs programs on it: nobody queues for her sim, not even her teacher.
    tess = school["tess"]
    status, answer = api(tess)("POST", f"/api/programs/{program_of(tess).pk}/run", {"robot": sim})
    assert status == 403 and "Only its owner runs programs" in answer["detail"], answer
    # Her teacher's workbench does not offer it to run on (it is hers).
    editor = signed_in(tess).get(reverse("program-edit", args=[program_of(tess).pk]))
    assert f'value="{sim}"' not in editor.content.decode()


def test_a_student_may_not_share_a_serial_port_through_her_sim(school):
    sim = make_sim(school["alice"])["name"]
    body = {"device": "/dev/ttyUSB0", "address": "127.0.0.1:0"}
    status, answer = api(school["alice"])("POST", f"/api/robots/{sim}/bridges", body)
    assert status == 403 and "no serial port" in answer["detail"], answer


# -- a twin ------------------------------------------------------------------------------------


def test_a_twin_of_a_pioneer_has_its_speeds_and_its_sonar_ring(school):
    alice = school["alice"]
    pioneer = Robot.objects.create(name="p3", url="pioneer:///dev/ttyUSB9")  # no agent: offline
    pioneer.groups.add(Group.objects.get(name="class-a"))
    twin = make_sim(alice, twin_of="p3")
    assert twin["twin_of"] == "p3" and twin["personal"], twin
    options = twin["settings"]
    # Before the robot named its model, the driver's own: ARIA's p3dx-sh, MobileSim's robot.
    assert options["sonar"] == P3DX_RING, options
    assert options["range_cone_deg"] == 50.0  # the discs at ±10° that make `range`, ±15° each
    assert (options["max_linear"], options["max_angular"]) == (0.5, 2.0)  # the driver's limits
    assert options["start_each_run"] is True
    # A P3-AT set to go slower: its ring, its speeds.
    pioneer.settings = {"model": "p3at", "max_linear": 0.4, "max_angular": 1.2}
    pioneer.save()
    options = make_sim(alice, twin_of="p3")["settings"]
    assert options["sonar"][:8] == P3AT_FRONT and len(options["sonar"]) == 16, options
    assert (options["max_linear"], options["max_angular"]) == (0.4, 1.2)


def test_a_twin_of_a_robot_one_may_not_see_is_a_404(school):
    hidden = Robot.objects.create(name="lab-pioneer", url="pioneer:///dev/ttyUSB9")
    hidden.groups.add(Group.objects.get(name="class-b"))
    status, answer = api(school["alice"])("POST", "/api/sims", {"twin_of": "lab-pioneer"})
    assert status == 404, answer
    assert not Robot.objects.filter(personal=True).exists()


# -- caps --------------------------------------------------------------------------------------


def test_the_per_user_cap_refuses_with_a_clear_message(school):
    alice = school["alice"]
    first, _second = make_sim(alice), make_sim(alice)
    status, answer = api(alice)("POST", "/api/sims", {})
    assert status == 409, answer
    assert answer["detail"] == (
        "you have 2 sims already (your limit is 2): delete one, or reuse it"
    )
    assert api(alice)("DELETE", f"/api/sims/{first['name']}") == (204, None)
    assert make_sim(alice)["name"] == "sim-alice-1"  # its name is free again (no runs)


def test_the_server_cap_refuses_with_a_clear_message(school, settings):
    settings.SIMS_MAX = 3
    make_sim(school["alice"]), make_sim(school["alice"]), make_sim(school["bob"])
    status, answer = api(school["carol"])("POST", "/api/sims")
    assert status == 409, answer
    assert answer["detail"].startswith("the server has 3 sims already (its limit is 3)")


def test_sims_switched_off(school, settings):
    settings.SIMS_PER_USER = 0
    status, answer = api(school["alice"])("POST", "/api/sims", {})
    assert status == 409 and "switched off" in answer["detail"], answer


# -- removed when idle, its runs kept ----------------------------------------------------------


def finished_run(user, robot: Robot, ended) -> Run:
    run = Run.create_for(program_of(user), robot, user)
    run.log_path.parent.mkdir(parents=True, exist_ok=True)
    run.log_path.write_text("o hello from the sim\n")
    Run.objects.filter(pk=run.pk).update(
        state=Run.State.FINISHED, exit_code=0, created=ended, started=ended, ended=ended
    )
    return run


def test_an_idle_sim_is_removed_its_runs_and_their_logs_kept(school):
    from robots import sims

    alice = school["alice"]
    long_ago = timezone.now() - timedelta(minutes=90)
    with_run, without = make_sim(alice)["name"], make_sim(alice)["name"]
    robot = Robot.objects.get(name=with_run)
    run = finished_run(alice, robot, long_ago)
    Robot.objects.filter(personal=True).update(used=long_ago, created=long_ago)
    busy = make_sim(school["bob"])["name"]  # used now: not idle
    assert sorted(sims.reap_idle()) == sorted([with_run, without])
    assert not Robot.objects.filter(name=without).exists()  # no run names it: gone
    robot.refresh_from_db()
    assert robot.reaped is not None  # kept for its run, out of every list
    assert Robot.objects.filter(name=busy, reaped__isnull=True).exists()
    alice_api = api(alice)
    status, answer = alice_api("GET", f"/api/robots/{with_run}")
    assert status == 404 and "was removed" in answer["detail"], answer
    assert with_run not in [r["name"] for r in alice_api("GET", "/api/robots")[1]]
    assert alice_api("GET", "/api/sims")[1] == []
    # Her run and its log: readable as before, its page without a link to the robot.
    status, shown = alice_api("GET", f"/api/runs/{run.pk}")
    assert status == 200 and shown["state"] == "finished", shown
    pages = signed_in(alice)
    log = b"".join(pages.get(f"/runs/{run.pk}/log").streaming_content).decode()
    assert "hello from the sim" in log
    page = html.unescape(pages.get(f"/runs/{run.pk}/").content.decode())
    assert "hello from the sim" in page and "(a sim since removed)" in page
    assert f'href="/robots/{with_run}/"' not in page
    assert with_run in pages.get("/runs/").content.decode()
    # Her cap counts the sims she has, not those removed.
    assert make_sim(alice)["name"] == "sim-alice-2"  # sim-alice-1 is still her run's robot


def test_a_sim_with_a_run_going_or_used_lately_is_not_removed(school):
    from robots import sims

    alice = school["alice"]
    long_ago = timezone.now() - timedelta(minutes=90)
    going, recent = make_sim(alice)["name"], make_sim(alice)["name"]
    Run.create_for(program_of(alice), Robot.objects.get(name=going), alice)  # asked, not ended
    finished_run(alice, Robot.objects.get(name=recent), timezone.now() - timedelta(minutes=5))
    Robot.objects.filter(personal=True).update(used=long_ago, created=long_ago)
    assert sims.reap_idle() == []
    status, answer = api(alice)("DELETE", f"/api/sims/{going}")
    assert status == 409 and "has a run going or waiting" in answer["detail"], answer


# -- the workbench's "My sim" ------------------------------------------------------------------


def test_a_student_with_no_robot_of_her_class_runs_on_my_sim(school):
    carol = school["carol"]
    lab = Robot.objects.create(name="lab-sim", url="sim://")
    lab.groups.add(Group.objects.get(name="class-a"))  # not her class's
    program = program_of(carol)
    pages = signed_in(carol)
    editor = html.unescape(pages.get(reverse("program-edit", args=[program.pk])).content.decode())
    assert '<option value="+sim">My sim (new)</option>' in editor
    assert "or run on a simulated robot of your own" in editor and 'id="sim-note"' in editor
    run_button = editor[editor.index('value="run"') :]
    assert "disabled" not in run_button[: run_button.index(">")]
    started = pages.post(
        reverse("program-start", args=[program.pk]),
        {"source": program.source, "language": "python", "robot": "+sim"},
    )
    assert started.status_code == 200, started.content
    assert started["X-Robot"] == "sim-carol-1"
    assert Run.objects.filter(robot__name="sim-carol-1", owner=carol).exists()
    again = pages.post(
        reverse("program-start", args=[program.pk]),
        {"source": program.source, "language": "python", "robot": "+sim"},
    )
    assert again["X-Robot"] == "sim-carol-1"  # the one she has, not another
    assert Robot.objects.filter(personal=True, owner=carol).count() == 1
    editor = html.unescape(pages.get(reverse("program-edit", args=[program.pk])).content.decode())
    assert '<option value="sim-carol-1">sim-carol-1 (my sim)</option>' in editor
    assert "My sim (new)" not in editor and 'id="sim-note"' not in editor
    panel = pages.get(reverse("program-panel", args=[program.pk]), {"robot": "+sim"})
    assert panel.status_code == 200 and "My sim" in panel.content.decode()
    # The API says the same to her, where it named a robot she may not use.
    status, answer = api(carol)("POST", f"/api/programs/{program.pk}/run", {"robot": "lab-sim"})
    assert status == 404, answer  # she has a robot now: her sim


# -- with real agents: both runs at once, nobody queued ------------------------------------------

HOLDS = """\
import os, time
print('going', flush=True)
while not os.path.exists(os.path.expanduser('~/done')):
    time.sleep(0.05)
"""


@pytest.mark.django_db(transaction=True)
async def test_two_students_run_on_their_own_sims_at_once_nobody_queued(settings):
    """Each makes a sim (its agent started by the web process's AgentManager, as embedded
    mode runs it), both run at once with no queue; deleting one stops its agent."""
    from asgiref.sync import sync_to_async
    from channels.layers import get_channel_layer

    from robots.agent import AgentManager
    from tests.e2e.agents import run_program, until
    from tests.e2e.test_fair_shares import let_end
    from tests.e2e.test_run_queue import in_state

    settings.RUNS_PER_USER = 2
    await get_channel_layer().flush()
    alice, bob = [await sync_to_async(User.objects.create_user)(name) for name in ("ann", "ben")]
    manager = AgentManager()
    await manager.start()
    try:
        names = [(await sync_to_async(make_sim)(user))["name"] for user in (alice, bob)]
        assert names == ["sim-ann-1", "sim-ben-1"]
        for name in names:
            await until(lambda n=name: n in manager.agents, what=f"{name}'s agent")
            agent = manager.agents[name][0]
            await asyncio.wait_for(agent.ready.wait(), 60)
        robots = [await sync_to_async(Robot.objects.get)(name=name) for name in names]
        runs = [
            await run_program(user, robot, HOLDS)
            for user, robot in zip((alice, bob), robots, strict=True)
        ]
        for run in runs:
            await in_state(run, "running", timeout=60)
        states = await sync_to_async(lambda: [Run.objects.get(pk=r.pk) for r in runs])()
        assert [run.state for run in states] == ["running", "running"]  # both at once
        assert all(run.queue_position is None and not run.reason for run in states)
        # Hers is not deleted under her run; once it ended it is, and its agent stops.
        delete = sync_to_async(lambda: api(alice)("DELETE", f"/api/sims/{names[0]}"))
        status, answer = await delete()
        assert status == 409, answer
        for run, name in zip(runs, names, strict=True):
            await let_end(manager.agents[name][0], run)
        assert (await delete())[0] == 204
        await until(lambda: names[0] not in manager.agents, what="its agent stopped")
        assert names[1] in manager.agents and not manager.agents[names[1]][1].done()
    finally:
        await manager.shutdown()


@pytest.mark.django_db(transaction=True)
async def test_a_twin_of_a_live_pioneer_has_the_ring_of_the_model_it_named(robot_on):  # noqa: F811
    """Its settings name no model; the robot named itself an AmigoBot when its agent connected
    (robot.state says so): the twin has an AmigoBot's ring of 8, not the driver's default
    P3-DX ring of 16, and its options build the sim driver with that ring."""
    from asgiref.sync import sync_to_async

    import rhal

    _peer, _agent, pioneer, student = await robot_on("pioneer", model="amigo-sh")
    assert pioneer.settings == {}
    twin = await sync_to_async(make_sim)(student, twin_of=pioneer.name)
    options = twin["settings"]
    assert options["sonar"] == [90, 41, 15, -15, -41, -90, -145, 145], options
    assert options["range_cone_deg"] == 60.0  # the discs at ±15° that make its `range`
    robot = await sync_to_async(Robot.objects.get)(name=twin["name"])
    sim = rhal.connect(robot.url, **robot.driver_options())  # as its agent builds it
    doc = sim.capabilities()["sim"]
    assert list(doc["sonar"]) == options["sonar"], doc
    assert sim.capabilities()["drive"] == {
        "max_linear": options["max_linear"], "max_angular": options["max_angular"]
    }  # fmt: skip


def test_a_sim_chosen_watched_or_reset_is_in_use(school):
    """What counts as use besides runs (robots.sims.touch): the workbench's panel, the robot's
    page, a reset (its agent away here: the reset fails, the sim was used all the same)."""
    alice = school["alice"]
    name = make_sim(alice)["name"]
    long_ago = timezone.now() - timedelta(minutes=90)
    program = program_of(alice)
    pages = signed_in(alice)
    for use in (
        lambda: pages.get(reverse("program-panel", args=[program.pk]), {"robot": name}),
        lambda: pages.get(f"/robots/{name}/"),
        lambda: api(alice)("POST", f"/api/robots/{name}/reset"),
    ):
        Robot.objects.filter(name=name).update(used=long_ago, created=long_ago)
        use()
        assert Robot.objects.get(name=name).used > long_ago
    Robot.objects.filter(name=name).update(used=long_ago, created=long_ago)
    from robots import sims

    assert sims.reap_idle() == [name]


# -- where the agents and the reaper run ---------------------------------------------------------


@pytest.mark.django_db(transaction=True)
async def test_the_personal_sims_agent_process_serves_sims_only_and_reaps(monkeypatch, settings):
    """`robotide agent --personal-sims` (fleet mode): an AgentManager that starts the personal
    sims' agents, those made later (not other robots'), stops removed ones, and runs the
    reaper, which stops the agent of a sim left idle."""
    from asgiref.sync import sync_to_async
    from channels.layers import get_channel_layer

    from robots import sims
    from robots.agent import AgentManager
    from tests.e2e.agents import until

    await get_channel_layer().flush()
    monkeypatch.setattr(sims, "REAP_EVERY", 0.05)
    started, stopped = [], []
    manager = AgentManager()
    monkeypatch.setattr(manager, "start_agent", started.append)

    async def stop_agent(name):
        stopped.append(name)

    monkeypatch.setattr(manager, "stop_agent", stop_agent)
    user = await sync_to_async(User.objects.create_user)("pat")
    await sync_to_async(Robot.objects.create)(name="lab-robot", url="sim://")
    old = (await sync_to_async(make_sim)(user))["name"]
    await manager.start(personal_only=True)
    try:
        assert started == [old]
        await sync_to_async(Robot.objects.create)(name="another-lab-robot", url="sim://")
        await sync_to_async(sims.announce)("another-lab-robot")  # not a sim: not started here
        new = (await sync_to_async(make_sim)(user))["name"]  # robot.added, heard after it
        await until(lambda: new in started, what="the new sim's agent started")
        long_ago = timezone.now() - timedelta(hours=2)
        await sync_to_async(Robot.objects.filter(name=old).update)(used=long_ago)
        await until(lambda: old in stopped, what="the idle sim's agent stopped by the reaper")
        # (its own robot.added, sent before the manager listened, is heard too: start_agent
        # starts an agent once)
        assert set(started) == {old, new} and stopped == [old]
        assert not await sync_to_async(Robot.objects.filter(name=old).exists)()
    finally:
        await manager.shutdown()


def test_the_admin_shows_a_sim_as_personal_and_filters_them(school):
    admin = User.objects.create_superuser("root", password="x")
    sim = make_sim(school["alice"])["name"]
    robot = Robot.objects.get(name=sim)
    pages = signed_in(admin)
    change = pages.get(reverse("admin:robots_robot_change", args=[robot.pk]))
    assert change.status_code == 200 and "personal sim" in change.content.decode()
    listing = pages.get(reverse("admin:robots_robot_changelist"), {"personal__exact": "1"})
    assert listing.status_code == 200 and sim in listing.content.decode()


def test_the_program_lists_run_offers_my_sim_too(school):
    """Scripts or not: the program list's Run with "My sim (new)" makes the sim and runs."""
    alice = school["alice"]
    program = program_of(alice)
    pages = signed_in(alice)
    listing = html.unescape(pages.get(reverse("program-list")).content.decode())
    assert '<option value="+sim">My sim (new)</option>' in listing
    ran = pages.post(reverse("program-run", args=[program.pk]), {"robot": "+sim"})
    run = Run.objects.get(robot__name="sim-alice-1", owner=alice)
    assert ran.status_code == 302 and ran["Location"] == reverse("run-detail", args=[run.pk])
    # Her sim is the choice from then on, and nothing more is made.
    listing = html.unescape(pages.get(reverse("program-list")).content.decode())
    assert "My sim (new)" not in listing
    assert '<input type="hidden" name="robot" value="sim-alice-1">' in listing  # her one robot
