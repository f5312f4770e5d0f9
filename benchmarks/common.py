"""What the benchmarks share: figures and their table, statistics, the appliance, /proc."""

import contextlib
import math
import os
import re
import shutil
import sys
import tempfile
import threading
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
if str(ROOT) not in sys.path:
    sys.path.insert(0, str(ROOT))

from tests.appliance import Appliance, cookie_header  # noqa: E402

MS = 1000.0
MB = 1024 * 1024


@dataclass
class Figure:
    """One measured figure; `ok` is None for a figure that has no target (context only)."""

    bench: str
    name: str
    value: float | None
    unit: str
    target: str = ""
    ok: bool | None = None
    note: str = ""

    def shown(self) -> str:
        if self.value is None:
            return "n/a"
        v = self.value
        if self.unit in ("lines/s", "calls/s"):
            return f"{v:,.0f} {self.unit}"
        if self.unit == "us":
            return f"{v:,.0f} µs"
        if self.unit == "ms":
            return f"{v:.2f} ms" if v < 10 else f"{v:.1f} ms"
        if self.unit == "MB":
            return f"{v:.1f} MB"
        if self.unit == "x":
            return f"{v:.2f}x"
        if self.unit == "":
            return f"{v:,.0f}"
        return f"{v:,.4g} {self.unit}"


def verdict(ok: bool | None) -> str:
    return {True: "yes", False: "NO", None: "-"}[ok]


def print_table(figures: list[Figure], title: str = "robotide benchmarks") -> None:
    headers = ("benchmark", "figure", "value", "target", "meets")
    rows = [(f.bench, f.name, f.shown(), f.target, verdict(f.ok)) for f in figures]
    widths = [
        max(len(h), *(len(r[i]) for r in rows)) if rows else len(h) for i, h in enumerate(headers)
    ]
    line = "  ".join("-" * w for w in widths)
    print()
    print(title)
    print(line)
    print("  ".join(h.ljust(w) for h, w in zip(headers, widths, strict=True)))
    print(line)
    last = None
    for row in rows:
        if last is not None and row[0] != last:
            print()
        last = row[0]
        print("  ".join(c.ljust(w) for c, w in zip(row, widths, strict=True)).rstrip())
    print(line)
    notes = [f for f in figures if f.note]
    if notes:
        print("notes:")
        for f in notes:
            print(f"  {f.bench} / {f.name}: {f.note}")
    judged = [f for f in figures if f.ok is not None]
    met = sum(1 for f in judged if f.ok)
    print(f"{met} of {len(judged)} targets met")
    sys.stdout.flush()


def median(values: list[float]) -> float:
    s = sorted(values)
    n = len(s)
    if not n:
        return math.nan
    return s[n // 2] if n % 2 else (s[n // 2 - 1] + s[n // 2]) / 2


def percentile(values: list[float], p: float) -> float:
    """Nearest-rank percentile (p in 0..100)."""
    s = sorted(values)
    if not s:
        return math.nan
    rank = max(1, math.ceil(p / 100 * len(s)))
    return s[rank - 1]


def say(*args) -> None:
    print(*args, flush=True)


# -- the appliance ---------------------------------------------------------------------------


@contextlib.contextmanager
def appliance(name: str, **extra_env) -> Iterator[Appliance]:
    """A fresh embedded appliance in a temporary data folder, stopped and removed after."""
    data = Path(tempfile.mkdtemp(prefix=f"robotide-bench-{name}-"))
    app = Appliance(data, extra_env={k: str(v) for k, v in extra_env.items()})
    try:
        app.start()
    except Exception:
        print(app.logs(), file=sys.stderr)
        app.stop()
        shutil.rmtree(data, ignore_errors=True)
        raise
    try:
        yield app
    finally:
        app.stop()
        shutil.rmtree(data, ignore_errors=True)


def server_pid(app: Appliance) -> int:
    return app.server.pid


def runs_dir(app: Appliance) -> Path:
    return app.data_dir / "runs"


def api_client(app: Appliance):
    """A keep-alive HTTP client with the admin's API token (one connection for many calls)."""
    import httpx

    return httpx.Client(
        base_url=app.url, headers={"Authorization": f"Bearer {app.token}"}, timeout=10
    )


def ws_connect(app: Appliance, path: str, cookie: str, timeout: float = 5.0):
    from websockets.sync.client import connect

    return connect(
        f"ws://127.0.0.1:{app.port}{path}",
        additional_headers={"Cookie": cookie, "Origin": app.url},
        open_timeout=timeout,
        max_size=None,
        compression=None,
    )


def browser_session(app: Appliance):
    """A signed-in client as a browser's page is: its session cookie, and the CSRF token its
    unsafe requests carry (X-CSRFToken, as the pages' scripts send it)."""
    client = app.session()
    client.headers["X-CSRFToken"] = client.cookies["csrftoken"]
    return client


def session_cookie(app: Appliance) -> str:
    client = app.session()
    try:
        client.get("/programs/")
        return cookie_header(client)
    finally:
        client.close()


def parse_api_time(text: str | None) -> float | None:
    """An API timestamp ('2026-11-22T14:40:54.095Z') as seconds since the epoch."""
    if not text:
        return None
    from datetime import datetime

    return datetime.fromisoformat(text.replace("Z", "+00:00")).timestamp()


# -- /proc ----------------------------------------------------------------------------------


def proc_status(pid: int) -> dict[str, int]:
    """The kB figures of /proc/PID/status (VmRSS, VmHWM, RssAnon, ...), in bytes."""
    values = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            key, _, rest = line.partition(":")
            parts = rest.split()
            if len(parts) == 2 and parts[1] == "kB":
                values[key] = int(parts[0]) * 1024
    return values


def proc_rollup(pid: int) -> dict[str, int]:
    """/proc/PID/smaps_rollup (Rss, Pss, Pss_Anon, ...), in bytes."""
    values = {}
    with open(f"/proc/{pid}/smaps_rollup") as f:
        for line in f:
            m = re.match(r"(\w+):\s+(\d+) kB", line)
            if m:
                values[m.group(1)] = int(m.group(2)) * 1024
    return values


def proc_cpu_seconds(pid: int) -> float:
    """User + system CPU time the process has used so far."""
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


class RssSampler:
    """Samples a process's VmRSS in a thread; `peak` is the largest sample."""

    def __init__(self, pid: int, interval: float = 0.02):
        self.pid, self.interval = pid, interval
        self.peak = 0
        self.samples = 0
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def __enter__(self) -> "RssSampler":
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def _loop(self) -> None:
        while not self._stop.is_set():
            with contextlib.suppress(OSError):
                self.peak = max(self.peak, proc_status(self.pid)["VmRSS"])
                self.samples += 1
            self._stop.wait(self.interval)
