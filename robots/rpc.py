"""The Robot API: JSON-RPC 2.0, one JSON object per line, over a local socket.

A program connects to ``$ROBOT_API`` (``unix:/path`` or ``host:port``), calls ``auth`` with
``$ROBOT_TOKEN`` and may then call the robot's methods. A token is only worth something while
its run is alive. The server listens on a Unix socket (the faster, and reachable from a program
without network) and on loopback TCP (``$ROBOT_API_TCP``), which every language's standard
library speaks (Tcl has no Unix sockets).
"""

import asyncio
import json
import logging
import math
import os
import re
import socket
import struct
import time
import traceback
from collections import Counter, deque
from collections.abc import Awaitable, Callable
from itertools import accumulate
from typing import Any

log = logging.getLogger(__name__)

PARSE_ERROR = -32700
INVALID_REQUEST = -32600
METHOD_NOT_FOUND = -32601
INVALID_PARAMS = -32602
INTERNAL_ERROR = -32603
ROBOT_ERROR = -32000
UNAUTHORIZED = -32001
LIMIT_REACHED = -32002  # a cap on what one run may make the robot hold (robots.robot_api)

MAX_REQUEST_BYTES = 1024 * 1024
MAX_DEPTH = 64  # arrays and objects nested in a request, the batch's own array included
MAX_BATCH = 1000  # requests in one batch
MAX_BATCH_REPLY_BYTES = 4 * 2**20  # a batch's replies, held until the last is made
# Connections at once from one run (its threads and processes): each costs the agent a file
# descriptor, and a run may hold thousands (processes x open files) that would otherwise use
# up the agent's, which are the web server's too in the embedded appliance.
MAX_CONNECTIONS_PER_RUN = 64


def _finite(text: str) -> float:
    value = float(text)
    if not math.isfinite(value):  # 1e400: an overflow JSON cannot mean
        raise ValueError(f"number out of range: {text[:40]}")
    return value


def _lone_surrogate(value) -> bool:
    if isinstance(value, str):
        try:
            value.encode()
        except UnicodeEncodeError:
            return True
        return False
    if isinstance(value, dict):
        return any(_lone_surrogate(k) or _lone_surrogate(v) for k, v in value.items())
    if isinstance(value, list):
        return any(_lone_surrogate(v) for v in value)
    return False


def _no_constant(name: str):
    raise ValueError(f"{name} is not JSON")


# Strict JSON: Python's json takes NaN and Infinity, and a NaN that reaches a timeout or a
# timer corrupts the event loop's schedule for every robot and page it serves.
_decode = json.JSONDecoder(parse_float=_finite, parse_constant=_no_constant).decode
# One encoder for every reply: json.dumps() with options builds a new one each call.
_encode = json.JSONEncoder(separators=(",", ":"), check_circular=False).encode


class RpcError(Exception):
    def __init__(self, code: int, message: str, data: Any = None):
        super().__init__(message)
        self.code, self.message, self.data = code, message, data

    def as_json(self) -> dict:
        error = {"code": self.code, "message": self.message}
        if self.data is not None:
            error["data"] = self.data
        return error


class Session:
    """One client connection; `run` is set once it has authenticated."""

    __slots__ = ("run", "peer", "subscriptions", "queued")

    def __init__(self, peer):
        self.run = None
        self.peer = peer
        self.subscriptions: dict = {}  # topic -> its subscription (robots.robot_api)
        self.queued = 0  # bytes of the values waiting in its subscriptions


# handler(session, method, params) -> result; raises RpcError for a clean error reply
Handler = Callable[[Session, str, Any], Awaitable[Any]]


class RobotApiServer:
    """Serves `handler`; `quick(method)`, if given, names the methods safe to step eagerly."""

    def __init__(
        self, handler: Handler, host="127.0.0.1", port=0, unix_path=None, quick=None, closed=None
    ) -> None:
        self.handler = handler
        self.quick = quick
        self.closed = closed  # closed(session): a connection has gone
        self.host, self.port = host, port
        self.unix_path = unix_path
        self._servers: list[asyncio.base_events.Server] = []
        self._connections: set[_Connection] = set()
        self._open: Counter = Counter()  # connections now, by where they come from (peer_of)
        self._refused_from: set = set()  # said in the log once each

    @property
    def address(self) -> str:
        """host:port of the TCP endpoint."""
        host, port = self._servers[0].sockets[0].getsockname()[:2]
        return f"{host}:{port}"

    def answers_at_once(self, line: bytes) -> bool:
        """Whether a request may run outside a task until it first waits (see _Connection).

        Only for handlers that never need a task of their own (asyncio.timeout does): the
        ones `quick` names. The method is read cheaply off the line; anything unusual (a
        batch, odd spacing) just takes the task path.
        """
        if self.quick is None:
            return False
        at = line.find(b'"method":"')
        if at < 0:
            return False
        start = at + len(b'"method":"')
        end = line.find(b'"', start)
        return end > 0 and self.quick(line[start:end].decode("ascii", "replace"))

    @property
    def url(self) -> str:
        """What programs get in $ROBOT_API: the Unix socket if there is one."""
        return f"unix:{self.unix_path}" if self.unix_path else self.address

    async def start(self) -> str:
        loop = asyncio.get_running_loop()
        self._servers.append(
            await loop.create_server(lambda: _Connection(self, "host"), self.host, self.port)
        )
        if self.unix_path:
            factory = lambda: _Connection(self, PEER)  # noqa: E731
            self._servers.append(await loop.create_unix_server(factory, str(self.unix_path)))
        return self.address

    async def serve_socket(self, sock: socket.socket) -> "asyncio.Server":
        """Serve on a socket made elsewhere too (one in a run's network namespace): its
        connections are one run's."""
        loop = asyncio.get_running_loop()
        source = object()
        return await loop.create_server(lambda: _Connection(self, source), sock=sock)

    def close_where(self, belongs: Callable[[Session], bool]) -> None:
        """Close the connections whose session `belongs` (a run's, once it has ended)."""
        for connection in list(self._connections):
            if belongs(connection.session):
                connection.transport.close()

    def admit(self, source) -> bool:
        """One more connection from `source`, unless it has MAX_CONNECTIONS_PER_RUN open."""
        if self._open[source] >= MAX_CONNECTIONS_PER_RUN:
            if source not in self._refused_from:
                self._refused_from.add(source)
                log.warning("Robot API: a run opened more than %d connections at once; the"
                            " others are closed", MAX_CONNECTIONS_PER_RUN)  # fmt: skip
            return False
        self._open[source] += 1
        return True

    def release(self, source) -> None:
        self._open[source] -= 1
        if self._open[source] <= 0:
            del self._open[source]
            self._refused_from.discard(source)

    async def close(self) -> None:
        servers, self._servers = self._servers, []
        for server in servers:
            server.close()
        for connection in list(self._connections):
            connection.transport.close()
        for server in servers:
            await server.wait_closed()

    async def _batch(self, session: Session, requests: list):
        """A batch's replies, in one piece: past MAX_BATCH_REPLY_BYTES the rest are refused
        (a small batch of large answers would make the server hold them all at once)."""
        replies, size = [], 0
        for request in requests:
            if size > MAX_BATCH_REPLY_BYTES:
                if isinstance(request, dict) and "id" not in request:
                    continue  # a notification: no reply, even refused
                req_id = request.get("id") if isinstance(request, dict) else None
                why = f"the batch's replies passed {MAX_BATCH_REPLY_BYTES // 2**20} MB: ask again"
                replies.append(_error(req_id, LIMIT_REACHED, why))
                continue
            reply = await self.handle_request(session, request)
            if reply is not None:
                replies.append(reply)
                size += len(_encode(reply))
        return replies or None

    async def handle_line(self, session: Session, line: bytes):
        """The reply to one line (None for notifications only); never raises."""
        try:
            return await self._handle_line(session, line)
        except Exception as exc:  # a bug here must cost one request, not the connection
            _log_unexpected("Robot API request", exc)
            return _error(None, INTERNAL_ERROR, "internal error")

    async def _handle_line(self, session: Session, line: bytes):
        # A line shorter than the limit cannot be nested deeper: most requests skip the scan.
        if len(line) > MAX_DEPTH and too_deep(line):
            return _error(None, PARSE_ERROR, f"parse error: nested deeper than {MAX_DEPTH} levels")
        try:
            message = _decode(line.decode())
        except (ValueError, UnicodeDecodeError) as exc:
            return _error(None, PARSE_ERROR, f"parse error: {exc}")
        except RecursionError:  # too_deep() is exact for JSON; this is a second line of defence
            return _error(None, PARSE_ERROR, f"parse error: nested deeper than {MAX_DEPTH} levels")
        # "\ud800" alone decodes to a str no UTF-8 can carry: it would break whatever shows
        # or sends it on (the robot's page, the channel layer). Looked for only after a \u.
        if b"\\u" in line and _lone_surrogate(message):
            return _error(None, PARSE_ERROR, "parse error: a lone surrogate (\\ud800-\\udfff)")
        if isinstance(message, list):
            if not message:
                return _error(None, INVALID_REQUEST, "empty batch")
            if len(message) > MAX_BATCH:
                return _error(None, INVALID_REQUEST, f"batch of more than {MAX_BATCH} requests")
            return await self._batch(session, message)
        return await self.handle_request(session, message)

    async def handle_request(self, session: Session, request):
        if not isinstance(request, dict) or request.get("jsonrpc") != "2.0":
            return _error(
                None, INVALID_REQUEST, 'invalid request: expected {"jsonrpc": "2.0", ...}'
            )
        req_id = request.get("id")
        method = request.get("method")
        params = request.get("params", [])
        if not isinstance(method, str) or not isinstance(params, list | dict):
            return _error(req_id, INVALID_REQUEST, "invalid request: method must be a string")
        try:
            result = await self.handler(session, method, params)
        except RpcError as exc:
            reply = {"jsonrpc": "2.0", "id": req_id, "error": exc.as_json()}
        except Exception as exc:
            _log_unexpected(f"Robot API method {method[:64]!r}", exc)
            reply = _error(req_id, INTERNAL_ERROR, f"internal error in {method[:64]}")
        else:
            reply = {"jsonrpc": "2.0", "id": req_id, "result": result}
        return None if "id" not in request else reply


PEER = "peer"  # a listener several runs share: a connection's run is its peer's (see below)


def peer_pid_namespace(sock) -> str:
    """Which run a Unix connection comes from: the pid namespace of the process at the other
    end (each run's box has its own; the host's processes share the host's)."""
    try:
        creds = sock.getsockopt(socket.SOL_SOCKET, socket.SO_PEERCRED, struct.calcsize("3i"))
        pid = struct.unpack("3i", creds)[0]
        return os.readlink(f"/proc/{pid}/ns/pid")
    except (OSError, AttributeError):  # gone already, or not a socket of ours
        return "unknown"


class _Connection(asyncio.Protocol):
    """One client: requests are answered in order, one at a time.

    A request for a quick method (its handler never needs a task: the sim robot, cached
    readings) runs straight from data_received until it first waits, and is answered at once
    if it never does; others run in a task while later requests queue behind them. Skipping
    a task per request is what makes ten thousand round trips a second possible.
    """

    def __init__(self, server: RobotApiServer, source):
        self.server = server
        self.source = source  # where it comes from: PEER (ask the socket), else its listener
        self.admitted = False
        self.buffer = b""
        self.backlog: deque[bytes] = deque()
        self.busy = False
        self.write_paused = False
        self.read_paused = False

    def connection_made(self, transport) -> None:
        self.transport = transport
        sock = transport.get_extra_info("socket")
        if self.source is PEER:
            self.source = peer_pid_namespace(sock)
        if not self.server.admit(self.source):
            transport.abort()
            return
        self.admitted = True
        if sock is not None and sock.family != socket.AF_UNIX:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        self.session = Session(transport.get_extra_info("peername"))
        self.server._connections.add(self)

    def connection_lost(self, exc) -> None:
        if not self.admitted:
            return
        self.server.release(self.source)
        self.server._connections.discard(self)
        self.backlog.clear()
        if self.server.closed is not None:
            try:
                self.server.closed(self.session)
            except Exception as error:
                _log_unexpected("Robot API connection close", error)

    def pause_writing(self) -> None:  # a client that does not read its replies: stop reading
        self.write_paused = True
        self.flow()

    def resume_writing(self) -> None:
        self.write_paused = False
        self.answer_backlog()  # what waited for the client to read its replies
        self.flow()

    def flow(self) -> None:
        """Read on only while replies go out and no request waits behind a slow one: what a
        client sends ahead waits in the kernel's socket buffer, not in ours."""
        pause = self.write_paused or bool(self.backlog)
        if pause != self.read_paused and not self.transport.is_closing():
            self.read_paused = pause
            if pause:
                self.transport.pause_reading()
            else:
                self.transport.resume_reading()

    def data_received(self, data: bytes) -> None:
        *lines, self.buffer = (self.buffer + data).split(b"\n")
        if len(self.buffer) > MAX_REQUEST_BYTES:  # no end in sight: out of step for good
            self.send(_error(None, INVALID_REQUEST, "request too large"))
            self.transport.close()
            return
        self.backlog.extend(line for line in lines if line.strip())
        self.answer_backlog()
        if self.backlog or self.read_paused:
            self.flow()

    def answer(self, line: bytes):
        if len(line) > MAX_REQUEST_BYTES:
            return _done(_error(None, INVALID_REQUEST, "request too large"))
        return self.server.handle_line(self.session, line)

    def answer_backlog(self) -> None:
        # Not while the client leaves its replies unread: they would pile up here.
        while (
            self.backlog and not self.busy and not self.write_paused
            and not self.transport.is_closing()
        ):  # fmt: skip
            line = self.backlog.popleft()
            work = self.answer(line)
            if not self.server.answers_at_once(line):
                self.busy = True
                asyncio.ensure_future(work).add_done_callback(self.finished)
                continue
            try:
                waiting_on = work.send(None)
            except StopIteration as done:
                self.send(done.value)
                continue
            self.busy = True
            task = asyncio.ensure_future(_finish(work, waiting_on))
            task.add_done_callback(self.finished)

    def finished(self, task: asyncio.Task) -> None:
        self.busy = False
        if not task.cancelled():
            exc = task.exception()  # handle_line never raises; _finish might, if asyncio did
            if exc is None:
                self.send(task.result())
            else:
                _log_unexpected("Robot API request", exc)
                self.send(_error(None, INTERNAL_ERROR, "internal error"))
        self.answer_backlog()
        if self.backlog or self.read_paused:
            self.flow()

    def send(self, reply) -> None:
        if reply is None or self.transport.is_closing():
            return
        try:
            data = _encode(reply).encode()
        except Exception as exc:  # a handler's result that is not JSON: a bug, told as one
            _log_unexpected("Robot API reply", exc)
            req_id = reply.get("id") if isinstance(reply, dict) else None
            data = _encode(_error(req_id, INTERNAL_ERROR, "internal error: a reply not JSON"))
            data = data.encode()
        self.transport.write(data + b"\n")


async def _done(value):
    return value


async def _finish(coro, waiting_on):
    """Drive a coroutine that has already run up to its first wait, as a task would."""
    while True:
        try:
            if waiting_on is None:  # a bare yield, as in asyncio.sleep(0)
                await asyncio.sleep(0)
            else:
                await asyncio.wait([waiting_on])  # its outcome is the coroutine's to read
        except asyncio.CancelledError:
            coro.throw(asyncio.CancelledError())
            raise
        try:
            waiting_on = coro.send(None)
        except StopIteration as done:
            return done.value


def _error(req_id, code: int, message: str) -> dict:
    return {"jsonrpc": "2.0", "id": req_id, "error": {"code": code, "message": message}}


# -- how deep a request nests, found without parsing it ---------------------------------------

# A JSON string, escapes and all (the brackets inside one do not nest anything).
_STRING = re.compile(rb'"[^"\\]*(?:\\.[^"\\]*)*"', re.DOTALL)
_NOT_BRACKETS = bytes(b for b in range(256) if b not in b"[]{}")
# Openers -> 1, closers -> -1 (as a signed byte), for a running sum that is the depth.
_SIGNED = bytes.maketrans(b"[{]}", b"\x01\x01\xff\xff")
_TOO_DEEP_RUN = b"\x01" * (MAX_DEPTH + 1)


def too_deep(line: bytes) -> bool:
    """Whether the JSON text nests arrays and objects deeper than MAX_DEPTH.

    C-speed steps only (count, a regular expression, translate, a running sum), so a
    megabyte line costs milliseconds, however it nests; json.loads would recurse instead.
    """
    if line.count(b"[") + line.count(b"{") <= MAX_DEPTH:  # the usual case: done
        return False
    brackets = _STRING.sub(b"", line).translate(None, _NOT_BRACKETS)
    if len(brackets) <= MAX_DEPTH:
        return False
    signed = brackets.translate(_SIGNED)
    if _TOO_DEEP_RUN in signed:  # "[[[[..." : found without summing
        return True
    return max(accumulate(memoryview(signed).cast("b"))) > MAX_DEPTH


# -- unexpected errors: said, but never a flood of tracebacks ---------------------------------

LOG_BURST = 10  # unexpected errors logged per LOG_PERIOD; the others are counted
LOG_PERIOD = 60.0
_log_window = [0.0, 0, 0]  # when the window began, lines logged in it, lines suppressed
_tracebacks_seen: set[tuple] = set()  # (exception type, where): its traceback logged once


def _log_unexpected(what: str, exc: BaseException) -> None:
    """One log line per unexpected error, at most LOG_BURST a minute; the first error of each
    kind and place gets its traceback (once), the rest one line each."""
    now = time.monotonic()
    if now - _log_window[0] >= LOG_PERIOD:
        _log_window[0], _log_window[1] = now, 0
    if _log_window[1] >= LOG_BURST:
        _log_window[2] += 1
        return
    _log_window[1] += 1
    suppressed, _log_window[2] = _log_window[2], 0
    more = f" ({suppressed} more not logged)" if suppressed else ""
    frames = traceback.extract_tb(exc.__traceback__)
    where = f"{frames[-1].filename}:{frames[-1].lineno}" if frames else "?"
    key = (type(exc), where)
    first = key not in _tracebacks_seen and len(_tracebacks_seen) < 100
    if first:
        _tracebacks_seen.add(key)
    log.error(
        "%s failed: %s: %s (at %s)%s",
        what, type(exc).__name__, str(exc)[:200], where, more,
        exc_info=exc if first else None,
    )  # fmt: skip


def bind_params(params, names: tuple[str, ...], required: int) -> list:
    """Positional or named params -> a list in `names` order, with a clear error if wrong."""
    if isinstance(params, dict):
        unknown = set(params) - set(names)
        if unknown:
            raise RpcError(INVALID_PARAMS, f"unknown parameter(s): {', '.join(sorted(unknown))}")
        values = [params.get(n, _MISSING) for n in names]
    else:
        if len(params) > len(names):
            raise RpcError(INVALID_PARAMS, f"expected at most {len(names)} parameter(s)")
        values = list(params) + [_MISSING] * (len(names) - len(params))
    missing = [n for n, v in zip(names[:required], values, strict=False) if v is _MISSING]
    if missing:
        raise RpcError(INVALID_PARAMS, f"missing parameter(s): {', '.join(missing)}")
    return [None if v is _MISSING else v for v in values]


_MISSING = object()
