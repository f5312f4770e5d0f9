"""A sim faster than real time, and a program's clock sped up to match (runbox.timescale), in
every language: a program that sleeps one second by its own clock sees the sim's clock
advance one second too, a tenth of a real second at 10x. And the same program at 1x and at
10x ends where it should, within a stated tolerance of the same pose."""

import json
import math
import re

import pytest

from runbox import timescale
from tests.sim_programs import LANGUAGES, example, run_program, sims

pytestmark = pytest.mark.skipif(
    timescale.library() is None, reason="no libfaketime (scripts/install-test-deps.sh)"
)

# Each prints the sim's clock's advance across a sleep of 1 s by the program's own clock,
# then its own clock's over the same calls and more ("" where it has none: Blocks).
SLEEP_A_SECOND = {
    "python": """\
import time
import robot
bot = robot.Robot()
start = time.monotonic()
before = bot.sensors()["time"]
time.sleep(1)
after = bot.sensors()["time"]
print(after - before, time.monotonic() - start)
""",
    "shell": """\
start=$(date +%s.%N)
before=$(robot sensors time)
sleep 1
after=$(robot sensors time)
end=$(date +%s.%N)
awk -v a="$after" -v b="$before" -v s="$start" -v e="$end" 'BEGIN { print a - b, e - s }'
""",
    "perl": """\
use strict;
use warnings;
use Robot;
use Time::HiRes qw(time sleep);
my $bot = Robot->new;
my $start = time;
my $before = $bot->sensors->{time};
sleep(1);
my $after = $bot->sensors->{time};
print $after - $before, " ", time - $start, "\\n";
""",
    "ruby": """\
require 'robot'
bot = Robot.new
start = Process.clock_gettime(Process::CLOCK_MONOTONIC)
before = bot.sensors['time']
sleep 1
after = bot.sensors['time']
puts "#{after - before} #{Process.clock_gettime(Process::CLOCK_MONOTONIC) - start}"
""",
    "lua": """\
local socket = require('socket')
local Robot = require('robot')
local bot = Robot.new()
local start = socket.gettime()
local before = bot:sensors().time
socket.sleep(1)
local after = bot:sensors().time
print(after - before, socket.gettime() - start)
""",
    "javascript": """\
const { Robot } = require('robot');
const sleep = (ms) => new Promise((resolve) => setTimeout(resolve, ms));
(async () => {
  const bot = new Robot();
  await bot.connect();
  const start = process.hrtime.bigint();
  const before = (await bot.sensors()).time;
  await sleep(1000);
  const after = (await bot.sensors()).time;
  console.log(after - before, Number(process.hrtime.bigint() - start) / 1e9);
  bot.close();
})();
""",
    "tcl": """\
package require robot
set start [clock microseconds]
set before [dict get [robot::sensors] time]
after 1000
set later [dict get [robot::sensors] time]
puts "[expr {$later - $before}] [expr {([clock microseconds] - $start) / 1e6}]"
""",
}


def blocks_sleep_a_second() -> str:
    """Blocks: before = the sim's time; wait 1 s; print the sim's time - before."""

    def sensor_time(block_id):
        return {"block": {"type": "robot_sensor", "id": block_id, "fields": {"SENSOR": "time"}}}

    print_advance = {
        "type": "text_print", "id": "print",
        "inputs": {"TEXT": {"block": {
            "type": "math_arithmetic", "id": "minus", "fields": {"OP": "MINUS"},
            "inputs": {"A": sensor_time("after"), "B": {"block": {
                "type": "variables_get", "id": "get", "fields": {"VAR": {"id": "v-before"}},
            }}},
        }}},
    }  # fmt: skip
    wait = {
        "type": "robot_wait", "id": "wait",
        "inputs": {"SECONDS": {"shadow": {"type": "math_number", "id": "one",
                                          "fields": {"NUM": 1}}}},
        "next": {"block": print_advance},
    }  # fmt: skip
    first = {
        "type": "variables_set", "id": "set", "x": 20, "y": 20,
        "fields": {"VAR": {"id": "v-before"}}, "inputs": {"VALUE": sensor_time("before")},
        "next": {"block": wait},
    }  # fmt: skip
    workspace = {
        "blocks": {"languageVersion": 0, "blocks": [first]},
        "variables": [{"name": "before", "id": "v-before"}],
    }
    return json.dumps(workspace)


def sleep_program(language: str) -> str:
    return blocks_sleep_a_second() if language == "blocks" else SLEEP_A_SECOND[language]


@pytest.mark.parametrize("language", LANGUAGES)
async def test_a_second_of_sleep_is_a_second_of_the_sims_time_at_10x(language, tmp_path):
    async with sims(1, speed=10) as (agent,):
        ran = await run_program(agent, language, sleep_program(language), tmp_path)
    assert ran.status == 0, ran.err
    sim, *own = map(float, ran.out.split())
    # The sim's clock across the sleep: the second slept, and the calls around it (a
    # shell's `robot` is a process started at each call: a few tenths at 10x). Without the
    # program's clock sped up it would be 10 s.
    assert 1.0 <= sim < 2.5, ran.out
    if own:  # the program's own clock across the same calls and more: the same rate
        assert own[0] >= sim - 0.01, ran.out
    assert ran.seconds < 5, ran  # the whole program, start-up included, in real time


async def test_at_1x_a_second_is_a_real_one(tmp_path):
    async with sims(1, speed=1) as (agent,):
        ran = await run_program(agent, "python", SLEEP_A_SECOND["python"], tmp_path)
    assert ran.status == 0, ran.err
    sim, own = map(float, ran.out.split())
    assert 1.0 <= sim <= own and ran.seconds >= 1.0


# ---------------------------------------------------------------------------------------------
# 1x against 10x: the same program, the same end pose

# The end pose at 10x may differ from 1x's by what the real time of the program's own calls
# turns into: each call takes about a millisecond of real time (the Unix socket, the client,
# the agent), ten of the sim's at 10x, in which the robot goes on moving; the square's turns
# end once the compass is within 2 degrees of their target, read every 10 ms of the program's
# clock plus a call, so each turn may stop a degree or two apart. Four sides of 0.8 m with a
# heading off by 2.5 degrees land up to 4 cm aside; a busy machine makes calls slower, and at
# 10x each costs ten times as much of the sim's time.
SAME_POSE_M = 0.10
SAME_HEADING_DEG = 6.0


def end_pose(out: str) -> tuple[float, float]:
    match = re.search(r"x=(-?\d+\.\d+) m, y=(-?\d+\.\d+) m", out)
    assert match, out
    return float(match.group(1)), float(match.group(2))


async def test_the_square_at_1x_and_at_10x_ends_at_the_same_pose(tmp_path):
    source = example("square.py")
    async with sims(1, speed=1) as (slow,), sims(1, speed=10) as (fast,):
        at_1x = await run_program(slow, "python", source, tmp_path / "1x")
        at_10x = await run_program(fast, "python", source, tmp_path / "10x")
        poses = [(await sim.driver.sensors()) for sim in (slow, fast)]
    assert at_1x.status == 0 and at_10x.status == 0, (at_1x.err, at_10x.err)
    assert at_10x.seconds < at_1x.seconds / 4, (at_1x.seconds, at_10x.seconds)
    (x1, y1), (x10, y10) = end_pose(at_1x.out), end_pose(at_10x.out)
    assert math.hypot(x10 - x1, y10 - y1) <= SAME_POSE_M, (at_1x.out, at_10x.out)
    headings = [sensors["heading"] for sensors in poses]
    assert abs((headings[1] - headings[0] + 180) % 360 - 180) <= SAME_HEADING_DEG, headings
