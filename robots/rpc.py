"""The Robot API: JSON-RPC 2.0, one JSON object per line, over a local TCP socket.

A program connects to ``$ROBOT_API`` (host:port), calls ``auth`` with ``$ROBOT_TOKEN`` and may
then call the robot's methods. A token is only worth something while its run is alive. TCP on
the loopback interface because every language's standard library speaks it (Tcl has no Unix
sockets).
"""

import asyncio
import json
import logging
import socket
from collections.abc import Awaitable, Callable
from typing import Any

log = logging.getLogger(__name__)

PARSE_ERROR = -32700
INVALID_REQUEST = -32600
METHOD_NOT_FOUND = -32601
INVALID_PARAMS = -32602
INTERNAL_ERROR = -32603
ROBOT_ERROR = -32000
UNAUTHORIZED = -32001
LEASE_HELD = -32002

MAX_REQUEST_BYTES = 1024 * 1024


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

    __slots__ = ("run", "peer")

    def __init__(self, peer):
        self.run = None
        self.peer = peer


# handler(session, method, params) -> result; raises RpcError for a clean error reply
Handler = Callable[[Session, str, Any], Awaitable[Any]]


class RobotApiServer:
    def __init__(self, handler: Handler, host: str = "127.0.0.1", port: int = 0):
        self.handler = handler
        self.host, self.port = host, port
        self._server: asyncio.base_events.Server | None = None
        self._connections: set[asyncio.StreamWriter] = set()

    @property
    def address(self) -> str:
        host, port = self._server.sockets[0].getsockname()[:2]
        return f"{host}:{port}"

    async def start(self) -> str:
        self._server = await asyncio.start_server(
            self._serve, self.host, self.port, limit=MAX_REQUEST_BYTES
        )
        return self.address

    async def close(self) -> None:
        if self._server is None:
            return
        self._server.close()
        for writer in list(self._connections):
            writer.close()
        await self._server.wait_closed()
        self._server = None

    async def _serve(self, reader: asyncio.StreamReader, writer: asyncio.StreamWriter) -> None:
        sock = writer.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        session = Session(writer.get_extra_info("peername"))
        self._connections.add(writer)
        try:
            while True:
                try:
                    line = await reader.readline()
                except ValueError:  # longer than the limit: the stream is no longer in step
                    await self._send(writer, _error(None, INVALID_REQUEST, "request too large"))
                    break
                if not line:
                    break
                if not line.strip():
                    continue
                reply = await self.handle_line(session, line)
                if reply is not None:
                    await self._send(writer, reply)
        except (ConnectionError, asyncio.IncompleteReadError):
            pass
        finally:
            self._connections.discard(writer)
            writer.close()

    @staticmethod
    async def _send(writer: asyncio.StreamWriter, reply) -> None:
        writer.write(json.dumps(reply, separators=(",", ":")).encode() + b"\n")
        await writer.drain()

    async def handle_line(self, session: Session, line: bytes):
        try:
            message = json.loads(line)
        except (ValueError, UnicodeDecodeError) as exc:
            return _error(None, PARSE_ERROR, f"parse error: {exc}")
        if isinstance(message, list):
            if not message:
                return _error(None, INVALID_REQUEST, "empty batch")
            replies = [await self.handle_request(session, m) for m in message]
            return [r for r in replies if r is not None] or None
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
        except Exception:
            log.exception("Robot API method %s failed", method)
            reply = _error(req_id, INTERNAL_ERROR, f"internal error in {method}")
        else:
            reply = {"jsonrpc": "2.0", "id": req_id, "result": result}
        return None if "id" not in request else reply


def _error(req_id, code: int, message: str) -> dict:
    return {"jsonrpc": "2.0", "id": req_id, "error": {"code": code, "message": message}}


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
