"""The Robot API protocol over a real socket, served by a real agent's methods and sim robot."""

import asyncio
import json
import sys

import pytest

from programs.languages import CLIENTS_DIR

sys.path.insert(0, str(CLIENTS_DIR / "python"))
import robot as robot_client  # noqa: E402  (the client programs get on their path)

from tests.robot_api_server import admit


def end(agent, active):
    agent.tokens.pop(active.token)
    agent.runs.pop(active.run_id)


class Conn:
    def __init__(self, reader, writer):
        self.reader, self.writer, self.next_id = reader, writer, 0

    async def send_raw(self, data: bytes):
        self.writer.write(data)
        await self.writer.drain()
        return json.loads(await self.reader.readline())

    async def call(self, method, *params):
        self.next_id += 1
        request = {"jsonrpc": "2.0", "id": self.next_id, "method": method, "params": list(params)}
        return await self.send_raw(json.dumps(request).encode() + b"\n")


@pytest.fixture
async def conn(agent):
    host, port = agent.api_address.rsplit(":", 1)
    reader, writer = await asyncio.open_connection(host, int(port))
    yield Conn(reader, writer)
    writer.close()


async def test_invalid_json_is_a_parse_error_and_the_connection_goes_on(agent, conn):
    reply = await conn.send_raw(b"{not json\n")
    assert reply["error"]["code"] == -32700 and reply["id"] is None
    admit(agent)
    assert (await conn.call("auth", "good-token"))["result"]["run"] == 7


async def test_a_request_without_jsonrpc_version_is_invalid(conn):
    reply = await conn.send_raw(b'{"id": 1, "method": "sensors"}\n')
    assert reply["error"]["code"] == -32600


async def test_methods_need_auth_first(conn):
    reply = await conn.call("sensors")
    assert reply["error"]["code"] == -32001
    assert "auth" in reply["error"]["message"]


async def test_a_wrong_token_is_refused(agent, conn):
    admit(agent)
    reply = await conn.call("auth", "someone-elses-guess")
    assert reply["error"]["code"] == -32001
    assert (await conn.call("sensors"))["error"]["code"] == -32001


async def test_a_token_is_worthless_once_its_run_ended(agent, conn):
    active = admit(agent)
    await conn.call("auth", "good-token")
    assert "result" in await conn.call("sensors")
    end(agent, active)
    reply = await conn.call("sensors")
    assert reply["error"]["code"] == -32001 and "ended" in reply["error"]["message"]
    assert (await conn.call("auth", "good-token"))["error"]["code"] == -32001


async def test_drive_is_clamped_to_the_robot_limits(agent, conn):
    active = admit(agent)
    await conn.call("auth", "good-token")
    reply = await conn.call("drive", 5.0, 0.0)
    assert reply["result"] == {"linear": 0.5, "angular": 0.0}
    assert agent.motion_owner == active.run_id
    await asyncio.sleep(0.2)
    assert (await conn.call("sensors"))["result"]["velocity"]["linear"] == 0.5


async def test_bad_params_are_invalid_params(agent, conn):
    admit(agent)
    await conn.call("auth", "good-token")
    assert (await conn.call("drive", "fast", 0))["error"]["code"] == -32602
    assert (await conn.call("drive"))["error"]["code"] == -32602
    assert (await conn.call("drive", 1, 2, 3))["error"]["code"] == -32602
    named = await conn.send_raw(
        b'{"jsonrpc":"2.0","id":9,"method":"drive","params":{"linear":0.1,"angular":0.2}}\n'
    )
    assert named["result"] == {"linear": 0.1, "angular": 0.2}


async def test_unknown_method_and_missing_sensor_are_clear_errors(agent, conn):
    admit(agent)
    await conn.call("auth", "good-token")
    reply = await conn.call("fly")
    assert reply["error"]["code"] == -32601 and "drive" in reply["error"]["message"]
    reply = await conn.call("sensor", "gps")
    assert reply["error"]["code"] == -32000 and "gps" in reply["error"]["message"]
    assert (await conn.call("sensor", "heading"))["result"] == 0.0


async def test_batches_and_notifications(agent, conn):
    admit(agent)
    await conn.call("auth", "good-token")
    batch = [
        {"jsonrpc": "2.0", "id": 1, "method": "sensor", "params": ["range"]},
        {"jsonrpc": "2.0", "method": "stop"},  # a notification: no reply
        {"jsonrpc": "2.0", "id": 2, "method": "capabilities"},
    ]
    replies = await conn.send_raw(json.dumps(batch).encode() + b"\n")
    assert [r["id"] for r in replies] == [1, 2]
    assert replies[1]["result"]["kind"] == "sim"


async def test_show_keeps_values_and_refuses_bad_ones(agent, conn):
    admit(agent)
    await conn.call("auth", "good-token")
    assert "result" in await conn.call("show", "heading", 42)
    assert "result" in await conn.call("show", "compass", "<svg></svg>")
    assert agent.shows["heading"]["value"] == 42 and agent.shows["compass"]["run"] == 7
    assert (await conn.call("show", "", 1))["error"]["code"] == -32602
    assert (await conn.call("show", "x", {"a": 1}))["error"]["code"] == -32602
    assert (await conn.call("show", "x", "y" * 300_000))["error"]["code"] == -32602


async def test_a_request_too_large_is_refused(agent, conn):
    reply = await conn.send_raw(
        b'{"jsonrpc":"2.0","id":1,"method":"x","params":["' + b"a" * 1_100_000 + b'"]}\n'
    )
    assert reply["error"]["code"] == -32600


async def test_the_python_client_round_trip(agent):
    admit(agent)

    def program():
        bot = robot_client.Robot(agent.api_address, "good-token")
        applied = bot.drive(0.2, 0.0)
        heading = bot.sensors()["heading"]
        try:
            bot.sensor("gps")
        except robot_client.RobotError as exc:
            error = (exc.code, str(exc))
        bot.close()
        return applied, heading, error

    applied, heading, error = await asyncio.to_thread(program)
    assert applied == {"linear": 0.2, "angular": 0.0} and heading == 0.0
    assert error[0] == -32000 and "gps" in error[1]


async def test_the_python_client_over_the_unix_socket(agent):
    admit(agent)
    assert agent.server.url.startswith("unix:")
    bot = await asyncio.to_thread(robot_client.Robot, agent.server.url, "good-token")
    assert (await asyncio.to_thread(bot.sensors))["range"] == 2.0
    bot.close()


async def test_the_python_client_refuses_a_wrong_token(agent):
    with pytest.raises(robot_client.RobotError, match="invalid token"):
        await asyncio.to_thread(robot_client.Robot, agent.api_address, "nope")


async def test_units_are_named_as_the_page_names_readings(agent):
    from robots.agent import flat_units

    units = flat_units(agent.driver.capabilities()["sensors"])
    assert units["heading"] == "deg" and units["position.x"] == "m"
    assert units["position.theta"] == "rad" and units["velocity.angular"] == "rad/s"


async def connect_as(agent, token):
    host, port = agent.api_address.rsplit(":", 1)
    conn = Conn(*await asyncio.open_connection(host, int(port)))
    assert "result" in await conn.call("auth", token)
    return conn


async def test_programs_exchange_messages_by_topic(agent):
    admit(agent, "tok-a", 1)
    admit(agent, "tok-b", 2)
    a, b = await connect_as(agent, "tok-a"), await connect_as(agent, "tok-b")
    assert (await a.call("publish", "cmd", "early"))["result"] == 0  # nobody listens yet
    assert (await b.call("subscribe", "cmd"))["result"] is None
    assert (await a.call("publish", "cmd", {"go": [1, 2]}))["result"] == 1
    assert (await a.call("publish", "cmd", "second"))["result"] == 1
    assert (await b.call("receive", "cmd", 1))["result"] == {"go": [1, 2]}
    assert (await b.call("receive", "cmd", 1))["result"] == "second"
    assert (await b.call("receive", "cmd", 0.05))["result"] is None  # timed out
    waiting = asyncio.ensure_future(b.call("receive", "cmd"))  # waits for ever...
    await asyncio.sleep(0.05)
    await a.call("publish", "cmd", 3)
    assert (await asyncio.wait_for(waiting, 2))["result"] == 3  # ...until a value comes
    b.writer.close()
    await asyncio.sleep(0.05)
    assert (await a.call("publish", "cmd", "gone"))["result"] == 0  # subscription closed
    a.writer.close()


async def test_receive_needs_a_subscription_and_a_sane_timeout(agent):
    admit(agent)
    conn = await connect_as(agent, "good-token")
    assert (await conn.call("receive", "t", 1))["error"]["code"] == -32602
    await conn.call("subscribe", "t")
    assert (await conn.call("receive", "t", -1))["error"]["code"] == -32602
    assert (await conn.call("receive", "t", "soon"))["error"]["code"] == -32602
    assert (await conn.call("publish", "", 1))["error"]["code"] == -32602
    conn.writer.close()


async def test_the_shared_memory(agent):
    admit(agent, "tok-a", 1)
    admit(agent, "tok-b", 2)
    a, b = await connect_as(agent, "tok-a"), await connect_as(agent, "tok-b")
    assert (await a.call("memory_get", "speed"))["result"] is None
    await a.call("memory_set", "speed", 0.25)
    assert (await b.call("memory_get", "speed"))["result"] == 0.25
    too_big = await a.call("memory_set", "blob", "x" * 70_000)
    assert too_big["error"]["code"] == -32602
    a.writer.close()
    b.writer.close()


async def test_shown_values_outlive_their_run_until_room_is_needed(agent, conn):
    from robots.robot_api import MAX_SHOWS

    first = admit(agent, "tok-1", 1)
    await conn.call("auth", "tok-1")
    for i in range(MAX_SHOWS):
        assert "result" in await conn.call("show", f"v{i}", i)
    assert "error" in await conn.call("show", "one more", 1)  # its own values are all live
    end(agent, first)
    admit(agent, "tok-2", 2)
    second = await connect_as(agent, "tok-2")
    assert "result" in await second.call("show", "new", 1)
    assert "v0" not in agent.shows and "v1" in agent.shows and len(agent.shows) == MAX_SHOWS
    second.writer.close()
