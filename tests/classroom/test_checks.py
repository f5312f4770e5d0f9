"""Exercise checks (classroom.checks): each kind against a program written to pass it and one
written to fail it, on the trace a real sim records (rhal.simulator.trace).

A "program" here is a student's program run in-process against the sim: it reads the robot,
drives it, prints and says, and its sleeps move the sim's manual clock (at the check sims'
speed), so a 40-second exercise takes milliseconds. How it ended is written as the agent
writes it (robots.check_sims). Edge cases are traces written by hand.
"""

import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

import rhal
from classroom import checks as checks_module
from classroom.checks import (
    STATIC_KINDS,
    CheckError,
    Outcome,
    evaluate,
    evaluate_static,
    is_static,
    validate_checks,
)
from classroom.trace import Trace
from rhal.simulator.worlds import load
from tests.rhal.conftest import ManualClock

WORLD = load("boxes")
EXAMPLES = Path(__file__).resolve().parents[2] / "programs" / "examples"
SPEED = 5  # the check sims' clock, times real time
VISIBLE = (-0.5, 0.0, math.pi / 2)  # below the kitchen, facing north
HIDDEN_SOUTH = (-0.5, -1.0, math.pi / 2)  # further south: 3 s of driving falls short
HIDDEN_NORTH = (-0.5, 0.8, math.pi / 2)  # further north: 3 s of driving hits the wall
BELOW_THE_BOX = (1.05, -0.2, math.pi / 2)  # facing the north-east box


class TimeUp(Exception):
    pass


class Student:
    """What a program has: the robot, a sleep on the sim's clock, print and say."""

    def __init__(self, bot, clock, limit):
        self.bot, self.clock, self.limit = bot, clock, limit
        self.output = []

    async def sleep(self, seconds):
        left = self.limit - self.bot.trace_time()
        if seconds >= left:
            self.clock.advance(max(left, 0.0) / SPEED)
            raise TimeUp
        self.clock.advance(seconds / SPEED)

    async def range(self):
        return await self.bot.sensor("range")

    async def position(self):
        return await self.bot.sensor("position")

    def print(self, line):
        self.output.append([round(self.bot.trace_time(), 6), line])

    def say(self, text):
        self.bot.note_said(text)


async def run(program, start=VISIBLE, limit=40.0):
    """The trace of ``program`` from ``start`` on a fresh check sim, ended as the agent ends
    a run: its end taken when the program ended, the robot stopped after."""
    clock = ManualClock()
    async with rhal.connect(f"sim://?world=boxes&speed={SPEED}", clock=clock) as bot:
        await bot.reset(start)
        bot.start_trace()
        student = Student(bot, clock, limit)
        end = {"state": "finished", "exit_code": 0, "reason": "", "time_limit": False}
        try:
            code = await program(student)
            if code:
                end |= {"state": "failed", "exit_code": code, "reason": f"exit code {code}"}
        except TimeUp:
            end |= {"state": "stopped", "exit_code": None, "time_limit": True,
                    "reason": f"time limit reached: {limit:g} s of sim time"}  # fmt: skip
        except RuntimeError as exc:
            end |= {"state": "failed", "exit_code": 1, "reason": str(exc)}
        end["t"] = round(bot.trace_time(), 6)
        trace = bot.take_trace()
        await bot.stop()  # the agent's stop, after the program's end
    doc = {**trace, "output": student.output, "end": end}
    return Trace.from_dict(json.loads(json.dumps(doc)))


# -- programs ----------------------------------------------------------------------------------


def to_the_wall(stop_at=0.45, then=None):
    """Drive north until the range sensor reads less than ``stop_at``, stop, say where."""

    async def program(s):
        await s.bot.drive(0.3, 0.0)
        while await s.range() >= stop_at:
            await s.sleep(0.05)
        await s.bot.stop()
        s.print("I stopped at the wall")
        if then is not None:
            await then(s)

    return program


def hard_coded(seconds=3.0):
    """Drive 0.5 m/s for some seconds then turn: tuned to the visible start."""

    async def program(s):
        await s.bot.drive(0.5, 0.0)
        await s.sleep(seconds)
        await s.bot.drive(0.0, 1.0)
        await s.sleep(1.0)
        await s.bot.stop()

    return program


async def kitchen_then_home(s):
    """The kitchen, then west along the wall and south into home."""
    await to_the_wall()(s)
    await s.bot.drive(0.0, 1.0)
    await s.sleep(math.pi / 2)
    await s.bot.drive(0.3, 0.0)
    while await s.range() >= 0.45:
        await s.sleep(0.05)
    await s.bot.drive(0.0, 1.0)
    await s.sleep(math.pi / 2)
    await s.bot.drive(0.3, 0.0)
    while (await s.position())["y"] > 0.3:
        await s.sleep(0.05)
    await s.bot.stop()


async def forever(s):
    await s.bot.drive(0.0, 0.5)
    while True:
        await s.sleep(0.1)


async def exits_while_driving(s):
    await s.bot.drive(0.2, 0.0)
    await s.sleep(2.0)


async def crashes(s):
    await s.bot.drive(0.2, 0.0)
    await s.sleep(1.0)
    raise RuntimeError("Traceback: ZeroDivisionError")


async def says_the_landmark(s):
    await to_the_wall()(s)
    s.say("I read KITCHEN")


def check(**fields):
    return validate_checks([fields], WORLD)[0]


def judge(trace, **fields):
    return evaluate(check(**fields), trace, WORLD)


# -- validating --------------------------------------------------------------------------------


def test_checks_come_back_with_their_defaults():
    checks = validate_checks(
        [
            {"kind": "reach_zone", "zone": "kitchen"},
            {"kind": "no_contact", "points": 2, "message": "Careful!"},
            {"kind": "output_matches", "pattern": "kitchen"},
        ],
        WORLD,
    )
    assert checks == [
        {"kind": "reach_zone", "points": 1, "message": "", "zone": "kitchen", "within_s": None},
        {"kind": "no_contact", "points": 2, "message": "Careful!"},
        {"kind": "output_matches", "points": 1, "message": "", "pattern": "kitchen", "flags": ""},
    ]
    assert validate_checks(checks, WORLD) == checks


@pytest.mark.parametrize(
    ("checks", "path", "words"),
    [
        ("no_contact", "checks", "list"),
        ([{"kind": "fly"}], "checks[0].kind", "reach_zone, zones_in_order"),
        ([{"zone": "kitchen"}], "checks[0].kind", "unknown kind"),
        ([{"kind": "no_contact"}, {"kind": "no_contact"}, {"kind": "reach_zone", "zone": "attic"}],
         "checks[2].zone", "kitchen, lab, garage, home"),
        ([{"kind": "reach_zone"}], "checks[0].zone", "needs zone"),
        ([{"kind": "zones_in_order", "zones": ["kitchen"]}], "checks[0].zones", "2 to"),
        ([{"kind": "zones_in_order", "zones": ["kitchen", "cellar"]}], "checks[0].zones[1]",
         "its zones are"),
        ([{"kind": "reach_zone", "zone": "lab", "within_s": -3}], "checks[0].within_s", "above 0"),
        ([{"kind": "stop_near_wall", "min_m": 0.6, "max_m": 0.3}], "checks[0].min_m",
         "more than max_m"),
        ([{"kind": "stop_near_wall", "min_m": -0.1, "max_m": 0.3}], "checks[0].min_m", "from 0"),
        ([{"kind": "stop_near_wall", "min_m": 0.1}], "checks[0].max_m", "needs max_m"),
        ([{"kind": "ends_within", "seconds": "soon"}], "checks[0].seconds", "seconds"),
        ([{"kind": "ends_within", "seconds": math.inf}], "checks[0].seconds", "seconds"),
        ([{"kind": "no_contact", "points": -1}], "checks[0].points", "from 0"),
        ([{"kind": "no_contact", "points": True}], "checks[0].points", "from 0"),
        ([{"kind": "no_contact", "within_s": 3}], "checks[0].within_s", "no \"within_s\""),
        ([{"kind": "output_matches", "pattern": "(kitchen"}], "checks[0].pattern",
         "not a valid regular expression"),
        ([{"kind": "output_matches", "pattern": ""}], "checks[0].pattern", "1 to"),
        ([{"kind": "output_matches", "pattern": "a", "flags": "x"}], "checks[0].flags",
         "ignore case"),
        ([{"kind": "uses_block", "block": "if; drop"}], "checks[0].block", "block type"),
        ([{"kind": "max_blocks", "count": 0}], "checks[0].count", "1 to 10000"),
        ([{"kind": "max_blocks", "count": 2.5}], "checks[0].count", "whole number"),
        ([{"kind": "no_contact", "message": 7}], "checks[0].message", "text"),
        (["no_contact"], "checks[0]", "object"),
    ],
)  # fmt: skip
def test_what_cannot_be_judged_is_refused_with_its_place(checks, path, words):
    with pytest.raises(CheckError) as caught:
        validate_checks(checks, WORLD)
    assert caught.value.path == path
    assert words in caught.value.message
    assert str(caught.value).startswith(path)


def test_a_world_without_zones_says_so():
    square = {"format": 1, "name": "bare", "title": "Bare", "size": {"width": 3, "height": 3}}
    with pytest.raises(CheckError, match="this world has no zones"):
        validate_checks([{"kind": "reach_zone", "zone": "kitchen"}], load(square))


def test_messages_go_through_the_translator_given():
    with pytest.raises(CheckError) as caught:
        validate_checks([{"kind": "reach_zone", "zone": "x"}], WORLD, lambda s: "pt: " + s)
    assert caught.value.message.startswith("pt: there is no zone")
    trace = Trace.from_dict(hand_made())
    assert evaluate(check(kind="no_contact"), trace, WORLD, lambda s: "pt: " + s).why == (
        "pt: it touched nothing"
    )


# -- reach_zone --------------------------------------------------------------------------------


async def test_reach_zone_passes_a_program_that_gets_there_in_time():
    trace = await run(to_the_wall())
    outcome = judge(trace, kind="reach_zone", zone="kitchen", within_s=30)
    assert outcome.passed
    assert re.fullmatch(r"it reached the kitchen zone after \d+\.\d s", outcome.why)


async def test_reach_zone_fails_a_hard_coded_program_from_a_hidden_start():
    assert judge(await run(hard_coded()), kind="reach_zone", zone="kitchen").passed
    outcome = judge(await run(hard_coded(), HIDDEN_SOUTH), kind="reach_zone", zone="kitchen")
    assert outcome == Outcome(False, "it never reached the kitchen zone (the run lasted 4.0 s)")


async def test_reach_zone_fails_a_program_that_gets_there_too_late():
    outcome = judge(await run(to_the_wall()), kind="reach_zone", zone="kitchen", within_s=2)
    assert not outcome.passed
    assert "the exercise wants it there within 2 s" in outcome.why


# -- zones_in_order ----------------------------------------------------------------------------


async def test_zones_in_order_passes_the_order_driven_and_fails_the_other():
    trace = await run(kitchen_then_home)
    passed = judge(trace, kind="zones_in_order", zones=["kitchen", "home"], within_s=40)
    assert passed.passed, passed.why
    assert passed.why.startswith("it visited kitchen, home in that order, the last after")
    failed = judge(trace, kind="zones_in_order", zones=["home", "kitchen"])
    assert not failed.passed
    assert re.fullmatch(
        r"it reached the home zone after \d+\.\d s, but never the kitchen zone after it",
        failed.why,
    )


async def test_zones_in_order_fails_when_the_first_is_never_reached():
    outcome = judge(await run(to_the_wall()), kind="zones_in_order", zones=["lab", "kitchen"])
    assert outcome == Outcome(
        False, "it never reached the lab zone, the first of the zones to visit"
    )


async def test_zones_in_order_fails_when_done_too_late():
    trace = await run(kitchen_then_home)
    outcome = judge(trace, kind="zones_in_order", zones=["kitchen", "home"], within_s=5)
    assert not outcome.passed and "within 5 s" in outcome.why


# -- no_contact --------------------------------------------------------------------------------


async def test_no_contact_passes_a_program_that_stops_short_of_the_wall():
    assert judge(await run(to_the_wall()), kind="no_contact") == Outcome(True, "it touched nothing")


async def test_no_contact_fails_a_program_that_drives_into_the_wall():
    outcome = judge(await run(hard_coded(), HIDDEN_NORTH), kind="no_contact")
    # From y 0.8 the wall stops its centre at 1.85: 1.05 m at 0.5 m/s.
    assert outcome == Outcome(False, "it touched a wall 2.1 s into the run")


async def test_no_contact_says_a_box_was_touched_and_how_often():
    trace = await run(hard_coded(seconds=2.0), BELOW_THE_BOX)
    outcome = judge(trace, kind="no_contact")
    assert outcome.why.startswith("it touched a box")
    bounced = Trace.from_dict(
        {**trace.to_dict(), "contacts": [list(c) for c in trace.contacts] * 3}
    )
    assert judge(bounced, kind="no_contact").why.endswith("and 2 times more after")


async def test_a_contact_after_the_program_ended_is_not_the_programs():
    trace = (await run(to_the_wall())).to_dict()
    trace["contacts"] = [[trace["end"]["t"] + 0.5, -0.5, 1.85]]
    assert judge(Trace.from_dict(trace), kind="no_contact").passed


# -- stop_near_wall ----------------------------------------------------------------------------


async def test_stop_near_wall_passes_a_program_that_stops_in_the_band():
    outcome = judge(await run(to_the_wall(0.6)), kind="stop_near_wall", min_m=0.3, max_m=0.6)
    assert outcome.passed, outcome.why
    assert re.fullmatch(
        r"it stopped 0\.4\d m from the nearest wall, within 0\.30–0\.60 m", outcome.why
    )


async def test_stop_near_wall_fails_a_program_that_stops_too_far():
    outcome = judge(await run(to_the_wall(1.2)), kind="stop_near_wall", min_m=0.3, max_m=0.6)
    assert not outcome.passed
    assert re.fullmatch(
        r"it stopped 1\.0\d m from the nearest wall; the exercise wants 0\.30–0\.60 m",
        outcome.why,
    )


async def test_stop_near_wall_fails_a_program_that_ends_still_driving():
    # The agent stops the robot after the program ended: that stop is not the program's.
    outcome = judge(await run(exits_while_driving), kind="stop_near_wall", min_m=0, max_m=3)
    assert outcome == Outcome(False, "it was still moving when the program ended, after 2.0 s")
    timed_out = judge(await run(forever, limit=10), kind="stop_near_wall", min_m=0, max_m=3)
    assert timed_out == Outcome(False, "it was still moving when the time was up, after 10.0 s")


async def test_pushing_against_a_wall_is_standing_still():
    trace = await run(hard_coded(seconds=6.0), HIDDEN_NORTH)  # its turn rubs the wall
    pushing = (await run(exits_while_driving, (-0.5, 1.7, math.pi / 2))).to_dict()
    assert judge(Trace.from_dict(pushing), kind="stop_near_wall", min_m=0, max_m=0.05).passed
    assert judge(trace, kind="stop_near_wall", min_m=0, max_m=0.05).passed


async def test_stop_near_wall_names_a_box_when_a_box_is_nearest():
    outcome = judge(
        await run(to_the_wall(0.6), BELOW_THE_BOX), kind="stop_near_wall", min_m=0.3, max_m=0.6
    )
    assert outcome.passed and "nearest box" in outcome.why


# -- ends_within -------------------------------------------------------------------------------


async def test_ends_within_passes_a_program_that_ends_on_its_own_in_time():
    outcome = judge(await run(to_the_wall()), kind="ends_within", seconds=40)
    assert outcome.passed
    assert re.fullmatch(r"it ended on its own after \d+\.\d s", outcome.why)


async def test_ends_within_fails_a_program_still_running_at_the_time_limit():
    outcome = judge(await run(forever, limit=12), kind="ends_within", seconds=40)
    assert outcome == Outcome(False, "it was still running when the time was up, after 12.0 s")


async def test_ends_within_fails_a_program_that_ends_late_or_with_an_error():
    late = judge(await run(to_the_wall()), kind="ends_within", seconds=3)
    assert not late.passed and "the exercise wants it to end within 3 s" in late.why
    error = judge(await run(crashes), kind="ends_within", seconds=40)
    assert error == Outcome(False, "it ended with an error (exit code 1) after 1.0 s")


def test_ends_within_fails_a_program_stopped_by_hand():
    trace = Trace.from_dict(
        {**hand_made(), "end": {"t": 3.0, "state": "stopped", "exit_code": None,
                                "reason": "stopped by user", "time_limit": False}}
    )  # fmt: skip
    outcome = judge(trace, kind="ends_within", seconds=40)
    assert outcome == Outcome(False, "it did not end on its own: it was stopped after 3.0 s")
    assert not judge(Trace.from_dict(hand_made()), kind="ends_within", seconds=40).passed


# -- output_matches ----------------------------------------------------------------------------


async def test_output_matches_a_printed_line_or_a_said_text():
    printed = judge(await run(to_the_wall()), kind="output_matches", pattern=r"stopped at the")
    assert printed.passed
    assert re.fullmatch(r"it printed a matching line \d+\.\d s into the run", printed.why)
    said = await run(says_the_landmark)
    assert not judge(said, kind="output_matches", pattern="kitchen").passed
    outcome = judge(said, kind="output_matches", pattern="kitchen", flags="i")
    assert outcome.passed and outcome.why.startswith("it said a matching text")


async def test_output_matches_fails_when_nothing_matches_without_giving_the_pattern_away():
    outcome = judge(await run(to_the_wall()), kind="output_matches", pattern="^kitchen$")
    assert outcome == Outcome(
        False,
        "no output line or said text matched what the exercise expects (it printed 1 lines "
        "and said 0 texts)",
    )


def test_output_matches_gives_up_on_a_pattern_that_backtracks_without_end(monkeypatch):
    """A student's output against a teacher's catastrophic pattern (`re` takes hours on this
    line) must not hold the process that checks: the check fails in time, saying why."""
    monkeypatch.setattr(checks_module, "MATCH_SECONDS", 0.2)
    trace = Trace.from_dict(hand_made(output=[[0.5, "a" * 60 + "b"]]))
    outcome = judge(trace, kind="output_matches", pattern=r"^(a|aa)+$")
    assert not outcome.passed and "took more than 0.2 s" in outcome.why


# -- uses_block, max_blocks --------------------------------------------------------------------


def source(name):
    return (EXAMPLES / name).read_text()


@pytest.mark.parametrize(
    ("block", "example", "passed", "why"),
    [
        ("loop", "square.json", True, "the program uses a loop"),
        ("loop", "wall.json", True, "the program uses a loop"),
        ("controls_whileUntil", "wall.json", True,
         "the program uses the block controls_whileUntil"),
        ("controls_whileUntil", "square.json", False,
         "the program does not use the block controls_whileUntil"),
        ("condition", "wall_turn.json", False, "the program has no condition (an if block)"),
        ("math_number", "square.json", False, "the program does not use the block math_number"),
    ],
)  # fmt: skip
def test_uses_block(block, example, passed, why):
    outcome = evaluate_static(check(kind="uses_block", block=block), "blocks", source(example))
    assert outcome == Outcome(passed, why)


def test_uses_block_sees_blocks_inside_others_but_not_disabled_ones():
    workspace = json.loads(source("square.json"))
    repeat = workspace["blocks"]["blocks"][0]
    print_block = repeat["next"]["block"]
    print_block["next"] = {
        "block": {
            "type": "controls_if",
            "id": "if-1",
            "inputs": {
                "DO0": {"block": {"type": "controls_whileUntil", "id": "w", "enabled": False}}
            },
        }
    }
    text = json.dumps(workspace)
    assert evaluate_static(check(kind="uses_block", block="condition"), "blocks", text).passed
    whiles = check(kind="uses_block", block="controls_whileUntil")
    assert not evaluate_static(whiles, "blocks", text).passed  # fmt: skip


def test_max_blocks_counts_blocks_not_shadows():
    # square.json: repeat, forward, turn, print and its text; four numbers are shadows.
    five = evaluate_static(check(kind="max_blocks", count=5), "blocks", source("square.json"))
    assert five == Outcome(True, "the program has 5 blocks, at most 5")
    four = evaluate_static(check(kind="max_blocks", count=4), "blocks", source("square.json"))
    assert four == Outcome(False, "the program has 5 blocks; the exercise allows at most 4")


@pytest.mark.parametrize("kind", sorted(STATIC_KINDS))
def test_a_python_program_is_refused_by_a_blocks_check(kind):
    fields = {"uses_block": {"block": "loop"}, "max_blocks": {"count": 20}}[kind]
    outcome = evaluate_static(check(kind=kind, **fields), "python", source("wall.py"))
    assert outcome == Outcome(False, "this check needs a blocks program; this program is in Python")


def test_a_blocks_source_that_cannot_be_read_fails():
    for text in ("{not json", "[]", '{"blocks": 3}'):
        outcome = evaluate_static(check(kind="max_blocks", count=3), "blocks", text)
        assert outcome == Outcome(False, "the blocks program could not be read")


def test_static_and_trace_checks_are_told_apart():
    assert is_static({"kind": "uses_block"}) and not is_static({"kind": "no_contact"})
    with pytest.raises(ValueError, match="evaluate_static"):
        evaluate(check(kind="max_blocks", count=3), Trace.from_dict(hand_made()), WORLD)
    with pytest.raises(ValueError, match="evaluate"):
        evaluate_static(check(kind="no_contact"), "blocks", source("square.json"))


# -- hidden variants ---------------------------------------------------------------------------


async def test_no_why_gives_a_start_pose_away():
    """Times, distances to walls and counts, never a coordinate or a heading: whatever is a
    number in a why is one of those."""
    every = [
        {"kind": "reach_zone", "zone": "kitchen", "within_s": 1},
        {"kind": "zones_in_order", "zones": ["kitchen", "home"]},
        {"kind": "no_contact"},
        {"kind": "stop_near_wall", "min_m": 0.3, "max_m": 0.6},
        {"kind": "ends_within", "seconds": 1},
        {"kind": "output_matches", "pattern": "nothing like this"},
    ]
    checks = validate_checks(every, WORLD)
    allowed = re.compile(
        r"\d+(\.\d+)? s\b|\d+\.\d+(–\d+\.\d+)? m\b|\d+ (times|lines|texts)\b"
        r"|exit code \d+"
    )
    seen = set()
    for start in (HIDDEN_SOUTH, HIDDEN_NORTH, BELOW_THE_BOX):
        for program in (hard_coded(), to_the_wall(), kitchen_then_home, forever):
            trace = await run(program, start, limit=20)
            for one in checks:
                why = evaluate(one, trace, WORLD).why
                seen.add(why)
                assert not re.search(r"\d", allowed.sub("", why)), why
                assert not re.search(r"\b(x|y|heading|theta|pose|degrees?)\b|°", why), why
    assert len(seen) > 20  # many different whys were looked at


# -- the trace document ------------------------------------------------------------------------


def hand_made(**changes):
    doc = {
        "version": 1, "speed": 5.0, "radius": 0.15, "start": {"x": 0, "y": 0, "theta": 0},
        "poses": [[0, 0, 0, 0], [1.0, 0.5, 0, 0]], "contacts": [], "commands": [[0, 0.5, 0]],
        "said": [], "output": [], "truncated": False,
    }  # fmt: skip
    return doc | changes


@pytest.mark.parametrize(
    ("changes", "words"),
    [
        ({"poses": []}, "poses: at least one pose"),
        ({"poses": None}, "poses: a list"),
        ({"poses": [[0, 0, 0]]}, "poses[0]: a list of 4 values"),
        ({"poses": [[0, 0, "north", 0]]}, "poses[0]: a finite number"),
        ({"poses": [[1, 0, 0, 0], [0.5, 0, 0, 0]]}, "poses[1]: earlier than the one before"),
        ({"poses": [[0, math.nan, 0, 0]]}, "poses[0]: a finite number"),
        ({"radius": 0}, "radius: a number above 0"),
        ({"start": [0, 0, 0]}, "start: an object"),
        ({"output": [[0.1, 3]]}, "output[0]: a text"),
        ({"end": {"t": 1, "state": "crashed"}}, "end.state: one of finished"),
        ({"end": {"t": 1, "state": "failed", "exit_code": "1"}}, "end.exit_code"),
        ({"end": {"state": "finished", "exit_code": 0}}, "end.t"),
        ({"truncated": "no"}, "truncated"),
        ({"version": 2}, "version"),
    ],
)
def test_a_trace_document_that_cannot_be_read_is_refused(changes, words):
    with pytest.raises(ValueError, match=re.escape(words)):
        Trace.from_dict(hand_made(**changes))


def test_a_trace_is_read_back_as_it_was_written():
    doc = hand_made(end={"t": 1.0, "state": "finished", "exit_code": 0, "reason": "",
                         "time_limit": False})  # fmt: skip
    trace = Trace.from_dict(doc)
    assert Trace.from_dict(trace.to_dict()) == trace
    assert trace.pose_at(0.5) == pytest.approx((0.25, 0.0, 0.0))
    assert trace.pose_at(7.0) == pytest.approx((0.5, 0.0, 0.0))
    assert trace.first_time_in((0.45, 0.0, 0.1, 0.1)) == pytest.approx(0.8)
    assert trace.first_time_in((0.45, 0.0, 0.1, 0.1), after=0.9) == pytest.approx(0.9)
    assert trace.first_time_in((0.45, 0.0, 0.1, 0.1), until=0.7) is None
    # A corner cut between two poses, neither of them inside, is a visit.
    diagonal = Trace.from_dict(hand_made(poses=[[0, 0, 0, 0], [1, 1, 1, 0]]))
    assert diagonal.first_time_in((0.5, 0.5, 0.02, 0.02)) == pytest.approx(0.49)


async def test_a_check_the_world_no_longer_allows_fails_saying_why():
    trace = await run(to_the_wall())
    lost = {"kind": "reach_zone", "zone": "attic", "points": 1, "message": ""}
    outcome = evaluate(lost, trace, WORLD)
    assert not outcome.passed
    assert outcome.why.startswith("this check cannot be judged as it is written: there is no zone")
    broken = {"kind": "output_matches", "pattern": "(", "flags": ""}
    assert not evaluate(broken, trace, WORLD).passed
    unsaved = {"kind": "max_blocks", "count": -1}
    assert not evaluate_static(unsaved, "blocks", source("square.json")).passed


def test_a_time_just_past_a_limit_does_not_read_as_within_it():
    late = hand_made(
        poses=[[0, -0.5, 1.0, 0], [30.04, -0.5, 1.4, 0]],
        end={"t": 40.02, "state": "finished", "exit_code": 0, "reason": "", "time_limit": False},
    )
    trace = Trace.from_dict(late)
    outcome = judge(trace, kind="reach_zone", zone="kitchen", within_s=30)
    assert "after 30.04 s; the exercise wants it there within 30 s" in outcome.why
    assert "after 40.02 s" in judge(trace, kind="ends_within", seconds=40).why


def test_checks_are_plain_python_without_django():
    code = (
        "import sys, classroom.checks, classroom.trace, classroom.blocks_checks\n"
        "assert not [m for m in sys.modules if m.split('.')[0] == 'django'], 'django imported'\n"
    )
    root = Path(__file__).resolve().parents[2]
    env = {**os.environ, "PYTHONPATH": str(root)}
    env.pop("DJANGO_SETTINGS_MODULE", None)
    done = subprocess.run([sys.executable, "-c", code], cwd=root, env=env, capture_output=True)
    assert done.returncode == 0, done.stderr.decode()
