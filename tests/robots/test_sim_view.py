"""A sim drawn by the browser (issue 30, "Drawn in the browser"): its agent streams robot.pose
to the robot's page at up to 20 Hz while it moves and not at all while it stands still; the
page asks its world once (GET /robots/<name>/world.json, robot.world)."""

import asyncio
import json
import math
import time

import pytest
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer
from django.contrib.auth.models import Group, User
from django.test import Client

from robots.consumers import RobotConsumer
from robots.lease import Holder
from robots.models import Robot, robot_group
from robots.sim_view import PoseStream
from tests.programs.test_consumers import communicator

pytestmark = pytest.mark.django_db(transaction=True)

WINDOW = 2.0  # s of motion counted: 20 Hz sends 40, the test asks for 15 Hz's 30


async def frames(comm, seconds: float) -> list:
    """The pose frames (JSON) a page's socket receives in ``seconds``; its HTML is skipped.
    (A receive that times out would end the consumer: the queue is looked at instead.)"""
    poses = []
    end = time.monotonic() + seconds
    while time.monotonic() < end:
        if await comm.receive_nothing(timeout=0.02, interval=0.005):
            continue
        text = await comm.receive_from()
        if text.startswith("{"):
            poses.append(json.loads(text)["pose"])
    return poses


async def first_pose(comm, check=lambda pose: True) -> dict:
    """The next pose frame that passes ``check`` (receive_from waits up to 30 s for each)."""
    while True:
        text = await comm.receive_from()
        if text.startswith("{") and check(pose := json.loads(text)["pose"]):
            return pose


async def test_poses_reach_the_page_while_the_sim_moves_and_stop_when_it_is_still(sim_agent):
    alice = await database_sync_to_async(User.objects.create_user)("alice")
    comm = communicator(RobotConsumer, "/ws/robots/sim/", alice, name="sim")
    assert (await comm.connect())[0]
    holder = Holder("teleop", "test-driver", "alice")
    # Turning on the spot: it never meets a wall, however long the window.
    await sim_agent.drive_for(holder, 0.0, 1.0)
    moving = await frames(comm, WINDOW)
    assert len(moving) >= 15 * WINDOW, f"{len(moving)} poses in {WINDOW} s"
    assert all(p["angular"] == 1.0 and p["linear"] == 0.0 for p in moving)
    assert len({p["theta"] for p in moving}) == len(moving), "each pose is a new one"
    assert set(moving[0]) >= {"x", "y", "theta", "linear", "angular", "bumper", "range", "t"}

    await sim_agent.stop_motion_of(holder.key)
    last = await first_pose(comm, lambda pose: pose["angular"] == 0.0)
    reading = (await sim_agent.driver.sensors())["position"]
    assert (last["x"], last["y"], last["theta"]) == pytest.approx(
        (reading["x"], reading["y"], reading["theta"]), abs=1e-3
    ), "the last pose is where it stopped"
    assert await frames(comm, 1.0) == [], "nothing is sent while it stands still"
    await comm.disconnect()


async def test_a_robot_put_elsewhere_is_sent_once(sim_agent):
    """A reset moves the robot without a drive command: the telemetry loop notices."""
    alice = await database_sync_to_async(User.objects.create_user)("alice")
    comm = communicator(RobotConsumer, "/ws/robots/sim/", alice, name="sim")
    assert (await comm.connect())[0]
    holder = Holder("teleop", "test-driver", "alice")
    await sim_agent.drive_for(holder, 0.0, 2.0)
    await first_pose(comm, lambda pose: pose["angular"] != 0.0)
    await sim_agent.stop_motion_of(holder.key)
    await first_pose(comm, lambda pose: pose["angular"] == 0.0)
    await sim_agent.driver.reset()
    start = await first_pose(comm)
    assert start["linear"] == start["angular"] == 0.0
    assert (start["x"], start["y"]) == pytest.approx((0.0, 0.0), abs=1e-3)
    assert await frames(comm, 1.0) == []
    await comm.disconnect()


async def test_a_real_robot_sends_no_poses(sim_agent, monkeypatch):
    monkeypatch.setattr("robots.sim_view.is_sim", lambda driver: False)
    sent = []
    monkeypatch.setattr(PoseStream, "_publish", lambda self, pose: sent.append(pose))
    await sim_agent.drive_for(Holder("teleop", "test-driver", "alice"), 0.0, 1.0)
    await asyncio.sleep(0.3)  # what would have been six poses; a failure shows them all
    assert sent == []
    assert "error" in await ask_world()


async def ask_world() -> dict:
    from robots.bus import AgentUnavailable, ask_agent

    try:
        return await ask_agent("sim", "robot.world")
    except AgentUnavailable as exc:
        return {"error": str(exc)}


async def test_the_agent_answers_its_world(sim_agent):
    answer = await ask_world()
    world, robot = answer["world"], answer["robot"]
    assert world["format"] == 1 and world["size"]["width"] > 0 and world["start"]
    assert robot["radius"] > 0 and "cone_deg" in robot["range"]
    assert answer["speed"] >= 1
    assert set(answer["pose"]) >= {"x", "y", "theta", "range", "bumper"}


def test_world_json_for_those_who_may_see_the_robot(monkeypatch):
    robot = Robot.objects.create(name="sim", url="sim://")
    world = {"world": {"format": 1, "size": {"width": 4, "height": 4}}, "robot": {}, "speed": 1}
    monkeypatch.setattr(
        "robots.views.ask_agent_sync", lambda *a, **k: {"type": "agent.reply", **world}
    )
    client = Client()
    assert client.get("/robots/sim/world.json").status_code == 302  # to the sign-in page
    client.force_login(User.objects.create_user("alice"))
    response = client.get("/robots/sim/world.json")
    assert response.status_code == 200 and response.json() == world
    assert response["Cache-Control"] == "no-store"
    robot.groups.add(Group.objects.create(name="class-a"))  # alice is not in it
    assert client.get("/robots/sim/world.json").status_code == 404


def test_a_page_draws_a_sim_and_shows_a_real_robots_camera(monkeypatch):
    Robot.objects.create(name="sim", url="sim://")
    state = {"sensors": {}, "units": {}, "camera": True, "drive": None, "lease": None,
             "shows": {}, "sim": {"world": "boxes", "speed": 3}}  # fmt: skip
    monkeypatch.setattr("robots.views.ask_agent_sync", lambda *args, **kwargs: state)
    client = Client()
    client.force_login(User.objects.create_user("alice"))
    page = client.get("/robots/sim/").content.decode()
    assert 'class="simview-canvas' in page and 'data-world-url="/robots/sim/world.json"' in page
    assert "World: boxes" in page and "3× real time" in page
    # The stream only inside <noscript>: a page with scripts never asks for it.
    assert page.count("camera.mjpg") == 1
    noscript = page[page.index("<noscript><img") :]
    assert noscript.index("camera.mjpg") < noscript.index("</noscript>")
    state["sim"] = None  # a real robot: its camera as before
    page = client.get("/robots/sim/").content.decode()
    assert "simview-canvas" not in page
    assert '<img class="camera" id="camera" src="/robots/sim/camera.mjpg"' in page


async def test_pressing_on_a_wall_is_sent_as_standing_still(sim_agent):
    """Driven into a wall head-on, the sim stays where it is while its command goes on: the
    page is told it stands (speeds 0, bumper pressed) and then nothing more, rather than a
    speed it would draw the robot going into the wall with."""
    alice = await database_sync_to_async(User.objects.create_user)("alice")
    comm = communicator(RobotConsumer, "/ws/robots/sim/", alice, name="sim")
    assert (await comm.connect())[0]
    await sim_agent.driver.reset((0.0, 1.7, math.pi / 2))  # 0.15 m from the north wall
    holder = Holder("teleop", "test-driver", "alice")
    await sim_agent.drive_for(holder, 0.3, 0.0)
    pressed = await first_pose(comm, lambda pose: pose["bumper"])
    if pressed["linear"] != 0.0:  # the last moving pose touched; standing comes next
        pressed = await first_pose(comm, lambda pose: pose["linear"] == 0.0)
    assert pressed["bumper"] and pressed["angular"] == 0.0
    assert await frames(comm, 1.0) == [], "nothing more while it presses on the wall"
    await sim_agent.stop_motion_of(holder.key)
    await comm.disconnect()


async def test_a_moving_sim_nobody_watches_sends_no_poses(sim_agent):
    """Poses go out only while a page's socket holds a watch: a class's moving sims that
    nobody looks at cost nothing for drawing. The socket's close ends its watch."""
    layer = get_channel_layer()
    listener = await layer.new_channel()
    await layer.group_add(robot_group("sim"), listener)
    holder = Holder("teleop", "test-driver", "alice")
    await sim_agent.drive_for(holder, 0.0, 1.0)

    async def poses_heard(seconds: float) -> int:
        heard, end = 0, time.monotonic() + seconds
        while (left := end - time.monotonic()) > 0:
            try:
                message = await asyncio.wait_for(layer.receive(listener), left)
            except TimeoutError:
                break
            heard += message["type"] == "robot.pose"
        return heard

    assert await poses_heard(1.0) == 0, "nobody watches: no poses"
    alice = await database_sync_to_async(User.objects.create_user)("alice")
    comm = communicator(RobotConsumer, "/ws/robots/sim/", alice, name="sim")
    assert (await comm.connect())[0]
    assert await poses_heard(1.0) >= 10, "a page watches: the poses flow"
    await comm.disconnect()
    await poses_heard(0.3)  # what was on its way when the watch ended
    assert await poses_heard(1.0) == 0, "the page left: no poses"
    await sim_agent.stop_motion_of(holder.key)
