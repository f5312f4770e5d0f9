"""Output throughput: a program printing N lines as fast as it can, through the appliance.

Two programs: Python printing N numbers with print() (one write per print, as the launcher
runs Python unbuffered), and shell `yes | head -n N` (large block writes). For each:

- captured: lines/s written to the run's log file, from the first line to the final
  "[robotide] ..." line (the file is polled every few ms); then the log's output lines are
  counted and checked against what was printed: any loss is reported;
- live: a websocket client on the run (connected as soon as the run id is known) counts the
  lines it was shown and the "N line(s) not shown live" notes;
- memory: the `robotide up` process's VmRSS is sampled during the flood (peak), VmHWM after;
  and its CPU time for the flood;
- late viewer: a websocket opened on the run once it has ended (a page reload): time to its
  first message (the log tail) and the server's RSS growth meanwhile.

Baseline, same run: the same program file and interpreter, launched from this process with the
launcher's environment, its stdout a pipe read here in 64 KB chunks (the producer's own speed).

Targets: >= 200,000 lines/s captured, none lost; server memory bounded (peak growth over the
pre-flood RSS <= 32 MB, while the log of the Python flood alone is ~20 MB; the same for the
late viewer).
"""

import os
import re
import subprocess
import tempfile
import threading
import time
from pathlib import Path

from benchmarks.common import (
    MB,
    Figure,
    RssSampler,
    api_client,
    appliance,
    print_table,
    proc_cpu_seconds,
    proc_status,
    runs_dir,
    say,
    server_pid,
    session_cookie,
    ws_connect,
)
from programs.languages import get_language
from runbox import launcher

BENCH = "2 throughput"
N = 2_000_000
RUN_TIMEOUT = 60.0
TARGET_RATE = 200_000
MEMORY_GROWTH_BOUND = 32 * MB
PROGRAMS = {
    "python": (
        "import sys, time\n"
        f"N = {N}\n"
        "t = time.perf_counter()\n"
        "for i in range(N):\n"
        "    print(i)\n"
        'sys.stderr.write(f"producer {N / (time.perf_counter() - t):.0f} lines/s\\n")\n'
    ),
    "shell": f"yes | head -n {N}\n",
}
SKIPPED_RE = re.compile(r"(\d+) line\(s\) not shown live")
END_MARKERS = ("[robotide] finished", "[robotide] failed", "[robotide] stopped")


def expected_output(language: str) -> bytes:
    if language == "python":
        return b"".join(b"o %d\n" % i for i in range(N))
    return b"o y\n" * N


class LogPoller(threading.Thread):
    """Notes when the log first has data and when its final robotide line is there."""

    def __init__(self, path: Path, timeout: float):
        super().__init__(daemon=True)
        self.path, self.timeout = path, timeout
        self.first: float | None = None
        self.done: float | None = None

    def run(self) -> None:
        deadline = time.perf_counter() + self.timeout
        while time.perf_counter() < deadline:
            try:
                with open(self.path, "rb") as f:
                    size = f.seek(0, os.SEEK_END)
                    if size and self.first is None:
                        self.first = time.perf_counter()
                    f.seek(max(0, size - 200))
                    tail = f.read()
            except FileNotFoundError:
                tail = b""
            if b"\ns [robotide] " in tail and tail.endswith(b"\n"):
                self.done = time.perf_counter()
                return
            time.sleep(0.002)


class LiveClient(threading.Thread):
    """A websocket client on the run, counting what it is shown."""

    def __init__(self, app, run_id: int, cookie: str, timeout: float):
        super().__init__(daemon=True)
        self.app, self.run_id, self.cookie, self.timeout = app, run_id, cookie, timeout
        self.shown = self.system = self.skipped = self.messages = 0
        self.first: float | None = None
        self.last: float | None = None
        self.ended = False
        self.error: str | None = None
        self.stop = threading.Event()

    def run(self) -> None:
        deadline = time.perf_counter() + self.timeout
        try:
            with ws_connect(self.app, f"/ws/runs/{self.run_id}/", self.cookie) as ws:
                while not self.stop.is_set() and time.perf_counter() < deadline:
                    try:
                        message = ws.recv(timeout=0.25)
                    except TimeoutError:
                        continue
                    self.messages += 1
                    shown = message.count('class="ln o"')
                    if shown:
                        now = time.perf_counter()
                        self.first = self.first or now
                        self.last = now
                        self.shown += shown
                    self.skipped += sum(int(n) for n in SKIPPED_RE.findall(message))
                    self.system += message.count('class="ln s"')
                    if any(marker in message for marker in END_MARKERS):
                        self.ended = True
                        return
        except Exception as exc:  # reported, not raised: the other figures still count
            self.error = repr(exc)


def bare_flood(argv: list[str], env: dict, cwd: str) -> dict:
    """The producer alone: its stdout a pipe read here in 64 KB chunks."""
    t0 = time.perf_counter()
    proc = subprocess.Popen(
        argv,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        env=env,
        cwd=cwd,
    )
    fd = proc.stdout.fileno()
    lines = 0
    first = None
    while chunk := os.read(fd, 1 << 16):
        first = first or time.perf_counter()
        lines += chunk.count(b"\n")
    last = time.perf_counter()
    stderr = proc.stderr.read().decode()
    proc.wait()
    proc.stdout.close()
    proc.stderr.close()
    return {"lines": lines, "rate": lines / (last - first), "total": last - t0, "stderr": stderr}


def appliance_flood(app, http, cookie: str, program_id: int) -> dict:
    pid = server_pid(app)
    time.sleep(0.5)  # let the previous run's aftermath settle
    rss_before = proc_status(pid)["VmRSS"]
    cpu_before = proc_cpu_seconds(pid)
    with RssSampler(pid) as sampler:
        t0 = time.perf_counter()
        response = http.post(f"/api/programs/{program_id}/run", json={"robot": "sim"})
        response.raise_for_status()
        run_id = response.json()["id"]
        live = LiveClient(app, run_id, cookie, RUN_TIMEOUT)
        live.start()
        log_path = runs_dir(app) / str(run_id) / "output.log"
        poller = LogPoller(log_path, RUN_TIMEOUT)
        poller.start()
        poller.join()
        t_done = time.perf_counter()
        run = wait_ended(http, run_id)
        live.join(5.0)
        live.stop.set()
        live.join()
        cpu_after = proc_cpu_seconds(pid)
    time.sleep(1.0)
    status = proc_status(pid)
    data = log_path.read_bytes() if log_path.exists() else b""
    out = b"".join(line + b"\n" for line in data.split(b"\n") if line.startswith(b"o "))
    err = [line[2:].decode() for line in data.split(b"\n") if line.startswith(b"e ")]
    sys_lines = [line[2:].decode() for line in data.split(b"\n") if line.startswith(b"s ")]
    late = late_viewer(app, run_id, cookie)
    return {
        "late": late,
        "run": run,
        "first": poller.first and poller.first - t0,
        "done": poller.done and poller.done - t0,
        "total": t_done - t0,
        "out": out,
        "stderr": "\n".join(err),
        "system": sys_lines,
        "rss_before": rss_before,
        "rss_peak": max(sampler.peak, rss_before),
        "rss_after": status["VmRSS"],
        "hwm": status["VmHWM"],
        "cpu": cpu_after - cpu_before,
        "live": live,
    }


def late_viewer(app, run_id: int, cookie: str) -> dict:
    """The run's websocket opened once it has ended: the whole log is behind it."""
    pid = server_pid(app)
    before = proc_status(pid)["VmRSS"]
    first = None
    with RssSampler(pid, interval=0.005) as sampler:
        t0 = time.perf_counter()
        try:
            with ws_connect(app, f"/ws/runs/{run_id}/", cookie, timeout=RUN_TIMEOUT) as ws:
                ws.recv(timeout=RUN_TIMEOUT)
                first = time.perf_counter() - t0
        except Exception as exc:
            say(f"[{BENCH}] late viewer: {exc!r}")
        time.sleep(0.2)
    return {"first": first, "growth": max(0, sampler.peak - before), "before": before}


def wait_ended(http, run_id: int) -> dict:
    deadline = time.monotonic() + RUN_TIMEOUT
    while True:
        run = http.get(f"/api/runs/{run_id}").json()
        if run["state"] not in ("starting", "running"):
            return run
        if time.monotonic() > deadline:
            http.post(f"/api/runs/{run_id}/stop")
            return run
        time.sleep(0.05)


def producer_rate(stderr: str) -> float | None:
    m = re.search(r"producer (\d+) lines/s", stderr)
    return float(m.group(1)) if m else None


def run() -> list[Figure]:
    with tempfile.TemporaryDirectory(prefix="robotide-bench-flood-") as work:
        return measure(Path(work))


def measure(work: Path) -> list[Figure]:
    figures: list[Figure] = []
    with appliance("throughput") as app:
        http = api_client(app)
        cookie = session_cookie(app)
        # A warm-up run, so lazily imported code does not count as flood memory.
        warm = app.create_program("bench warm-up", "print('warm')\n")
        wait_ended(http, app.run_program(warm["id"])["id"])
        for name, source in PROGRAMS.items():
            language = get_language(name)
            file = work / f"flood{language.extension}"
            file.write_text(source)
            env = launcher.environment(language, work, {})
            say(f"[{BENCH}] {name}: bare producer, {N:,} lines")
            bare = bare_flood(language.command(str(file)), env, str(work))
            say(f"[{BENCH}] {name}: through the appliance, {N:,} lines")
            program = app.create_program(f"bench flood {name}", source, language=name)
            flood = appliance_flood(app, http, cookie, program["id"])
            figures += flood_figures(name, bare, flood)
        http.close()
    return figures


def flood_figures(name: str, bare: dict, flood: dict) -> list[Figure]:
    figures = []
    out = flood["out"]
    captured = out.count(b"\n")
    expected = expected_output(name)
    intact = out == expected
    lost = N - captured
    window = (flood["done"] or 0) - (flood["first"] or 0)
    rate = captured / window if flood["done"] and flood["first"] and window > 0 else None
    run = flood["run"]
    note = f"run {run['state']} ({run['reason']}); log {len(out) / MB:.1f} MB"
    if not intact and lost == 0:
        note += "; the lines are NOT the ones printed (order or content differs)"
    producer = producer_rate(flood["stderr"])
    if producer:
        note += f"; the producer itself reported {producer:,.0f} lines/s"
    figures.append(
        Figure(
            BENCH,
            f"{name}: lines/s captured to the log file",
            rate,
            "lines/s",
            f">= {TARGET_RATE:,}",
            rate is not None and rate >= TARGET_RATE,
            note,
        )
    )
    figures.append(
        Figure(
            BENCH, f"{name}: lines lost in the log (of {N:,})", lost, "", "0", lost == 0 and intact
        )
    )
    bare_note = ""
    if bare_rate := producer_rate(bare["stderr"]):
        bare_note = f"the producer itself reported {bare_rate:,.0f} lines/s"
    figures.append(
        Figure(
            BENCH,
            f"{name}: baseline, bare producer -> pipe",
            bare["rate"],
            "lines/s",
            note=bare_note,
        )
    )
    if rate:
        figures.append(Figure(BENCH, f"{name}: captured / bare", rate / bare["rate"], "x"))
    figures.append(Figure(BENCH, f"{name}: request -> whole log written", flood["done"], "s"))
    live = flood["live"]
    live_window = (live.last - live.first) if live.first and live.last else None
    live_rate = live.shown / window if rate else None
    accounted = live.shown + live.skipped
    live_note = (
        f"{live.messages} messages over {live_window or 0:.2f} s; shown + noted as not"
        f" shown = {accounted:,} of {N:,} output lines"
    )
    if not live.ended:
        live_note += "; the final line never arrived"
    if live.error:
        live_note += f"; websocket error: {live.error}"
    figures.append(
        Figure(BENCH, f"{name}: lines shown live on the websocket", live.shown, "", note=live_note)
    )
    figures.append(
        Figure(BENCH, f"{name}: lines shown live per second of flood", live_rate, "lines/s")
    )
    figures.append(Figure(BENCH, f"{name}: lines noted 'not shown live'", live.skipped, ""))
    growth = flood["rss_peak"] - flood["rss_before"]
    figures.append(
        Figure(
            BENCH,
            f"{name}: server peak RSS growth during the flood",
            growth / MB,
            "MB",
            f"<= {MEMORY_GROWTH_BOUND // MB} MB",
            growth <= MEMORY_GROWTH_BOUND,
            f"RSS before {flood['rss_before'] / MB:.1f} MB, peak"
            f" {flood['rss_peak'] / MB:.1f} MB, 1 s after {flood['rss_after'] / MB:.1f}"
            f" MB, VmHWM (lifetime) {flood['hwm'] / MB:.1f} MB",
        )
    )
    figures.append(
        Figure(BENCH, f"{name}: server CPU per million lines", flood["cpu"] / N * 1e6, "s")
    )
    late = flood["late"]
    figures.append(
        Figure(
            BENCH,
            f"{name}: late viewer, websocket opened -> log tail shown",
            None if late["first"] is None else late["first"] * 1000,
            "ms",
            note="a websocket opened on the run after it ended (e.g. a page reload)",
        )
    )
    figures.append(
        Figure(
            BENCH,
            f"{name}: late viewer, server peak RSS growth",
            late["growth"] / MB,
            "MB",
            f"<= {MEMORY_GROWTH_BOUND // MB} MB",
            late["growth"] <= MEMORY_GROWTH_BOUND,
        )
    )
    return figures


if __name__ == "__main__":
    print_table(run())
