"""Every RHAL driver against its peer: command-to-wire latency, telemetry rate, CPU.

For each wired kind (dtmf, nxt, pioneer, mavlink, can) the peer of tests/peers.py runs in a
process of its own (benchmarks/driver_peer.py) and reports, on the shared monotonic clock,
when a new command is decoded off the wire. This process opens the driver on the peer's URL:
- latency: drive() call -> the peer has decoded the new command, over 40 changes of speed
  (after a warm-up, so a MAVLink vehicle is already guided and armed), median and p90;
- telemetry: sensors() sampled every 5 ms for 3 s while driving, the rate at which the
  readings change (each change is new data from the robot);
- CPU: this process's CPU time over 5 s holding a speed and reading sensors() at 4 Hz, as
  the agent does: the driver's own keep-alives, setpoint streams and polling.
Baselines, same run: a pipe between two processes (the floor of "bytes on the other side",
with the same polling peer) and the sim:// driver in the same CPU loop (no wire at all).
"""

import asyncio
import contextlib
import os
import resource
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import rhal
from benchmarks.common import Figure, print_table, say

BENCH = "6 drivers"
KINDS = ("dtmf", "nxt", "pioneer", "mavlink", "can")
CHANGES = 40
# DTMF plays a tone and a gap (80 ms) before the next command can be heard.
SPACING = {"dtmf": 0.25}
DEFAULT_SPACING = 0.05
ROOT = Path(__file__).resolve().parent.parent


class Peer:
    def __init__(self, kind: str, folder: str) -> None:
        self.process = subprocess.Popen(
            [sys.executable, "-m", "benchmarks.driver_peer", kind, folder],
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=ROOT,
        )  # fmt: skip
        first = self.process.stdout.readline().split()
        if first[:1] != ["url"]:
            raise RuntimeError(f"the {kind} peer did not start: {first}")
        self.url = first[1]
        self.lines: asyncio.Queue = asyncio.Queue()

    def start_reading(self) -> None:
        loop = asyncio.get_running_loop()
        loop.add_reader(self.process.stdout.fileno(), self._read)

    def _read(self) -> None:
        line = self.process.stdout.readline()
        if line.startswith("cmd "):
            _, t, linear, angular = line.split()
            self.lines.put_nowait((float(t), float(linear), float(angular)))

    def drain(self) -> None:
        while not self.lines.empty():
            self.lines.get_nowait()

    async def next_change(self, timeout: float = 5.0) -> tuple[float, float, float]:
        return await asyncio.wait_for(self.lines.get(), timeout)

    def close(self) -> None:
        with contextlib.suppress(Exception):
            asyncio.get_running_loop().remove_reader(self.process.stdout.fileno())
        self.process.stdin.close()
        try:
            self.process.wait(10)
        except subprocess.TimeoutExpired:
            self.process.kill()


async def latency(robot: rhal.Robot, peer: Peer, spacing: float) -> list[float]:
    await robot.drive(0.2, 0.0)  # warm-up: arming, mode changes, first packets
    await peer.next_change(timeout=30.0)
    await asyncio.sleep(0.5)
    delays = []
    for i in range(CHANGES):
        speed = 0.1 if i % 2 else -0.1
        peer.drain()
        sent = time.monotonic()
        await robot.drive(speed, 0.0)
        # A command may reach the wire in parts (one motor, then the other): wait for all.
        while True:
            t, linear, angular = await peer.next_change()
            if linear * speed > 0 and abs(angular) < 1e-6:
                break
        delays.append((t - sent) * 1000.0)
        await asyncio.sleep(spacing)
    return delays


async def telemetry_rate(robot: rhal.Robot, seconds: float = 3.0) -> float:
    await robot.drive(0.1, 0.3)
    changes, last = 0, None
    deadline = time.monotonic() + seconds
    while time.monotonic() < deadline:
        readings = {k: v for k, v in (await robot.sensors()).items() if k != "time"}
        if readings != last:
            changes, last = changes + 1, readings
        await asyncio.sleep(0.005)
    return (changes - 1) / seconds


async def cpu_share(robot: rhal.Robot, seconds: float = 5.0) -> float:
    await robot.drive(0.1, 0.0)
    start_cpu, start = _cpu(), time.monotonic()
    while time.monotonic() - start < seconds:
        with contextlib.suppress(rhal.RhalError):
            await robot.sensors()
        await asyncio.sleep(0.25)
    return 100.0 * (_cpu() - start_cpu) / (time.monotonic() - start)


def _cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


async def measure(kind: str, folder: str, floor: float) -> list[Figure]:
    Path(folder).mkdir(parents=True, exist_ok=True)
    peer = Peer(kind, folder)
    peer.start_reading()
    try:
        async with rhal.connect(peer.url) as robot:
            delays = await latency(robot, peer, SPACING.get(kind, DEFAULT_SPACING))
            rate = await telemetry_rate(robot)
            cpu = await cpu_share(robot)
            await robot.stop()
    finally:
        peer.close()
    median, p90 = statistics.median(delays), statistics.quantiles(delays, n=10)[-1]
    say(f"{kind}: latency median {median:.2f} ms p90 {p90:.2f} ms, {rate:.1f} readings/s,"
        f" CPU {cpu:.2f} %")  # fmt: skip
    return [
        Figure(
            BENCH,
            f"{kind} drive() -> on the wire, median",
            median,
            "ms",
            note=f"{median / floor:.0f}x the pipe baseline",
        ),
        Figure(BENCH, f"{kind} drive() -> on the wire, p90", p90, "ms"),
        Figure(
            BENCH,
            f"{kind} telemetry",
            rate,
            "readings/s",
            note="" if rate else "nothing measured: it reports what it was told",
        ),
        Figure(BENCH, f"{kind} CPU while driving", cpu, "%"),
    ]


async def pipe_baseline() -> float:
    """Write a byte to a pipe, another process timestamps it: the floor of any wire."""
    script = (
        "import os, sys, time\n"
        "while (b := os.read(0, 1)):\n"
        "    print(time.monotonic(), flush=True)\n"
    )
    child = subprocess.Popen([sys.executable, "-c", script], stdin=subprocess.PIPE,
                             stdout=subprocess.PIPE, text=True)  # fmt: skip
    delays = []
    for _ in range(CHANGES):
        sent = time.monotonic()
        os.write(child.stdin.fileno(), b"x")
        delays.append((float(child.stdout.readline()) - sent) * 1000.0)
        await asyncio.sleep(0.01)
    child.stdin.close()
    child.wait()
    return statistics.median(delays)


async def sim_cpu() -> float:
    async with rhal.connect("sim://") as robot:
        return await cpu_share(robot)


async def main() -> list[Figure]:
    floor = await pipe_baseline()
    figures = [
        Figure(BENCH, "baseline: pipe to another process", floor, "ms"),
        Figure(BENCH, "baseline: sim:// CPU (no wire)", await sim_cpu(), "%"),
    ]
    with tempfile.TemporaryDirectory() as folder:
        for kind in KINDS:
            try:
                figures += await measure(kind, str(Path(folder) / kind), floor)
            except Exception as exc:  # one driver failing still reports the others
                say(f"{kind}: could not measure: {exc!r}")
                figures.append(Figure(BENCH, f"{kind}", None, "", note=repr(exc)))
    return figures


def run() -> list[Figure]:
    return asyncio.run(main())


if __name__ == "__main__":
    print_table(run(), title="RHAL drivers")
