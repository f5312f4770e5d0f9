"""Program start overhead: Run request -> first output line, against the bare interpreter.

Through the appliance, as a browser does it: POST /api/programs/{id}/run with a signed-in
session (and its CSRF token), then at once the run's websocket the answer names (``live``:
/ws/runs/{id}/ with the session's pass, as the run's page has it); the first output line
counts whether it comes in the initial tail or in a later message. A thread watches the run's
log file at the same time for "request -> first line in the log file".

Baseline, measured in the same run and interleaved with it: the same interpreter running the
same program file from this process (spawn -> first line read on a pipe), and the launcher's
chain as the agent builds it, run by benchmarks/boxstart.py (a driver in a process of its own,
no web tier): a runbox Box (bubblewrap, --info-fd/--block-fd, seccomp, the run's tmpfs folder,
the Robot API's tcp:7010 listener opened in the run's network namespace, a shell waiting for
its script), setpriv into the run's account, interpreter, spawned as the supervisor does, with
box.prepare() and go() awaited; with the chain's parts added one by one (bwrap alone, +
setpriv, + prlimit, the box made at the start) and their steps timed, and the box made ahead
as the agent keeps one (go() -> first line). Where the account `nobody` can make user
namespaces, a second driver runs as nobody with the system's python3: the rootless chain
(unshare + runbox.inbox).

The programs print the time at their first statement (Python's time.time(), bash's
$EPOCHREALTIME), which splits the latency into launch (request -> program running), capture
(program -> log file) and streaming (log file -> websocket).

Target: request -> first line on the websocket within 1.2 x the bare start + 15 ms. Measured
two ways, alternating: a websocket opened for the run after the request (the run's own page),
and the workbench's console websocket, open before the request, which the run is attached to.
"""

import contextlib
import ctypes
import json
import os
import pwd
import select
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

from benchmarks.common import (
    MS,
    Figure,
    api_client,
    appliance,
    browser_session,
    cookie_header,
    median,
    parse_api_time,
    percentile,
    print_table,
    runs_dir,
    say,
    ws_connect,
)
from programs.languages import get_language
from runbox import launcher
from runbox.isolation import InForce

BENCH = "1 start overhead"
RUNS = 12
WARMUP = 2
RUN_TIMEOUT = 10.0
END_TIMEOUT = 2.0  # a one-line program that has not ended by then is reported as stuck
SOURCES = {
    "python": "import time; print(time.time())\n",
    "shell": "echo $EPOCHREALTIME\n",
}
DRIVER = Path(__file__).resolve().parent / "boxstart.py"
# The launcher chain's parts, added one by one (root), and the whole chain (root, rootless).
STAGES = ("bare", "bwrap", "bwrap+setpriv", "bwrap+setpriv+prlimit", "box", "ahead")
STAGES_ROOTLESS = ("bare", "box", "ahead")


_libc = ctypes.CDLL(None, use_errno=True)
IN_MODIFY, IN_CREATE, IN_NONBLOCK, IN_CLOEXEC = 0x2, 0x100, 0o4000, 0o2000000


class LogWatcher(threading.Thread):
    """Finds the next run's folder and notes when its log file first holds an output line.

    Woken by inotify, not by polling: a watcher that polls takes CPU from what it measures
    (a 0.3 ms poll is 14% of a core here, on a machine of two)."""

    def __init__(self, runs: Path, known: set[str], timeout: float = RUN_TIMEOUT):
        super().__init__(daemon=True)
        self.runs, self.known, self.timeout = runs, known, timeout
        self.seen_at: float | None = None
        self.data = b""
        self.cancel = threading.Event()
        # Made here, before the request: nothing of the run can come before the watch.
        runs.mkdir(parents=True, exist_ok=True)
        self.fd = _libc.inotify_init1(IN_NONBLOCK | IN_CLOEXEC)
        if self.fd < 0 or self._watch(runs, IN_CREATE) < 0:
            raise OSError(ctypes.get_errno(), f"inotify on {runs}")

    def _watch(self, path: Path, mask: int) -> int:
        return _libc.inotify_add_watch(self.fd, str(path).encode(), mask)

    def run(self) -> None:
        try:
            self._follow()
        finally:
            os.close(self.fd)

    def _follow(self) -> None:
        deadline = time.perf_counter() + self.timeout
        log = None
        while not self.cancel.is_set() and time.perf_counter() < deadline:
            if log is None and (new := [n for n in os.listdir(self.runs) if n not in self.known]):
                log = self.runs / new[0] / "output.log"
                self._watch(log.parent, IN_CREATE | IN_MODIFY)
            if log is not None and self._has_output(log):
                return
            select.select([self.fd], [], [], 0.05)  # an event, or a look at `cancel`
            with contextlib.suppress(BlockingIOError):
                os.read(self.fd, 65536)

    def _has_output(self, log: Path) -> bool:
        try:
            with open(log, "rb") as f:
                data = f.read(4096)
        except FileNotFoundError:
            return False
        if data.startswith(b"o ") or b"\no " in data:
            self.seen_at = time.perf_counter()
            self.data = data
            return True
        return False


def first_output(data: bytes) -> str:
    for line in data.split(b"\n"):
        if line.startswith(b"o "):
            return line[2:].decode(errors="replace")
    return ""


def program_time(text: str) -> float | None:
    try:
        return float(text.strip().split()[0])
    except (ValueError, IndexError):
        return None


def appliance_run(app, http, web, program_id: int, known: set[str]) -> dict:
    """The run's page's way: the request, then the websocket its answer names (``live``: with
    the pass for this session, as the page that shows the run gets it)."""
    runs = runs_dir(app)
    watcher = LogWatcher(runs, set(known))  # a copy: the new run goes into `known` below
    watcher.start()
    wall0, t0 = time.time(), time.perf_counter()
    response = web.post(f"/api/programs/{program_id}/run", json={"robot": "sim"})
    t_response = time.perf_counter()
    response.raise_for_status()
    answer = response.json()
    run_id, live = answer["id"], answer["live"]
    known.add(str(run_id))
    t_ws = t_open = None
    in_tail = False
    try:
        with ws_connect(app, live, cookie_header(web)) as ws:
            t_open = time.perf_counter()
            first = True
            deadline = t0 + RUN_TIMEOUT
            while time.perf_counter() < deadline:
                message = ws.recv(timeout=max(0.01, deadline - time.perf_counter()))
                if 'class="ln o"' in message:
                    t_ws = time.perf_counter()
                    in_tail = first and 'id="log-lines"' in message and "hx-swap-oob" not in message
                    break
                first = False
    finally:
        watcher.join(RUN_TIMEOUT)
        watcher.cancel.set()
    run = wait_ended(http, run_id)
    stmt = program_time(first_output(watcher.data))
    created, started = parse_api_time(run.get("created")), parse_api_time(run.get("started"))

    def wall(t):
        return None if t is None else wall0 + (t - t0)

    return {
        "ws": None if t_ws is None else t_ws - t0,
        "file": None if watcher.seen_at is None else watcher.seen_at - t0,
        "response": t_response - t0,
        "ws_open": None if t_open is None else t_open - t0,
        "in_tail": in_tail,
        "created": None if created is None else created - wall0,
        "started": None if started is None else started - wall0,
        "statement": None if stmt is None else stmt - wall0,
        "capture": None
        if stmt is None or watcher.seen_at is None
        else wall(watcher.seen_at) - stmt,
        "stream": None if t_ws is None or watcher.seen_at is None else t_ws - watcher.seen_at,
        "state": run["state"],
    }


def console_run(app, http, web, program_id: int, known: set[str]) -> dict:
    """The workbench's way: its console websocket is open before the request, and the run
    comes on it (console.attach); the request is the same API call."""
    with ws_connect(app, f"/ws/programs/{program_id}/console/", cookie_header(web)) as ws:
        t0 = time.perf_counter()
        response = web.post(f"/api/programs/{program_id}/run", json={"robot": "sim"})
        response.raise_for_status()
        run_id = response.json()["id"]
        known.add(str(run_id))
        t_line, deadline = None, t0 + RUN_TIMEOUT
        while time.perf_counter() < deadline:
            message = ws.recv(timeout=max(0.01, deadline - time.perf_counter()))
            if 'class="ln o"' in message:
                t_line = time.perf_counter()
                break
    run = wait_ended(http, run_id)
    return {"console": None if t_line is None else t_line - t0, "state": run["state"]}


def wait_ended(http, run_id: int) -> dict:
    """The run once ended; as it is after END_TIMEOUT if it never ends (reported, not waited)."""
    deadline = time.monotonic() + END_TIMEOUT
    while True:
        run = http.get(f"/api/runs/{run_id}").json()
        if run["state"] not in ("starting", "running") or time.monotonic() > deadline:
            return run
        time.sleep(0.01)


def bare_run(argv: list[str], env: dict[str, str], cwd: str) -> dict:
    wall0, t0 = time.time(), time.perf_counter()
    proc = subprocess.Popen(
        argv,
        stdin=subprocess.DEVNULL,
        stdout=subprocess.PIPE,
        env=env,
        cwd=cwd,
        start_new_session=True,
    )
    line = proc.stdout.readline()
    t1 = time.perf_counter()
    proc.wait()
    proc.stdout.close()
    stmt = program_time(line.decode(errors="replace"))
    return {"first": t1 - t0, "statement": None if stmt is None else stmt - wall0}


def probe_connect(app, http, web, run_id: int) -> dict:
    """Costs with no program starting: an API GET, a websocket handshake + first message,
    without a pass (access read first) and with one."""
    t0 = time.perf_counter()
    live = web.get(f"/api/runs/{run_id}").json()["live"]
    t1 = time.perf_counter()
    figures = {"get": t1 - t0}
    for key, path in (("", f"/ws/runs/{run_id}/"), ("pass ", live)):
        began = time.perf_counter()
        with ws_connect(app, path, cookie_header(web)) as ws:
            opened = time.perf_counter()
            ws.recv(timeout=RUN_TIMEOUT)
            figures |= {f"{key}open": opened - began, f"{key}first": time.perf_counter() - began}
    return figures


class BoxDriver:
    """benchmarks/boxstart.py in a process of its own: one boxed start per request."""

    def __init__(self, argv: list[str]):
        self.proc = subprocess.Popen(
            argv, stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd="/"
        )
        ready = self.proc.stdout.readline()
        if not ready:
            self.close()
            raise RuntimeError(f"{' '.join(argv)}: the driver did not start")
        self.rootless = json.loads(ready)["rootless"]

    def start(self, request: dict) -> dict:
        self.proc.stdin.write(json.dumps(request) + "\n")
        self.proc.stdin.flush()
        answer = json.loads(self.proc.stdout.readline() or '{"error": "driver ended"}')
        if "error" in answer:
            raise RuntimeError(f"boxed start ({request['stage']}): {answer['error']}")
        return answer

    def close(self) -> None:
        self.proc.stdin.close()
        try:
            self.proc.wait(timeout=10)
        except subprocess.TimeoutExpired:
            self.proc.kill()


def rootless_driver() -> tuple[BoxDriver | None, str]:
    """The driver as the account nobody (the system's python3), or why there is none."""
    if os.geteuid() != 0:
        return None, "this benchmark is not root: its own driver is the rootless one"
    try:
        nobody = pwd.getpwnam("nobody")
    except KeyError:
        return None, "no account nobody"
    argv = [
        "setpriv", f"--reuid={nobody.pw_uid}", f"--regid={nobody.pw_gid}", "--clear-groups",
        "/usr/bin/python3", "-I", str(DRIVER),
    ]  # fmt: skip
    try:
        return BoxDriver(argv), ""
    except (OSError, RuntimeError, ValueError) as exc:
        return None, f"no rootless driver: {exc}"


def stats(rows: list[dict], key: str) -> tuple[float, float, int]:
    values = [r[key] for r in rows if r.get(key) is not None]
    return median(values), percentile(values, 90), len(values)


def run() -> list[Figure]:
    with tempfile.TemporaryDirectory(prefix="robotide-bench-bare-") as work:
        return measure(Path(work))


def measure(work: Path) -> list[Figure]:
    languages = {name: get_language(name) for name in SOURCES}
    bare_cmds: dict[str, tuple[list[str], dict]] = {}
    box_requests: dict[str, dict] = {}
    for name, language in languages.items():
        file = work / f"prog{language.extension}"
        file.write_text(SOURCES[name])
        env = launcher.environment(language, work, {})
        bare_cmds[f"bare {name}"] = (language.command(str(file)), env)
        # What the agent gives a boxed run (robots/agent.py _launch), less the Robot API's
        # variables (the program does not call it).
        box_requests[name] = {
            "command": language.command("FILE")[:-1],
            "source": SOURCES[name],
            "filename": f"main{language.extension}",
            "env": launcher.environment(language, InForce.HOME, {}, clients_dir=InForce.CLIENTS),
        }
    python = languages["python"].interpreter_path()
    bare_cmds["python3 -u -c print(1)"] = ([python, "-u", "-c", "print(1)"], {"PATH": "/usr/bin"})
    bare_cmds["sh -c 'echo 1'"] = (["/bin/sh", "-c", "echo 1"], {"PATH": "/usr/bin"})

    bare: dict[str, list[dict]] = {k: [] for k in bare_cmds}
    app_rows: dict[str, list[dict]] = {name: [] for name in SOURCES}
    # (driver, language, stage) -> rows
    boxed: dict[tuple[str, str, str], list[dict]] = {}
    drivers = {"root": BoxDriver([sys.executable, str(DRIVER)])}
    rootless, why_not = rootless_driver()
    if rootless is not None:
        drivers["rootless"] = rootless
    try:
        with appliance("start") as app:
            http, web = api_client(app), browser_session(app)
            programs = {
                name: app.create_program(f"bench start {name}", source, language=name)["id"]
                for name, source in SOURCES.items()
            }
            known: set[str] = set()
            say(
                f"[{BENCH}] {WARMUP} warm-up + {RUNS} measured runs per language, interleaved"
                f" with the bare baselines and the launcher chain ({', '.join(drivers)})"
            )
            for i in range(WARMUP + RUNS):
                for key, (argv, env) in bare_cmds.items():
                    row = bare_run(argv, env, str(work))
                    if i >= WARMUP:
                        bare[key].append(row)
                for who, driver in drivers.items():
                    stages = STAGES_ROOTLESS if driver.rootless else STAGES
                    for name, request in box_requests.items():
                        for stage in stages:
                            row = driver.start({**request, "stage": stage})
                            if i >= WARMUP:
                                boxed.setdefault((who, name, stage), []).append(row)
                for name, program_id in programs.items():
                    row = appliance_run(app, http, web, program_id, known)
                    time.sleep(0.02)
                    row.update(console_run(app, http, web, program_id, known))
                    if i >= WARMUP:
                        app_rows[name].append(row)
                    time.sleep(0.02)
            last = max(int(k) for k in known)
            probes = [probe_connect(app, http, web, last) for _ in range(10)]
            http.close()
            web.close()
    finally:
        for driver in drivers.values():
            driver.close()
    figures = appliance_figures(bare_cmds, bare, app_rows, boxed)
    figures += chain_figures(boxed, drivers, why_not)
    for key in ("python3 -u -c print(1)", "sh -c 'echo 1'"):
        figures.append(
            Figure(
                BENCH, f"bare {key} -> first line, median", stats(bare[key], "first")[0] * MS, "ms"
            )
        )
    for label, key in [
        ("API GET /api/runs/{id} round trip (session)", "get"),
        ("websocket open, existing run", "open"),
        ("websocket connect -> first message (log tail), existing run", "first"),
        ("websocket open, existing run, with the API's pass", "pass open"),
        ("websocket connect -> first message, existing run, with the API's pass", "pass first"),
    ]:
        figures.append(Figure(BENCH, f"{label}, median", stats(probes, key)[0] * MS, "ms"))
    return figures


def med_p90(rows: list[dict], key: str) -> str:
    med, p90, n = stats(rows, key)
    return f"median {med * MS:.2f} ms, p90 {p90 * MS:.2f} ms, n={n}"


def target_figures(name: str, rows, key: str, bare: tuple[float, float], note="") -> list:
    """Median and p90 of ``key`` against the target: 1.2 x the bare start's + 15 ms."""
    (value_med, value_p90, n), figures = stats(rows, key), []
    for label, value, base in (("median", value_med, bare[0]), ("p90", value_p90, bare[1])):
        bound = 1.2 * base + 0.015
        figures.append(
            Figure(
                BENCH,
                f"{name}, {label}",
                value * MS,
                "ms",
                f"<= {bound * MS:.1f} ms (1.2 x {base * MS:.1f} + 15)",
                value <= bound,
                f"n={n}" + (f"; {note}" if note else "") if label == "median" else "",
            )
        )
    return figures


def appliance_figures(bare_cmds, bare, app_rows, boxed) -> list[Figure]:
    figures = []
    for name in SOURCES:
        rows = app_rows[name]
        tail = sum(1 for r in rows if r["in_tail"])
        bad = [r["state"] for r in rows if r["state"] != "finished"]
        bad = {state: bad.count(state) for state in sorted(set(bad))}
        note = f"the first line came in the initial log tail in {tail} of {len(rows)} runs"
        if bad:
            note += f"; runs not finished {END_TIMEOUT:g} s after their output, by state: {bad}"
        b_med, b_p90, b_n = stats(bare[f"bare {name}"], "first")
        figures += target_figures(
            f"{name}: request -> first line on websocket", rows, "ws", (b_med, b_p90), note
        )
        figures += target_figures(
            f"{name}: request -> first line on the open workbench console",
            rows,
            "console",
            (b_med, b_p90),
        )
        f_med, f_p90, _ = stats(rows, "file")
        figures.append(
            Figure(BENCH, f"{name}: request -> first line in log file, median", f_med * MS, "ms")
        )
        figures.append(
            Figure(BENCH, f"{name}: request -> first line in log file, p90", f_p90 * MS, "ms")
        )
        figures.append(
            Figure(
                BENCH,
                f"{name}: bare start (same file) -> first line, median",
                b_med * MS,
                "ms",
                note=" ".join(bare_cmds[f"bare {name}"][0][:-1])
                + f" FILE, from this process, n={b_n}",
            )
        )
        figures.append(Figure(BENCH, f"{name}: bare start, p90", b_p90 * MS, "ms"))
        for stage, made, what in (
            ("box", "made at the start", "spawn -> first line, box.prepare() and go() included"),
            ("ahead", "made ahead", "go() -> first line, as the agent's box made ahead"),
        ):
            chain = boxed.get(("root", name, stage), [])
            figures.append(
                Figure(
                    BENCH,
                    f"{name}: launcher chain (box {made}, root), median",
                    stats(chain, "first")[0] * MS,
                    "ms",
                    note=f"benchmarks/boxstart.py: {what}; " + med_p90(chain, "first"),
                )
            )
        # Where the time goes (medians), from the program's own clock at its first statement.
        parts = [
            ("request -> HTTP response", "response"),
            ("request -> run row created", "created"),
            ("request -> run marked running (after spawn)", "started"),
            ("request -> program's first statement", "statement"),
            ("first statement -> log file", "capture"),
            ("log file -> websocket", "stream"),
            ("request -> websocket open", "ws_open"),
        ]
        for label, key in parts:
            value = stats(rows, key)[0]
            figures.append(Figure(BENCH, f"{name}:   {label}, median", value * MS, "ms"))
        figures.append(
            Figure(
                BENCH,
                f"{name}:   bare spawn -> first statement, median",
                stats(bare[f"bare {name}"], "statement")[0] * MS,
                "ms",
            )
        )
    return figures


def chain_figures(boxed, drivers, why_not: str) -> list[Figure]:
    """The launcher chain, part by part, from the drivers (no web tier)."""
    figures = []
    for who, driver in drivers.items():
        stages = STAGES_ROOTLESS if driver.rootless else STAGES
        account = "as nobody, rootless" if driver.rootless else "as root"
        for name in SOURCES:
            base = stats(boxed[(who, name, "bare")], "first")[0]
            for stage in stages:
                rows = boxed[(who, name, stage)]
                med = stats(rows, "first")[0]
                label = {
                    "bare": "bare interpreter (driver's spawn)",
                    "box": "whole chain, box made at the start",
                    "ahead": "whole chain, box made ahead (go -> first line)",
                }.get(stage, stage)
                note = med_p90(rows, "first")
                if stage != "bare":
                    note += f"; +{(med - base) * MS:.2f} ms over the bare interpreter"
                figures.append(
                    Figure(
                        BENCH,
                        f"chain {account}, {name}: {label}, median",
                        med * MS,
                        "ms",
                        note=note,
                    )
                )
            rows = boxed[(who, name, "box")]
            for key, label in (
                ("prepare", "make_box + seccomp fd + the program's command"),
                ("spawn", "subprocess_exec returns"),
                ("open", "box.prepare() + go() in all"),
            ):
                figures.append(
                    Figure(
                        BENCH,
                        f"chain {account}, {name}:   {label}, median",
                        stats(rows, key)[0] * MS,
                        "ms",
                    )  # fmt: skip
                )
            steps = [{k: v for k, v in r["steps"].items()} for r in rows]
            for step in steps[0] if steps else ():
                figures.append(
                    Figure(
                        BENCH,
                        f"chain {account}, {name}:     {step}, median",
                        stats(steps, step)[0] * MS,
                        "ms",
                    )
                )
            figures.append(
                Figure(
                    BENCH,
                    f"chain {account}, {name}:   box.close() after the exit, median",
                    stats(rows, "close")[0] * MS,
                    "ms",
                )
            )
    if why_not:
        figures.append(Figure(BENCH, "chain as nobody, rootless", None, "", note=why_not))
    return figures


if __name__ == "__main__":
    print_table(run())
