"""MAVLink from programs goes through the control lease, with a real agent on the MAVLink
robot (its vehicle: tests/rhal/mavlink_emulator.py, which records every command and setpoint
and who sent it).

Each run has its own endpoint, at ROBOT_MAVLINK's port inside its own network namespace:
a run on another robot cannot reach it; a second run of the same user (it does not wait
in line) cannot arm the vehicle or send it a setpoint while the first holds the robot; the
holder can; an emergency stop ends them both. A ground station set to ``control: lease`` is
refused commands while a program holds the robot; one set to ``always`` is not. A run whose
claim is not answered yet (its program starts meanwhile) may listen, not command.
"""

import asyncio

import pytest
from channels.db import database_sync_to_async
from pymavlink import mavutil

from robots.bus import ask_agent
from robots.models import GatewayEndpoint
from tests.e2e.agents import output_of, run_program, until
from tests.e2e.test_run_queue import fresh, in_state

pytestmark = pytest.mark.django_db(transaction=True)
DENIED = mavutil.mavlink.MAV_RESULT_DENIED

# A program on the MAVLink robot: it makes itself heard, then hears the vehicle.
HEARS = """
import os, time
from pymavlink import mavutil
link = mavutil.mavlink_connection(os.environ["ROBOT_MAVLINK"], source_system={system})
link.mav.heartbeat_send(6, 8, 0, 0, 0)  # a UDP server answers whom it has heard
beat = link.wait_heartbeat(timeout=10)
while beat.get_srcSystem() != 1:
    beat = link.wait_heartbeat(timeout=10)
print("heard the vehicle", flush=True)
"""
ARMS = (
    HEARS
    + """
link.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)  # arm
ack = link.recv_match(type="COMMAND_ACK", condition="COMMAND_ACK.command == 400",
                      blocking=True, timeout=10)
print("arm ack", None if ack is None else ack.result, flush=True)
link.mav.set_position_target_local_ned_send(0, 1, 1, 8, 0b110111000111, 0, 0, 0, 1.0, 0, 0,
                                            0, 0, 0, 0, 0)
print("setpoint sent", flush=True)
time.sleep(120)
"""
)
REACHES_FOR_IT = """
import os, socket
from pymavlink import mavutil
print("ROBOT_MAVLINK" in os.environ, flush=True)
link = mavutil.mavlink_connection("udpout:127.0.0.1:14551", source_system=202)
for _ in range(5):
    link.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
print("sent", flush=True)
"""
ARMS_UNTIL_ACCEPTED = (
    HEARS
    + """
while True:
    link.mav.set_position_target_local_ned_send(0, 1, 1, 8, 0b110111000111, 0, 0, 0, 1.0, 0, 0,
                                                0, 0, 0, 0, 0)
    link.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)  # arm
    ack = link.recv_match(type="COMMAND_ACK", condition="COMMAND_ACK.command == 400",
                          blocking=True, timeout=10)
    result = None if ack is None else ack.result
    print("arm ack", result, flush=True)
    if result == 0:
        break
    time.sleep(0.1)
time.sleep(120)
"""
)


def program(system: int) -> str:
    return ARMS.format(system=system)


def from_system(emulator, system: int) -> tuple[list, list]:
    commands = [c for c in emulator.commands if c.source[0] == system and c.name == "ARM_DISARM"]
    setpoints = [s for s in emulator.setpoints if s.source[0] == system]
    return commands, setpoints


async def said(run, text: str, timeout: float = 20.0) -> str:
    await until(lambda: run.log_path.exists() and text in run.log_path.read_text(),
                timeout=timeout, what=f"run {run.pk} saying {text!r}")  # fmt: skip
    return output_of(run)


@pytest.fixture
async def rover(robot_on):
    peer, agent, robot, user = await robot_on("mavlink")
    return peer.emulator, agent, robot, user


async def test_only_the_run_holding_the_robot_commands_the_vehicle(rover, robot_on):
    emulator, agent, robot, user = rover
    holder = await run_program(user, robot, program(200))
    out = await said(holder, "setpoint sent")
    assert agent.lease.holds(holder.pk)  # its first command took the free lease
    commands, setpoints = from_system(emulator, 200)
    assert commands and setpoints, out  # the vehicle had them (and answered itself)
    assert f"arm ack {commands[0].result}" in out

    # The same user's second run: it runs (no wait in line), and may read, not command.
    second = await run_program(user, robot, program(201))
    out = await said(second, "setpoint sent")
    assert "heard the vehicle" in out and f"arm ack {DENIED}" in out, out
    await asyncio.sleep(0.5)
    assert from_system(emulator, 201) == ([], [])

    # A run on another robot has no ROBOT_MAVLINK, and nothing of this robot's at the port.
    sim_peer, sim_agent, sim, _ = await robot_on("sim")
    elsewhere = await run_program(user, sim, REACHES_FOR_IT)
    out = await said(elsewhere, "sent")
    assert out.startswith("False"), out
    await asyncio.sleep(0.5)
    assert not [c for c in emulator.commands if c.source[0] == 202]

    # An emergency stop: both runs end at once, and their endpoints with them.
    reply = await ask_agent("mavlink", "robot.estop", by=user.username)
    assert sorted(reply["runs"]) == sorted([holder.pk, second.pk])
    for run in (holder, second):
        await in_state(run, "stopped")
    endpoints = agent.gateway.router.endpoints
    await until(lambda: not [e for e in endpoints.values() if e.name.startswith("run #")],
                what="the runs' endpoints gone")  # fmt: skip
    before = len(emulator.commands)
    await asyncio.sleep(0.3)
    assert len(emulator.commands) == before


def ground_station_arms(port: int) -> int | None:
    gcs = mavutil.mavlink_connection(f"udpout:127.0.0.1:{port}", source_system=255,
                                     source_component=190)  # fmt: skip
    try:
        gcs.mav.heartbeat_send(6, 8, 0, 0, 0)
        beat = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=10)
        while beat is not None and beat.get_srcSystem() != 1:
            beat = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=10)
        gcs.mav.command_long_send(1, 1, 400, 0, 1, 0, 0, 0, 0, 0, 0)
        ack = gcs.recv_match(type="COMMAND_ACK", condition="COMMAND_ACK.command == 400",
                             blocking=True, timeout=10)  # fmt: skip
        return None if ack is None else ack.result
    finally:
        gcs.close()


@pytest.mark.parametrize("control", ["lease", "always"])
async def test_a_ground_station_commands_as_its_control_setting_says(rover, control):
    emulator, agent, robot, user = rover
    row = await database_sync_to_async(GatewayEndpoint.objects.get)(robot=robot, role="gcs")
    await database_sync_to_async(GatewayEndpoint.objects.filter(pk=row.pk).update)(control=control)
    stats = await ask_agent("mavlink", "gateway.reload")
    port = int(stats["endpoints"][row.pk]["bound"].rpartition(":")[2])
    holder = await run_program(user, robot, program(200))
    await said(holder, "setpoint sent")
    assert agent.lease.holds(holder.pk)
    before = len([c for c in emulator.commands if c.source[0] == 255])
    result = await asyncio.to_thread(ground_station_arms, port)
    after = [c for c in emulator.commands if c.source[0] == 255]
    if control == "lease":
        assert result == DENIED and len(after) == before
    else:  # a pilot's ground station takes over whatever runs: the page says it commands
        assert result is not None
        assert len(after) == before + 1
        stats = await ask_agent("mavlink", "gateway.stats")
        assert stats["endpoints"][row.pk]["commanding"] < 10
    await ask_agent("mavlink", "robot.estop", by=user.username)
    await in_state(await fresh(holder), "stopped")


async def test_a_run_commands_the_vehicle_only_once_its_claim_is_answered(rover, held_claim):
    emulator, agent, robot, user = rover
    run = await run_program(user, robot, ARMS_UNTIL_ACCEPTED.format(system=203))
    out = await said(run, f"arm ack {DENIED}")  # up, and listening, before the answer
    assert "heard the vehicle" in out, out
    assert from_system(emulator, 203) == ([], []), out  # nothing of it reached the vehicle
    assert agent.lease.holder is None
    held_claim.set()
    out = await said(run, "arm ack 0")
    commands, setpoints = from_system(emulator, 203)
    assert commands and setpoints, out
    assert agent.lease.holds(run.pk)
