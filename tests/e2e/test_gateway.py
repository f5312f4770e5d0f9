"""The MAVLink gateway inside the agent: one vehicle link shared by the RHAL driver, a ground
station and a user's pymavlink program, all at once; endpoints through the API, kept in the
database and restored when the agent starts again."""

import asyncio
import json
import socket

import pytest
from asgiref.sync import sync_to_async
from channels.db import database_sync_to_async
from django.test import Client
from pymavlink import mavutil

from gateway.framing import Framer
from robots.bus import ask_agent
from robots.models import GatewayEndpoint
from tests.e2e.agents import finished, output_of, run_program

pytestmark = pytest.mark.django_db(transaction=True)

PROGRAM = """
import os, robot, time
from pymavlink import mavutil
bot = robot.Robot()
link = mavutil.mavlink_connection(os.environ["ROBOT_MAVLINK"], source_system=200)
link.mav.heartbeat_send(6, 8, 0, 0, 0)  # a UDP server answers whom it has heard
beat = link.wait_heartbeat(timeout=10)
while beat.get_srcSystem() != 1:  # the driver's and the ground station's come too
    beat = link.wait_heartbeat(timeout=10)
print("vehicle", beat.get_srcSystem(), beat.autopilot)
link.mav.command_long_send(1, 1, 511, 0, 33, 200000, 0, 0, 0, 0, 0)
ack = link.recv_match(type="COMMAND_ACK", blocking=True, timeout=10)
print("ack", ack.command, ack.result, ack.target_system)
bot.drive(0.2, 0.0)
time.sleep(0.5)
bot.stop()
"""


async def gateway_stats(name):
    return (await ask_agent(name, "gateway.stats"))["endpoints"]


def bound_port(stats, role_row_id):
    return int(stats[role_row_id]["bound"].rpartition(":")[2])


async def rows(robot, role):
    return await database_sync_to_async(
        lambda: list(GatewayEndpoint.objects.filter(robot=robot, role=role))
    )()


def ground_station(port):
    """QGroundControl as pymavlink plays it: sends to the robot's ground station endpoint."""
    gcs = mavutil.mavlink_connection(
        f"udpout:127.0.0.1:{port}", source_system=255, source_component=190
    )
    gcs.mav.heartbeat_send(6, 8, 0, 0, 0)
    beat = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=10)
    while beat is not None and beat.get_srcSystem() != 1:  # the driver's come too
        beat = gcs.recv_match(type="HEARTBEAT", blocking=True, timeout=10)
    assert beat is not None
    gcs.mav.command_long_send(1, 1, 511, 0, 24, 500000, 0, 0, 0, 0, 0)
    ack = gcs.recv_match(type="COMMAND_ACK", blocking=True, timeout=10)
    gcs.close()
    return ack


async def test_driver_ground_station_and_program_share_the_vehicle(robot_on):
    peer, agent, robot, user = await robot_on("mavlink")
    gcs_row = (await rows(robot, "gcs"))[0]
    stats = await gateway_stats("mavlink")
    assert stats["vehicle"]["status"] == "up" and stats["robot"]["status"] == "up"
    run = await run_program(user, robot, PROGRAM)
    ack = await asyncio.to_thread(ground_station, bound_port(stats, gcs_row.pk))
    run = await finished(run)
    assert run.state == "finished", f"{run.reason}\n{output_of(run)}"
    # Each got the vehicle's answer to its own command: acks are routed to their target.
    assert (ack.command, ack.result, ack.target_system) == (511, 0, 255)
    assert "vehicle 1 3" in output_of(run) and "ack 511 0 200" in output_of(run)
    emulator = peer.emulator
    sources = {command.source[0] for command in emulator.commands}
    assert {255, 200, agent.driver.sysid} <= sources  # the driver armed it meanwhile
    assert any(s.applied and s.vx == pytest.approx(0.2) for s in emulator.setpoints)
    stats = await gateway_stats("mavlink")
    heard = {s["system"] for s in stats[gcs_row.pk]["systems"]}
    assert heard == {255}
    assert (
        stats["vehicle"]["stats"]["frames_in"] > 0
        and stats["vehicle"]["stats"]["parse_errors"] == 0
    )


async def test_endpoints_through_the_api_route_at_once_and_survive_a_restart(robot_on, monkeypatch):
    # Views ask the agent on this loop from their worker thread, as in the server.
    monkeypatch.setattr("robots.bus._server_loop", asyncio.get_running_loop())
    peer, agent, robot, user = await robot_on("mavlink")
    await database_sync_to_async(robot.__class__.objects.filter(pk=robot.pk).update)(owner=user)
    client = Client()
    await sync_to_async(client.force_login)(user)
    api = f"/api/robots/{robot.name}/endpoints"

    def call(method, path, body=None):
        response = getattr(client, method)(
            path, data=json.dumps(body) if body is not None else None,
            content_type="application/json",
        )  # fmt: skip
        return response.status_code, (response.json() if response.content else None)

    # Off the thread the agent's database calls use, as a request's own thread in the server.
    api_call = sync_to_async(call, thread_sensitive=False)
    listening = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    listening.bind(("127.0.0.1", 0))
    listening.settimeout(5)
    port = listening.getsockname()[1]
    status, added = await api_call(
        "post", api, {"type": "udp", "mode": "client", "address": f"127.0.0.1:{port}"}
    )
    assert status == 201 and added["status"] == "up", added
    data = await asyncio.to_thread(listening.recv, 65536)
    assert data  # the vehicle's stream reaches the new endpoint at once

    taken = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    taken.bind(("127.0.0.1", 0))
    status, clash = await api_call(
        "post", api,
        {"type": "udp", "mode": "server", "address": f"127.0.0.1:{taken.getsockname()[1]}"},
    )  # fmt: skip
    assert status == 201 and clash["status"] == "error" and "in use" in clash["error"]
    status, bad = await api_call("post", api, {"type": "udp", "address": "nowhere"})
    assert status == 422
    status, listing = await api_call("get", api)
    defaults = {row["id"] for row in listing if row["role"] in ("gcs", "programs")}
    by_id = {row["id"]: row for row in listing}
    assert by_id["vehicle"]["status"] == "up" and by_id[added["id"]]["stats"]["frames_out"] > 0
    assert {row["role"] for row in listing} >= {"vehicle", "robot", "gcs", "programs", ""}

    # The agent starts again: the rows come back, and route.
    status, _ = await api_call("delete", f"{api}/{clash['id']}")
    assert status == 204
    await robot_on.restart("mavlink")
    while True:  # what was queued before, then the new agent's stream
        data = await asyncio.to_thread(listening.recv, 65536)
        if any(frame[3] == 0 for frame in Framer().feed(data)):  # a HEARTBEAT
            break
    status, listing = await api_call("get", api)
    assert {row["id"] for row in listing} == {"vehicle", "robot", added["id"], *defaults}
    assert all(row["status"] == "up" for row in listing), listing

    # Removed: it routes no more.
    status, _ = await api_call("delete", f"{api}/{added['id']}")
    assert status == 204
    listening.settimeout(1.5)
    with pytest.raises(TimeoutError):
        while True:
            await asyncio.to_thread(listening.recv, 65536)
    taken.close()
    listening.close()


async def test_a_recording_of_the_vehicle_link_is_kept_and_downloaded(
    robot_on, monkeypatch, tmp_path, settings
):
    settings.DATA_DIR = tmp_path
    monkeypatch.setattr("robots.bus._server_loop", asyncio.get_running_loop())
    peer, agent, robot, user = await robot_on("mavlink")
    await database_sync_to_async(robot.__class__.objects.filter(pk=robot.pk).update)(owner=user)
    client = Client()
    await sync_to_async(client.force_login)(user)
    api = f"/api/robots/{robot.name}/recordings"

    def post(on):
        return client.post(api, json.dumps({"on": on}), content_type="application/json").json()

    post_off_thread = sync_to_async(post, thread_sensitive=False)
    started = await post_off_thread(True)
    assert started["current"]["frames"] == 0 and started["current"]["error"] == ""
    await asyncio.sleep(2.5)  # heartbeats come once a second
    stopped = await post_off_thread(False)
    assert stopped["current"] is None and len(stopped["files"]) == 1
    name = stopped["files"][0]["name"]
    download = await sync_to_async(client.get, thread_sensitive=False)(f"{api}/{name}")
    assert download.status_code == 200
    path = tmp_path / "downloaded.tlog"
    path.write_bytes(b"".join(download.streaming_content))
    log = mavutil.mavlink_connection(str(path))
    kinds = set()
    while (message := log.recv_match()) is not None:
        kinds.add((message.get_srcSystem(), message.get_type()))
    # Both ways: the vehicle's telemetry and the driver's own heartbeats.
    assert (1, "HEARTBEAT") in kinds and (1, "ATTITUDE") in kinds
    assert (agent.driver.sysid, "HEARTBEAT") in kinds
    missing = await sync_to_async(client.get, thread_sensitive=False)(f"{api}/..%2Fx.tlog")
    assert missing.status_code == 404
