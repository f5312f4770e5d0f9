"""Blocks programs: Blockly's JSON, run as the Python programs/blocks.py makes of it.

Every block type's Python runs, as the launcher would run it (the blocks language's command
and environment, the Python client on its path), against a real Robot API server on a sim
robot; what reaches the robot is recorded at its driver. The examples run on the sim; bad JSON
and unknown blocks give errors that name the block; field values cannot become code. Then the
whole path through an appliance's agent, the examples every new account gets, and
robotide/static/robotide/blocks.js in Debian's Chromium with the vendored Blockly.
"""

import ast
import asyncio
import itertools
import json
import math
import os
import re
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import pytest
from django.test import Client
from django.urls import reverse
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from programs.blocks import BlocksError, block_types, to_python, to_runnable_python
from programs.languages import CLIENTS_DIR, LANGUAGES
from robots.host_services import HostServices
from runbox import launcher
from tests.appliance import ROOT, wait_for
from tests.robot_api_server import admit, check_wall_turn

sys.path.insert(0, str(CLIENTS_DIR / "python"))
import robot as robot_client  # noqa: E402  (the client programs get on their path)

EXAMPLES = ROOT / "programs" / "examples"
STATIC = ROOT / "robotide" / "static"
BLOCKS = LANGUAGES["blocks"]
TOKEN = "blocks-token"
INJECTION = '"); import os; os.system("touch PWNED") #'
INJECTIONS = [
    INJECTION,
    "'); import os; os.system('touch PWNED') #",
    "x\nimport os\nos.system('touch PWNED')\n",
    "x\\'); __import__('os').system('touch PWNED')  # \u2028 \r",
    '"""; import os; os.system("touch PWNED"); """',
]


# -- building blocks as Blockly saves them ---------------------------------------------------

_ids = itertools.count(1)


def block(kind: str, fields: dict | None = None, **inputs) -> dict:
    """A block; an input given a list is a statement input (a stack of blocks)."""
    made: dict = {"type": kind, "id": f"{kind}-{next(_ids)}"}
    if fields:
        made["fields"] = fields
    if inputs:
        made["inputs"] = {
            name: {"block": stack(*value) if isinstance(value, list) else value}
            for name, value in inputs.items()
        }
    return made


def stack(*blocks: dict) -> dict:
    for upper, lower in itertools.pairwise(blocks):
        upper["next"] = {"block": lower}
    return blocks[0]


def workspace(*stacks: dict, variables=()) -> str:
    tops = [{**top, "x": 20, "y": 20 + 100 * n} for n, top in enumerate(stacks)]
    made: dict = {"blocks": {"languageVersion": 0, "blocks": tops}}
    if variables:
        made["variables"] = [{"name": name, "id": f"var-{name}"} for name in variables]
    return json.dumps(made)


def num(value) -> dict:
    return block("math_number", {"NUM": value})


def text(value: str) -> dict:
    return block("text", {"TEXT": value})


def var(name: str) -> dict:
    return {"id": f"var-{name}"}


def get(name: str) -> dict:
    return block("variables_get", {"VAR": var(name)})


def set_(name: str, value: dict) -> dict:
    return block("variables_set", {"VAR": var(name)}, VALUE=value)


def change(name: str, delta) -> dict:
    return block("math_change", {"VAR": var(name)}, DELTA=num(delta))


def show(value: dict) -> dict:  # print it
    return block("text_print", TEXT=value)


def compare(op: str, a: dict, b: dict) -> dict:
    return block("logic_compare", {"OP": op}, A=a, B=b)


def arithmetic(op: str, a: dict, b: dict) -> dict:
    return block("math_arithmetic", {"OP": op}, A=a, B=b)


def sensor(name: str) -> dict:
    return block("robot_sensor", {"SENSOR": name})


def for_(name: str, start: dict, end: dict, step: dict, body: list) -> dict:
    return block("controls_for", {"VAR": var(name)}, FROM=start, TO=end, BY=step, DO=body)


def if_(*branches, otherwise: list | None = None) -> dict:
    """if_((condition, [body]), (condition, [body]), ..., otherwise=[body])."""
    made = block("controls_if")
    made["extraState"] = {"elseIfCount": len(branches) - 1, "hasElse": otherwise is not None}
    made["inputs"] = {}
    for n, (condition, body) in enumerate(branches):
        made["inputs"][f"IF{n}"] = {"block": condition}
        if body:
            made["inputs"][f"DO{n}"] = {"block": stack(*body)}
    if otherwise is not None:
        made["inputs"]["ELSE"] = {"block": stack(*otherwise)}
    return made


def join(*items: dict) -> dict:
    made = block("text_join", **{f"ADD{n}": item for n, item in enumerate(items)})
    made["extraState"] = {"itemCount": len(items)}
    return made


# -- running as the launcher would ------------------------------------------------------------


@dataclass
class Finished:
    status: int
    out: str
    err: str
    python: str

    @property
    def lines(self) -> list[str]:
        return self.out.splitlines()


@pytest.fixture
async def agent(agent):
    admit(agent, TOKEN, 7)
    return agent


@pytest.fixture
def calls(agent, monkeypatch) -> list[tuple]:
    """What reaches the robot's driver: ("drive", linear, angular, t) and ("stop", t)."""
    made: list[tuple] = []
    drive, stop = agent.driver.drive, agent.driver.stop

    async def recording_drive(linear, angular):
        made.append(("drive", linear, angular, time.monotonic()))
        return await drive(linear, angular)

    async def recording_stop():
        made.append(("stop", time.monotonic()))
        return await stop()

    monkeypatch.setattr(agent.driver, "drive", recording_drive)
    monkeypatch.setattr(agent.driver, "stop", recording_stop)
    return made


def kinds(calls: list[tuple]) -> list[tuple]:
    """The calls without their times."""
    return [call[:-1] for call in calls]


async def run(agent, tmp_path: Path, source: str, timeout: float = 60) -> Finished:
    """The blocks program `source` (JSON text), written and run as the agent's launch does."""
    filename, python = BLOCKS.program_file("program.json", source)
    assert filename == "program.py"
    (tmp_path / filename).write_text(python)
    env = launcher.environment(
        BLOCKS, tmp_path, {"ROBOT_API": agent.server.url, "ROBOT_TOKEN": TOKEN}
    )
    process = await asyncio.create_subprocess_exec(
        *BLOCKS.command(str(tmp_path / filename)), env=env, cwd=tmp_path,
        stdout=asyncio.subprocess.PIPE, stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip
    try:
        out, err = await asyncio.wait_for(process.communicate(), timeout)
    except TimeoutError:
        process.kill()
        out, err = await process.communicate()
        pytest.fail(f"still running after {timeout} s: {out.decode()} {err.decode()}")
    return Finished(process.returncode, out.decode(), err.decode(), python)


async def run_ok(agent, tmp_path, source: str) -> Finished:
    result = await run(agent, tmp_path, source)
    assert result.status == 0, f"{result.err}\n{result.python}"
    return result


# -- the generated program ------------------------------------------------------------------


def test_the_program_starts_with_the_robot_and_says_it_was_generated():
    python = to_python(workspace(show(text("hi"))))
    assert python.splitlines()[:5] == [
        "# Generated from a blocks program by robotide: edit the blocks, not this text.",
        "import robot, time",
        "",
        "bot = robot.Robot()",
        "",
    ]
    assert python.endswith("print('hi')\n")


@pytest.mark.parametrize("empty", ["{}", '{"blocks": {"languageVersion": 0, "blocks": []}}'])
def test_an_empty_workspace_is_a_program_that_does_nothing(empty):
    assert to_python(empty).rstrip().endswith("bot = robot.Robot()")


# -- the robot's blocks ---------------------------------------------------------------------


async def test_drive_wait_and_stop(agent, calls, tmp_path):
    source = workspace(
        stack(
            block("robot_drive", LINEAR=num(0.25), ANGULAR=num(-0.5)),
            block("robot_wait", SECONDS=num(0.3)),
            show(sensor("velocity.linear")),
            block("robot_stop"),
            show(sensor("velocity.linear")),
        )
    )
    result = await run_ok(agent, tmp_path, source)
    assert "bot.drive(0.25, -0.5)" in result.python and "time.sleep(0.3)" in result.python
    assert kinds(calls) == [("drive", 0.25, -0.5), ("stop",)]
    assert calls[1][-1] - calls[0][-1] >= 0.3
    assert result.lines == ["0.25", "0.0"]


async def test_forward_drives_straight_for_the_seconds_then_stops(agent, calls, tmp_path):
    source = workspace(block("robot_forward", SECONDS=num(0.5), SPEED=num(0.2)))
    await run_ok(agent, tmp_path, source)
    assert kinds(calls) == [("drive", 0.2, 0.0), ("stop",)]
    assert calls[1][-1] - calls[0][-1] >= 0.5
    after = await agent.driver.sensors()
    assert 0.1 <= after["odometry"]["distance"] < 0.2  # (more only if the machine stalls)
    assert after["velocity"] == {"linear": 0.0, "angular": 0.0}


@pytest.mark.parametrize("max_angular", [2.0, 0.5])  # 0.5: the robot turns slower than asked
async def test_turn_left_and_right_by_degrees(agent, calls, tmp_path, max_angular):
    agent.driver.max_angular = max_angular
    source = workspace(
        stack(
            block("robot_turn", {"DIRECTION": "LEFT"}, DEGREES=num(90)),
            block("robot_turn", {"DIRECTION": "RIGHT"}, DEGREES=num(45)),
        )
    )
    result = await run_ok(agent, tmp_path, source)
    assert "turn(90)" in result.python and "turn(-45)" in result.python
    # Asked at 1 rad/s, timed at what the robot applies
    assert kinds(calls) == [("drive", 0.0, 1.0), ("stop",), ("drive", 0.0, -1.0), ("stop",)]
    applied = min(1.0, max_angular)
    assert calls[1][-1] - calls[0][-1] >= math.pi / 2 / applied
    assert calls[3][-1] - calls[2][-1] >= math.pi / 4 / applied
    theta = (await agent.driver.sensors())["position"]["theta"]
    # Started facing north; a timed turn is a few hundredths off, more if the machine stalls.
    assert theta == pytest.approx(math.pi / 2 + math.pi / 4, abs=0.2)


async def test_sensor_blocks_read_the_robot(agent, tmp_path):
    names = [
        "range", "heading", "bumper", "position.x", "position.y", "position.theta",
        "velocity.linear", "velocity.angular", "odometry.distance", "battery",
    ]  # fmt: skip
    result = await run_ok(agent, tmp_path, workspace(stack(*(show(sensor(n)) for n in names))))
    assert "bot.sensor('position')['x']" in result.python
    readings = await agent.driver.sensors()  # it has not moved: the same now
    for name, line in zip(names, result.lines, strict=True):
        expected = readings
        for part in name.split("."):
            expected = expected[part]
        assert ast.literal_eval(line) == pytest.approx(expected, abs=0.01), name


async def test_a_sensor_the_robot_lacks_is_a_clear_error(agent, tmp_path):
    result = await run(agent, tmp_path, workspace(show(sensor("gps"))))
    assert result.status == 1 and "gps" in result.err and "RobotError" in result.err


@pytest.mark.django_db(transaction=True)  # the robot's speech settings: from its row
async def test_show_and_say_reach_the_robots_page(agent, tmp_path):
    agent.api.methods.update(HostServices(agent).methods)  # as RobotApi registers them
    source = workspace(
        stack(
            block("robot_show", {"NAME": "answer"}, VALUE=num(42)),
            block("robot_show", {"NAME": "where"}, VALUE=sensor("range")),
            block("robot_say", TEXT=join(text("I am "), num(7))),
        )
    )
    result = await run_ok(agent, tmp_path, source)
    assert "bot.say('I am ' + str(7))" in result.python
    assert agent.shows["answer"]["value"] == 42 and agent.shows["answer"]["run"] == 7
    assert agent.shows["where"]["value"] == pytest.approx(2.0, abs=0.1)
    assert agent.shows["said"]["value"] == "I am 7"


async def test_publish_receive_and_the_shared_memory(agent, tmp_path):
    source = workspace(
        stack(
            block("robot_publish", {"TOPIC": "news"}, VALUE=text("hello")),
            show(block("robot_receive", {"TOPIC": "news"}, TIMEOUT=num(5))),
            show(block("robot_receive", {"TOPIC": "quiet"}, TIMEOUT=num(0.2))),
            block("robot_memory_set", {"KEY": "laps"}, VALUE=num(3)),
            show(block("robot_memory_get", {"KEY": "laps"})),
            show(block("logic_null")),
        )
    )
    result = await run_ok(agent, tmp_path, source)
    # Subscribed before anything runs: its own message waits for the receive.
    assert "bot.subscribe('news')\nbot.subscribe('quiet')\n" in result.python
    assert result.lines == ["hello", "None", "3", "None"]


async def test_receive_waits_for_another_programs_message(agent, tmp_path):
    source = workspace(show(block("robot_receive", {"TOPIC": "go"})))  # no timeout: for ever
    task = asyncio.create_task(run(agent, tmp_path, source, timeout=20))
    bot = await asyncio.to_thread(robot_client.Robot, agent.server.url, TOKEN)
    try:
        deadline = time.monotonic() + 10
        while await asyncio.to_thread(bot.publish, "go", {"speed": 0.2}) < 1:
            assert time.monotonic() < deadline, "the program never subscribed"
            await asyncio.sleep(0.02)
    finally:
        bot.close()
    result = await task
    assert result.status == 0, result.err
    assert result.lines == ["{'speed': 0.2}"]


# -- logic, loops, math, text and variables ---------------------------------------------------

CASES = {
    "repeat": (
        [block("controls_repeat_ext", TIMES=num(3), DO=[show(text("hi"))])],
        ["hi", "hi", "hi"],
    ),
    "repeat, Blockly's older block (a number field)": (
        [block("controls_repeat", {"TIMES": 2}, DO=[show(text("ho"))])],
        ["ho", "ho"],
    ),
    "repeats inside repeats, a counter each": (
        [
            set_("n", num(0)),
            block(
                "controls_repeat_ext",
                TIMES=num(2),
                DO=[block("controls_repeat_ext", TIMES=num(3), DO=[change("n", 1)])],
            ),
            block("controls_repeat_ext", TIMES=num(1), DO=[change("n", 10)]),
            show(get("n")),
        ],
        ["16"],
    ),
    "repeat a computed number of times": (
        [
            set_("n", num(0)),
            block(
                "controls_repeat_ext",
                TIMES=arithmetic("DIVIDE", num(5), num(2)),
                DO=[change("n", 1)],
            ),
            show(get("n")),
        ],
        ["2"],
    ),
    "while": (
        [
            set_("n", num(0)),
            block(
                "controls_whileUntil",
                {"MODE": "WHILE"},
                BOOL=compare("LT", get("n"), num(3)),
                DO=[change("n", 1)],
            ),
            show(get("n")),
        ],
        ["3"],
    ),
    "until": (
        [
            set_("n", num(0)),
            block(
                "controls_whileUntil",
                {"MODE": "UNTIL"},
                BOOL=compare("GTE", get("n"), num(5)),
                DO=[change("n", 2)],
            ),
            show(get("n")),
        ],
        ["6"],
    ),
    "count up by a step": ([for_("i", num(1), num(5), num(2), [show(get("i"))])], ["1", "3", "5"]),
    "count down (the step's sign follows the direction)": (
        [for_("i", num(3), num(1), num(1), [show(get("i"))])],
        ["3", "2", "1"],
    ),
    "count with values known only when running": (
        [
            set_("n", num(2)),
            for_("i", get("n"), num(1), num(1), [show(get("i"))]),
            for_("i", num(1), get("n"), num(0.5), [show(get("i"))]),
        ],
        ["2", "1", "1", "1.5", "2.0"],
    ),
    "break and continue": (
        [
            for_(
                "i",
                num(1),
                num(10),
                num(1),
                [
                    if_(
                        (
                            compare("EQ", get("i"), num(2)),
                            [block("controls_flow_statements", {"FLOW": "CONTINUE"})],
                        )
                    ),
                    if_(
                        (
                            compare("EQ", get("i"), num(4)),
                            [block("controls_flow_statements", {"FLOW": "BREAK"})],
                        )
                    ),
                    show(get("i")),
                ],
            ),
        ],
        ["1", "3"],
    ),
    "if, else if, else": (
        [
            for_(
                "i",
                num(1),
                num(3),
                num(1),
                [
                    if_(
                        (compare("EQ", get("i"), num(1)), [show(text("one"))]),
                        (compare("EQ", get("i"), num(2)), [show(text("two"))]),
                        otherwise=[show(text("many"))],
                    ),
                ],
            ),
            if_((block("logic_boolean", {"BOOL": "FALSE"}), [show(text("never"))])),
            if_((block("logic_boolean", {"BOOL": "TRUE"}), [])),
        ],
        ["one", "two", "many"],
    ),
    "comparisons": (
        [show(compare(op, num(2), num(3))) for op in ("EQ", "NEQ", "LT", "LTE", "GT", "GTE")]
        + [
            show(
                compare(
                    "EQ", compare("LT", num(1), num(2)), block("logic_boolean", {"BOOL": "TRUE"})
                )
            )
        ],
        ["False", "True", "True", "True", "False", "False", "True"],
    ),
    "and, or, not, true, false, null": (
        [
            show(
                block(
                    "logic_operation",
                    {"OP": "AND"},
                    A=block("logic_boolean", {"BOOL": "TRUE"}),
                    B=block("logic_boolean", {"BOOL": "FALSE"}),
                )
            ),
            show(
                block(
                    "logic_operation",
                    {"OP": "OR"},
                    A=block("logic_boolean", {"BOOL": "FALSE"}),
                    B=block("logic_boolean", {"BOOL": "TRUE"}),
                )
            ),
            show(block("logic_negate", BOOL=compare("LT", num(1), num(2)))),
            show(
                block(
                    "logic_negate",
                    BOOL=block(
                        "logic_operation",
                        {"OP": "OR"},
                        A=block("logic_boolean", {"BOOL": "TRUE"}),
                        B=block("logic_boolean", {"BOOL": "TRUE"}),
                    ),
                )
            ),
            show(block("logic_null")),
        ],
        ["False", "True", "False", "False", "None"],
    ),
    "arithmetic and its order": (
        [
            show(arithmetic(op, num(7), num(2)))
            for op in ("ADD", "MINUS", "MULTIPLY", "DIVIDE", "POWER")
        ]
        + [
            show(arithmetic("MINUS", num(1), arithmetic("MINUS", num(2), num(3)))),
            show(arithmetic("MINUS", arithmetic("MINUS", num(1), num(2)), num(3))),
            show(arithmetic("POWER", arithmetic("POWER", num(2), num(3)), num(2))),
            show(arithmetic("POWER", num(2), arithmetic("POWER", num(3), num(2)))),
            show(arithmetic("POWER", num(-2), num(2))),
            show(arithmetic("MULTIPLY", arithmetic("ADD", num(1), num(2)), num(-3))),
            show(arithmetic("MULTIPLY", num(1.5), num("1e3"))),
        ],
        ["9", "5", "14", "3.5", "49", "2", "-4", "64", "512", "4", "-9", "1500.0"],
    ),
    "round, up and down": (
        [
            show(block("math_round", {"OP": op}, NUM=num(value)))
            for op, value in (("ROUND", 3.6), ("ROUNDUP", 3.2), ("ROUNDDOWN", 3.8))
        ],
        ["4", "4", "3"],
    ),
    "random whole numbers": (
        [
            set_("r", block("math_random_int", FROM=num(1), TO=num(6))),
            show(
                block(
                    "logic_operation",
                    {"OP": "AND"},
                    A=compare("GTE", get("r"), num(1)),
                    B=compare("LTE", get("r"), num(6)),
                )
            ),
            show(block("math_random_int", FROM=num(5), TO=num(5))),
            show(block("math_random_int", FROM=num(9), TO=num(9))),
            set_("r", block("math_random_int", FROM=get("r"), TO=get("r"))),
            show(compare("LTE", get("r"), num(6))),
        ],
        ["True", "5", "9", "True"],
    ),
    "texts, joined": (
        [
            show(join(text("a"), num(1), block("logic_boolean", {"BOOL": "TRUE"}))),
            show(join()),
            show(join(num(5))),
            show(text("")),
            show(text('it\'s "quoted"')),
        ],
        ["a1True", "", "5", "", 'it\'s "quoted"'],
    ),
    "variables: set, get, change": (
        [set_("x", num(5)), change("x", 2), show(get("x")), change("y", -1), show(get("y"))],
        ["7", "-1"],
    ),
    "a value on its own, and disabled blocks": (
        [
            num(5),
            {**show(text("skipped")), "enabled": False},
            {**show(text("skipped too")), "disabledReasons": ["MANUALLY_DISABLED"]},
            show(text("after them")),
        ],
        ["after them"],
    ),
}


@pytest.mark.parametrize("case", CASES)
async def test_standard_blocks_behave(agent, tmp_path, case):
    blocks, expected = CASES[case]
    result = await run_ok(
        agent, tmp_path, workspace(stack(*blocks), variables=("n", "i", "x", "y", "r"))
    )
    assert result.lines == expected, result.python


async def test_the_top_stack_as_they_lie_runs_and_the_others_are_loose(agent, tmp_path):
    """The program is the top stack (Blockly's reading order); the rest is loose, not run
    (the editor greys it out): tests/programs/test_blocks_source_map.py has more."""
    lower = {**show(text("second")), "x": 0, "y": 300}
    upper = {**show(text("first")), "x": 400, "y": 10}
    source = json.dumps({"blocks": {"languageVersion": 0, "blocks": [lower, upper]}})
    assert (await run_ok(agent, tmp_path, source)).lines == ["first"]


def test_every_block_type_is_run_here():
    """The generator's block types, each run by a test of this module: a new one needs one."""
    tested = {
        "controls_if", "controls_repeat", "controls_repeat_ext", "controls_whileUntil",
        "controls_for", "controls_flow_statements", "logic_compare", "logic_operation",
        "logic_negate", "logic_boolean", "logic_null", "math_number", "math_arithmetic",
        "math_random_int", "math_round", "text", "text_join", "text_print", "variables_get",
        "variables_set", "math_change", "robot_drive", "robot_stop", "robot_turn", "robot_forward",
        "robot_wait", "robot_sensor", "robot_show", "robot_say", "robot_publish", "robot_receive",
        "robot_memory_set", "robot_memory_get",
    }  # fmt: skip
    assert block_types() == tested


# -- the examples on the sim robot --------------------------------------------------------------


async def test_stop_before_the_wall_stops_before_the_wall(agent, calls, tmp_path):
    result = await run_ok(agent, tmp_path, (EXAMPLES / "wall.json").read_text())
    after = await agent.driver.sensors()
    assert kinds(calls) == [("drive", 0.3, 0.0), ("stop",)]
    assert after["velocity"] == {"linear": 0.0, "angular": 0.0} and not after["bumper"]
    assert 0.25 < after["range"] < 0.4  # (nearer only if the machine stalls)
    assert after["position"]["y"] > 1.0  # it drove ahead first
    (line,) = result.lines
    said = float(re.fullmatch(r"Stopped (\d\.\d+) m before the wall", line).group(1))
    assert said == pytest.approx(after["range"])
    assert agent.shows["range"]["value"] == pytest.approx(after["range"], abs=0.05)


async def test_drive_a_square_comes_back_to_the_start(agent, calls, tmp_path):
    result = await run_ok(agent, tmp_path, (EXAMPLES / "square.json").read_text())
    side = [("drive", 0.3, 0.0), ("stop",), ("drive", 0.0, 1.0), ("stop",)]
    assert kinds(calls) == side * 4
    after = await agent.driver.sensors()
    # Timed moves: a machine's late wake-ups show as centimetres and degrees.
    assert math.hypot(after["position"]["x"], after["position"]["y"]) < 0.15
    turned = (after["position"]["theta"] - math.pi / 2 + math.pi) % math.tau - math.pi
    assert abs(turned) < math.radians(15)
    assert 1.2 <= after["odometry"]["distance"] < 1.4
    assert result.lines == ["A square, and back near the start"]


async def test_the_wall_and_turn_example(agent, tmp_path):
    result = await run(agent, tmp_path, (EXAMPLES / "wall_turn.json").read_text())
    await check_wall_turn(agent, result.status, result.out, result.err)


# -- errors -----------------------------------------------------------------------------------

BAD = {
    "not JSON": ('{"blocks": ', "not valid JSON"),
    "not an object": ("[1, 2]", "a JSON object"),
    "blocks not an object": ('{"blocks": []}', "'blocks' must be an object"),
    "blocks' blocks not a list": ('{"blocks": {"blocks": {}}}', "must be a list"),
    "a top block not an object": ('{"blocks": {"blocks": [3]}}', "must be an object"),
    "a block without a type": ('{"blocks": {"blocks": [{"id": "a"}]}}', "'type'"),
    "variables not a list": ('{"variables": 3}', "'variables'"),
    "an unknown block": (
        workspace(block("robot_fly", {"HEIGHT": 3})),
        "Unknown block 'robot_fly' (id 'robot_fly-",
    ),
    "an unknown block inside another": (
        workspace(block("controls_repeat_ext", TIMES=num(2), DO=[block("robot_teleport")])),
        "Unknown block 'robot_teleport'",
    ),
    "an unknown value block": (
        workspace(show(block("math_on_list", {"OP": "SUM"}))),
        "Unknown block 'math_on_list'",
    ),
    "a statement where a value goes": (
        workspace(show(block("robot_stop"))),
        "block 'robot_stop' (id 'robot_stop-",
    ),
    "an operator out of its table": (
        workspace(show(compare("IS", num(1), num(1)))),
        "OP must be one of EQ, NEQ, LT, LTE, GT, GTE, not 'IS'",
    ),
    "a number that is not one": (workspace(show(num("1; import os"))), "is not a number"),
    "NaN": (workspace(show(num("NaN"))), "NaN"),
    "true for a number": (workspace(show(num(True))), "is not a number"),
    "a huge number": (workspace(show(num(10**400))), "too large"),
    "break outside a loop": (
        workspace(block("controls_flow_statements", {"FLOW": "BREAK"})),
        "'break' works only inside a loop",
    ),
    "a variable the workspace lacks": (
        json.dumps({"blocks": {"blocks": [show(block("variables_get", {"VAR": {"id": "nope"}}))]}}),
        "a variable the workspace does not have",
    ),
    "a sensor name that is no name": (
        workspace(show(sensor(INJECTION))),
        "is not a sensor's name",
    ),
    "an else-if count that is not a number": (
        json.dumps({"blocks": {"blocks": [
            {"type": "controls_if", "extraState": {"elseIfCount": "9"}},
        ]}}),
        "elseIfCount",
    ),
}  # fmt: skip


def _loops_inside_loops(depth: int) -> str:
    inner = show(text("deep"))
    for _ in range(depth):
        inner = block("controls_repeat_ext", TIMES=num(2), DO=[inner])
    return workspace(inner)


def _negations(depth: int) -> str:
    """Too deep for json.dumps to write, so written by hand."""
    negate = '{"type": "logic_negate", "inputs": {"BOOL": {"block": '
    true = '{"type": "logic_boolean", "fields": {"BOOL": "TRUE"}}'
    return '{"blocks": {"blocks": [' + negate * depth + true + "}}}" * depth + "]}}"


BAD["loops inside loops deeper than Python allows"] = (
    _loops_inside_loops(25),
    "cannot run as Python",
)
BAD["blocks nested too deeply"] = (_negations(5000), "nested too deeply")


@pytest.mark.parametrize("case", BAD)
def test_bad_programs_are_clear_errors(case):
    source, message = BAD[case]
    with pytest.raises(BlocksError) as raised:
        to_python(source)
    assert isinstance(raised.value, ValueError)
    assert message in str(raised.value)


async def test_a_run_of_bad_blocks_fails_saying_why(agent, tmp_path):
    source = workspace(stack(show(text("never")), block("robot_fly")))
    result = await run(agent, tmp_path, source)
    assert result.status == 1 and result.out == ""
    assert re.fullmatch(
        r"Unknown block 'robot_fly' \(id 'robot_fly-\d+'\): robotide cannot run it\.\n", result.err
    )
    assert "import robot" not in to_runnable_python("{")  # it fails before using the robot


_json = st.recursive(
    st.none() | st.booleans() | st.integers() | st.floats() | st.text(max_size=8),
    lambda inner: (
        st.lists(inner, max_size=4) | st.dictionaries(st.text(max_size=8), inner, max_size=4)
    ),
    max_leaves=20,
)
_paths = st.lists(st.integers(min_value=0, max_value=50), max_size=12)


def _replace(value, path: list[int], new):
    """`value` with the node found by walking `path` (indices into lists and dicts) replaced."""
    if not path or not isinstance(value, dict | list) or not value:
        return new
    step, rest = path[0], path[1:]
    if isinstance(value, list):
        i = step % len(value)
        return [*value[:i], _replace(value[i], rest, new), *value[i + 1 :]]
    key = list(value)[step % len(value)]
    return {**value, key: _replace(value[key], rest, new)}


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(example=st.sampled_from(["wall", "square", "wall_turn"]), path=_paths, new=_json)
def test_damaged_programs_are_blocks_errors_or_good_python(example, path, new):
    program = _replace(json.loads((EXAMPLES / f"{example}.json").read_text()), path, new)
    try:
        python = to_python(json.dumps(program))
    except BlocksError:
        return
    compile(python, "<blocks>", "exec")


# -- nothing from a field becomes code ------------------------------------------------------


@pytest.mark.parametrize("payload", INJECTIONS)
async def test_field_values_stay_strings(agent, tmp_path, payload):
    source = workspace(
        stack(
            show(text(payload)),
            set_(payload, text(payload)),
            show(get(payload)),
            block("robot_show", {"NAME": payload}, VALUE=text(payload)),
            block("robot_publish", {"TOPIC": payload}, VALUE=text(payload)),
            show(block("robot_receive", {"TOPIC": payload}, TIMEOUT=num(5))),
            block("robot_memory_set", {"KEY": payload}, VALUE=text(payload)),
            show(block("robot_memory_get", {"KEY": payload})),
        ),
        variables=(payload,),
    )
    result = await run_ok(agent, tmp_path, source)
    assert not (tmp_path / "PWNED").exists()
    assert result.out == (payload + "\n") * 4  # printed, the variable, received, remembered
    assert agent.shows[payload]["value"] == payload
    tree = ast.parse(result.python)
    imported = {
        alias.name
        for node in ast.walk(tree)
        if isinstance(node, ast.Import)
        for alias in node.names
    }
    assert imported == {"robot", "time"}
    assert not any(isinstance(node, ast.ImportFrom) for node in ast.walk(tree))


def test_variables_become_distinct_python_names():
    names = ["my speed", "2nd", "print", "bot", "for", "ﬁx", "fix", "count", "count2", "Ω", "", "_"]
    python = to_python(
        workspace(
            block("controls_repeat_ext", TIMES=num(1), DO=[
                block("controls_repeat_ext", TIMES=num(1), DO=[
                    set_(name, text(name)) for name in names
                ]),
            ]),
            variables=names,
        )
    )  # fmt: skip
    assigned = re.findall(r"^ +(\S+) = '", python, re.M)
    assert len(assigned) == len(names) == len(set(assigned))
    assert assigned[:5] == ["my_speed", "var_2nd", "print2", "bot2", "for2"]
    for name in assigned:
        assert name.isidentifier() and name not in ("print", "bot", "for", "robot")
    counters = re.findall(r"for (\w+) in range", python)
    assert len(set(counters)) == 2 and not set(counters) & set(assigned)


async def test_variables_keep_their_values_apart(agent, tmp_path):
    names = ["my speed", "my_speed", "ﬁx", "fix", "print"]
    source = workspace(
        stack(*(set_(name, text(name)) for name in names), *(show(get(name)) for name in names)),
        variables=names,
    )
    assert (await run_ok(agent, tmp_path, source)).lines == names


# -- through an appliance: the agent's launch, the examples every account gets ---------------


@pytest.fixture(scope="module")
def sim_blocks(appliance):
    body = {"name": "sim-blocks", "url": "sim://?arena=square"}
    assert appliance.api("POST", "/api/robots", body).status_code == 201
    wait_for(lambda: appliance.api("GET", "/api/robots/sim-blocks/sensors").status_code == 200)
    return "sim-blocks"


def test_the_agent_runs_a_blocks_program_as_its_python(appliance, sim_blocks):
    source = (EXAMPLES / "wall.json").read_text()
    program = appliance.create_program("blocks wall", source, language="blocks")
    assert program["language"] == "blocks"
    run = appliance.wait_run(
        appliance.run_program(program["id"], robot=sim_blocks)["id"], timeout=60
    )
    log = appliance.api("GET", f"/api/runs/{run['id']}/log").text
    assert run["state"] == "finished", log
    assert re.search(r"^Stopped 0\.3\d+ m before the wall$", log, re.M), log
    sensors = appliance.api("GET", f"/api/robots/{sim_blocks}/sensors").json()
    assert sensors["velocity"] == {"linear": 0.0, "angular": 0.0} and not sensors["bumper"]
    assert 0.3 < sensors["range"] < 0.4


@pytest.mark.parametrize(
    "source, message",
    [
        ("{not json", "This blocks program is not valid JSON"),
        (workspace(block("robot_fly")), "Unknown block 'robot_fly'"),
    ],
)
def test_the_agent_fails_a_run_of_bad_blocks_saying_why(appliance, sim_blocks, source, message):
    program = appliance.create_program(f"bad blocks {message[:10]}", source, language="blocks")
    run = appliance.wait_run(
        appliance.run_program(program["id"], robot=sim_blocks)["id"], timeout=30
    )
    stderr = appliance.api("GET", f"/api/runs/{run['id']}/log?stream=stderr").text
    assert run["state"] == "failed" and run["exit_code"] == 1, stderr
    assert message in stderr


@pytest.mark.django_db
def test_new_accounts_get_the_blocks_examples(django_user_model):
    user = django_user_model.objects.create_user("newcomer")
    for name in (
        "Stop before the wall (Blocks)",
        "Drive a square (Blocks)",
        "Wall and turn (Blocks)",
    ):
        program = user.programs.get(name=name)
        assert program.language == "blocks" and program.filename.endswith(".json")
        to_python(program.source)


# -- blocks.js in a browser ---------------------------------------------------------------------

PAGE = """<!doctype html>
<html><head><meta charset="utf-8"><title>blocks</title>
<script src="{static}/vendor/blockly/blockly_compressed.js"></script>
<script src="{static}/vendor/blockly/blocks_compressed.js"></script>
<script src="{static}/vendor/blockly/msg/en.js"></script>
<script src="catalog.js"></script>
<script src="{static}/robotide/blocks.js"></script>
</head><body style="margin: 0">
<div id="blocks" style="height: 560px; width: 960px"></div>
</body></html>
"""


VALUE_TYPES = {
    "logic_compare", "logic_operation", "logic_negate", "logic_boolean", "logic_null",
    "math_number", "math_arithmetic", "math_random_int", "math_round", "text", "text_join",
    "variables_get", "robot_sensor", "robot_receive", "robot_memory_get",
}  # fmt: skip


def each_stack_as_a_program(saved: str) -> str:
    """The Python of each top block of `saved` as the program (a value, printed): only the
    top stack runs, the others are loose."""
    workspace = json.loads(saved)
    made = []
    for top in workspace["blocks"]["blocks"]:
        top.pop("disabledReasons", None)  # loose where it lay
        if top["type"] in VALUE_TYPES:
            top = {"type": "text_print", "inputs": {"TEXT": {"block": top}}}
        alone = {**workspace, "blocks": {"languageVersion": 0, "blocks": [top]}}
        made.append(to_python(json.dumps(alone)))
    return "\n".join(made)


def test_blocks_js_mounts_a_workspace_in_chromium(tmp_path):
    chromium = os.environ.get("ROBOTIDE_TEST_CHROMIUM", "/usr/bin/chromium")
    if not Path(chromium).exists():
        pytest.skip(f"no Chromium at {chromium}: apt-get install chromium")
    from playwright.sync_api import sync_playwright

    page_file = tmp_path / "blocks.html"
    page_file.write_text(PAGE.format(static=STATIC.as_uri()))
    # The scripts' gettext, as the pages load it before them (the JavaScript catalog).
    (tmp_path / "catalog.js").write_bytes(Client().get(reverse("javascript-catalog")).content)
    square = (EXAMPLES / "square.json").read_text()
    with sync_playwright() as p:
        browser = p.chromium.launch(executable_path=chromium, headless=True, args=["--no-sandbox"])
        try:
            page = browser.new_page(viewport={"width": 960, "height": 560})
            problems: list[str] = []
            page.on("pageerror", lambda error: problems.append(str(error)))
            page.on("console", lambda m: m.type in ("error", "warning") and problems.append(m.text))
            outside: list[str] = []
            page.on("request", lambda r: r.url.startswith("file:") or outside.append(r.url))
            page.goto(page_file.as_uri())
            # No sounds: a file:// page may not fetch them (over HTTP the page gets them).
            page.evaluate(
                """(json) => {
                  window.changes = [];
                  window.editor = robotideBlocks.mount(document.getElementById('blocks'), json,
                    (text) => window.changes.push(text), {sounds: false});
                }""",
                square,
            )
            page.wait_for_timeout(300)  # the load's own events: no change to tell
            assert page.evaluate("window.changes.length") == 0
            assert page.evaluate("editor.workspace.getAllBlocks(false).length") == 9
            page.screenshot(path="/tmp/blocks.png")
            # What Blockly saves of the example runs as what the file does.
            assert to_python(page.evaluate("editor.save()")) == to_python(square)

            # A change is told, with the whole program.
            page.evaluate("editor.workspace.getTopBlocks(true)[0].moveBy(10, 10)")
            wait_for(lambda: page.evaluate("window.changes.length") == 1, what="a change")
            assert json.loads(page.evaluate("window.changes[0]"))["blocks"]["blocks"][0]["x"] == 50

            # Every block of the toolbox, as Blockly makes and saves it, is one the server runs.
            saved = page.evaluate(
                """() => {
                  const ws = editor.workspace;
                  ws.clear();
                  for (const category of robotideBlocks.toolbox.contents) {
                    for (const entry of category.contents || []) {
                      const state = Object.assign({}, entry);
                      delete state.kind;
                      // (break and continue go in a loop: one is added inside a loop below)
                      if (state.type !== "controls_flow_statements") {
                        Blockly.serialization.blocks.append(state, ws);
                      }
                    }
                  }
                  ws.getVariableMap().createVariable("my speed", "", "v-speed");
                  Blockly.serialization.blocks.append({
                    type: "controls_repeat_ext",
                    inputs: {TIMES: {shadow: {type: "math_number", fields: {NUM: 2}}},
                             DO: {block: {
                               type: "variables_set", fields: {VAR: {id: "v-speed"}},
                               inputs: {VALUE: {block: {type: "variables_get",
                                                        fields: {VAR: {id: "v-speed"}}}}},
                               next: {block: {
                                 type: "math_change", fields: {VAR: {id: "v-speed"}},
                                 next: {block: {type: "controls_flow_statements"}}}}}}},
                  }, ws);
                  return editor.save();
                }"""
            )
            python = each_stack_as_a_program(saved)
            for call in ("bot.drive(0.2, 0)", "turn(90)", "bot.sensor('position')['x']",
                         "bot.publish('news', 'hello')", "bot.receive('news', 5)",
                         "random.randint(1, 100)", "bot.memory_get('laps')",
                         "my_speed = my_speed", "my_speed += 0", "    break"):  # fmt: skip
                assert call in python, python
            toolbox = page.evaluate("robotideBlocks.toolbox.contents.map((c) => c.name)")
            assert toolbox == [
                "Robot", "Sensors", "Logic", "Loops", "Math", "Text", "Variables", "Messages"
            ]  # fmt: skip
            # Text that is not JSON is an error that says so.
            error = page.evaluate(
                """() => { try { editor.load('{oops'); } catch (e) { return e.message; } }"""
            )
            assert error.startswith("This program is not blocks")
            assert problems == [] and outside == []
        finally:
            browser.close()
