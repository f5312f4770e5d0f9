"""The base class's own rules, through the sim and through a minimal driver of our own."""

import math
from fractions import Fraction

import pytest

import rhal
from rhal import Robot


class RecordingRobot(Robot):
    """The smallest possible driver: it remembers what the base asked it to do."""

    kind = "recorder"

    def __init__(self, url="recorder://", *, fail_open=False, **limits):
        super().__init__(url, **limits)
        self.fail_open = fail_open
        self.calls = []

    async def _open(self):
        if self.fail_open:
            raise ConnectionRefusedError("nobody home")
        self.calls.append("open")

    async def _close(self):
        self.calls.append("close")

    async def _drive(self, linear, angular):
        self.calls.append(("drive", linear, angular))

    async def _read_sensors(self):
        return {"light": 0.5}

    def _sensor_specs(self):
        return {"light": {"unit": "fraction"}}


@pytest.mark.parametrize(
    ("linear", "angular", "applied"),
    [(5.0, 0.0, (0.5, 0.0)), (-5.0, 0.0, (-0.5, 0.0)), (0.1, 10.0, (0.1, 2.0)),
     (0.1, -10.0, (0.1, -2.0)), (0.25, 1.5, (0.25, 1.5)), (1, -3, (0.5, -2.0))],
)  # fmt: skip
async def test_drive_clamps_to_the_limits(robot, linear, angular, applied):
    result = await robot.drive(linear, angular)
    assert result == {"linear": applied[0], "angular": applied[1]}
    assert (await robot.sensors())["velocity"] == result


async def test_limits_come_from_options(clock):
    async with rhal.connect("sim://?max_linear=0.2&max_angular=0.5", clock=clock) as bot:
        assert await bot.drive(1.0, -1.0) == {"linear": 0.2, "angular": -0.5}
        clock.advance(1.0)
        assert (await bot.sensors())["odometry"]["distance"] == pytest.approx(0.2)


async def test_drive_accepts_any_real_number(robot):
    assert await robot.drive(Fraction(1, 4), 0) == {"linear": 0.25, "angular": 0.0}


@pytest.mark.parametrize("bad", [math.nan, math.inf, -math.inf, "0.3", None, True, [0.1], 1j])
async def test_drive_rejects_what_is_not_a_finite_number(robot, bad):
    await robot.drive(0.1, 0.2)
    with pytest.raises(ValueError, match="linear speed must be"):
        await robot.drive(bad, 0.0)
    with pytest.raises(ValueError, match="angular speed must be"):
        await robot.drive(0.0, bad)
    assert (await robot.sensors())["velocity"] == {"linear": 0.1, "angular": 0.2}


@pytest.mark.parametrize("bad", [0, -1.0, math.nan, "fast"])
def test_limits_must_be_positive_numbers(bad):
    with pytest.raises(ValueError, match="max_linear"):
        rhal.connect("sim://", max_linear=bad)


async def test_close_is_idempotent_and_stops_the_motors():
    bot = RecordingRobot()
    await bot.open()
    await bot.drive(0.3, 0.0)
    await bot.close()
    await bot.close()
    assert bot.calls == ["open", ("drive", 0.3, 0.0), ("drive", 0.0, 0.0), "close"]
    assert not bot.is_open


async def test_open_twice_opens_once():
    bot = RecordingRobot()
    await bot.open()
    await bot.open()
    assert bot.calls == ["open"]


async def test_a_closed_robot_refuses_commands_but_stop_is_harmless():
    bot = RecordingRobot()
    with pytest.raises(rhal.RobotConnectionError, match="not open"):
        await bot.drive(0.1, 0.0)
    with pytest.raises(rhal.RobotConnectionError, match="not open"):
        await bot.sensors()
    await bot.stop()
    assert bot.calls == []


async def test_async_with_opens_and_closes():
    async with RecordingRobot() as bot:
        assert bot.is_open
    assert not bot.is_open
    assert bot.calls == ["open", ("drive", 0.0, 0.0), "close"]


async def test_failing_to_open_is_a_connection_error():
    bot = RecordingRobot(fail_open=True)
    with pytest.raises(rhal.RobotConnectionError, match="nobody home"):
        await bot.open()
    assert not bot.is_open


async def test_without_a_camera_a_frame_is_not_supported():
    async with RecordingRobot() as bot:
        assert bot.capabilities()["camera"] is None
        with pytest.raises(rhal.NotSupportedError, match="recorder robot has no camera"):
            await bot.camera_jpeg()


async def test_missing_sensor_error_lists_the_sensors_it_has():
    async with RecordingRobot() as bot:
        assert await bot.sensor("light") == 0.5
        with pytest.raises(rhal.NotSupportedError, match=r"no sensor 'range'; .*: light"):
            await bot.sensor("range")


def test_every_rhal_error_is_a_rhal_error():
    for error in (
        rhal.UnknownDriverError,
        rhal.DriverUnavailableError,
        rhal.NotSupportedError,
        rhal.RobotConnectionError,
    ):
        assert issubclass(error, rhal.RhalError)
