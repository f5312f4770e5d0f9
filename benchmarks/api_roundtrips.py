"""Robot API round trips: how many bot.sensors() calls a program gets through per second.

One Python program, run through the appliance like any user program (so in its box: the
run's own namespaces, seccomp filter and account), times `bot.sensors()` calls with the real
client library (programs/clients/python/robot.py) and prints the rate and the per-call
latency; the figures are read from the run's log. Over the Robot API's Unix socket (ROBOT_API,
bound into the box) and over its TCP side inside the run's network namespace (ROBOT_API_TCP,
127.0.0.1:7010, a socket the agent opened there and serves itself).

Baselines, same program file and client, launched from here with the launcher's environment
against a server in a process of its own:
- "canned reply": a bare asyncio.Protocol writing one fixed reply line per request line, no
  JSON-RPC (the floor of a Python server doing a round trip per call on this machine), on a
  Unix socket as the appliance's Robot API for programs by default, and again on TCP
  127.0.0.1 (the floor of the boxed program's TCP side);
- "rpc only": robots.rpc.RobotApiServer answering every call with a fixed sensors dict
  (the JSON-RPC framing, socket and event loop costs alone);
- "RobotApi + sim": the real robots.robot_api.RobotApi over a real sim:// driver, without the
  web server and agent around it (adds the method dispatch and the simulation).
The appliance adds to that sharing its event loop with the web server and the agent.

A virtual machine's speed drifts by a fifth within a minute: every path is measured once per
round, in turn, for ROUNDS rounds; a figure is the median round, its note the range.

Target: >= 10,000 sensors() round trips/s through the appliance.
"""

import asyncio
import json
import re
import subprocess
import sys
import tempfile
from pathlib import Path
from types import SimpleNamespace

from benchmarks.common import (
    Figure,
    appliance,
    print_table,
    say,
)

BENCH = "3 Robot API"
ROUNDS = 5  # each path measured once per round, the paths in turn: a drift hits them all
CALLS = 5_000  # per round and path
TARGET = 10_000
RUN_TIMEOUT = 60.0
TOKEN = "bench-token"
PROGRAM = """\
import os
import sys
import time
import robot

# argv: "tcp" (the Robot API's TCP side in the run's own namespace) or "unix", and the calls
bot = robot.Robot(os.environ["ROBOT_API_TCP"] if sys.argv[1] == "tcp" else None)
for _ in range(500):
    bot.sensors()
N = int(sys.argv[2])
times = []
now = time.perf_counter
t = start = now()
for _ in range(N):
    bot.sensors()
    t2 = now()
    times.append(t2 - t)
    t = t2
total = now() - start
times.sort()
print("RATE %.1f P50 %.6f P99 %.6f" % (N / total, times[N // 2], times[int(N * 0.99)]))
"""
RESULT_RE = re.compile(r"RATE ([\d.]+) P50 ([\d.]+) P99 ([\d.]+)")


def parse(text: str) -> dict | None:
    m = RESULT_RE.search(text)
    if not m:
        return None
    return {"rate": float(m.group(1)), "p50": float(m.group(2)), "p99": float(m.group(3))}


# -- the baseline servers (run in a process of their own: python -m ... serve MODE) ----------


def serve(mode: str, sample: str) -> None:
    import os

    import django

    os.environ.setdefault("DJANGO_SETTINGS_MODULE", "robotide.settings")
    os.environ.setdefault("ROBOTIDE_DATA", tempfile.mkdtemp(prefix="bench-api-data-"))
    django.setup()  # robots.robot_api reaches robots.models

    import rhal
    from robots.agent import ActiveRun
    from robots.robot_api import RobotApi
    from robots.rpc import RobotApiServer, RpcError

    class Echo(asyncio.Protocol):
        """No JSON-RPC at all: one canned reply line per request line."""

        def __init__(self, reply: bytes):
            self.reply, self.buffer = reply, b""

        def connection_made(self, transport):
            self.transport = transport

        def data_received(self, data):
            self.buffer += data
            *lines, self.buffer = self.buffer.split(b"\n")
            self.transport.write(self.reply * len(lines))

    async def main():
        if mode in ("echo", "echo-tcp"):
            loop = asyncio.get_running_loop()
            reply = json.dumps({"jsonrpc": "2.0", "id": 0, "result": json.loads(sample)})
            factory = lambda: Echo(reply.encode() + b"\n")  # noqa: E731
            if mode == "echo-tcp":  # the floor of the boxed program's TCP side
                server = await loop.create_server(factory, "127.0.0.1", 0)
                host, port = server.sockets[0].getsockname()[:2]
                print(f"{host}:{port}", flush=True)
            else:
                path = Path(tempfile.mkdtemp(prefix="bench-")) / "api.sock"
                await loop.create_unix_server(factory, str(path))
                print(f"unix:{path}", flush=True)
            await loop.run_in_executor(None, sys.stdin.read)
            return
        if mode == "rpc":
            fixed = json.loads(sample)
            quick = lambda method: True  # noqa: E731 - its handler never waits

            async def handler(session, method, params):
                if method == "auth":
                    if params != [TOKEN]:
                        raise RpcError(-32001, "invalid token")
                    session.run = True
                    return {"robot": "bench", "run": 0}
                return fixed

        else:
            driver = rhal.connect("sim://")
            await driver.open()
            active = ActiveRun(run_id=0, token=TOKEN, process=None)  # claimed: no claim asked
            agent = SimpleNamespace(name="bench", tokens={TOKEN: active}, shows={}, driver=driver)
            api = RobotApi(agent)
            handler, quick = api.handle, api.quick
        # The same transport as the appliance gives programs: a Unix socket.
        folder = Path(tempfile.mkdtemp(prefix="bench-"))
        server = RobotApiServer(handler, unix_path=folder / "s", quick=quick)
        await server.start()
        print(server.url, flush=True)
        await asyncio.get_running_loop().run_in_executor(None, sys.stdin.read)  # until EOF

    asyncio.run(main())


class Baseline:
    """A baseline server in a process of its own (``serve MODE``), kept for all the rounds."""

    def __init__(self, mode: str, sample: str):
        self.server = subprocess.Popen(
            [sys.executable, "-m", "benchmarks.api_roundtrips", "serve", mode, sample],
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
        self.address = self.server.stdout.readline().strip()

    def measure(self, file: Path, work: Path) -> dict | None:
        """One round: the program, launched from here with the launcher's environment."""
        from programs.languages import get_language
        from runbox import launcher

        language = get_language("python")
        tcp = self.address.startswith("127.0.0.1:")
        variable = "ROBOT_API_TCP" if tcp else "ROBOT_API"
        env = launcher.environment(language, work, {variable: self.address, "ROBOT_TOKEN": TOKEN})
        done = subprocess.run(
            [*language.command(str(file)), "tcp" if tcp else "unix", str(CALLS)],
            env=env,
            cwd=work,
            capture_output=True,
            text=True,
            timeout=RUN_TIMEOUT,
        )
        result = parse(done.stdout)
        if result is None:
            say(f"[{BENCH}] baseline at {self.address} printed: {done.stdout!r} {done.stderr!r}")
        return result

    def close(self) -> None:
        self.server.stdin.close()
        try:
            self.server.wait(timeout=5)
        except subprocess.TimeoutExpired:
            self.server.kill()


def through_appliance(app, program_id: int, transport: str) -> dict | None:
    """One round: the program run through the appliance, in its box; figures from its log."""
    response = app.api(
        "POST",
        f"/api/programs/{program_id}/run",
        {"robot": "sim", "args": [transport, str(CALLS)]},
    )
    response.raise_for_status()
    run_id = response.json()["id"]
    ended = app.wait_run(run_id, timeout=RUN_TIMEOUT)
    log = (app.data_dir / "runs" / str(run_id) / "output.log").read_text()
    result = parse(log)
    if result is None:
        say(f"[{BENCH}] the run ended {ended['state']} ({ended['reason']}):\n{log[-2000:]}")
    return result


def middle(results: list[dict | None]) -> tuple[dict | None, str]:
    """The round with the median rate, and the rounds' range (a note)."""
    done = sorted((r for r in results if r), key=lambda r: r["rate"])
    if not done:
        return None, "no result"
    spread = f"{len(done)} rounds: {done[0]['rate']:,.0f}–{done[-1]['rate']:,.0f} calls/s"
    return done[len(done) // 2], spread


def latency_note(result: dict | None) -> str:
    if not result:
        return "no result"
    p50, p99 = result["p50"] * 1e6, result["p99"] * 1e6
    return f"latency per call: median {p50:.0f} µs, p99 {p99:.0f} µs"


def run() -> list[Figure]:
    with tempfile.TemporaryDirectory(prefix="robotide-bench-api-") as work:
        return measure(Path(work))


BASELINES = {  # mode: (label, transport of the appliance's figure it is compared with)
    "echo": ("baseline: canned reply per line, asyncio Protocol, no JSON-RPC", "unix"),
    "echo-tcp": ("baseline: the same canned reply over TCP 127.0.0.1", "tcp"),
    "rpc": ("baseline: rpc server only, fixed reply", "unix"),
    "api": ("baseline: RobotApi + sim driver, no web tier", "unix"),
}
APPLIANCE = {
    "unix": "sensors() round trips/s, boxed program, Unix socket",
    "tcp": "sensors() round trips/s, boxed program, TCP 127.0.0.1:7010 in its namespace",
}


def measure(work: Path) -> list[Figure]:
    file = work / "calls.py"
    file.write_text(PROGRAM)
    rounds: dict[str, list[dict | None]] = {key: [] for key in [*APPLIANCE, *BASELINES]}
    with appliance("api") as app:
        sample = json.dumps(app.api("GET", "/api/robots/sim/sensors").json())
        program = app.create_program("bench sensors calls", PROGRAM)
        servers = {mode: Baseline(mode, sample) for mode in BASELINES}
        try:
            say(
                f"[{BENCH}] {ROUNDS} rounds of {CALLS:,} sensors() calls per path: through the"
                f" appliance (Unix, TCP), then the baselines ({', '.join(BASELINES)})"
            )
            for _ in range(ROUNDS):
                for transport in APPLIANCE:
                    rounds[transport].append(through_appliance(app, program["id"], transport))
                for mode, server in servers.items():
                    rounds[mode].append(server.measure(file, work))
        finally:
            for server in servers.values():
                server.close()
    return figures_of(rounds, sample)


def figures_of(rounds: dict[str, list[dict | None]], sample: str) -> list[Figure]:
    figures: list[Figure] = []
    rates: dict[str, float | None] = {}
    for transport, label in APPLIANCE.items():
        result, spread = middle(rounds[transport])
        value = rates[transport] = result and result["rate"]
        note = f"median of {spread}; payload {len(sample)} bytes of JSON"
        ok = value is not None and value >= TARGET
        figures.append(Figure(BENCH, label, value, "calls/s", f">= {TARGET:,}", ok, note))
        if result:
            figures.append(Figure(BENCH, "  latency per call, median", result["p50"] * 1e6, "us"))
            figures.append(Figure(BENCH, "  latency per call, p99", result["p99"] * 1e6, "us"))
    for mode, (label, transport) in BASELINES.items():
        result, spread = middle(rounds[mode])
        value = result and result["rate"]
        note = f"median of {spread}; {latency_note(result)}"
        figures.append(Figure(BENCH, label, value, "calls/s", note=note))
        if value and rates[transport]:
            name = f"  appliance ({'TCP' if transport == 'tcp' else 'Unix'}) / this baseline"
            figures.append(Figure(BENCH, name, rates[transport] / value, "x"))
    return figures


if __name__ == "__main__":
    if sys.argv[1:2] == ["serve"]:
        serve(sys.argv[2], sys.argv[3])
    else:
        print_table(run())
