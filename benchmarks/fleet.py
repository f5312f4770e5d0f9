"""A lab's load on fleet mode, and on embedded mode doing the same work, on this machine.

Fleet: the compose file's services run natively by robotide.fleet (as `make fleet` does) on
this machine's PostgreSQL (a fresh database) and Redis (an empty database): `robotide up` with
2 web workers, the file's `agent-sim`, and an override adding ROBOTS robots r1..rN, each its own
`robotide agent rN --url sim://` process (one block per robot, as a lab adds them). Embedded:
`robotide up` alone (SQLite, in-memory channel layer), the same robots added through
POST /api/robots, its agents in the server process. Both therefore serve ROBOTS + 1 sim robots.

The same work on both, timed from a start instant T0 a few seconds after the first run request:
- on each robot a Python program prints `t=<time.time()> i=<n>` every 100 ms for SECONDS (the
  robots' ticks spread evenly over the 100 ms), on an absolute schedule;
- VIEWERS signed-in websocket viewers of the runs' pages (/ws/runs/<id>/, as the run page's
  htmx does, with an Origin header and permessage-deflate offered as browsers do), spread evenly
  over the runs, each connected before T0; every stamp in the HTML they receive gives a log
  latency print -> viewer (the same machine clock at both ends);
- from T0 + WARM to the end of the programs (the window), a load generator in a process of its
  own (wrk, else a bounded Python client) GETs a signed-in page (FLEET_BENCH_PAGE, /robots/) on
  CONNECTIONS keep-alive connections, each pausing THINK_MS between requests (a lab's people
  clicking), bounded by the window: page latency p50/p99 and requests/s.
Measured over the window: CPU time of each process (/proc/PID/stat) grouped as web tier, agents,
programs, Redis, PostgreSQL (the backends serving this database), the benchmark's own process
(viewers) and the load generator, and the machine's (/proc/stat); memory (PSS, RSS and private
bytes from /proc/PID/smaps_rollup) mid-window, and with the robots idle before. Per agent:
fleet, each agent process; embedded, the server's growth when the robots were added, / ROBOTS.
Fleet only: a tap on Redis (channels_redis, joined to TAP_RUNS runs' groups) timestamps their
output as the agents publish it, which splits those runs' latency into print -> Redis and
Redis -> viewer; once a second, the longest process inbox on Redis (a web worker's backlog).
Before the work: 4 s of the robots idle (CPU); the page as under load, on one keep-alive
connection back to back, and on a new connection per request.

Env: FLEET_BENCH_ROBOTS (20), FLEET_BENCH_VIEWERS (100), FLEET_BENCH_SECONDS (20),
FLEET_BENCH_WORKERS (2), FLEET_BENCH_PAGE (/robots/), FLEET_BENCH_CONNECTIONS (4),
FLEET_BENCH_THINK_MS (100; 0: flat out), FLEET_BENCH_MODES (fleet,embedded),
FLEET_BENCH_PERIOD (0.1 s between a program's lines), FLEET_BENCH_TAP_RUNS (2; 0: no tap).
"""

import asyncio
import contextlib
import json
import os
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import threading
import time
from collections.abc import Iterator
from pathlib import Path

import httpx
import yaml

from benchmarks.common import (
    MB,
    MS,
    ROOT,
    Figure,
    percentile,
    print_table,
    proc_rollup,
    say,
)
from tests.appliance import ADMIN_PASSWORD, REDIS, Appliance, cookie_header, free_port

BENCH = "8 fleet"
ROBOTS = int(os.environ.get("FLEET_BENCH_ROBOTS", 20))
VIEWERS = int(os.environ.get("FLEET_BENCH_VIEWERS", 100))
SECONDS = float(os.environ.get("FLEET_BENCH_SECONDS", 20))
WORKERS = int(os.environ.get("FLEET_BENCH_WORKERS", 2))
PAGE = os.environ.get("FLEET_BENCH_PAGE", "/robots/")
CONNECTIONS = int(os.environ.get("FLEET_BENCH_CONNECTIONS", 4))
THINK_MS = int(os.environ.get("FLEET_BENCH_THINK_MS", 100))
TAP_RUNS = int(os.environ.get("FLEET_BENCH_TAP_RUNS", 2))  # fleet: runs the Redis tap follows
MODES = [m for m in os.environ.get("FLEET_BENCH_MODES", "fleet,embedded").split(",") if m]
PERIOD = float(os.environ.get("FLEET_BENCH_PERIOD", 0.1))  # s between a program's lines
LEAD = 8.0  # s from the first run request to T0: every run started, every viewer connected
WARM = 2.0  # s after T0 before the window opens
IDLE_SECONDS = 4.0
READY_TIMEOUT = 150.0
CLK_TCK = os.sysconf("SC_CLK_TCK")
STAMP = re.compile(r"t=(\d+\.\d+) i=(\d+)")
LIVE = 'hx-swap-oob="beforeend"'  # a live batch of lines (the first message is the log's tail)

PROGRAM = """\
import time
T0, PHASE, COUNT, PERIOD = {t0!r}, {phase!r}, {count}, {period}
for i in range(COUNT):
    delay = T0 + PHASE + i * PERIOD - time.time()
    if delay > 0:
        time.sleep(delay)
    print(f"t={{time.time():.6f}} i={{i}}", flush=True)
"""


# -- processes, CPU and memory, from /proc ---------------------------------------------------


def stat_fields(pid: int) -> list[str]:
    with open(f"/proc/{pid}/stat") as f:
        return f.read().rsplit(")", 1)[1].split()


def children_map() -> dict[int, list[int]]:
    kids: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            with contextlib.suppress(OSError, IndexError):
                kids.setdefault(int(stat_fields(int(entry))[1]), []).append(int(entry))
    return kids


def descendants(pid: int, kids: dict[int, list[int]]) -> list[int]:
    found, todo = [], list(kids.get(pid, []))
    while todo:
        child = todo.pop()
        found.append(child)
        todo += kids.get(child, [])
    return found


def cpu_ticks(pids) -> dict[int, tuple[int, int]]:
    """pid -> (utime + stime, start time), both in clock ticks."""
    ticks = {}
    for pid in set(pids):
        with contextlib.suppress(OSError, IndexError):
            fields = stat_fields(pid)
            ticks[pid] = (int(fields[11]) + int(fields[12]), int(fields[19]))
    return ticks


def uptime_ticks() -> int:
    with open("/proc/uptime") as f:
        return int(float(f.read().split()[0]) * CLK_TCK)


def machine_ticks() -> tuple[int, int]:
    """(busy, all) clock ticks of every CPU since boot."""
    with open("/proc/stat") as f:
        values = [int(v) for v in f.readline().split()[1:]]
    idle = values[3] + values[4]
    return sum(values) - idle, sum(values)


def pids_named(name: str) -> list[int]:
    """Processes whose command name is `name` (pgrep -x without a child process)."""
    found = []
    for entry in os.listdir("/proc"):
        if entry.isdigit():
            with contextlib.suppress(OSError), open(f"/proc/{entry}/comm") as f:
                if f.read().strip() == name:
                    found.append(int(entry))
    return found


class CpuWindow:
    """CPU time of process groups between open() and close(), in % of one CPU."""

    def open(self, groups: dict[str, list[int]]) -> None:
        self.t0, self.up0 = time.monotonic(), uptime_ticks()
        self.machine0 = machine_ticks()
        self.start = cpu_ticks(pid for pids in groups.values() for pid in pids)

    def close(self, groups: dict[str, list[int]]) -> dict[str, float]:
        elapsed = time.monotonic() - self.t0
        end = cpu_ticks(pid for pids in groups.values() for pid in pids)
        busy1, _ = machine_ticks()
        shares = {"machine": (busy1 - self.machine0[0]) / CLK_TCK / elapsed * 100}
        for name, pids in groups.items():
            ticks = 0
            for pid in set(pids):
                if pid not in end:
                    continue
                used, started = end[pid]
                if pid in self.start and self.start[pid][1] == started:
                    ticks += used - self.start[pid][0]
                elif started >= self.up0:  # began within the window: all of it counts
                    ticks += used
            shares[name] = ticks / CLK_TCK / elapsed * 100
        return shares


def memory(pids) -> dict[str, float]:
    """Summed smaps_rollup of these processes, in MB: Rss, Pss, Private (clean + dirty)."""
    total = {"rss": 0.0, "pss": 0.0, "private": 0.0, "count": 0}
    for pid in set(pids):
        try:
            rollup = proc_rollup(pid)
        except OSError:
            continue
        total["rss"] += rollup.get("Rss", 0) / MB
        total["pss"] += rollup.get("Pss", 0) / MB
        total["private"] += (rollup.get("Private_Clean", 0) + rollup.get("Private_Dirty", 0)) / MB
        total["count"] += 1
    return total


# -- the two ways to run it -----------------------------------------------------------------


def robot_names() -> list[str]:
    return [f"r{n}" for n in range(1, ROBOTS + 1)]


@contextlib.contextmanager
def this_tree_on_pythonpath() -> Iterator[None]:
    """Every robotide process started from here imports this tree's code (not the editable
    install's), so a clean worktree of HEAD measures HEAD."""
    old = os.environ.get("PYTHONPATH")
    os.environ["PYTHONPATH"] = os.pathsep.join([str(ROOT), *([old] if old else [])])
    try:
        yield
    finally:
        if old is None:
            os.environ.pop("PYTHONPATH", None)
        else:
            os.environ["PYTHONPATH"] = old


def empty_redis_db() -> int:
    """A Redis database nobody uses now (the tests take 7..14, `make fleet` 1): 15 first."""
    import redis

    for db in (15, 6, 5, 4, 3, 2):
        client = redis.Redis.from_url(f"{REDIS}/{db}")
        try:
            if client.dbsize() == 0:
                return db
        finally:
            client.close()
    raise RuntimeError("no empty Redis database among 15, 6..2")


def flush_redis(db: int) -> None:
    import redis

    client = redis.Redis.from_url(f"{REDIS}/{db}")
    try:
        client.flushdb()
    finally:
        client.close()


class Setup:
    """A started appliance, either mode: its URL, admin token, processes and robots."""

    mode: str
    app: Appliance
    redis_url: str | None = None
    grown_per_robot: float | None = None  # embedded: server PSS growth per robot added, MB
    started_s: float = 0.0

    def groups(self) -> dict[str, list[int]]:
        raise NotImplementedError


class FleetSetup(Setup):
    mode = "fleet"

    def __init__(self, data: Path):
        self.data = data
        self.app = Appliance(data, mode="split")
        self.fleet = None
        self.redis_db: int | None = None

    def start(self) -> None:
        from robotide.fleet import Fleet

        t0 = time.monotonic()
        port = free_port()
        self.app.port, self.app.url = port, f"http://127.0.0.1:{port}"
        self.app._create_database()
        self.redis_db = empty_redis_db()
        self.redis_url = self.app.env["REDIS_URL"] = f"{REDIS}/{self.redis_db}"
        agents = {
            f"agent-{name}": {
                "command": ["robotide", "agent", name, "--url", "sim://"],
                "environment": {"DATABASE_URL": "x", "REDIS_URL": "x", "ROBOTIDE_DATA": "x"},
                "depends_on": {"web": {"condition": "service_healthy"}},
            }  # no health check of its own: ready() asks the portal about every robot
            for name in robot_names()
        }
        extra = self.data / "lab.yml"
        extra.write_text(
            yaml.safe_dump({"services": {"web": {"ports": [f"{port}:8000"]}, **agents}})
        )
        variables = {
            "ROBOTIDE_WEB_WORKERS": str(WORKERS),
            "ROBOTIDE_ADMIN_PASSWORD": ADMIN_PASSWORD,
            "ROBOTIDE_SIM_ROBOTS": "0",
        }
        self.fleet = Fleet(
            [ROOT / "docker-compose.yml", extra], data=self.data,
            database=self.app.env["DATABASE_URL"], redis=self.redis_url, host="127.0.0.1",
            variables=variables, only=["web", "agent-sim", *agents],
        )  # fmt: skip
        self.fleet.start(timeout=READY_TIMEOUT)
        self.app.token = self.app.cli("token", "admin").strip()
        ready(self.app, ["sim", *robot_names()])
        self.started_s = time.monotonic() - t0

    def stop(self) -> None:
        try:
            if self.fleet is not None:
                self.fleet.stop()
        finally:
            try:
                self.app.stop()  # drops the database
            finally:
                if self.redis_db is not None:
                    flush_redis(self.redis_db)

    def logs(self) -> str:
        return "\n".join(
            f"--- {p.name}\n{p.read_text()[-3000:]}" for p in sorted(self.data.glob("*.log"))
        )

    def groups(self) -> dict[str, list[int]]:
        kids = children_map()
        web = self.fleet.services["web"].process.pid
        agents = [s.process.pid for n, s in self.fleet.services.items() if n.startswith("agent-")]
        programs = [pid for agent in agents for pid in descendants(agent, kids)]
        return {
            "web": [web, *descendants(web, kids)],
            **{f"worker {pid}": [pid] for pid in kids.get(web, [])},
            "agents": agents,
            "programs": programs,
            "redis": pids_named("redis-server"),
            "postgres": postgres_backends(self.app.database),
        }


def postgres_backends(database: str) -> list[int]:
    import psycopg

    from tests.appliance import POSTGRES

    with psycopg.connect(f"{POSTGRES}/postgres", autocommit=True) as conn:
        rows = conn.execute(
            "SELECT pid FROM pg_stat_activity WHERE datname = %s", (database,)
        ).fetchall()
    return [row[0] for row in rows]


class EmbeddedSetup(Setup):
    mode = "embedded"

    def __init__(self, data: Path):
        self.data = data
        self.app = Appliance(data)

    def start(self) -> None:
        t0 = time.monotonic()
        self.app.start()  # the built-in sim robot answering
        time.sleep(2.0)
        before = memory([self.app.server.pid])["pss"]
        for name in robot_names():
            response = self.app.api("POST", "/api/robots", {"name": name, "url": "sim://"})
            assert response.status_code == 201, response.text
        ready(self.app, ["sim", *robot_names()])
        self.started_s = time.monotonic() - t0
        time.sleep(2.0)
        self.grown_per_robot = (memory([self.app.server.pid])["pss"] - before) / ROBOTS

    def stop(self) -> None:
        self.app.stop()

    def logs(self) -> str:
        return self.app.logs()[-5000:]

    def groups(self) -> dict[str, list[int]]:
        server = self.app.server.pid
        return {"server": [server], "programs": descendants(server, children_map())}


def ready(app: Appliance, names: list[str]) -> None:
    """Every robot online in the portal, and its agent answering through it."""
    deadline = time.monotonic() + READY_TIMEOUT
    waiting = list(names)
    while waiting:
        if time.monotonic() > deadline:
            raise TimeoutError(f"robots not ready within {READY_TIMEOUT:g} s: {waiting}")
        with contextlib.suppress(httpx.HTTPError, ValueError):
            online = {r["name"] for r in app.api("GET", "/api/robots").json() if r["online"]}
            waiting = [
                name for name in waiting
                if name not in online
                or app.api("GET", f"/api/robots/{name}/sensors").status_code != 200
            ]  # fmt: skip
        if waiting:
            time.sleep(0.5)


# -- the load generator: wrk, or a Python client in a process of its own ---------------------

PY_LOADER = """\
import json, sys, threading, time, httpx
url, cookie, connections, seconds, think = sys.argv[1], sys.argv[2], int(sys.argv[3]), \\
    float(sys.argv[4]), float(sys.argv[5])
latencies, errors, deadline = [], [0], time.monotonic() + seconds
def loop():
    with httpx.Client(headers={"Cookie": cookie}, timeout=10) as client:
        while time.monotonic() < deadline:
            t = time.perf_counter()
            try:
                ok = client.get(url).status_code == 200
            except httpx.HTTPError:
                ok = False
            if ok:
                latencies.append(time.perf_counter() - t)
            else:
                errors[0] += 1
            time.sleep(think)
started = time.monotonic()
threads = [threading.Thread(target=loop) for _ in range(connections)]
[t.start() for t in threads]
[t.join() for t in threads]
s = sorted(latencies)
pick = lambda p: s[max(0, min(len(s) - 1, int(len(s) * p / 100 + 0.999) - 1))] if s else None
print(json.dumps({"p50": pick(50), "p99": pick(99), "requests": len(s), "errors": errors[0],
                  "seconds": time.monotonic() - started}))
"""

WRK_UNITS = {"us": 1e-6, "ms": 1e-3, "s": 1.0, "m": 60.0}


def wrk_seconds(text: str) -> float:
    number, unit = re.fullmatch(r"([\d.]+)(us|ms|s|m)", text).groups()
    return float(number) * WRK_UNITS[unit]


def page_load(url: str, cookie: str, connections: int, seconds: float, think_ms: int) -> dict:
    """GET url on `connections` connections for `seconds`; p50/p99 in s, requests/s, errors,
    and the generator's own CPU (% of one CPU while it ran)."""
    seconds = max(1, round(seconds))
    if shutil.which("wrk"):
        with tempfile.NamedTemporaryFile("w", suffix=".lua", delete=False) as script:
            script.write(f"function delay()\n  return {think_ms}\nend\n")
        argv = ["wrk", "-t1", f"-c{connections}", f"-d{seconds}s", "--timeout", "10s",
                "--latency", "-s", script.name, "-H", f"Cookie: {cookie}", url]  # fmt: skip
    else:
        script = None
        argv = [sys.executable, "-c", PY_LOADER, url, cookie, str(connections), str(seconds),
                str(think_ms / 1000)]  # fmt: skip
    t0 = time.monotonic()
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    killer = threading.Timer(seconds + 30, proc.kill)  # bounded, whatever happens
    killer.start()
    try:
        out = proc.stdout.read()
        _, status, usage = os.wait4(proc.pid, 0)  # its own CPU time, from its exit
        proc.returncode = os.waitstatus_to_exitcode(status)
    finally:
        killer.cancel()
        proc.stdout.close()
        if script is not None:
            os.unlink(script.name)
    elapsed = time.monotonic() - t0
    cpu = (usage.ru_utime + usage.ru_stime) / elapsed * 100
    if script is None:
        result = json.loads(out.strip().splitlines()[-1])
        return {"p50": result["p50"], "p99": result["p99"], "rate": result["requests"]
                / result["seconds"], "errors": result["errors"], "tool": "python",
                "cpu": cpu}  # fmt: skip
    found = dict(re.findall(r"^\s+(50|99)%\s+(\S+)$", out, re.M))
    if "50" not in found:
        raise RuntimeError(f"wrk said:\n{out}")
    rate = float(re.search(r"Requests/sec:\s+([\d.]+)", out).group(1))
    errors = sum(int(n) for n in re.findall(r"(?:connect|read|write|timeout) (\d+)", out))
    non2xx = re.search(r"Non-2xx or 3xx responses: (\d+)", out)
    errors += int(non2xx.group(1)) if non2xx else 0
    return {"p50": wrk_seconds(found["50"]), "p99": wrk_seconds(found["99"]), "rate": rate,
            "errors": errors, "tool": "wrk", "cpu": cpu}  # fmt: skip


def fresh_connections(url: str, cookie: str, count: int = 20) -> float:
    """p50 in ms of `count` GETs in turn, each on a connection of its own (http.client: no
    client set-up in the time)."""
    from http.client import HTTPConnection
    from urllib.parse import urlsplit

    parts = urlsplit(url)
    times = []
    for _ in range(count):
        t = time.perf_counter()
        connection = HTTPConnection(parts.hostname, parts.port, timeout=10)
        try:
            connection.request("GET", parts.path, headers={"Cookie": cookie})
            response = connection.getresponse()
            response.read()
        finally:
            connection.close()
        times.append((time.perf_counter() - t) * MS)
        assert response.status == 200, response.status
    return percentile(times, 50)


# -- the work -------------------------------------------------------------------------------


async def viewer(setup: Setup, cookie: str, run_id: int, record: list, sockets: list, info: list):
    from websockets.asyncio.client import connect

    ws = await connect(
        f"ws://127.0.0.1:{setup.app.port}/ws/runs/{run_id}/",
        additional_headers={"Cookie": cookie, "Origin": setup.app.url},
        open_timeout=30, max_size=None, ping_interval=None,
    )  # fmt: skip
    sockets.append(ws)
    worker = ws.response.headers.get("x-robotide-worker", "")
    info.append(worker)
    with contextlib.suppress(Exception):
        async for message in ws:
            now = time.time()
            live = LIVE in message
            for match in STAMP.finditer(message):
                record.append((now, float(match[1]), int(match[2]), live, run_id, worker))


async def redis_tap(redis_url: str, groups: asyncio.Queue, record: list, own: set) -> None:
    """Joins the runs' groups on the fleet's channel layer: output as the agents publish it."""
    from channels_redis.core import RedisChannelLayer

    layer = RedisChannelLayer(hosts=[{"address": redis_url, "socket_timeout": 15}])
    channel = await layer.new_channel()
    own.add(layer.prefix + layer.non_local_name(channel))
    joined = []
    try:
        while True:
            while not groups.empty():
                group = groups.get_nowait()
                if group is None:
                    return
                await layer.group_add(group, channel)
                joined.append(group)
            try:
                message = await asyncio.wait_for(layer.receive(channel), 0.5)
            except TimeoutError:
                continue
            now = time.time()
            if message.get("type") == "run.output":
                for _, _, text in message["lines"]:
                    if match := STAMP.search(text):
                        record.append(
                            (now, float(match[1]), int(match[2]), True, message["run_id"], "")
                        )
    finally:
        for group in joined:
            with contextlib.suppress(Exception):
                await layer.group_discard(group, channel)
        with contextlib.suppress(Exception):
            await layer.close_pools()


async def inbox_backlog(redis_url: str, samples: list, stop: asyncio.Event, skip: set) -> None:
    """Once a second, the longest process inbox on the channel layer: channels_redis keeps one
    sorted set per process (asgi + specific.ID!) that its receive loop pops one at a time,
    at most `capacity` (1000) long; group messages beyond that are dropped."""
    import redis.asyncio

    client = redis.asyncio.Redis.from_url(redis_url)
    try:
        while not stop.is_set():
            longest = 0
            async for key in client.scan_iter(match="asgispecific.*", count=1000):
                if key.decode() not in skip:  # the tap's own
                    longest = max(longest, await client.zcard(key))
            samples.append((time.time(), longest))
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(stop.wait(), 1.0)
    finally:
        await client.aclose()


async def lag_probe(samples: list, stop: asyncio.Event) -> None:
    while not stop.is_set():
        t = time.monotonic()
        await asyncio.sleep(0.01)
        samples.append(time.monotonic() - t - 0.01)


async def sleep_until(when: float) -> None:
    await asyncio.sleep(max(0.0, when - time.time()))


async def work(setup: Setup, cookie: str) -> dict:
    app = setup.app
    names = robot_names()
    count = int(SECONDS / PERIOD)
    headers = {"Authorization": f"Bearer {app.token}"}
    viewers_rec: list = []
    tap_rec: list = []
    sockets: list = []
    workers: list = []
    lag: list = []
    stop = asyncio.Event()
    tap_groups: asyncio.Queue = asyncio.Queue()
    backlog: list = []
    tap_key: set = set()
    tasks = [asyncio.create_task(lag_probe(lag, stop))]
    if setup.redis_url:
        tasks.append(asyncio.create_task(inbox_backlog(setup.redis_url, backlog, stop, tap_key)))
        if TAP_RUNS:
            tasks.append(
                asyncio.create_task(redis_tap(setup.redis_url, tap_groups, tap_rec, tap_key))
            )
    result: dict = {}
    async with httpx.AsyncClient(base_url=app.url, headers=headers, timeout=30) as http:
        t0 = time.time() + LEAD
        programs = []
        for k, name in enumerate(names):
            source = PROGRAM.format(t0=t0, phase=round(k * PERIOD / len(names), 4),
                                    count=count, period=PERIOD)  # fmt: skip
            body = {"name": f"fleet bench {name}", "language": "python", "source": source}
            response = await http.post("/api/programs", json=body)
            assert response.status_code == 201, response.text
            programs.append(response.json()["id"])
        runs, viewer_tasks = [], []
        # A few runs only: popping every message of every run costs the tap ~20 % of a CPU.
        tapped = {k * ROBOTS // TAP_RUNS for k in range(TAP_RUNS)}
        for k, (name, program) in enumerate(zip(names, programs, strict=True)):
            response = await http.post(f"/api/programs/{program}/run", json={"robot": name})
            assert response.status_code == 201, response.text
            run_id = response.json()["id"]
            runs.append(run_id)
            if k in tapped:
                tap_groups.put_nowait(f"run-{run_id}")  # robots.bus.run_group
            for _ in range(k, VIEWERS, len(names)):
                viewer_tasks.append(asyncio.create_task(
                    viewer(setup, cookie, run_id, viewers_rec, sockets, workers)
                ))  # fmt: skip
        requested = time.time()
        while len(sockets) < VIEWERS and time.time() < t0:
            await asyncio.sleep(0.05)
        result["connected_before_t0"] = len(sockets)
        result["runs_requested_s"] = requested - (t0 - LEAD)
        states = await asyncio.gather(*(http.get(f"/api/runs/{r}") for r in runs))
        result["running_before_t0"] = sum(s.json()["state"] == "running" for s in states)
        if time.time() > t0:
            say(f"  late: the runs and viewers were not all ready by T0 ({len(sockets)} viewers)")
        # The window: from T0 + WARM to the last tick of the programs.
        w0, w1 = t0 + WARM, t0 + count * PERIOD
        await sleep_until(w0)
        cpu = CpuWindow()
        await asyncio.to_thread(lambda: cpu.open(setup.groups()))
        cpu_self0 = proc_self_cpu()
        lag_from = len(lag)
        load = asyncio.create_task(asyncio.to_thread(
            page_load, app.url + PAGE, cookie, CONNECTIONS, w1 - w0 - 1, THINK_MS
        ))  # fmt: skip
        await sleep_until((w0 + w1) / 2)
        groups = await asyncio.to_thread(setup.groups)
        result["memory"], result["memory_each"] = await asyncio.to_thread(
            lambda: (
                {name: memory(pids) for name, pids in groups.items()},
                {pid: memory([pid]) for pid in groups.get("agents", [])},
            )
        )
        result["page"] = await load
        await sleep_until(w1)
        result["cpu"] = await asyncio.to_thread(lambda: cpu.close(setup.groups()))
        elapsed = time.time() - w0
        result["cpu"]["bench process (viewers)"] = (proc_self_cpu() - cpu_self0) / elapsed * 100
        result["cpu"]["load generator"] = result["page"]["cpu"]
        result["lag"] = lag[lag_from:]
        result["backlog"] = [b for t, b in backlog if w0 <= t <= w1]
        result["window"] = (w0, w1)
        # Everything printed, then shown: the runs end by themselves.
        ended = await asyncio.to_thread(lambda: [app.wait_run(r, timeout=60) for r in runs])
        result["run_states"] = [run["state"] for run in ended]
        await asyncio.sleep(1.0)  # the last batches on their way
        logs = await asyncio.gather(*(http.get(f"/api/runs/{r}/log") for r in runs))
        result["printed"] = [
            [(float(m[1]), int(m[2])) for m in STAMP.finditer(log.text)] for log in logs
        ]
    stop.set()
    tap_groups.put_nowait(None)
    for ws in sockets:
        with contextlib.suppress(Exception):
            await ws.close()
    await asyncio.wait_for(asyncio.gather(*viewer_tasks, return_exceptions=True), 15)
    await asyncio.wait_for(asyncio.gather(*tasks, return_exceptions=True), 15)
    result["viewers"] = viewers_rec
    result["tap"] = tap_rec
    result["runs"] = runs
    result["tapped"] = {runs[k] for k in tapped}
    result["workers"] = workers
    result["t0"] = t0
    return result


def proc_self_cpu() -> float:
    usage = os.times()
    return usage.user + usage.system


# -- figures --------------------------------------------------------------------------------


def measure(setup: Setup) -> tuple[list[Figure], dict]:
    app = setup.app
    bench = f"{BENCH}: {setup.mode}"
    say(f"  {setup.mode}: {ROBOTS} robots + sim ready in {setup.started_s:.1f} s")
    client = app.session()
    try:
        cookie = cookie_header(client)
        assert client.get(PAGE).status_code == 200
    finally:
        client.close()
    time.sleep(2.0)
    idle = CpuWindow()
    idle.open(setup.groups())
    time.sleep(IDLE_SECONDS)
    idle_groups = setup.groups()
    idle_cpu = idle.close(idle_groups)
    idle_mem = {name: memory(pids) for name, pids in idle_groups.items()}
    idle_each = [memory([pid]) for pid in idle_groups.get("agents", [])]
    quiet_page = page_load(app.url + PAGE, cookie, CONNECTIONS, 3, THINK_MS)
    back_to_back = page_load(app.url + PAGE, cookie, 1, 3, 0)
    fresh = fresh_connections(app.url + PAGE, cookie)
    say(f"  idle: CPU {fmt_cpu(idle_cpu)}; page {PAGE} p50 {quiet_page['p50'] * MS:.1f} ms, one"
        f" keep-alive connection back to back {back_to_back['p50'] * MS:.1f} ms, a new"
        f" connection each {fresh:.1f} ms")  # fmt: skip
    result = asyncio.run(work(setup, cookie))
    w0, w1 = result["window"]

    def latencies(record: list, runs=None, worker=None) -> list[float]:
        return [
            (now - stamp) * MS
            for now, stamp, _, live, run, by in record
            if live and w0 <= stamp < w1 and (runs is None or run in runs)
            and (worker is None or by == worker)
        ]  # fmt: skip

    to_viewer = latencies(result["viewers"])
    to_redis = latencies(result["tap"])
    tapped_viewers = latencies(result["viewers"], result["tapped"])
    expected = sum(1 for printed in result["printed"] for stamp, _ in printed if w0 <= stamp < w1)
    per_run = VIEWERS / ROBOTS
    shown = {(run, i) for _, stamp, i, _, run, _ in result["viewers"] if w0 <= stamp < w1}
    by_worker = {
        name: latencies(result["viewers"], worker=name) for name in sorted(set(result["workers"]))
    }
    per_worker = "; ".join(
        f"{len([w for w in result['workers'] if w == name])} viewers on {name}: p50"
        f" {percentile(values, 50):.0f} ms, p99 {percentile(values, 99):.0f} ms"
        for name, values in by_worker.items()
    )
    delivered = len(latencies(result["viewers"]))
    expected_views = sum(
        len(range(k, VIEWERS, ROBOTS)) * sum(1 for stamp, _ in printed if w0 <= stamp < w1)
        for k, printed in enumerate(result["printed"])
    )
    lateness = [
        (stamp - (result["t0"] + k * PERIOD / ROBOTS + i * PERIOD)) * MS
        for k, printed in enumerate(result["printed"])
        for stamp, i in printed
        if w0 <= stamp < w1
    ]
    cpu, mem, page = result["cpu"], result["memory"], result["page"]
    say(f"  work: CPU {fmt_cpu(cpu)}")
    if others(cpu) > 20:
        say(f"  warning: other work on the machine took {others(cpu):.0f} % of a CPU during the"
            " window: the figures are skewed (fleet mode most: see the README)")  # fmt: skip
    say(f"  log latency print -> viewer p50 {percentile(to_viewer, 50):.1f} ms, p99"
        f" {percentile(to_viewer, 99):.1f} ms ({len(to_viewer)} samples, {delivered} of"
        f" {expected_views} expected; {len(shown)} of {expected} lines seen by any)")  # fmt: skip
    if to_redis:
        say(f"  {len(result['tapped'])} runs: print -> Redis (tap) p50"
            f" {percentile(to_redis, 50):.1f} ms, p99 {percentile(to_redis, 99):.1f} ms"
            f" ({len(to_redis)} samples); -> their viewers p50"
            f" {percentile(tapped_viewers, 50):.1f} ms, p99"
            f" {percentile(tapped_viewers, 99):.1f} ms")  # fmt: skip
    say(f"  page {PAGE} under load ({page['tool']}, {CONNECTIONS} connections, think"
        f" {THINK_MS} ms): p50 {page['p50'] * MS:.1f} ms, p99 {page['p99'] * MS:.1f} ms,"
        f" {page['rate']:.1f} req/s, {page['errors']} errors")  # fmt: skip
    workers = {}
    for name in result["workers"]:
        workers[name] = workers.get(name, 0) + 1
    if len(by_worker) > 1:
        say(f"  {per_worker}")
    say(f"  viewers per web worker: {sorted(workers.values(), reverse=True)}; runs"
        f" {sorted(set(result['run_states']))}; before T0: {result['running_before_t0']} runs"
        f" running, {result['connected_before_t0']} viewers connected")  # fmt: skip
    say(f"  viewers' event loop lag p99 {percentile(result['lag'], 99) * MS:.1f} ms; programs'"
        f" print lateness p50 {percentile(lateness, 50):.1f} ms p99"
        f" {percentile(lateness, 99):.1f} ms")  # fmt: skip

    figures = []

    def add(name, value, unit, note=""):
        figures.append(Figure(bench, name, value, unit, note=note))

    robotide_cpu = cpu.get("web", 0) + cpu.get("agents", 0) + cpu.get("server", 0)
    backing_cpu = cpu.get("redis", 0) + cpu.get("postgres", 0)
    add(f"start: {ROBOTS} robots + sim ready", setup.started_s, "s")
    add("log latency print -> viewer, p50", percentile(to_viewer, 50), "ms",
        note=f"{len(to_viewer)} samples over {w1 - w0:.0f} s; viewers' own event-loop lag p99"
        f" {percentile(result['lag'], 99) * MS:.1f} ms; programs printed late by p99"
        f" {percentile(lateness, 99):.1f} ms")  # fmt: skip
    add("log latency print -> viewer, p99", percentile(to_viewer, 99), "ms",
        note=per_worker if len(by_worker) > 1 else "")  # fmt: skip
    add("log latency print -> viewer, max", max(to_viewer, default=None), "ms")
    if to_redis:
        add(f"  print -> on Redis ({len(result['tapped'])} runs, tap), p50",
            percentile(to_redis, 50), "ms",
            note=f"the same runs' lines -> their viewers: p50"
            f" {percentile(tapped_viewers, 50):.1f} ms, p99"
            f" {percentile(tapped_viewers, 99):.1f} ms")  # fmt: skip
        add(f"  print -> on Redis ({len(result['tapped'])} runs, tap), p99",
            percentile(to_redis, 99), "ms")  # fmt: skip
    add(
        "lines not delivered to a viewer",
        expected_views - delivered,
        "",
        note=f"{expected_views} expected ({per_run:g} viewers x each run's lines in the window)"
        + (
            f"; longest web-worker inbox on Redis {max(result['backlog'], default=0)} messages"
            " (channels_redis drops group messages to a process inbox at its capacity, 1000)"
            if setup.mode == "fleet"
            else ""
        ),
    )
    add(f"page {PAGE} idle, p50", quiet_page["p50"] * MS, "ms",
        note=f"as under load; on one keep-alive connection back to back"
        f" {back_to_back['p50'] * MS:.1f} ms, on a new connection each {fresh:.1f} ms")  # fmt: skip
    add(f"page {PAGE} under load, p50", page["p50"] * MS, "ms",
        note=f"{page['tool']}, {CONNECTIONS} connections each pausing {THINK_MS} ms,"
        f" {page['errors']} errors")  # fmt: skip
    add(f"page {PAGE} under load, p99", page["p99"] * MS, "ms")
    add(f"page {PAGE} under load, requests/s", page["rate"], "req/s")
    if setup.mode == "fleet":
        per_worker = sorted(
            (v for k, v in cpu.items() if k.startswith("worker ") and v > 0.5), reverse=True
        )
        add(f"CPU web tier ({WORKERS} workers + master)", cpu["web"], "%",
            note=f"% of one CPU over the {w1 - w0:.0f} s window; the workers "
            + ", ".join(f"{v:.0f} %" for v in per_worker)
            + f"; viewers per worker {sorted(workers.values(), reverse=True)}")  # fmt: skip
        add(f"CPU agents ({len(result['memory_each'])} processes)", cpu["agents"], "%")
        add("CPU Redis", cpu["redis"], "%", note="the machine's redis-server: other users too")
        add("CPU PostgreSQL (this database's backends)", cpu["postgres"], "%")
    else:
        add(
            "CPU server (web + agents)",
            cpu["server"],
            "%",
            note=f"% of one CPU over the {w1 - w0:.0f} s window",
        )
    add("CPU robotide + Redis + PostgreSQL", robotide_cpu + backing_cpu, "%")
    add("CPU programs (not robotide's)", cpu["programs"], "%")
    add("CPU viewers + this benchmark", cpu["bench process (viewers)"], "%")
    add("CPU load generator", cpu["load generator"], "%")
    add("CPU machine (2 CPUs: 200 %)", cpu["machine"], "%",
        note=f"of which other work on the machine {others(cpu):.0f} %")  # fmt: skip
    idle_robotide = sum(idle_cpu.get(k, 0) for k in ("web", "agents", "server", "redis",
                                                      "postgres"))  # fmt: skip
    add(
        "CPU idle (robots online, nothing running)",
        idle_robotide,
        "%",
        note="robotide + Redis + PostgreSQL: "
        + fmt_cpu(idle_cpu)
        + f"; other work on the machine {others(idle_cpu):.0f} %",
    )
    if setup.mode == "fleet":
        each = list(result["memory_each"].values())
        add("memory per agent process, PSS", mean(m["pss"] for m in each), "MB",
            note=f"with a run going; RSS {mean(m['rss'] for m in each):.1f} MB, private"
            f" {mean(m['private'] for m in each):.1f} MB; idle PSS"
            f" {mean(m['pss'] for m in idle_each):.1f} MB")  # fmt: skip
        add("memory per agent process, RSS", mean(m["rss"] for m in each), "MB")
        add(
            "memory web tier, PSS",
            mem["web"]["pss"],
            "MB",
            note=f"{mem['web']['count']} processes, RSS {mem['web']['rss']:.1f} MB",
        )
        add("memory agents, PSS (all)", mem["agents"]["pss"], "MB")
        add(
            "memory PostgreSQL backends, PSS",
            mem["postgres"]["pss"],
            "MB",
            note=f"{mem['postgres']['count']} backends of this database"
            f" ({idle_mem['postgres']['count']} with the robots idle)",
        )
        total = mem["web"]["pss"] + mem["agents"]["pss"] + mem["postgres"]["pss"]
    else:
        add("memory per agent (server's growth / robot added), PSS", setup.grown_per_robot,
            "MB", note=f"the server's PSS grew {setup.grown_per_robot * ROBOTS:.1f} MB as the"
            f" {ROBOTS} robots were added and started")  # fmt: skip
        add(
            "memory server, PSS",
            mem["server"]["pss"],
            "MB",
            note=f"RSS {mem['server']['rss']:.1f} MB; idle PSS {idle_mem['server']['pss']:.1f} MB",
        )
        total = mem["server"]["pss"]
    add("memory robotide total (+ PostgreSQL backends), PSS", total, "MB")
    summary = {
        "p50": percentile(to_viewer, 50), "p99": percentile(to_viewer, 99),
        "page_p50": page["p50"] * MS, "page_p99": page["p99"] * MS,
        "cpu": robotide_cpu + backing_cpu, "memory": total,
    }  # fmt: skip
    return figures, summary


def fmt_cpu(cpu: dict[str, float]) -> str:
    return ", ".join(
        f"{name} {value:.1f} %" for name, value in cpu.items() if not name.startswith("worker ")
    )


def others(cpu: dict[str, float]) -> float:
    """The machine's CPU that none of the measured processes used: other work."""
    return cpu["machine"] - sum(
        value for name, value in cpu.items() if name != "machine" and not name.startswith("worker ")
    )


def mean(values) -> float:
    values = list(values)
    return sum(values) / len(values) if values else float("nan")


def run_mode(mode: str) -> tuple[list[Figure], dict]:
    data = Path(tempfile.mkdtemp(prefix=f"robotide-bench-fleet-{mode}-"))
    setup: Setup = FleetSetup(data) if mode == "fleet" else EmbeddedSetup(data)
    try:
        try:
            setup.start()
        except BaseException:
            print(setup.logs(), file=sys.stderr)
            raise
        return measure(setup)
    finally:
        try:
            setup.stop()
        finally:
            shutil.rmtree(data, ignore_errors=True)


def run() -> list[Figure]:
    figures, summaries = [], {}
    say(f"  {ROBOTS} robots, {VIEWERS} viewers, {SECONDS:g} s of output, modes {MODES}")
    previous = signal.getsignal(signal.SIGTERM)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # clean up on kill too
    try:
        with this_tree_on_pythonpath():
            for mode in MODES:
                found, summaries[mode] = run_mode(mode)
                figures += found
    finally:
        signal.signal(signal.SIGTERM, previous)
    if {"fleet", "embedded"} <= set(summaries):
        fleet, embedded = summaries["fleet"], summaries["embedded"]
        bench = f"{BENCH}: fleet / embedded"
        for key, name in (
            ("p50", "log latency p50"), ("p99", "log latency p99"),
            ("page_p50", "page p50 under load"), ("page_p99", "page p99 under load"),
            ("cpu", "CPU robotide + Redis + PostgreSQL"), ("memory", "memory total, PSS"),
        ):  # fmt: skip
            ratio = fleet[key] / embedded[key] if embedded[key] else None
            figures.append(Figure(bench, name, ratio, "x"))
    return figures


if __name__ == "__main__":
    print_table(run(), title="fleet mode under a lab's load, against embedded mode")
