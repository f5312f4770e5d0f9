"""A Robot API peer for the debuggee's tests, written from programs/clients/PROTOCOL.md (not
from the agent): JSON-RPC 2.0 lines over a Unix socket, `auth`, a robot driving at a wall
(`sensors`, `drive`, `stop`, `show`), and the debugger's methods scripted by the test: each
`debug_paused` state goes to `pauses`, and waits for the test's `answer`; `debug_poll` records
the line and returns what the test gave `change`.
"""

import json
import queue
import shutil
import socketserver
import tempfile
import threading

from tests.waiting import DEADLINE

TOKEN = "debug-token"
CLOSE = "(close the connection)"  # answer(CLOSE): the run ends during the pause


class Peer:
    def __init__(self, spec=None, report_line=None, start=2.0, step=0.01):
        self.folder = tempfile.mkdtemp(prefix="peer")  # a short path: a socket's is at most 107
        self.path = f"{self.folder}/api.sock"
        self.spec = {"breakpoints": [], "watches": [], **(spec or {})}
        self.report_line = report_line
        self.range, self.step = start, step  # the wall comes nearer at each sensors()
        self.pauses = queue.Queue()  # the states of debug_paused, in order
        self.answers = queue.Queue()  # the test's commands for them
        self.changes = queue.Queue()  # what debug_poll returns next
        self.lines = queue.Queue()  # the lines debug_poll was told
        self.calls = []  # (method, params) of every call
        self.sizes = []  # bytes of each debug_paused request
        self.started = False
        self.lock = threading.Lock()
        self.server = _Server(self.path, _Connection)
        self.server.peer = self
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    @property
    def environment(self):
        return {"ROBOT_API": f"unix:{self.path}", "ROBOT_TOKEN": TOKEN}

    def close(self):
        self.server.shutdown()
        self.server.server_close()
        shutil.rmtree(self.folder, ignore_errors=True)

    # -- the test's side -----------------------------------------------------------------

    def paused(self, timeout=DEADLINE) -> dict:
        """The next pause's state (the debuggee waits for `answer`)."""
        return self.pauses.get(timeout=timeout)

    def answer(self, command, breakpoints=None, watches=None):
        with self.lock:
            if breakpoints is not None:
                self.spec["breakpoints"] = breakpoints
            if watches is not None:
                self.spec["watches"] = watches
        self.answers.put(command)

    def change(self, breakpoints=None, watches=None, pause=False):
        """What the next debug_poll returns."""
        with self.lock:
            if breakpoints is not None:
                self.spec["breakpoints"] = breakpoints
            if watches is not None:
                self.spec["watches"] = watches
            self.changes.put({**self.now(), "pause": pause})

    def now(self):
        return {"breakpoints": self.spec["breakpoints"], "watches": self.spec["watches"]}

    def called(self, method):
        return [params for name, params in self.calls if name == method]

    # -- the methods -----------------------------------------------------------------------

    def sensors(self):
        with self.lock:
            self.range = max(self.range - self.step, 0.0)
            return {"heading": 0.0, "range": round(self.range, 4), "position": {"x": 0, "y": 0}}

    def debug_start(self):
        if self.started:
            raise _Refused("debug_start was called already")
        self.started = True
        return {**self.now(), "file": "program.py", "report_line": self.report_line}

    def debug_paused(self, state):
        self.pauses.put(state)
        command = self.answers.get(timeout=DEADLINE)
        if command == CLOSE:
            raise _Closed
        with self.lock:
            return {"command": command, **self.now()}

    def debug_poll(self, line, timeout):
        if not isinstance(timeout, int | float) or not 0 <= timeout <= 5:
            raise _Refused("timeout must be 0 to 5 seconds", -32602)
        self.lines.put(line)
        try:
            return self.changes.get(timeout=timeout)
        except queue.Empty:
            return None

    def call(self, method, params):
        self.calls.append((method, params))
        if method == "sensors":
            return self.sensors()
        if method == "sensor":
            return self.sensors()[params[0]]
        if method == "drive":
            return {"linear": params[0], "angular": params[1] if len(params) > 1 else 0.0}
        if method in ("stop", "show"):
            return None
        if method in ("debug_start", "debug_paused", "debug_poll"):
            return getattr(self, method)(*params)
        raise _Refused(f"no such method: {method}", -32601)


class _Refused(Exception):
    def __init__(self, message, code=-32000):
        super().__init__(message)
        self.code = code


class _Closed(Exception):
    pass


class _Server(socketserver.ThreadingUnixStreamServer):
    daemon_threads = True


class _Connection(socketserver.StreamRequestHandler):
    def handle(self):
        peer = self.server.peer
        try:
            self.serve(peer)
        except (OSError, _Closed):
            pass  # the debuggee ended, or the test ended the connection

    def serve(self, peer):
        signed_in = False
        for line in self.rfile:
            request = json.loads(line)
            reply = {"jsonrpc": "2.0", "id": request["id"]}
            method, params = request["method"], request.get("params", [])
            try:
                if method == "auth":
                    if signed_in or params != [TOKEN]:
                        raise _Refused("bad token or signed in already", -32600)
                    signed_in = True
                    reply["result"] = {"robot": "peer", "run": 1}
                elif not signed_in:
                    raise _Refused("not authenticated", -32001)
                else:
                    if method == "debug_paused":
                        peer.sizes.append(len(line))
                        if len(json.dumps(params[0])) > 256 * 1024:
                            raise _Refused("the state is over 256 KB", -32602)
                    reply["result"] = peer.call(method, params)
            except _Refused as refused:
                reply["error"] = {"code": refused.code, "message": str(refused)}
            try:
                self.wfile.write(json.dumps(reply).encode() + b"\n")
            except OSError:
                return
