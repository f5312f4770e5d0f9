"""What one run can make the agent hold through the Robot API is capped, and what happens at a
cap is said, never silent: subscriptions per connection and run, values waiting per
subscription, connection, run and robot (the oldest are dropped, and receive counts them), the
shared memory and the shown values; and a request nested too deep, or a bug, costs one error
reply, not the server's time, memory or log.

Over real sockets against the real server: a real agent's (tests/robot_api_server.py), and for
the memory figure an agent's Robot API server in a process of its own, whose RSS is read."""

import asyncio
import json
import logging
import os
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest

from tests.robot_api_server import admit

ROOT = Path(__file__).resolve().parents[2]
VALUE_CHARS = 60_000  # a 60 KB value, as the attacker's


class Conn:
    def __init__(self, reader, writer):
        self.reader, self.writer, self.next_id = reader, writer, 0

    async def send_raw(self, data: bytes, timeout: float = 10.0):
        self.writer.write(data)
        await self.writer.drain()
        return json.loads(await asyncio.wait_for(self.reader.readline(), timeout))

    async def call(self, method, *params):
        self.next_id += 1
        request = {"jsonrpc": "2.0", "id": self.next_id, "method": method, "params": list(params)}
        return await self.send_raw(json.dumps(request).encode() + b"\n")

    async def pipelined(self, calls: list[tuple], window: int = 50) -> list[dict]:
        """Many calls sent ahead, ``window`` at a time; their replies in order."""
        replies = []
        for start in range(0, len(calls), window):
            chunk = calls[start : start + window]
            lines = []
            for method, *params in chunk:
                self.next_id += 1
                request = {"jsonrpc": "2.0", "id": self.next_id, "method": method,
                           "params": params}  # fmt: skip
                lines.append(json.dumps(request).encode() + b"\n")
            self.writer.write(b"".join(lines))
            await self.writer.drain()
            for _ in chunk:
                line = await asyncio.wait_for(self.reader.readline(), 30)
                replies.append(json.loads(line))
        return replies

    def close(self):
        self.writer.close()


async def connect(address: str, token: str | None = None) -> Conn:
    host, port = address.rsplit(":", 1)
    conn = Conn(*await asyncio.open_connection(host, int(port), limit=2**22))
    if token is not None:
        assert "result" in await conn.call("auth", token)
    return conn


def value(i: int, chars: int = VALUE_CHARS) -> str:
    return f"{i:06d}" + "x" * (chars - 6)


# -- the attacker's flood, against a server in a process of its own --------------------------

SERVER = textwrap.dedent(
    """
    import asyncio, os, sys
    import django
    django.setup()
    import rhal
    from robots.agent import ActiveRun, RobotAgent

    async def main():
        agent = RobotAgent("sim")
        agent.driver = rhal.connect("sim://")
        await agent.driver.open()
        address = await agent.server.start()
        active = ActiveRun(7, "flood-token", process=None)
        agent.tokens[active.token] = active
        agent.runs[active.run_id] = active
        print(address, os.getpid(), flush=True)
        await asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)  # until EOF

    asyncio.run(main())
    """
)


def rss_mb(pid: int) -> float:
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    raise AssertionError("no VmRSS")


@pytest.fixture
def server_process(tmp_path):
    env = {**os.environ, "DJANGO_SETTINGS_MODULE": "robotide.settings"}
    env["ROBOTIDE_DATA"] = str(tmp_path / "data")
    env["PYTHONPATH"] = str(ROOT)
    process = subprocess.Popen(
        [sys.executable, "-c", SERVER],
        cwd=ROOT,
        env=env,
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        address, pid = process.stdout.readline().split()
        yield address, int(pid)
    finally:
        process.stdin.close()
        try:
            process.wait(timeout=10)
        except subprocess.TimeoutExpired:
            process.kill()
            process.wait()


async def test_a_topic_flood_is_capped_and_nothing_is_lost_silently(server_process):
    address, pid = server_process
    topics, per_topic = [f"t{n}" for n in range(12)], 400  # 288 MB published in all
    conn = await connect(address, "flood-token")
    for topic in topics:
        assert (await conn.call("subscribe", topic))["result"] is None
    # Warm up: the server has handled a value of this size before the baseline is read.
    await conn.pipelined([("publish", t, value(0)) for t in topics])
    for topic in topics:
        assert (await conn.call("receive", topic, 1))["result"] == value(0)
    before = rss_mb(pid)
    calls = [("publish", t, value(i)) for i in range(1, per_topic + 1) for t in topics]
    replies = await conn.pipelined(calls)
    assert all(r.get("result") in (0, 1) for r in replies), replies[-1]
    grown = rss_mb(pid) - before
    assert grown < 50, f"the server grew by {grown:.0f} MB holding values nobody received"
    # What each subscriber gets: the newest values, in order, and how many it lost.
    for topic in topics:
        first = (await conn.call("receive", topic, 0, True))["result"]
        kept = [first["value"]]
        assert first["dropped"] > 0
        while (got := (await conn.call("receive", topic, 0))["result"]) is not None:
            kept.append(got)
        numbers = [int(v[:6]) for v in kept]
        assert numbers == list(range(per_topic - len(kept) + 1, per_topic + 1))
        assert first["dropped"] + len(kept) == per_topic  # every value received or counted
        after = (await conn.call("receive", topic, 0, True))["result"]
        assert after == {"value": None, "dropped": 0, "waiting": 0}
    conn.close()


# -- the caps one by one, against a real agent's server in this process ----------------------


async def test_topics_per_connection_and_per_run_are_capped(agent):
    admit(agent, "tok", 7)
    conn = await connect(agent.api_address, "tok")
    subscribed = await conn.pipelined([("subscribe", f"t{n}") for n in range(65)])
    assert all("result" in r for r in subscribed[:64])
    refused = subscribed[64]["error"]
    assert refused["code"] == -32002 and "at most 64 topics" in refused["message"]
    # A run opening more connections gets no more than its own cap.
    others = [await connect(agent.api_address, "tok") for _ in range(4)]
    count = 64
    for n, other in enumerate(others):
        replies = await other.pipelined([("subscribe", f"u{n}-{k}") for k in range(64)])
        count += sum("result" in r for r in replies)
    assert count == 256  # a run's cap
    for c in [conn, *others]:
        c.close()


async def test_a_runs_waiting_values_are_capped_over_all_its_connections(agent):
    admit(agent, "tok", 7)
    admit(agent, "pub", 8)
    publisher = await connect(agent.api_address, "pub")
    subscribers = [await connect(agent.api_address, "tok") for _ in range(3)]
    for conn in subscribers:  # each connection may hold 8 MB: 24 MB, over the run's 16 MB
        for topic in ("a", "b"):
            await conn.call("subscribe", topic)
    published = 150
    replies = await publisher.pipelined(
        [("publish", t, value(i)) for i in range(published) for t in ("a", "b")]
    )
    assert all("result" in r for r in replies)
    held = 0
    for conn in subscribers:
        for topic in ("a", "b"):
            first = (await conn.call("receive", topic, 0, True))["result"]
            kept = [] if first["value"] is None else [first["value"]]
            while (got := (await conn.call("receive", topic, 0))["result"]) is not None:
                kept.append(got)
            assert first["dropped"] + len(kept) == published  # received, or counted
            held += sum(len(json.dumps(v)) for v in kept)
    assert held <= 16 * 1024 * 1024  # a run's cap
    for conn in [publisher, *subscribers]:
        conn.close()


async def test_the_robots_waiting_values_are_capped_over_all_runs(agent, monkeypatch):
    monkeypatch.setattr("robots.robot_api.MAX_QUEUED_BYTES_ROBOT", 1024 * 1024, raising=False)
    subscribers = []
    for run in range(1, 5):
        admit(agent, f"tok{run}", run)
        conn = await connect(agent.api_address, f"tok{run}")
        await conn.call("subscribe", "news")
        subscribers.append(conn)
    admit(agent, "pub", 9)
    publisher = await connect(agent.api_address, "pub")
    await publisher.pipelined([("publish", "news", value(i, 10_000)) for i in range(100)])
    held = 0
    for conn in subscribers:
        first = (await conn.call("receive", "news", 0, True))["result"]
        kept = [] if first["value"] is None else [first["value"]]
        while (got := (await conn.call("receive", "news", 0))["result"]) is not None:
            kept.append(got)
        assert first["dropped"] + len(kept) == 100
        held += len(kept) * 10_000
    assert held <= 1024 * 1024
    for conn in [publisher, *subscribers]:
        conn.close()


async def test_the_shared_memory_is_capped_per_run_and_per_robot(agent):
    admit(agent, "tok-a", 1)
    admit(agent, "tok-b", 2)
    a = await connect(agent.api_address, "tok-a")
    b = await connect(agent.api_address, "tok-b")
    replies = await a.pipelined([("memory_set", f"k{n}", value(n)) for n in range(100)])
    refused = [r["error"] for r in replies if "error" in r]
    kept = sum("result" in r for r in replies)
    assert 60 <= kept < 70  # 4 MB a run
    assert refused and refused[0]["code"] == -32002 and "memory is full" in refused[0]["message"]
    # What it has it may still change; and another run has room of its own.
    assert "result" in await a.call("memory_set", "k0", "smaller")
    assert (await b.call("memory_get", "k0"))["result"] == "smaller"
    replies = await b.pipelined([("memory_set", f"b{n}", value(n)) for n in range(100)])
    assert 60 <= sum("result" in r for r in replies) < 70
    a.close()
    b.close()


async def test_keys_of_ended_runs_make_room_for_a_running_one(agent):
    """The memory keeps what ended programs set (for the next program to read) until the
    room is needed: then their oldest keys go, or two runs of 500 keys fill it for good."""
    for run_id in (1, 2):
        admit(agent, f"tok-{run_id}", run_id)
        conn = await connect(agent.api_address, f"tok-{run_id}")
        replies = await conn.pipelined([("memory_set", f"r{run_id}k{n}", n) for n in range(500)])
        assert all("result" in r for r in replies)
        conn.close()
        del agent.tokens[f"tok-{run_id}"], agent.runs[run_id]  # the run ended
    admit(agent, "tok-3", 3)
    conn = await connect(agent.api_address, "tok-3")
    assert "result" in await conn.call("memory_set", "score", 1)
    assert (await conn.call("memory_get", "r1k0"))["result"] is None  # the oldest went
    assert (await conn.call("memory_get", "r2k499"))["result"] == 499  # the newest stayed
    assert len(agent.api.memory) == 1000
    conn.close()


async def test_shown_values_are_capped_per_run(agent):
    admit(agent, "tok", 1)
    conn = await connect(agent.api_address, "tok")
    big = "<svg>" + "x" * (256 * 1024 - 11) + "</svg>"  # the largest one value may be
    replies = await conn.pipelined([("show", f"v{n}", big) for n in range(10)])
    assert sum("result" in r for r in replies) == 7  # 2 MB a run
    refused = replies[7]["error"]
    assert refused["code"] == -32002 and "2 MB" in refused["message"]
    assert "result" in await conn.call("show", "v0", big)  # shown again under its name: room
    conn.close()


# -- requests nested too deep, and bugs: one error reply each --------------------------------


class Records(logging.Handler):
    def __init__(self):
        super().__init__(logging.DEBUG)
        self.records: list[logging.LogRecord] = []

    def emit(self, record):
        self.records.append(record)


@pytest.fixture
def logged():
    """What the Robot API server and asyncio log (pytest's own log capture is off)."""
    records = Records()
    loggers = [logging.getLogger("robots.rpc"), logging.getLogger("asyncio")]
    for logger in loggers:
        logger.addHandler(records)
    yield records.records
    for logger in loggers:
        logger.removeHandler(records)


async def test_a_request_nested_too_deep_is_a_parse_error_and_the_connection_goes_on(agent, logged):
    admit(agent, "tok", 7)
    conn = await connect(agent.api_address, "tok")
    for line in (b"[" * 200_000, b"[" * 1_000_000, b'{"a":' * 100_000):
        reply = await conn.send_raw(line + b"\n")
        assert reply["error"]["code"] == -32700 and "nested" in reply["error"]["message"]
        assert reply["id"] is None
    deep = json.loads("[" * 70 + "]" * 70)
    reply = await conn.call("publish", "t", deep)
    assert reply["error"]["code"] == -32700
    fine = json.loads("[" * 50 + "]" * 50)
    assert (await conn.call("publish", "t", fine))["result"] == 0
    assert "heading" in (await conn.call("sensors"))["result"]
    assert [r for r in logged if r.levelno >= logging.ERROR] == []
    conn.close()


async def test_a_bug_is_an_internal_error_with_a_log_line_not_a_flood(logged):
    from robots.rpc import RobotApiServer

    async def handler(session, method, params):
        if method == "crash":
            raise RuntimeError("a bug")
        if method == "not_json":
            return {1, 2}  # a set: no JSON for it
        return "fine"

    server = RobotApiServer(handler)
    await server.start()
    try:
        conn = await connect(server.address)
        replies = await conn.pipelined([("crash",)] * 100 + [("not_json",), ("echo",)])
        assert all(r["error"]["code"] == -32603 for r in replies[:101])
        assert replies[101]["result"] == "fine"
        errors = [r for r in logged if r.levelno >= logging.ERROR]
        assert 1 <= len(errors) <= 20  # rate-limited: not one per request
        assert sum(r.exc_info is not None for r in errors) <= 2  # a traceback once per kind
        conn.close()
    finally:
        await server.close()


async def test_a_receive_waiting_when_its_connection_closes_ends_with_it(agent):
    """Else each such connection leaves a task pending for good (and, once collected, an
    error in the log): a program could open, receive(topic, null) and close in a loop."""
    admit(agent, "tok", 1)
    before = len(asyncio.all_tasks())
    for _ in range(20):
        conn = await connect(agent.api_address, "tok")
        assert "result" in await conn.call("subscribe", "never")
        conn.writer.write(
            b'{"jsonrpc": "2.0", "id": 9, "method": "receive", "params": ["never", null]}\n'
        )
        await conn.writer.drain()
        await asyncio.sleep(0.02)
        conn.close()
    await asyncio.sleep(0.2)
    assert len(asyncio.all_tasks()) <= before + 1
    assert agent.api.subscriptions == 0
