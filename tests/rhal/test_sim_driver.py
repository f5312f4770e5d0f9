"""The sim:// driver's options on rhal.simulator: worlds, speed, reset with a pose, twins."""

import copy
import json
import math

import pytest

import rhal
from rhal.options import driver_options
from rhal.simulator.worlds import BUILTIN, load

R = 0.15


async def test_reset_with_a_pose_places_the_robot_there(robot, drive_for):
    await drive_for(0.3, 0.5, 2.0)
    await robot.reset((-1.0, 0.5, 0.25))
    readings = await robot.sensors()
    assert readings["position"] == pytest.approx({"x": -1.0, "y": 0.5, "theta": 0.25})
    assert readings["velocity"] == {"linear": 0.0, "angular": 0.0}
    assert readings["odometry"] == {"distance": 0.0}
    assert readings["battery"] == 100.0
    moved = await drive_for(0.5, 0.0, 1.0)
    assert moved["position"]["x"] == pytest.approx(-1.0 + 0.5 * math.cos(0.25))


@pytest.mark.parametrize(
    ("pose", "words"),
    [((2.5, 0.0, 0.0), "outside the arena"),
     ((1.05, 0.75, 0.0), "inside a wall or box"),
     ((0.7, 0.75, 0.0), "0.10 m from a wall or box"),
     ((1.9, 0.0, 0.0), "needs 0.15 m clear"),
     (("a", 0, 0), "a pose is (x, y, theta)"),
     ((0.0, math.nan, 0.0), "finite")],
)  # fmt: skip
async def test_reset_refuses_a_pose_it_cannot_take_in_plain_words(robot, pose, words):
    with pytest.raises(ValueError, match=words.replace("(", r"\(").replace(")", r"\)")):
        await robot.reset(pose)
    readings = await robot.sensors()  # and stays where it was
    assert readings["position"] == pytest.approx({"x": 0.0, "y": 0.0, "theta": math.pi / 2})


async def test_speed_10_moves_ten_times_as_far_per_real_second(clock):
    async with rhal.connect("sim://?speed=10", clock=clock) as fast:
        async with rhal.connect("sim://", clock=clock) as slow:
            for bot in (fast, slow):
                await bot.drive(0.1, 0.0)
            clock.advance(1.0)
            far, near = await fast.sensors(), await slow.sensors()
    assert far["position"]["y"] == pytest.approx(1.0)
    assert near["position"]["y"] == pytest.approx(0.1)
    assert (far["time"], near["time"]) == pytest.approx((10.0, 1.0))


@pytest.mark.parametrize("speed", [0, 11, "fast", True])
def test_speed_is_1_to_10(speed):
    with pytest.raises(ValueError, match="speed must be a number from 1 to 10"):
        rhal.connect("sim://", speed=speed)


async def test_the_url_names_a_world_and_a_speed(clock):
    async with rhal.connect("sim://?world=maze&speed=10", clock=clock) as bot:
        readings = await bot.sensors()
        caps = bot.capabilities()
        assert bot.world_doc() == load("maze").to_doc()
    assert readings["position"] == pytest.approx({"x": -2.0, "y": -2.0, "theta": 0.0})
    assert caps["sim"] == {"world": "maze", "speed": 10.0, **load("maze").robot.to_doc()}
    assert json.loads(json.dumps(caps)) == caps


def test_arena_is_the_old_name_of_world():
    assert rhal.connect("sim://?arena=square").world == load("square")
    assert rhal.connect("sim://?arena=square&world=rooms").world.name == "rooms"  # world wins
    assert rhal.connect("sim://").world.name == "boxes"


def test_an_unknown_world_names_the_built_in_ones():
    with pytest.raises(ValueError, match="unknown world 'moon'; choose one of: boxes, square"):
        rhal.connect("sim://?world=moon")


async def test_a_world_document_is_a_world(clock):
    doc = copy.deepcopy(BUILTIN["square"])
    doc["name"] = "mine"
    doc["walls"] = [{"from": [-2, 1], "to": [2, 1], "thickness": 0.1}]
    async with rhal.connect("sim://", world=doc, clock=clock) as bot:
        assert await bot.sensor("range") == pytest.approx(0.95)
        await bot.drive(0.5, 0.0)
        clock.advance(10.0)
        readings = await bot.sensors()
        assert bot.capabilities()["sim"]["world"] == "mine"
    assert readings["position"]["y"] == pytest.approx(0.95 - R, abs=1e-6)
    assert readings["bumper"] is True


def test_a_bad_world_document_says_where():
    doc = copy.deepcopy(BUILTIN["square"])
    doc["walls"] = [{"from": [0, 0], "to": [3, 0]}]
    with pytest.raises(ValueError, match=r"at walls\[0\].to.*wall 1 ends outside the arena"):
        rhal.connect("sim://", world=doc)


def test_twin_options_override_the_worlds_robot():
    bot = rhal.connect("sim://?world=maze&sonar=-90,90&floor_sensor=false&range_cone_deg=30")
    assert bot.robot_doc() == {
        "radius": 0.15,
        "range": {"cone_deg": 30.0, "rays": 5, "min": 0.03, "max": 4.0},
        "sonar": [-90.0, 90.0],
        "floor_sensor": False,
    }
    assert set(bot.capabilities()["sensors"]) >= {"sonar", "zone"}
    assert "floor" not in bot.capabilities()["sensors"]
    assert rhal.connect("sim://?sonar=90").robot_doc()["sonar"] == [90.0]
    assert rhal.connect("sim://", sonar=[45, -45]).robot_doc()["sonar"] == [45.0, -45.0]
    assert rhal.connect("sim://?world=maze&sonar=").robot_doc()["sonar"] == []


@pytest.mark.parametrize(
    ("options", "words"),
    [({"sonar": "left"}, "sonar must be angles"), ({"sonar": [200]}, "-180 to 180"),
     ({"range_cone_deg": 120}, "0 to 90"), ({"floor_sensor": "yes"}, "true or false")],
)  # fmt: skip
def test_bad_twin_options_are_refused(options, words):
    with pytest.raises(ValueError, match=words):
        rhal.connect("sim://", **options)


def test_the_options_a_form_shows():
    options = {option.name: option for option in driver_options("sim://")}
    assert {"world", "arena", "speed", "sonar", "floor_sensor", "range_cone_deg"} <= set(options)
    assert options["world"].kind is str and options["world"].default is None
    assert options["speed"].kind is float and options["speed"].default == 1.0
    assert options["sonar"].kind is str and options["floor_sensor"].kind is bool
    assert options["arena"].choices == tuple(BUILTIN)
    # What a form's text field gives back builds the driver.
    chosen = {"sonar": options["sonar"].parse("90, 0, -90"), "speed": 10}
    assert rhal.connect("sim://", **chosen).robot_doc()["sonar"] == [90.0, 0.0, -90.0]


async def test_the_path_depends_on_the_commands_not_on_how_often_it_is_read(clock):
    # Sliding along the north wall and round the box: read every 1 ms or only at the end.
    async def run(reads: int) -> dict:
        async with rhal.connect("sim://", clock=clock) as bot:
            await bot.reset((0.3, 0.2, math.radians(70)))
            await bot.drive(0.5, 0.3)
            for _ in range(reads):
                clock.advance(6.0 / reads)
                await bot.sensors()
            clock.advance(6.0 - 6.0 / reads * reads)
            return await bot.sensors()

    often, once = await run(6000), await run(1)
    assert often["position"] == pytest.approx(once["position"], abs=1e-9)
    assert often["odometry"]["distance"] == pytest.approx(once["odometry"]["distance"], abs=1e-9)
