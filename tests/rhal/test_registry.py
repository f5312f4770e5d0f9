import subprocess
import sys

import pytest

import rhal
from rhal.registry import DRIVERS, parse_query_options


@pytest.mark.parametrize("scheme", sorted(DRIVERS))
def test_every_registered_driver_loads_as_a_robot(scheme):
    bot = rhal.connect(f"{scheme}://")
    assert isinstance(bot, rhal.Robot)
    assert not bot.is_open, "connect() must not open the robot"
    assert bot.capabilities()["kind"] == bot.kind


@pytest.mark.parametrize("url", ["warp://enterprise", "localhost:5760", ""])
def test_unknown_scheme_lists_the_known_ones(url):
    with pytest.raises(rhal.UnknownDriverError, match=r"known schemes: .*sim://"):
        rhal.connect(url)


def test_scheme_is_case_insensitive():
    assert rhal.connect("SIM://").kind == "sim"


def test_query_options_reach_the_driver():
    bot = rhal.connect("sim://?arena=square&max_linear=0.3&max_angular=1")
    assert bot.arena_name == "square"
    assert bot.capabilities()["drive"] == {"max_linear": 0.3, "max_angular": 1.0}


def test_keyword_options_override_the_query():
    bot = rhal.connect("sim://?max_linear=0.3", max_linear=0.2)
    assert bot.max_linear == 0.2


def test_an_option_the_driver_does_not_take_is_an_error():
    with pytest.raises(TypeError, match="arean"):
        rhal.connect("sim://?arean=square")


def test_query_values_are_converted():
    assert parse_query_options("a=1&b=0.5&c=x&d=true&e=False&f=nan&g=&a=2") == {
        "a": 2,
        "b": 0.5,
        "c": "x",
        "d": True,
        "e": False,
        "f": "nan",
        "g": "",
    }


def test_a_missing_driver_library_says_what_to_install(monkeypatch):
    monkeypatch.setitem(DRIVERS, "ghost", ("rhal_ghost_wire_protocol", "GhostRobot"))
    with pytest.raises(rhal.DriverUnavailableError, match="rhal_ghost_wire_protocol"):
        rhal.connect("ghost://")


def test_the_sim_path_stays_light():
    # Idle memory matters on a Raspberry Pi: Pillow only once a camera is watched (numpy is
    # the simulator's geometry, rhal.simulator).
    script = (
        "import asyncio, sys, rhal\n"
        "async def main():\n"
        "    async with rhal.connect('sim://') as bot:\n"
        "        await bot.drive(0.2, 0.1)\n"
        "        await bot.sensors()\n"
        "asyncio.run(main())\n"
        "print(sorted(m for m in ('PIL', 'django') if m in sys.modules))\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, check=True
    )
    assert result.stdout.strip() == "[]"
