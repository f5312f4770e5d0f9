"""The JSON-RPC server on its own: handlers that answer at once and handlers that wait."""

import asyncio
import contextlib
import json
import socket

import pytest

from robots.rpc import (
    MAX_BATCH_REPLY_BYTES,
    MAX_CONNECTIONS_PER_RUN,
    RobotApiServer,
    RpcError,
)


async def handler(session, method, params):
    if method == "wait":
        await asyncio.sleep(params[0])
        return f"waited {params[0]}"
    if method == "echo":
        return params
    if method == "big":  # a large answer to a small question (a camera's snapshot)
        return "x" * params[0]
    if method == "fail":
        raise RpcError(-32000, "no")
    if method == "crash":
        raise RuntimeError("bug")
    if method == "yield":
        await asyncio.sleep(0)
        return "after a bare yield"
    raise RpcError(-32601, "no such method")


@pytest.fixture
async def server():
    server = RobotApiServer(handler)
    await server.start()
    yield server
    await server.close()


async def open_client(server):
    host, port = server.address.rsplit(":", 1)
    return await asyncio.open_connection(host, int(port))


def request(i, method, *params):
    return json.dumps({"jsonrpc": "2.0", "id": i, "method": method, "params": list(params)})


async def test_pipelined_requests_are_answered_in_order(server):
    reader, writer = await open_client(server)
    calls = [("wait", 0.05), ("echo", 1), ("yield",), ("wait", 0.01), ("echo", 2), ("fail",)]
    writer.write("".join(request(i, *c) + "\n" for i, c in enumerate(calls)).encode())
    replies = [json.loads(await reader.readline()) for _ in calls]
    assert [r["id"] for r in replies] == list(range(len(calls)))
    assert replies[0]["result"] == "waited 0.05" and replies[1]["result"] == [1]
    assert replies[2]["result"] == "after a bare yield" and replies[5]["error"]["code"] == -32000
    writer.close()


async def test_a_crashing_handler_is_an_internal_error_and_the_connection_goes_on(server):
    reader, writer = await open_client(server)
    writer.write((request(1, "crash") + "\n" + request(2, "echo", "still here") + "\n").encode())
    first, second = json.loads(await reader.readline()), json.loads(await reader.readline())
    assert first["error"]["code"] == -32603 and second["result"] == ["still here"]
    writer.close()


async def test_requests_split_across_packets(server):
    reader, writer = await open_client(server)
    line = (request(5, "echo", "x" * 10_000) + "\n").encode()
    for i in range(0, len(line), 333):
        writer.write(line[i : i + 333])
        await writer.drain()
        await asyncio.sleep(0)
    assert json.loads(await reader.readline())["result"] == ["x" * 10_000]
    writer.close()


async def test_closing_the_server_while_a_handler_waits(server):
    reader, writer = await open_client(server)
    writer.write((request(1, "wait", 10) + "\n").encode())
    await asyncio.sleep(0.05)
    await asyncio.wait_for(server.close(), 5)
    assert await reader.read() == b""


async def test_handlers_that_are_not_quick_run_in_a_task_and_may_use_timeouts():
    async def timed(session, method, params):
        async with asyncio.timeout(1):  # needs a task of its own
            await asyncio.sleep(0)
            return "in time"

    for quick in (None, lambda method: method == "other"):
        server = RobotApiServer(timed, quick=quick)
        await server.start()
        reader, writer = await open_client(server)
        writer.write((request(1, "timed") + "\n").encode())
        assert json.loads(await reader.readline())["result"] == "in time"
        writer.close()
        await server.close()


async def test_quick_methods_are_answered_in_order_with_slow_ones():
    server = RobotApiServer(handler, quick=lambda method: method == "echo")
    await server.start()
    reader, writer = await open_client(server)
    calls = [("echo", 1), ("wait", 0.02), ("echo", 2), ("yield",)]
    writer.write("".join(request(i, *c) + "\n" for i, c in enumerate(calls)).encode())
    replies = [json.loads(await reader.readline()) for _ in calls]
    assert [r["id"] for r in replies] == [0, 1, 2, 3]
    writer.close()
    await server.close()


async def served(reader, writer) -> bool:
    """Whether the server answers on this connection (a closed one reads as EOF)."""
    try:
        writer.write((request(1, "echo", "hi") + "\n").encode())
        await writer.drain()
        return bool(await asyncio.wait_for(reader.readline(), 5))
    except (ConnectionError, OSError):
        return False


async def test_one_run_may_hold_only_so_many_connections(tmp_path):
    """Each connection costs the agent a file descriptor: past MAX_CONNECTIONS_PER_RUN a run's
    next ones are closed (on a listener in its box, and on the Unix socket its runs share,
    where the peer's pid namespace says whose it is); one closed makes room again."""
    server = RobotApiServer(handler, unix_path=tmp_path / "api.sock")
    await server.start()
    inside = socket.socket()
    inside.bind(("127.0.0.1", 0))
    inside.listen()
    await server.serve_socket(inside)
    try:
        for connect in (
            lambda: asyncio.open_unix_connection(str(tmp_path / "api.sock")),
            lambda: asyncio.open_connection(*inside.getsockname()),
        ):
            clients = [await connect() for _ in range(MAX_CONNECTIONS_PER_RUN + 20)]
            answers = [await served(*client) for client in clients]
            assert answers == [True] * MAX_CONNECTIONS_PER_RUN + [False] * 20
            clients[0][1].close()
            await asyncio.sleep(0.1)
            assert await served(*await connect())
            for _, writer in clients:
                writer.close()
            await asyncio.sleep(0.1)
    finally:
        await server.close()
        inside.close()


@pytest.mark.parametrize("number", ["NaN", "Infinity", "-Infinity", "1e400", "-1e999"])
async def test_numbers_json_cannot_mean_are_a_parse_error(server, number):
    """Python's json reads NaN and Infinity (and 1e400 as infinity): a NaN timeout put in the
    event loop's schedule makes every timer of the agent late, robots' and pages' alike."""
    reader, writer = await open_client(server)
    line = f'{{"jsonrpc": "2.0", "id": 1, "method": "wait", "params": [{number}]}}\n'
    writer.write(line.encode() + (request(2, "echo", 1.5) + "\n").encode())
    first = json.loads(await asyncio.wait_for(reader.readline(), 5))
    second = json.loads(await asyncio.wait_for(reader.readline(), 5))
    assert first["error"]["code"] == -32700, first
    assert second["result"] == [1.5]
    writer.close()


@pytest.mark.parametrize("text", [r"\ud800", r"\uDFFF", r"x\udc00y"])
async def test_a_lone_surrogate_is_a_parse_error(server, text):
    """JSON's \\ud800 alone decodes to a string UTF-8 cannot carry: shown on the robot's page or
    sent through the channel layer it broke them, for everyone. A pair is a character."""
    reader, writer = await open_client(server)
    bad = f'{{"jsonrpc": "2.0", "id": 1, "method": "echo", "params": [{{"{text}": 1}}]}}\n'
    pair = '{"jsonrpc": "2.0", "id": 2, "method": "echo", "params": ["\\ud83d\\ude00"]}\n'
    writer.write(bad.encode() + pair.encode())
    first = json.loads(await asyncio.wait_for(reader.readline(), 5))
    second = json.loads(await asyncio.wait_for(reader.readline(), 5))
    assert first["error"]["code"] == -32700, first
    assert second["result"] == ["\N{GRINNING FACE}"]
    writer.close()


async def test_a_batch_of_large_replies_is_cut_where_they_pass_the_cap(server):
    """A batch's replies are held until its last is made: past MAX_BATCH_REPLY_BYTES the rest
    are refused, each saying so (a 53 KB batch of snapshots made the server hold 89 MB)."""
    reader, writer = await asyncio.open_connection(*server.address.rsplit(":", 1), limit=2**26)
    batch = [{"jsonrpc": "2.0", "id": i, "method": "big", "params": [100_000]} for i in range(100)]
    writer.write(json.dumps(batch).encode() + b"\n")
    replies = json.loads(await asyncio.wait_for(reader.readline(), 10))
    answered = [r for r in replies if "result" in r]
    refused = [r for r in replies if "error" in r]
    assert len(replies) == 100 and [r["id"] for r in replies] == list(range(100))
    assert len(answered) * 100_000 <= MAX_BATCH_REPLY_BYTES + 200_000 and refused
    assert refused[0]["error"]["code"] == -32002 and "ask again" in refused[0]["error"]["message"]
    writer.close()


async def test_a_client_that_reads_no_replies_makes_the_server_hold_little(server):
    """Requests keep coming, replies are never read: the server stops answering (and reading)
    until the client reads, instead of queueing its replies."""
    reader, writer = await asyncio.open_connection(*server.address.rsplit(":", 1), limit=2**20)
    writer.write("".join(request(i, "big", 100_000) + "\n" for i in range(300)).encode())
    with contextlib.suppress(asyncio.TimeoutError):
        await asyncio.wait_for(writer.drain(), 2)
    await asyncio.sleep(0.5)
    (connection,) = server._connections
    assert connection.transport.get_write_buffer_size() < 2 * 2**20
    got = 0
    while got < 300:  # and once read, every reply comes
        json.loads(await asyncio.wait_for(reader.readline(), 10))
        got += 1
    writer.close()
