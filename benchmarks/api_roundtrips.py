"""Robot API round trips: how many bot.sensors() calls a program gets through per second.

One Python program, run through the appliance like any user program (so in its box: the
run's own namespaces, seccomp filter and account), times 20,000 `bot.sensors()` calls with the
real client library (programs/clients/python/robot.py) and prints the rate and the per-call
latency; the figures are read from the run's log. Twice: over the Robot API's Unix socket
(ROBOT_API, bound into the box) and over its TCP side inside the run's network namespace
(ROBOT_API_TCP, 127.0.0.1:7010, a socket the agent opened there and serves itself).

Baselines, same run, same program file and client, launched from here with the launcher's
environment against a Robot API server in a process of its own:
- "canned reply": a bare asyncio.Protocol writing one fixed reply line per request line, no
  JSON-RPC (the floor of a Python server doing a round trip per call on this machine);
  all baselines listen on a Unix socket, as the appliance's Robot API does for programs;
- "rpc only": robots.rpc.RobotApiServer answering every call with a fixed sensors dict
  (the JSON-RPC framing, socket and event loop costs alone);
- "RobotApi + sim": the real robots.robot_api.RobotApi over a real sim:// driver, without the
  web server and agent around it (adds the method dispatch and the simulation).
The appliance adds to that sharing its event loop with the web server and the agent.

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
CALLS = 20_000
TARGET = 10_000
RUN_TIMEOUT = 60.0
TOKEN = "bench-token"
PROGRAM = f"""\
import os
import sys
import time
import robot

# argv[1] "tcp": the Robot API's TCP side in the run's own namespace; else its Unix socket
bot = robot.Robot(os.environ["ROBOT_API_TCP"] if sys.argv[1:] == ["tcp"] else None)
for _ in range(500):
    bot.sensors()
N = {CALLS}
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
        if mode == "echo":
            loop = asyncio.get_running_loop()
            reply = json.dumps({"jsonrpc": "2.0", "id": 0, "result": json.loads(sample)})
            path = Path(tempfile.mkdtemp(prefix="bench-")) / "api.sock"
            await loop.create_unix_server(lambda: Echo(reply.encode() + b"\n"), str(path))
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


def baseline(mode: str, sample: str, file: Path, work: Path) -> dict | None:
    from programs.languages import get_language
    from runbox import launcher

    server = subprocess.Popen(
        [sys.executable, "-m", "benchmarks.api_roundtrips", "serve", mode, sample],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        address = server.stdout.readline().strip()
        language = get_language("python")
        env = launcher.environment(language, work, {"ROBOT_API": address, "ROBOT_TOKEN": TOKEN})
        done = subprocess.run(
            language.command(str(file)),
            env=env,
            cwd=work,
            capture_output=True,
            text=True,
            timeout=RUN_TIMEOUT,
        )
        result = parse(done.stdout)
        if result is None:
            say(f"[{BENCH}] baseline {mode} printed: {done.stdout!r} {done.stderr!r}")
        return result
    finally:
        server.stdin.close()
        try:
            server.wait(timeout=5)
        except subprocess.TimeoutExpired:
            server.kill()


def latency_note(result: dict | None) -> str:
    if not result:
        return "no result"
    p50, p99 = result["p50"] * 1e6, result["p99"] * 1e6
    return f"latency per call: median {p50:.0f} µs, p99 {p99:.0f} µs"


def run() -> list[Figure]:
    with tempfile.TemporaryDirectory(prefix="robotide-bench-api-") as work:
        return measure(Path(work))


def measure(work: Path) -> list[Figure]:
    figures: list[Figure] = []
    file = work / "calls.py"
    file.write_text(PROGRAM)
    through: dict[str, dict | None] = {}
    with appliance("api") as app:
        sample = json.dumps(app.api("GET", "/api/robots/sim/sensors").json())
        program = app.create_program("bench sensors calls", PROGRAM)
        for transport in ("unix", "tcp"):
            say(f"[{BENCH}] {CALLS:,} sensors() calls through the appliance ({transport})")
            response = app.api(
                "POST", f"/api/programs/{program['id']}/run", {"robot": "sim", "args": [transport]}
            )
            response.raise_for_status()
            run_id = response.json()["id"]
            ended = app.wait_run(run_id, timeout=RUN_TIMEOUT)
            log = (app.data_dir / "runs" / str(run_id) / "output.log").read_text()
            through[transport] = parse(log)
            if through[transport] is None:
                say(f"[{BENCH}] the run ended {ended['state']} ({ended['reason']}):\n{log[-2000:]}")
    say(f"[{BENCH}] baselines: canned echo, rpc only, RobotApi + sim")
    echo = baseline("echo", sample, file, work)
    rpc_only = baseline("rpc", sample, file, work)
    api_sim = baseline("api", sample, file, work)

    for transport, label in (
        ("unix", "sensors() round trips/s, boxed program, Unix socket"),
        ("tcp", "sensors() round trips/s, boxed program, TCP 127.0.0.1:7010 in its namespace"),
    ):
        result = through[transport]
        value = result and result["rate"]
        figures.append(
            Figure(
                BENCH,
                label,
                value,
                "calls/s",
                f">= {TARGET:,}",
                value is not None and value >= TARGET,
                f"payload {len(sample)} bytes of JSON; {CALLS:,} calls",
            )
        )
        if result:
            figures.append(Figure(BENCH, "  latency per call, median", result["p50"] * 1e6, "us"))
            figures.append(Figure(BENCH, "  latency per call, p99", result["p99"] * 1e6, "us"))
    rate = through["unix"] and through["unix"]["rate"]
    for label, result in (
        ("baseline: canned reply per line, asyncio Protocol, no JSON-RPC", echo),
        ("baseline: rpc server only, fixed reply", rpc_only),
        ("baseline: RobotApi + sim driver, no web tier", api_sim),
    ):
        value = result and result["rate"]
        figures.append(Figure(BENCH, label, value, "calls/s", note=latency_note(result)))
        if value and rate:
            figures.append(Figure(BENCH, "  appliance (Unix) / this baseline", rate / value, "x"))
    return figures


if __name__ == "__main__":
    if sys.argv[1:2] == ["serve"]:
        serve(sys.argv[2], sys.argv[3])
    else:
        print_table(run())
