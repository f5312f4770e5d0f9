import pytest

import rhal


class ManualClock:
    """Seconds that pass only when a test says so, so simulated motion is exact."""

    def __init__(self) -> None:
        self.now = 1000.0

    def __call__(self) -> float:
        return self.now

    def advance(self, seconds: float) -> None:
        self.now += seconds


@pytest.fixture
def clock():
    return ManualClock()


@pytest.fixture
async def robot(clock):
    async with rhal.connect("sim://", clock=clock) as bot:
        yield bot


@pytest.fixture
def drive_for(robot, clock):
    """Drive at the given speeds for some seconds of simulated time; return the readings."""

    async def drive_for(linear: float, angular: float, seconds: float) -> dict:
        await robot.drive(linear, angular)
        clock.advance(seconds)
        return await robot.sensors()

    return drive_for
