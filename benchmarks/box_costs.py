"""What a run's box costs the agent: memory per concurrent run, and the relays to host services.

Memory: one appliance; the `robotide up` process (web tier and agent in one, embedded mode)
with 0, 10 and 20 concurrent idle boxed runs on its sim robot (a Python program that prints a
line and sleeps), each step measured once every run of it printed and ~2 s later: VmRSS, PSS
(smaps_rollup), open fds and threads of the server; the marginal cost per run is the growth
over the step divided by the runs added. For context, the PSS of one run's own processes
(bubblewrap's outside and inside processes, the program), and the server once all are stopped.

Relays (runbox/relays.py `relay_to_host`): a TCP and a UDP echo service on the host's
127.0.0.1 (a process of their own), reached by a Python program from inside a real box
(runbox.box.make_box with the two relays as listeners, runbox.supervisor.RunProcess, as the
agent's `_launch`; the relays served by this process's event loop, with nothing else on it)
and, as the baseline measured in the same run, by the same program unboxed on the host's
loopback: TCP round trips (64 bytes), TCP bulk (32 MB each way at once, 64 KB writes), UDP
round trips (64 bytes), UDP burst (5,000 datagrams of 512 bytes sent back to back: how many
echoes came back and how fast).
"""

import asyncio
import contextlib
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from functools import partial
from pathlib import Path

from benchmarks.common import (
    MB,
    Figure,
    api_client,
    appliance,
    median,
    print_table,
    proc_rollup,
    proc_status,
    runs_dir,
    say,
    server_pid,
)

BENCH = "9 box costs"
STEPS = (0, 10, 20)
SETTLE = 2.0
IDLE = "import time\nprint('up', flush=True)\ntime.sleep(600)\n"
RUN_TIMEOUT = 30.0

CLIENT = r"""
import socket, sys, threading, time
tcp_port, udp_port = int(sys.argv[1]), int(sys.argv[2])
now = time.perf_counter

def pct(values, p):
    values = sorted(values)
    return values[min(len(values) - 1, int(len(values) * p))]

def report(name, n, total, lat=None, extra=""):
    line = f"RESULT {name} n={n} seconds={total:.6f}"
    if lat:
        line += f" p50={pct(lat, 0.5):.7f} p99={pct(lat, 0.99):.7f}"
    print(line + extra, flush=True)

N = 5000
s = socket.create_connection(("127.0.0.1", tcp_port))
s.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
msg = b"x" * 63 + b"\n"
for _ in range(200):
    s.sendall(msg); s.recv(4096)
lat = []
t0 = t = now()
for _ in range(N):
    s.sendall(msg)
    got = s.recv(4096)
    while len(got) < 64:
        got += s.recv(4096)
    t2 = now(); lat.append(t2 - t); t = t2
report("tcp_rtt", N, now() - t0, lat)

SIZE = 32 * 1024 * 1024
chunk = b"y" * 65536
def send():
    sent = 0
    while sent < SIZE:
        s.sendall(chunk); sent += len(chunk)
t0 = now()
th = threading.Thread(target=send); th.start()
got = 0
while got < SIZE:
    data = s.recv(1 << 20)
    if not data:
        break
    got += len(data)
th.join()
report("tcp_bulk", got, now() - t0)
s.close()

u = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
u.connect(("127.0.0.1", udp_port))
u.settimeout(1.0)
for _ in range(200):
    u.send(msg); u.recv(4096)
lat, lost = [], 0
t0 = t = now()
for _ in range(N):
    u.send(msg)
    try:
        u.recv(4096)
    except socket.timeout:
        lost += 1
    t2 = now(); lat.append(t2 - t); t = t2
report("udp_rtt", N, now() - t0, lat, f" lost={lost}")

B = 5000
u.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
u.settimeout(0.5)
data = b"z" * 512
t0 = now()
back = 0
def recv():
    global back, t_last
    while True:
        try:
            u.recv(4096)
        except socket.timeout:
            return
        back += 1; t_last = now()
t_last = t0
th = threading.Thread(target=recv); th.start()
for _ in range(B):
    u.send(data)
th.join()
report("udp_burst", back, t_last - t0, extra=f" sent={B}")
"""
RESULT_RE = re.compile(r"RESULT (\w+) n=(\d+) seconds=([\d.]+)(?: p50=([\d.]+) p99=([\d.]+))?")


def parse(text: str) -> dict[str, dict]:
    found = {}
    for m in RESULT_RE.finditer(text):
        found[m.group(1)] = {
            "n": int(m.group(2)),
            "seconds": float(m.group(3)),
            "p50": m.group(4) and float(m.group(4)),
            "p99": m.group(5) and float(m.group(5)),
        }
    return found


# -- the host's services (python -m benchmarks.box_costs echo) ------------------------------


def echo_services() -> None:
    async def main():
        loop = asyncio.get_running_loop()

        async def echo(reader, writer):
            with contextlib.suppress(ConnectionError):
                while data := await reader.read(65536):
                    writer.write(data)
                    await writer.drain()
            writer.close()

        server = await asyncio.start_server(echo, "127.0.0.1", 0)

        class Udp(asyncio.DatagramProtocol):
            def connection_made(self, transport):
                self.transport = transport

            def datagram_received(self, data, addr):
                self.transport.sendto(data, addr)

        udp, _ = await loop.create_datagram_endpoint(Udp, local_addr=("127.0.0.1", 0))
        tcp_port = server.sockets[0].getsockname()[1]
        print(json.dumps({"tcp": tcp_port, "udp": udp.get_extra_info("sockname")[1]}), flush=True)
        await loop.run_in_executor(None, sys.stdin.read)

    asyncio.run(main())


async def boxed_client(work: Path, tcp: int, udp: int) -> tuple[str, str]:
    """The client program in a box whose 127.0.0.1 TCP and UDP ports are relays to the host's."""
    from programs.languages import CLIENTS_DIR, get_language
    from runbox import SYSTEM_PATH, launcher, seccomp
    from runbox.box import Launch, Listener, make_box
    from runbox.isolation import Policy
    from runbox.relays import relay_to_host
    from runbox.supervisor import RunProcess
    from runbox.watch import RunWatch

    language = get_language("python")
    in_force = Policy().resolve(CLIENTS_DIR)
    limits = launcher.Limits()
    sockets = work / "sockets"
    sockets.mkdir(exist_ok=True)
    services = [f"tcp:{tcp}", f"udp:{udp}"]
    box = make_box(
        in_force, socket_dir=sockets, disk_mb=limits.disk_mb,
        seccomp_fd=seccomp.open_filter_fd(),
        listeners=[Listener(s, partial(relay_to_host, s)) for s in services],
    )  # fmt: skip
    program = in_force.home() / "client.py"
    argv = [*language.command(str(program)), str(tcp), str(udp)]
    env = launcher.environment(language, in_force.home(), {}, clients_dir=in_force.clients())
    launch = Launch(
        "client.py",
        CLIENT.encode(),
        in_force.program_command(argv, in_force.uid(1, str(work))),
        env,
    )
    process = RunProcess(
        box.command(), env={"PATH": SYSTEM_PATH}, cwd=work, log_path=work / "boxed.log",
        on_output=lambda *_: None, watch=RunWatch(limits, box), box=box,
    )  # fmt: skip
    await process.start(launch=launch)
    try:
        outcome = await asyncio.wait_for(process.wait(), 120)
    finally:
        await box.close()
    return (work / "boxed.log").read_text(), f"{outcome.state} ({outcome.reason})"


def measure_relays(work: Path) -> list[Figure]:
    from programs.languages import get_language
    from runbox import launcher

    services = subprocess.Popen(
        [sys.executable, "-m", "benchmarks.box_costs", "echo"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
        text=True,
    )
    try:
        ports = json.loads(services.stdout.readline())
        tcp, udp = ports["tcp"], ports["udp"]
        file = work / "client.py"
        file.write_text(CLIENT)
        language = get_language("python")
        say(f"[{BENCH}] relays: the client unboxed, then boxed, then unboxed again")
        direct, boxed = [], []
        for _ in range(2):
            done = subprocess.run(
                [*language.command(str(file)), str(tcp), str(udp)],
                env=launcher.environment(language, work, {}),
                capture_output=True,
                text=True,
                timeout=120,
            )
            direct.append(parse(done.stdout))
            if len(boxed) < 1:
                log, outcome = asyncio.run(boxed_client(work, tcp, udp))
                boxed.append(parse(log))
                if not boxed[-1]:
                    say(f"[{BENCH}] the boxed client ended {outcome}:\n{log[-2000:]}")
    finally:
        services.stdin.close()
        services.wait(timeout=10)
    return relay_figures(direct, boxed[0])


def relay_figures(direct: list[dict], boxed: dict) -> list[Figure]:
    figures = []

    def best(name, key):
        values = [d[name][key] for d in direct if name in d and d[name][key] is not None]
        return median(values) if values else None

    for name, label in (
        ("tcp_rtt", "TCP round trips (64 B)"),
        ("udp_rtt", "UDP round trips (64 B)"),
    ):
        b = boxed.get(name)
        rate = b and b["n"] / b["seconds"]
        d_rate = median([d[name]["n"] / d[name]["seconds"] for d in direct if name in d])
        note = (
            f"latency median {b['p50'] * 1e6:.0f} µs, p99 {b['p99'] * 1e6:.0f} µs; direct:"
            f" median {best(name, 'p50') * 1e6:.0f} µs, p99 {best(name, 'p99') * 1e6:.0f} µs"
            f" (n={b['n']} each)"
            if b
            else "no result"
        )
        figures.append(Figure(BENCH, f"relay, {label}: boxed, per s", rate, "calls/s", note=note))
        figures.append(Figure(BENCH, f"  {label}: direct loopback, per s", d_rate, "calls/s"))
        if rate:
            figures.append(Figure(BENCH, "  relayed / direct", rate / d_rate, "x"))
    b = boxed.get("tcp_bulk")
    d = median([d["tcp_bulk"]["n"] / d["tcp_bulk"]["seconds"] for d in direct if "tcp_bulk" in d])
    value = b and b["n"] / b["seconds"] / MB
    figures.append(
        Figure(BENCH, "relay, TCP bulk (32 MB each way at once): boxed, MB/s echoed", value, "MB/s")
    )
    figures.append(Figure(BENCH, "  TCP bulk: direct loopback, MB/s echoed", d / MB, "MB/s"))
    if value:
        figures.append(Figure(BENCH, "  relayed / direct", value / (d / MB), "x"))
    b = boxed.get("udp_burst")
    burst = [d["udp_burst"] for d in direct if "udp_burst" in d]
    if b:
        figures.append(
            Figure(
                BENCH,
                "relay, UDP burst of 5,000 x 512 B: boxed, echoes back",
                b["n"],
                "",
                note=f"in {b['seconds'] * 1000:.0f} ms; direct: "
                + ", ".join(f"{x['n']} in {x['seconds'] * 1000:.0f} ms" for x in burst),
            )
        )
    return figures


# -- memory per concurrent run --------------------------------------------------------------


def server_figures(pid: int) -> dict:
    status, rollup = proc_status(pid), proc_rollup(pid)
    return {
        "rss": status["VmRSS"],
        "pss": rollup["Pss"],
        "fds": len(os.listdir(f"/proc/{pid}/fd")),
        "threads": len(os.listdir(f"/proc/{pid}/task")),
    }


def descendants(pid: int) -> list[int]:
    children = {}
    for entry in os.scandir("/proc"):
        if entry.name.isdigit():
            with contextlib.suppress(OSError):
                with open(f"/proc/{entry.name}/stat") as f:
                    ppid = int(f.read().rsplit(")", 1)[1].split()[1])
                children.setdefault(ppid, []).append(int(entry.name))
    found, todo = [], [pid]
    while todo:
        for child in children.get(todo.pop(), []):
            found.append(child)
            todo.append(child)
    return found


def wait_up(app, http, run_ids: list[int]) -> None:
    deadline = time.monotonic() + RUN_TIMEOUT
    waiting = set(run_ids)
    while waiting and time.monotonic() < deadline:
        for run_id in list(waiting):
            log = runs_dir(app) / str(run_id) / "output.log"
            with contextlib.suppress(FileNotFoundError):
                if b"o up" in log.read_bytes():
                    waiting.discard(run_id)
        time.sleep(0.05)
    if waiting:
        raise RuntimeError(f"runs {sorted(waiting)} did not start in {RUN_TIMEOUT:g} s")


def measure_memory() -> list[Figure]:
    figures = []
    with appliance("boxmem") as app:
        http = api_client(app)
        pid = server_pid(app)
        program = app.create_program("bench idle", IDLE)["id"]
        # One run first, stopped: the first run's imports and caches are not a run's cost.
        warm = http.post(f"/api/programs/{program}/run", json={"robot": "sim"}).json()["id"]
        wait_up(app, http, [warm])
        http.post(f"/api/runs/{warm}/stop").raise_for_status()
        app.wait_run(warm)
        time.sleep(SETTLE)
        seen = {0: server_figures(pid)}
        run_ids: list[int] = []
        per_run_pss = []
        for count in STEPS[1:]:
            while len(run_ids) < count:
                response = http.post(f"/api/programs/{program}/run", json={"robot": "sim"})
                response.raise_for_status()
                run_ids.append(response.json()["id"])
            wait_up(app, http, run_ids)
            time.sleep(SETTLE)
            seen[count] = server_figures(pid)
            runs_pss = 0
            for child in descendants(pid):
                with contextlib.suppress(OSError):
                    runs_pss += proc_rollup(child)["Pss"]
            per_run_pss.append(runs_pss / count)
            say(f"[{BENCH}] {count} idle runs: {seen[count]}")
        for run_id in run_ids:
            http.post(f"/api/runs/{run_id}/stop").raise_for_status()
        for run_id in run_ids:
            app.wait_run(run_id)
        time.sleep(SETTLE)
        after = server_figures(pid)
        http.close()
    for count in STEPS:
        s = seen[count]
        figures.append(
            Figure(
                BENCH,
                f"server with {count} idle boxed runs: RSS",
                s["rss"] / MB,
                "MB",
                note=f"PSS {s['pss'] / MB:.1f} MB, {s['fds']} fds, {s['threads']} threads",
            )
        )
    for a, b in zip(STEPS, STEPS[1:], strict=False):
        added = b - a
        rss = (seen[b]["rss"] - seen[a]["rss"]) / added
        pss = (seen[b]["pss"] - seen[a]["pss"]) / added
        figures.append(
            Figure(
                BENCH,
                f"  per run added, {a} -> {b}: RSS",
                rss / 1024,
                "KB",
                note=f"PSS {pss / 1024:.0f} KB, fds"
                f" {(seen[b]['fds'] - seen[a]['fds']) / added:.1f}, threads"
                f" {(seen[b]['threads'] - seen[a]['threads']) / added:.1f}",
            )
        )
    figures.append(
        Figure(
            BENCH,
            "  the run's own processes (bwrap x2 + python3), PSS per run",
            median(per_run_pss) / MB,
            "MB",
        )
    )
    figures.append(
        Figure(
            BENCH,
            "server after all stopped: RSS",
            after["rss"] / MB,
            "MB",
            note=f"PSS {after['pss'] / MB:.1f} MB, {after['fds']} fds, {after['threads']} threads",
        )
    )
    return figures


def run() -> list[Figure]:
    figures = measure_memory()
    with tempfile.TemporaryDirectory(prefix="robotide-bench-relay-") as work:
        os.chmod(work, 0o755)
        figures += measure_relays(Path(work))
    return figures


if __name__ == "__main__":
    if sys.argv[1:2] == ["echo"]:
        echo_services()
    else:
        print_table(run())
