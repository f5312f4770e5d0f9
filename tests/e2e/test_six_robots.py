"""The paper's claim: one program, every robot; only the driver behind the Robot API changes.

A real agent (in this process, on the in-memory channel layer) serves each robot; its peer
sits on the other side of the driver's wire and decodes what it is told. The same program
runs on each, and the robot's own stop is seen on the wire when a program ends, when a
browser that drove it leaves, and on an emergency stop.
"""

import asyncio
import json
import math
import time

import pytest
from channels.db import database_sync_to_async
from channels.testing import WebsocketCommunicator
from django.contrib.auth.models import User

from robots.bus import ask_agent, send_to_agent
from robots.consumers import RobotConsumer
from tests.e2e.agents import finished, log_of, output_of, run_program, until
from tests.peers import KINDS, LINKED, WIRED
from tests.rhal.arcos_models import MODELS

pytestmark = pytest.mark.django_db(transaction=True)

EXAMPLE = "programs/examples/any_robot.py"


@pytest.mark.parametrize("kind", KINDS)
async def test_the_same_program_runs_on_every_robot(kind, robot_on):
    peer, agent, robot, user = await robot_on(kind)
    stops = peer.stops  # a driver may stop the robot as it opens (dtmf does)
    with open(EXAMPLE) as source:
        run = await finished(await run_program(user, robot, source.read()))
    assert run.state == "finished", f"{run.state}: {run.reason}"
    out = output_of(run)
    assert f"stopped on a {agent.driver.kind} robot" in out
    has = agent.driver.capabilities()["sensors"]
    for name in ("heading", "range"):
        if name in has:
            assert f"{name}: " in out and "no such sensor" not in out.split(f"{name}: ")[1][:30]
        else:
            assert f"{name}: this robot has no such sensor" in out
    if kind != "sim":  # a wire may still be carrying the stop (tones play in real time)
        await until(lambda: peer.stops > stops, what="the robot's stop on the wire")
        await until(lambda: peer.commanded() == (0.0, 0.0), what="stopped on the wire")


@pytest.mark.parametrize("kind", WIRED)
async def test_a_program_that_ends_while_driving_stops_the_robot(kind, robot_on):
    peer, agent, robot, user = await robot_on(kind)
    source = "import robot, time\nrobot.Robot().drive(0.3, 0.0)\ntime.sleep(1.0)\n"
    run = await run_program(user, robot, source)
    await until(lambda: peer.commanded()[0] > 0, what="driving forward on the wire")
    stops = peer.stops
    run = await finished(run)
    assert run.state == "finished", run.reason
    await until(lambda: peer.stops > stops, what="the robot's stop on the wire")
    assert peer.commanded() == (0.0, 0.0)


def robot_page(kind, user) -> WebsocketCommunicator:
    page = WebsocketCommunicator(RobotConsumer.as_asgi(), f"/ws/robots/{kind}/")
    page.scope["user"] = user
    page.scope["url_route"] = {"kwargs": {"name": kind}}
    return page


@pytest.mark.parametrize("kind", WIRED)
async def test_a_browser_that_leaves_stops_the_robot_it_drove(kind, robot_on, monkeypatch):
    monkeypatch.setattr("robots.agent.TELEOP_DEADMAN", 600)  # so only the leaving stops it
    peer, agent, robot, user = await robot_on(kind)
    page = robot_page(kind, user)
    assert (await page.connect())[0]
    await page.send_to('{"drive": [0.0, 1.0]}')
    await until(lambda: peer.commanded()[1] > 0, what="turning left on the wire")
    stops = peer.stops
    await page.disconnect()
    await until(lambda: peer.stops > stops, what="the robot's stop on the wire")
    assert peer.commanded() == (0.0, 0.0)


@pytest.mark.parametrize("kind", WIRED)
async def test_an_emergency_stop_stops_the_robot_and_its_programs(kind, robot_on):
    peer, agent, robot, user = await robot_on(kind)
    source = "import robot, time\nrobot.Robot().drive(0.3, 0.0)\ntime.sleep(60)\n"
    run = await run_program(user, robot, source)
    await until(lambda: peer.commanded()[0] > 0, what="driving forward on the wire")
    stops = peer.stops
    reply = await ask_agent(kind, "robot.estop")
    assert reply["stopped"] == 1
    await until(lambda: peer.stops > stops, what="the robot's stop on the wire")
    assert peer.commanded() == (0.0, 0.0)
    assert (await finished(run)).state == "stopped"
    # Stopped again when already stopped: an e-stop is never skipped.
    stops = peer.stops
    await ask_agent(kind, "robot.estop")
    await until(lambda: peer.stops > stops, what="a second stop on the wire")


async def test_a_browser_that_goes_quiet_stops_the_robot(robot_on):
    peer, agent, robot, user = await robot_on("pioneer")
    page = robot_page("pioneer", user)
    assert (await page.connect())[0]
    await page.send_to('{"drive": [0.2, 0.0]}')
    await until(lambda: peer.commanded()[0] > 0, what="driving forward on the wire")
    # No more commands and no goodbye (a frozen tab, a lost network): the dead-man stops it.
    await until(lambda: peer.commanded() == (0.0, 0.0), what="the dead-man's stop")
    await page.disconnect()


async def test_while_a_person_drives_a_program_is_refused_with_who_controls(robot_on):
    peer, agent, robot, user = await robot_on("pioneer")
    page = robot_page("pioneer", user)
    assert (await page.connect())[0]
    await page.send_to('{"drive": [0.2, 0.0]}')
    await until(lambda: peer.commanded()[0] > 0, what="driving forward on the wire")
    await page_says(page, "You control the robot")
    source = (
        "import robot, time\nbot = robot.Robot()\n"
        "while True:\n"
        "    try:\n        bot.drive(0.1, 0.0)\n        break\n"
        "    except robot.RobotError as exc:\n        print(exc, flush=True)\n"
        "        time.sleep(0.2)\n"
        "print('driving', flush=True)\ntime.sleep(60)\n"
    )
    run = await run_program(user, robot, source)
    await until(lambda: run.log_path.exists() and "controlled by" in run.log_path.read_text(),
                what="the program told who controls the robot")  # fmt: skip
    assert f"controlled by {user.username}, driving by hand" in run.log_path.read_text()
    await page.disconnect()  # the person leaves: the robot stops and the program may drive
    await until(lambda: peer.commanded()[0] == pytest.approx(0.1), what="the program's speed")
    assert agent.lease.holds(run.pk)
    await ask_agent("pioneer", "robot.estop")
    assert (await finished(run)).state == "stopped"
    assert agent.lease.estopped  # until someone resumes


async def test_hand_driving_commands_that_are_not_numbers_are_ignored(robot_on):
    peer, agent, robot, user = await robot_on("pioneer")
    page = robot_page("pioneer", user)
    assert (await page.connect())[0]
    for junk in ('{"drive": [1e999, 0]}', '{"drive": ["fast", 0]}', '{"drive": [true, 0]}',
                 '{"drive": [1]}', "[1, 2]", "not json", '{"HEADERS": {}}'):  # fmt: skip
        await page.send_to(junk)
    await page.send_to('{"drive": [0.1, 0.0]}')
    await until(lambda: peer.commanded()[0] > 0, what="the one good command")
    vels = [c.arg for c in peer.emulator.named("VEL")]
    assert all(v in (0, 100) for v in vels), vels
    await page.disconnect()


async def test_new_settings_reopen_the_robot_with_them(robot_on):
    peer, agent, robot, user = await robot_on("pioneer")
    old = agent.driver
    robot.settings = {"max_linear": 0.15}
    await database_sync_to_async(robot.save)()
    await send_to_agent("pioneer", "robot.reconfigure")
    await until(lambda: agent.driver is not old and agent.driver.is_open, what="reopened")
    assert not old.is_open
    assert agent.driver.capabilities()["drive"]["max_linear"] == 0.15
    await agent.driver.drive(1.0, 0.0)
    await until(lambda: peer.commanded()[0] == pytest.approx(0.15), what="the new limit")


PATIENT = """\
import time
import robot

bot = robot.Robot()
bot.sensors()
print("ready", flush=True)
lost = False
for _ in range(1200):
    try:
        bot.sensors()
    except robot.RobotError as exc:
        if not lost:
            print("error:", exc, flush=True)
        lost = True
    else:
        if lost:
            print("back", flush=True)
            break
    time.sleep(0.05)
"""


async def page_says(page, text: str, timeout: float = 15.0) -> str:
    deadline = time.monotonic() + timeout
    while True:
        left = deadline - time.monotonic()
        assert left > 0, f"the robot page never said {text!r}"
        html = await page.receive_from(timeout=left)
        if text in html:
            return html


@pytest.mark.parametrize("kind", LINKED)
async def test_an_unplugged_robot_is_reported_and_comes_back(kind, robot_on):
    peer, agent, robot, user = await robot_on(kind)
    page = robot_page(kind, user)
    assert (await page.connect())[0]
    run = await run_program(user, robot, PATIENT)
    await until(lambda: run.log_path.exists() and "o ready" in run.log_path.read_text(),
                what="the program asking")  # fmt: skip
    await peer.unplug()
    html = await page_says(page, "Robot not reachable")
    assert 'role="alert"' in html
    await peer.replug()
    await page_says(page, "<th>")  # readings again
    run = await finished(run)
    out = output_of(run)
    assert run.state == "finished", run.reason
    error = next(line for line in out.splitlines() if line.startswith("error:"))
    assert kind in error and ("reconnect" in error or "lost" in error), error
    assert out.endswith("back")
    await page.disconnect()


async def test_staff_take_over_from_a_program_and_students_cannot(robot_on):
    peer, agent, robot, user = await robot_on("pioneer")
    source = "import robot, time\nrobot.Robot().drive(0.1, 0.0)\ntime.sleep(60)\n"
    run = await run_program(user, robot, source)
    await until(lambda: peer.commanded()[0] > 0, what="the program driving")
    student = robot_page("pioneer", user)
    assert (await student.connect())[0]
    await student.send_to('{"take": true}')  # not staff: ignored
    await student.send_to('{"drive": [0.0, 1.0]}')
    await page_says(student, "run #")  # told who controls the robot
    assert agent.lease.holds(run.pk)
    teacher = await database_sync_to_async(User.objects.create_user)("teacher", is_staff=True)
    staff = robot_page("pioneer", teacher)
    assert (await staff.connect())[0]
    await staff.send_to('{"take": true}')
    await until(lambda: peer.commanded() == (0.0, 0.0), what="the program's motion stopped")
    assert agent.lease.holder.user == "teacher"
    await staff.send_to('{"drive": [0.0, 1.0]}')
    await until(lambda: peer.commanded()[1] > 0, what="the teacher turning the robot")
    await staff.disconnect()
    await student.disconnect()
    await ask_agent("pioneer", "robot.estop")


# -- every Pioneer model the emulator knows ----------------------------------------------------

# A pose is read once the robot itself reports standing still: the first report after the
# stop took effect, whatever the machine's load (a guessed pause read it before, now and then).
FORWARD_TURN_STOP = """
import json, time, robot
bot = robot.Robot()
def still():
    while True:
        readings = bot.sensors()
        if readings["velocity"] == {"linear": 0.0, "angular": 0.0}:
            return readings["position"]
        time.sleep(0.05)
start = still()
bot.drive(0.3, 0.0); time.sleep(1.0); bot.stop()
moved = still()
bot.drive(0.0, 0.6); time.sleep(1.0); bot.stop()
print(json.dumps([start, moved, still()]))
"""
AT_ONCE = 8  # models driven at the same time


async def test_every_pioneer_model_reports_the_distance_and_turn_it_made(robot_on):
    """The unchanged "forward, turn, stop" program on each model's emulator: the distance and
    turn the driver reports agree with the emulator's true pose within 5 %."""
    gate = asyncio.Semaphore(AT_ONCE)

    async def drive(number, model):
        async with gate:
            name = f"pioneer-{number}"
            peer, agent, robot, user = await robot_on("pioneer", name, model=model)
            run = await finished(await run_program(user, robot, FORWARD_TURN_STOP))
            x, y, theta = peer.emulator.true_pose()  # it stood at 0, 0, 0 when opened
            await robot_on.retire(name)  # 37 live robots would load the test's loop
        assert run.state == "finished", f"{model}: {run.state}: {run.reason}\n{log_of(run)}"
        start, moved, turned = json.loads(output_of(run).splitlines()[-1])
        distance = math.hypot(moved["x"] - start["x"], moved["y"] - start["y"])
        turn = math.remainder(turned["theta"] - start["theta"], math.tau)
        return model, (distance, math.hypot(x, y)), (turn, theta)

    # A task group: one model failing cancels the others, rather than leaving them running
    # into the fixture's teardown.
    async with asyncio.TaskGroup() as group:
        drives = [group.create_task(drive(n, m)) for n, m in enumerate(sorted(MODELS))]
    results = [task.result() for task in drives]
    wrong = [
        f"{model}: {what} {reported:.3f}, truly {true:.3f}"
        for model, *pairs in results
        for what, (reported, true) in zip(("distance", "turn"), pairs, strict=True)
        if not abs(reported - true) <= 0.05 * abs(true)
    ]
    assert not wrong, "\n".join(wrong)
    assert all(true > 0 for _, (_, true), _ in results)  # they did drive
