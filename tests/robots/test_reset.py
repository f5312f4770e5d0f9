"""Reset (issue 30): a simulated robot put back at its world's start pose, or at a pose given,
through POST /api/robots/{name}/reset and the robot page's form, for whoever may drive it; and
the robot setting start_each_run, which holds for every run. A reset with a pose places the
robot for the next run whatever that setting says. Before, nothing called SimRobot.reset():
one student's run left the robot where it ended (jammed against a wall) for the next.

A real agent on the sim robot, in this process (its runs real programs), for most; the
refusals that come before the agent without one.
"""

import json
import math

import pytest
from asgiref.sync import sync_to_async
from channels.db import database_sync_to_async
from django.contrib.auth.models import User
from django.test import Client

import rhal
from robots import messages
from robots.agent import RobotAgent
from robots.bus import ask_agent
from robots.models import Robot
from tests.e2e.agents import finished, log_of, output_of, run_program
from tests.robots.test_run_queue import api
from tests.waiting import until

# Where it starts, then a turn and a drive: wherever it starts, it ends elsewhere.
WHERE_AND_MOVE = """import json, time, robot
bot = robot.Robot()
print(json.dumps(bot.sensors()["position"]), flush=True)
bot.drive(0.15, 0.8)
time.sleep(0.4)
bot.stop()
"""
SLEEPS = "import time\nprint('going', flush=True)\ntime.sleep(120)\n"
SPOT = {"x": 0.5, "y": -0.4, "theta": 0.3}  # free in the boxes world


@pytest.fixture(autouse=True)
def _no_heartbeat_meanwhile(settings):
    # The in-memory SQLite fails a write meeting another ("table is locked"): see
    # tests/robots/test_estop_race.py.
    settings.AGENT_HEARTBEAT = 3600


async def start_pose() -> dict:
    """The world's start pose, as a fresh sim reads it."""
    sim = rhal.connect("sim://")
    await sim.open()
    try:
        return (await sim.sensors())["position"]
    finally:
        await sim.close()


async def position(agent) -> dict:
    return (await agent.driver.sensors())["position"]


def at(position: dict, pose: dict) -> bool:
    return all(math.isclose(position[k], pose[k], abs_tol=1e-6) for k in ("x", "y", "theta"))


@database_sync_to_async
def users():
    return User.objects.create_user("sam"), User.objects.create_user("tina")


async def moved_away(agent, pose: dict) -> None:
    """The robot driven by hand (as the agent's teleop does) until it is no longer at `pose`."""
    await agent.driver.drive(0.1, 1.0)
    try:
        await until(lambda: _away(agent, pose))
    finally:
        await agent.driver.stop()


async def _away(agent, pose) -> bool:
    return not at(await position(agent), pose)


async def call(user, method: str, path: str, body=None):
    return await sync_to_async(lambda: api(user)(method, path, body))()


async def started_at(user, robot) -> dict:
    """Where a run of WHERE_AND_MOVE began (its first line), once it ended."""
    run = await finished(await run_program(user, robot, WHERE_AND_MOVE))
    assert run.state == "finished", log_of(run)
    return json.loads(output_of(run).splitlines()[0])


# -- the API ----------------------------------------------------------------------------------


@pytest.mark.django_db(transaction=True)
async def test_reset_puts_the_sim_back_at_its_start_and_a_pose_places_it(sim_agent):
    start = await start_pose()
    sam, _ = await users()
    await moved_away(sim_agent, start)

    status, body = await call(sam, "POST", "/api/robots/sim/reset")
    assert (status, body) == (200, {"robot": "sim", "pose": None}), body
    assert at(await position(sim_agent), start)
    sensors = await sim_agent.driver.sensors()
    assert sensors["odometry"]["distance"] == 0 and sensors["velocity"]["linear"] == 0

    status, body = await call(sam, "POST", "/api/robots/sim/reset", SPOT)
    assert status == 200, body
    assert body["pose"] == [SPOT["x"], SPOT["y"], SPOT["theta"]]
    # As sensors() shows it: the API's reading and the driver's.
    status, sensors = await call(sam, "GET", "/api/robots/sim/sensors")
    assert at(sensors["position"], SPOT), sensors


@pytest.mark.django_db(transaction=True)
async def test_a_pose_the_sim_cannot_take_is_refused_in_its_words(sim_agent):
    sam, _ = await users()
    before = await position(sim_agent)
    status, body = await call(sam, "POST", "/api/robots/sim/reset", {"x": 40, "y": 0, "theta": 0})
    assert status == 422, body
    assert body["detail"].startswith("That pose cannot be used: "), body
    assert len(body["detail"]) > len("That pose cannot be used: ") + 10, body
    assert at(await position(sim_agent), before)  # left where it was


@pytest.mark.django_db
@pytest.mark.parametrize(
    "body",
    [
        {"x": 1.0},
        {"x": 1.0, "y": 1.0},
        {"x": "one", "y": 0, "theta": 0},
        {"x": 1, "y": None, "theta": 0},
        ["x", 1],
    ],
)
def test_a_pose_is_all_three_numbers_or_none(body):
    sam = User.objects.create_user("sam")
    Robot.objects.create(name="sim", url="sim://")
    status, answer = api(sam)("POST", "/api/robots/sim/reset", body)
    assert status == 422, (body, answer)


@pytest.mark.django_db
def test_only_whoever_may_drive_it_may_reset_it():
    olga, sam = User.objects.create_user("olga"), User.objects.create_user("sam")
    Robot.objects.create(name="arm", url="sim://", owner=olga, drive_by="owner")
    status, body = api(sam)("POST", "/api/robots/arm/reset")
    assert status == 403 and body["detail"] == "Only its owner and staff may reset arm.", body
    status, body = api(sam)("POST", "/api/robots/nothing/reset")
    assert status == 404, body
    client = Client()
    client.force_login(sam)
    assert client.post("/robots/arm/reset").status_code == 403


@pytest.mark.django_db(transaction=True)
async def test_a_real_robot_cannot_be_reset():
    """A Pioneer (its serial link away here): 409, said plainly; its agent answers all the
    same."""
    await database_sync_to_async(Robot.objects.create)(name="pio", url="pioneer+tcp://127.0.0.1:9")
    agent = RobotAgent("pio")
    await agent.start()
    try:
        sam, _ = await users()
        status, body = await call(sam, "POST", "/api/robots/pio/reset")
        assert (status, body) == (409, {"detail": "Only simulated robots can be reset."})
        assert (await ask_agent("pio", "robot.state"))["resettable"] is False
    finally:
        await agent.shutdown()


@pytest.mark.django_db(transaction=True)
async def test_someone_elses_run_is_not_reset_under_it_but_ones_own_is(sim_agent):
    """While Tina's run goes on, Sam may not reset the robot (409: its owner, staff, or once
    it has ended); Tina may, and her run goes on. Staff may all the same."""
    sam, tina = await users()
    staff = await database_sync_to_async(User.objects.create_superuser)("staff")
    robot = await database_sync_to_async(Robot.objects.get)(name="sim")
    run = await run_program(tina, robot, SLEEPS)
    await until(lambda: run.pk in sim_agent.runs and sim_agent.runs[run.pk].process.started)

    status, body = await call(sam, "POST", "/api/robots/sim/reset")
    assert status == 409, body
    assert body["detail"] == (
        f"Run #{run.pk} of tina is going on the robot: it may be reset by its owner, staff, or"
        " once the run has ended."
    )
    for who in (tina, staff):
        status, body = await call(who, "POST", "/api/robots/sim/reset")
        assert status == 200, body
    assert run.pk in sim_agent.runs and not sim_agent.runs[run.pk].process.stop_requested
    sim_agent.stop_run(run.pk, "stopped by user")
    await finished(run)


# -- where each run starts ------------------------------------------------------------------


@pytest.mark.django_db(transaction=True)
async def test_start_each_run_holds_for_every_run_and_a_pose_given_for_the_next_only(sim_agent):
    start = await start_pose()
    sam, _ = await users()
    staff = await database_sync_to_async(User.objects.create_superuser)("staff")
    robot = await database_sync_to_async(Robot.objects.get)(name="sim")
    each_run = {"settings": {"start_each_run": True}}
    status, body = await call(staff, "PATCH", "/api/robots/sim", each_run)
    assert status == 200 and body["settings"] == {"start_each_run": True}, body
    # The agent has reopened the robot with it once it answers what was sent after.
    await ask_agent("sim", "robot.state")
    assert sim_agent.start_each_run

    # Two runs in a row: each starts at the start pose, though the first moved the robot.
    assert at(await started_at(sam, robot), start)
    assert not at(await position(sim_agent), start)
    assert at(await started_at(sam, robot), start)

    # A reset with a pose: the next run starts there (even after the robot was driven off
    # it), the one after at the start pose again.
    await moved_away(sim_agent, start)
    status, body = await call(sam, "POST", "/api/robots/sim/reset", SPOT)
    assert status == 200, body
    await moved_away(sim_agent, SPOT)
    assert at(await started_at(sam, robot), SPOT)
    assert at(await started_at(sam, robot), start)


@pytest.mark.django_db(transaction=True)
async def test_without_the_setting_a_run_starts_where_the_last_left_it_but_a_pose_given_wins(
    sim_agent,
):
    start = await start_pose()
    sam, _ = await users()
    robot = await database_sync_to_async(Robot.objects.get)(name="sim")
    assert sim_agent.start_each_run is False  # off unless set (personal sims set it)
    first = await started_at(sam, robot)
    left = await position(sim_agent)
    assert not at(left, first)
    assert at(await started_at(sam, robot), left)  # where the first one left it

    status, body = await call(sam, "POST", "/api/robots/sim/reset", SPOT)
    assert status == 200, body
    await moved_away(sim_agent, SPOT)
    assert at(await started_at(sam, robot), SPOT)
    # A plain reset forgets a pose given before it.
    assert (await call(sam, "POST", "/api/robots/sim/reset", SPOT))[0] == 200
    assert (await call(sam, "POST", "/api/robots/sim/reset"))[0] == 200
    await moved_away(sim_agent, start)
    assert not at(await started_at(sam, robot), SPOT)


# -- the setting and the page -----------------------------------------------------------------


@pytest.mark.django_db
def test_the_setting_is_checked_edited_and_shown():
    staff = User.objects.create_superuser("staff")
    robot = Robot.objects.create(name="sim", url="sim://", owner=staff)
    call = api(staff)
    status, body = call("PATCH", "/api/robots/sim", {"settings": {"start_each_run": "yes"}})
    assert status == 422 and "start_each_run must be true or false" in body["detail"], body
    client = Client()
    client.force_login(staff)
    form = client.get("/robots/sim/settings").content.decode()
    assert 'name="start_each_run"' in form and "Each run starts at the world" in form
    client.post("/robots/sim/settings", {"url": "sim://", "start_each_run": "on"})
    robot.refresh_from_db()
    assert robot.settings["start_each_run"] is True
    assert "start_each_run" not in robot.driver_options()  # a run setting, not the driver's
    page = client.get("/robots/sim/").content.decode()
    card = page.split("<code>start_each_run</code>")[1].split("</tr>")[0]
    assert ">yes<" in card and "set here" in card
    client.post("/robots/sim/settings", {"url": "sim://"})  # unticked
    robot.refresh_from_db()
    assert "start_each_run" not in robot.settings  # off: the default
    # A real robot has no such setting to edit.
    Robot.objects.create(name="pio", url="pioneer:///dev/ttyUSB0")
    assert 'name="start_each_run"' not in client.get("/robots/pio/settings").content.decode()


@pytest.mark.django_db(transaction=True)
async def test_the_page_form_resets_without_scripts_and_with_htmx(sim_agent):
    start = await start_pose()
    sam, _ = await users()
    client = Client()
    await sync_to_async(client.force_login)(sam)
    page = (await sync_to_async(client.get)("/robots/sim/")).content.decode()
    assert 'action="/robots/sim/reset"' in page and "Reset" in page

    await moved_away(sim_agent, start)
    post = sync_to_async(client.post)
    answer = await post("/robots/sim/reset", {"next": "/robots/sim/"}, follow=True)
    assert answer.redirect_chain == [("/robots/sim/", 302)]
    assert "sim is back at its start." in answer.content.decode()
    assert at(await position(sim_agent), start)

    answer = await post("/robots/sim/reset", SPOT, headers={"HX-Request": "true"})
    said = answer.content.decode()
    assert answer.status_code == 200 and "the next run starts there" in said, said
    assert at(await position(sim_agent), SPOT)
    answer = await post("/robots/sim/reset", {"x": "1", "y": "", "theta": ""},
                        headers={"HX-Request": "true"})  # fmt: skip
    assert 'class="error"' in answer.content.decode()


def test_the_agent_takes_robot_reset_messages_of_the_right_shape():
    good = {"type": "robot.reset", "pose": [0.5, -0.4, 0.3], "by": "sam", "override": False}
    assert messages.check(good) is None
    assert messages.check({"type": "robot.reset"}) is None
    for bad in ([1, 2], [1, 2, float("nan")], [1, 2, "3"], "0,0,0", {"x": 1}):
        assert messages.check({**good, "pose": bad}) is not None, bad
    assert messages.check({**good, "override": "yes"}) is not None
