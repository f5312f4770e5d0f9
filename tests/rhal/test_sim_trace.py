"""The sim's trace of a run (rhal.simulator.trace): what the exercise checks judge."""

import json
import math

import pytest

import rhal
from rhal.simulator import trace as trace_module

RADIUS = 0.15
WALL_Y = 2.0 - RADIUS  # where the robot's centre stops, driving north from the centre


async def program(bot, clock, steps, *, read_every=None):
    """Drive as ``steps`` say — (seconds of sim time to wait, then an action) — reading the
    robot every ``read_every`` sim seconds meanwhile (None: never)."""
    for seconds, action in steps:
        if read_every is None:
            clock.advance(seconds / bot.speed)
        else:
            left = seconds
            while left > 1e-12:
                step = min(read_every, left)
                clock.advance(step / bot.speed)
                left -= step
                bot._pose  # noqa: B018 - a read of the pose: the cheapest one there is
        await action(bot)


def drive(linear, angular):
    async def action(bot):
        await bot.drive(linear, angular)

    return action


async def nothing(bot):
    pass


# A wander: north into the wall, a slide along it, a turn on the spot, an arc, a stop.
WANDER = [
    (0.013, drive(0.5, 0.0)),
    (4.0, drive(-0.3, 0.4)),
    (1.5, drive(0.4, -1.0)),
    (2.2, drive(0.0, 1.5)),
    (1.0, drive(0.25, 0.3)),
    (3.0, drive(0.0, 0.0)),
    (1.0, nothing),
]


async def recorded(clock, steps, *, url="sim://", read_every=None):
    async with rhal.connect(url, clock=clock) as bot:
        bot.start_trace()
        await program(bot, clock, steps, read_every=read_every)
        return bot.take_trace()


async def test_a_trace_starts_at_the_current_pose_at_time_0(robot, clock):
    await robot.drive(0.5, 0.0)
    clock.advance(1.0)
    await robot.stop()
    robot.start_trace()
    clock.advance(2.0)
    trace = robot.take_trace()
    assert trace["version"] == 1
    assert trace["start"] == pytest.approx({"x": 0.0, "y": 0.5, "theta": math.pi / 2})
    assert trace["poses"][0] == pytest.approx([0.0, 0.0, 0.5, math.pi / 2])
    assert trace["poses"][-1] == pytest.approx([2.0, 0.0, 0.5, math.pi / 2])
    assert trace["radius"] == RADIUS and trace["speed"] == 1.0
    assert trace["contacts"] == trace["commands"] == trace["said"] == []
    assert trace["truncated"] is False
    assert json.loads(json.dumps(trace)) == trace


async def test_poses_come_every_50_ms_while_moving_and_at_each_command(clock):
    trace = await recorded(clock, WANDER)
    times = [pose[0] for pose in trace["poses"]]
    assert times == sorted(times)
    commands = [command[0] for command in trace["commands"]]
    assert set(commands) <= set(times)  # a pose at every change of command
    assert trace["commands"][0] == [0.013, 0.5, 0.0]
    assert trace["commands"][-1] == pytest.approx([11.713, 0.0, 0.0])
    moving_until = commands[-1]
    poses = trace["poses"]
    for a, b in zip(poses, poses[1:], strict=False):
        # Pinned against the wall it stands still: the stretch's two ends are kept.
        if b[0] <= moving_until and b[1:] != a[1:]:
            assert b[0] - a[0] <= 0.05 + 1e-9
    assert any(b[0] - a[0] > 0.05 for a, b in zip(poses, poses[1:], strict=False))
    # Standing still after the stop: no poses but the last, at the end.
    assert times[-2] == pytest.approx(moving_until)
    assert times[-1] == pytest.approx(12.713)
    assert trace["poses"][-1][1:] == trace["poses"][-2][1:]


async def test_the_trace_does_not_depend_on_how_often_the_robot_is_read(clock):
    never = await recorded(clock, WANDER)
    often = await recorded(clock, WANDER, read_every=0.001)
    odd = await recorded(clock, WANDER, read_every=0.037)
    for other in (often, odd):
        assert len(other["poses"]) == len(never["poses"])
        for a, b in zip(other["poses"], never["poses"], strict=True):
            assert a == pytest.approx(b, abs=1e-6)
        assert len(other["contacts"]) == len(never["contacts"]) == 2
        for a, b in zip(other["contacts"], never["contacts"], strict=True):
            assert a == pytest.approx(b, abs=1e-6)
        assert other["commands"] == never["commands"]


async def test_driving_into_a_wall_is_a_contact_when_it_begins(clock):
    # Off the 50 ms grid: the contact is seen at the physics' step, not the next sample.
    trace = await recorded(clock, [(0.013, drive(0.5, 0.0)), (6.0, drive(0.0, 0.0))])
    assert len(trace["contacts"]) == 1  # pushing on for seconds is the same contact
    t, x, y = trace["contacts"][0]
    assert t == pytest.approx(0.013 + WALL_Y / 0.5, abs=0.02)
    assert (x, y) == pytest.approx((0.0, WALL_Y), abs=0.01)


async def test_backing_off_and_driving_in_again_is_a_second_contact(clock):
    steps = [
        (0.0, drive(0.5, 0.0)),
        (5.0, drive(-0.5, 0.0)),
        (1.0, drive(0.5, 0.0)),
        (2.0, drive(0.0, 0.0)),
    ]
    trace = await recorded(clock, steps)
    assert [round(c[0], 2) for c in trace["contacts"]] == [3.7, 7.0]


async def test_a_box_is_touched_too(clock):
    # From the centre, east-north-east: into the north-east box's west face (x = 0.8).
    theta = math.atan2(0.7, 1.0)
    steps = [(0.0, drive(0.0, -1.0)), (math.pi / 2 - theta, drive(0.4, 0.0)), (5.0, nothing)]
    trace = await recorded(clock, steps)
    assert len(trace["contacts"]) == 1
    assert trace["contacts"][0][1] == pytest.approx(0.8 - RADIUS, abs=0.01)


async def test_what_a_program_said_is_kept_with_its_time(robot, clock):
    robot.start_trace()
    clock.advance(1.25)
    robot.note_said("I see the kitchen")
    clock.advance(1.0)
    trace = robot.take_trace()
    assert trace["said"] == [[1.25, "I see the kitchen"]]


async def test_nothing_is_said_into_a_trace_not_being_recorded(robot, clock):
    robot.note_said("nobody hears this")
    robot.start_trace()
    clock.advance(1.0)
    assert robot.take_trace()["said"] == []


async def test_times_are_the_sims_faster_clock(clock):
    async with rhal.connect("sim://?speed=5", clock=clock) as bot:
        bot.start_trace()
        await bot.drive(0.5, 0.0)
        clock.advance(0.2)  # a fifth of a real second: one sim second
        assert bot.trace_time() == pytest.approx(1.0)
        await bot.stop()
        clock.advance(0.2)
        trace = bot.take_trace()
    assert trace["speed"] == 5.0
    assert trace["commands"] == [[0.0, 0.5, 0.0], [1.0, 0.0, 0.0]]
    assert trace["poses"][-1] == pytest.approx([2.0, 0.0, 0.5, math.pi / 2])
    assert len(trace["poses"]) >= 20  # every 50 ms of sim time while it moved


async def test_trace_time_goes_on_after_the_trace_is_taken(robot, clock):
    with pytest.raises(RuntimeError):
        robot.trace_time()
    with pytest.raises(RuntimeError):
        robot.take_trace()
    robot.start_trace()
    clock.advance(1.0)
    robot.take_trace()
    clock.advance(0.5)
    assert robot.trace_time() == pytest.approx(1.5)  # output lines coming in late
    with pytest.raises(RuntimeError):
        robot.take_trace()


async def test_a_fresh_start_forgets_the_last_recording(robot, clock):
    robot.start_trace()
    await robot.drive(0.5, 0.0)
    clock.advance(1.0)
    robot.start_trace()
    clock.advance(1.0)
    trace = robot.take_trace()
    assert trace["start"]["y"] == pytest.approx(0.5)
    assert trace["commands"] == [[0.0, 0.5, 0.0]]  # the speeds in force when it began
    assert trace["poses"][-1] == pytest.approx([1.0, 0.0, 1.0, math.pi / 2])


async def test_a_reset_while_recording_is_a_jump_in_the_path(robot, clock):
    robot.start_trace()
    await robot.drive(0.5, 0.0)
    clock.advance(1.0)
    await robot.reset((-1.0, 0.0, 0.0))
    clock.advance(1.0)
    trace = robot.take_trace()
    assert trace["commands"] == [[0.0, 0.5, 0.0], [1.0, 0.0, 0.0]]
    assert trace["poses"][-2] == pytest.approx([1.0, -1.0, 0.0, 0.0])
    assert trace["poses"][-1] == pytest.approx([2.0, -1.0, 0.0, 0.0])


async def test_recording_costs_nothing_when_not_started(robot, clock):
    assert robot._recorder is None and robot._motion.observer is None
    robot.start_trace()
    assert robot._motion.observer is not None
    robot.take_trace()
    assert robot._recorder is None and robot._motion.observer is None


async def test_poses_beyond_the_cap_are_dropped_and_the_trace_says_so(robot, clock, monkeypatch):
    monkeypatch.setattr(trace_module, "MAX_POSES", 10)
    robot.start_trace()
    await robot.drive(0.0, 1.0)
    clock.advance(2.0)
    trace = robot.take_trace()
    assert trace["truncated"] is True
    assert len(trace["poses"]) == 11  # and the last, at the end
    assert trace["poses"][-1][0] == pytest.approx(2.0)
