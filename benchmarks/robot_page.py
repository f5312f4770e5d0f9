"""The robot page under load: command to motor, telemetry to many viewers, the e-stop.

One appliance (`robotide up`, embedded mode) with two robots: `sim`, and `wire`, a Pioneer
whose ARCOS peer runs in a process of its own (benchmarks/driver_peer.py) and timestamps each
command it decodes on the shared monotonic clock.
- click -> motor: a signed-in websocket on /ws/robots/wire/ sends what the page's drive
  button sends ({"drive": [...]}); the time until the peer decodes the VEL on its wire, 40
  alternating commands, median and p90. Baseline, same run: the same driver driven directly
  from this process (rhal, no web tier), as in benchmarks/drivers.py.
- fan-out: 50 websocket clients on /ws/robots/sim/ for 10 s; telemetry messages each
  receives per second (the agent sends 4) and the server's CPU, against the same 10 s with
  no viewer.
- e-stop: 10 programs running on `sim`, one of them driving; POST /api/robots/sim/estop
  -> its answer (every program told to stop, the motors stopped), and -> every run ended.
  Aim: under 100 ms.
"""

import asyncio
import contextlib
import statistics
import tempfile
import threading
import time
from pathlib import Path

import rhal
from benchmarks.common import (
    Figure,
    api_client,
    appliance,
    parse_api_time,
    print_table,
    proc_cpu_seconds,
    say,
    server_pid,
    session_cookie,
    ws_connect,
)
from benchmarks.drivers import Peer

BENCH = "7 robot page"
SAMPLES = 40
VIEWERS = 50
FANOUT_SECONDS = 10.0
PROGRAMS = 10
ESTOP_AIM_MS = 100.0
SLEEPER = "import time\nwhile True:\n    time.sleep(0.5)\n"
DRIVER = "import time, robot\nrobot.Robot().drive(0.0, 0.5)\nwhile True:\n    time.sleep(0.5)\n"


def click_to_motor(app, cookie: str, peer: Peer) -> list[float]:
    delays = []
    with ws_connect(app, "/ws/robots/wire/", cookie) as ws:
        ws.send('{"drive": [0.2, 0.0]}')  # warm-up, and take control
        peer_change(peer, timeout=10)
        time.sleep(0.3)
        for i in range(SAMPLES):
            speed = 0.1 if i % 2 else -0.1
            drain(peer)
            sent = time.monotonic()
            ws.send(f'{{"drive": [{speed}, 0.0]}}')
            while True:
                t, linear, _ = peer_change(peer)
                if linear * speed > 0:
                    break
            delays.append((t - sent) * 1000.0)
            time.sleep(0.1)  # within the 0.4 s dead-man
        ws.send('{"release": true}')
    return delays


def peer_change(peer: Peer, timeout: float = 5.0) -> tuple[float, float, float]:
    line = _readline(peer, timeout)
    while not line.startswith("cmd "):
        line = _readline(peer, timeout)
    _, t, linear, angular = line.split()
    return float(t), float(linear), float(angular)


def _readline(peer: Peer, timeout: float) -> str:
    result: list[str] = []
    reader = threading.Thread(target=lambda: result.append(peer.process.stdout.readline()))
    reader.start()
    reader.join(timeout)
    if not result:
        raise TimeoutError("the peer reported nothing")
    return result[0]


def drain(peer: Peer) -> None:
    import select

    while select.select([peer.process.stdout], [], [], 0)[0]:
        peer.process.stdout.readline()


async def direct_baseline(url: str, peer: Peer) -> list[float]:
    delays = []
    async with rhal.connect(url) as robot:
        await robot.drive(0.2, 0.0)
        peer_change(peer, timeout=10)
        for i in range(SAMPLES):
            speed = 0.1 if i % 2 else -0.1
            drain(peer)
            sent = time.monotonic()
            await robot.drive(speed, 0.0)
            while True:
                t, linear, _ = await asyncio.to_thread(peer_change, peer)
                if linear * speed > 0:
                    break
            delays.append((t - sent) * 1000.0)
            await asyncio.sleep(0.05)
    return delays


def fanout(app, cookie: str) -> dict:
    pid = server_pid(app)
    cpu0, t0 = proc_cpu_seconds(pid), time.monotonic()
    time.sleep(FANOUT_SECONDS)
    idle_cpu = (proc_cpu_seconds(pid) - cpu0) / (time.monotonic() - t0)
    counts = [0] * VIEWERS
    stop = threading.Event()

    def viewer(i: int) -> None:
        with ws_connect(app, "/ws/robots/sim/", cookie) as ws:
            while not stop.is_set():
                with contextlib.suppress(TimeoutError):
                    if 'id="sensors"' in ws.recv(timeout=0.5):
                        counts[i] += 1

    threads = [threading.Thread(target=viewer, args=(i,), daemon=True) for i in range(VIEWERS)]
    for thread in threads:
        thread.start()
    time.sleep(2.0)  # all connected and past their first snapshot
    start_counts = list(counts)
    cpu0, t0 = proc_cpu_seconds(pid), time.monotonic()
    time.sleep(FANOUT_SECONDS)
    elapsed = time.monotonic() - t0
    busy_cpu = (proc_cpu_seconds(pid) - cpu0) / elapsed
    rates = [(c - s) / elapsed for c, s in zip(counts, start_counts, strict=True)]
    stop.set()
    for thread in threads:
        thread.join(5)
    return {"idle_cpu": idle_cpu, "busy_cpu": busy_cpu, "rates": rates}


def estop(app, http) -> dict:
    runs = []
    for i in range(PROGRAMS):
        program = app.create_program(f"Busy {i}", DRIVER if i == 0 else SLEEPER)
        runs.append(app.run_program(program["id"])["id"])
    for run_id in runs:
        app.wait_run(run_id, states=("running",), timeout=30)
    time.sleep(0.5)
    sent_at, sent = time.time(), time.monotonic()
    answer = http.post("/api/robots/sim/estop")
    answered = time.monotonic()
    assert answer.json()["stopped_runs"] == PROGRAMS, answer.text
    # When each run ended, as the server recorded it (not when this loop looked).
    ended = max(parse_api_time(app.wait_run(run_id, timeout=30)["ended"]) for run_id in runs)
    velocity = http.get("/api/robots/sim/sensors").json()["velocity"]
    return {
        "answer_ms": (answered - sent) * 1000.0,
        "ended_ms": (ended - sent_at) * 1000.0,
        "halted": velocity == {"linear": 0.0, "angular": 0.0},
    }


def run() -> list[Figure]:
    with tempfile.TemporaryDirectory() as folder:
        Path(folder, "pioneer").mkdir()
        peer = Peer("pioneer", str(Path(folder, "pioneer")))
        try:
            return measure(peer)
        finally:
            peer.close()


def measure(peer: Peer) -> list[Figure]:
    figures = []
    with appliance("robot-page") as app:
        http = api_client(app)
        response = http.post("/api/robots", json={"name": "wire", "url": peer.url})
        assert response.status_code == 201, response.text
        cookie = session_cookie(app)
        time.sleep(1.0)  # the agent opens the robot
        clicks = click_to_motor(app, cookie, peer)
        say(f"click -> motor: median {statistics.median(clicks):.2f} ms")
        figures += [
            Figure(BENCH, "drive command -> on the robot's wire, median",
                   statistics.median(clicks), "ms"),
            Figure(BENCH, "drive command -> on the robot's wire, p90",
                   statistics.quantiles(clicks, n=10)[-1], "ms"),
        ]  # fmt: skip
        fan = fanout(app, cookie)
        rates = fan["rates"]
        say(f"fan-out: {min(rates):.2f}..{max(rates):.2f} msg/s per viewer,"
            f" CPU {fan['idle_cpu'] * 100:.1f} % -> {fan['busy_cpu'] * 100:.1f} %")  # fmt: skip
        figures += [
            Figure(BENCH, f"telemetry to {VIEWERS} viewers, slowest viewer", min(rates),
                   "msg/s", target="4 (the agent's rate)", ok=min(rates) >= 3.6),
            Figure(BENCH, "server CPU, no viewer", fan["idle_cpu"] * 100, "%"),
            Figure(BENCH, f"server CPU, {VIEWERS} viewers", fan["busy_cpu"] * 100, "%"),
        ]  # fmt: skip
        stop = estop(app, http)
        say(f"e-stop: answered {stop['answer_ms']:.1f} ms, all ended {stop['ended_ms']:.1f} ms")
        figures += [
            Figure(BENCH, f"e-stop with {PROGRAMS} programs -> answered, motors stopped",
                   stop["answer_ms"], "ms", target=f"< {ESTOP_AIM_MS:.0f} ms",
                   ok=stop["answer_ms"] < ESTOP_AIM_MS and stop["halted"]),
            Figure(BENCH, f"e-stop with {PROGRAMS} programs -> every run ended",
                   stop["ended_ms"], "ms"),
        ]  # fmt: skip
        http.close()
    # The same driver without the web tier, for the share the web tier adds.
    direct = asyncio.run(direct_baseline(peer.url, peer))
    figures.append(
        Figure(BENCH, "baseline: drive() -> wire from rhal directly, median",
               statistics.median(direct), "ms")
    )  # fmt: skip
    return figures


if __name__ == "__main__":
    print_table(run(), title="the robot page")
