"""A scripted debuggee: the debugger's side of the protocol (programs/clients/PROTOCOL.md, "The
debugger") spoken by a test, step by step, instead of bdb's (clients/python/robot_debug.py).

Standard library only, and self-contained: a test uses it over the agent's socket with a run's
token, or puts its text at the top of a run's program to speak from inside the box (conftest's
CLIENT_SOURCE).
"""

import json
import os
import socket

STATE_KEYS = ("reason", "line", "function", "stack", "locals", "globals", "watches", "exception")


class RpcError(Exception):
    def __init__(self, code, message):
        super().__init__(f"{code}: {message}")
        self.code, self.message = code, message


class Peer:
    """One signed-in connection to the Robot API (a debugger opens its own)."""

    def __init__(self, address=None, token=None):
        address = address or os.environ["ROBOT_API"]
        if address.startswith("unix:"):
            self.sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
            self.sock.connect(address[len("unix:") :])
        else:
            host, port = address.rsplit(":", 1)
            self.sock = socket.create_connection((host, int(port)))
        self.file = self.sock.makefile("rwb")
        self.ids = 0
        self.signed_in = self.call("auth", token or os.environ["ROBOT_TOKEN"])

    def call(self, method, *params):
        """The method's result; RpcError for an error reply, EOFError if the agent closed
        the connection (the run ended)."""
        self.ids += 1
        request = {"jsonrpc": "2.0", "id": self.ids, "method": method, "params": list(params)}
        self.file.write(json.dumps(request).encode() + b"\n")
        self.file.flush()
        line = self.file.readline()
        if not line:
            raise EOFError("the Robot API closed the connection")
        reply = json.loads(line)
        if "error" in reply:
            raise RpcError(reply["error"]["code"], reply["error"]["message"])
        return reply["result"]

    def error_of(self, method, *params):
        """The error code a call answers (None if it succeeds)."""
        try:
            self.call(method, *params)
        except RpcError as exc:
            return exc.code
        return None

    def close(self):
        self.file.close()
        self.sock.close()


def state(line, reason="breakpoint", **more):
    """A pause's state as the protocol shapes it."""
    variable = {"name": "distance", "type": "float", "value": "1.93", "children": None, "more": 0}
    made = {
        "reason": reason,
        "line": line,
        "function": "<module>",
        "stack": [{"function": "<module>", "line": line}],
        "locals": [],
        "globals": [variable],
        "watches": [],
        "exception": None,
    }
    made.update(more)
    return made
