"""The MAVLink router (``robotide route``) against references, with the shared router bench.

Drives ``../shared/bench/bench_router.py`` (see its README) in a subprocess with ``--jsonl``:
an emulated vehicle writes a realistic telemetry mix (~39 bytes a frame) into a pseudo-terminal,
the router under test forwards it to a ground-station sink on UDP, which sends COMMAND_LONG back;
every frame is compared byte for byte. Routers, each measured the same way in the same run:
- robotide: ``robotide route {serial}:{baud} --to udp:127.0.0.1:{gcs_port}`` (this tree's code);
- socat-raw: a raw byte forwarder, no framing at all (the ceiling; the ratios are against it);
- py-pymavlink: a plain pymavlink parse-and-resend loop;
- mavproxy: MAVProxy, when it is installed (``make bench-deps``), else reported as skipped.
Per router, three bench invocations:
- ``run --rate 1000``: one-way latency vehicle -> GCS and GCS -> vehicle (p50, p99), loss, CPU;
- ``run --rate max``: the vehicle writes unthrottled (the pty pushes back, so this is the rate
  the router drains), command latency while the vehicle stream is at its maximum, CPU, RSS;
- ``findmax``: a ladder of fixed rates, from CAP / 2**k (the first at or below half the
  unthrottled rate) doubling up to CAP, then two geometric refinements; a rate passes only with
  zero loss, no corrupt frame, >= 97 % of it sent and p99 < 100 ms: the highest rate passed.
Env overrides: GATEWAY_BENCH_ROUTERS (comma list), GATEWAY_BENCH_LAT_SECONDS,
GATEWAY_BENCH_MAX_SECONDS, GATEWAY_BENCH_FINDMAX_SECONDS, GATEWAY_BENCH_CMD_RATE (commands/s),
GATEWAY_BENCH_CAP (highest rate tried, msg/s), GATEWAY_BENCH_SCRIPT (the bench's path).
"""

import contextlib
import importlib.util
import json
import math
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

from benchmarks.common import ROOT, Figure, print_table, say

BENCH = "gateway"
SCRIPT = Path(
    os.environ.get("GATEWAY_BENCH_SCRIPT", ROOT.parent / "shared" / "bench" / "bench_router.py")
)
ROUTERS = os.environ.get("GATEWAY_BENCH_ROUTERS", "robotide,socat-raw,py-pymavlink,mavproxy")
LAT_RATE = 1000
LAT_SECONDS = float(os.environ.get("GATEWAY_BENCH_LAT_SECONDS", 4))
MAX_SECONDS = float(os.environ.get("GATEWAY_BENCH_MAX_SECONDS", 3))
FINDMAX_SECONDS = float(os.environ.get("GATEWAY_BENCH_FINDMAX_SECONDS", 2))
CMD_RATE = float(os.environ.get("GATEWAY_BENCH_CMD_RATE", 200))
CAP = int(os.environ.get("GATEWAY_BENCH_CAP", 400_000))
TIMEOUT = 150  # s, one bench invocation
BASELINE = "socat-raw"
ROBOTIDE = "robotide"
INSTALL = "make bench-deps (or: apt-get install -y socat; .venv/bin/pip install MAVProxy)"


class Rate(Figure):
    """A figure in msg/s, shown as a whole number (common.Figure shows it in 4 digits)."""

    def shown(self) -> str:
        if self.value is not None and self.unit == "msg/s":
            return f"{self.value:,.0f} msg/s"
        return super().shown()


def robotide_command() -> str:
    script = Path(sys.executable).parent / "robotide"
    head = str(script) if script.exists() else "{python} -c 'import robotide.cli as c; c.main()'"
    return head + " route {serial}:{baud} --to udp:127.0.0.1:{gcs_port}"


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def bench(router: str, mode: str, *extra: str, duration: float, workdir: str) -> list[dict]:
    """One bench_router.py invocation; its JSONL rows (its output lines are echoed)."""
    out = Path(workdir) / f"{router}-{mode}-{len(os.listdir(workdir))}.jsonl"
    which = ["--router-cmd", robotide_command()] if router == ROBOTIDE else ["--router", router]
    argv = [sys.executable, str(SCRIPT), mode, *which, "--label", router, "--source", "pty",
            "--duration", str(duration), "--gcs-port", str(free_udp_port()),
            "--ready-timeout", "15", "--workdir", workdir, "--jsonl", str(out), *extra]  # fmt: skip
    # The router imports this tree's code (the venv's editable install may point elsewhere).
    env = dict(os.environ, PYTHONPATH=str(ROOT))
    proc = subprocess.Popen(argv, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True,
                            env=env, cwd=ROOT, start_new_session=True)  # fmt: skip
    # An interrupted bench stops its router and helpers in its `finally`: SIGINT, then SIGKILL.
    timer = _Timer(proc, TIMEOUT)
    try:
        for line in proc.stdout:
            say("   ", line.rstrip())
    finally:
        timer.cancel()
        proc.wait()
    if timer.fired:
        raise RuntimeError(f"bench_router.py {mode} for {router}: over {TIMEOUT} s, stopped")
    rows = [json.loads(line) for line in out.read_text().splitlines()] if out.exists() else []
    for row in rows:
        row["router_log"] = log_tail(row)
    if not rows:
        raise RuntimeError(f"bench_router.py {mode} for {router} exited {proc.returncode}, no row")
    return rows


class _Timer:
    def __init__(self, proc: subprocess.Popen, seconds: float) -> None:
        self.proc, self.fired = proc, False
        self._done = threading.Event()
        self._thread = threading.Thread(target=self._run, args=(seconds,), daemon=True)
        self._thread.start()

    def _run(self, seconds: float) -> None:
        if self._done.wait(seconds):
            return
        self.fired = True
        with contextlib.suppress(ProcessLookupError):
            os.kill(self.proc.pid, signal.SIGINT)
        if not self._done.wait(15):
            with contextlib.suppress(ProcessLookupError):
                os.killpg(self.proc.pid, signal.SIGKILL)

    def cancel(self) -> None:
        self._done.set()
        self._thread.join()


def log_tail(row: dict) -> str:
    """The last line of the router's log in this trial (read before the work folder goes)."""
    with contextlib.suppress(OSError, KeyError, IndexError):
        return (Path(row["tmp"]) / "router.log").read_text().strip().splitlines()[-1]
    return ""


def trial_error(row: dict) -> str:
    """Why a trial failed, with the last line of the router's log."""
    tail = row.get("router_log", "")
    return f"{row.get('error', 'failed')}" + (f"; router log: {tail}" if tail else "")


def measure(router: str, workdir: str) -> dict:
    """The three invocations for one router: {'lat': row, 'max': row, 'findmax': {...}}."""
    lat = bench(router, "run", "--rate", str(LAT_RATE), "--cmd-rate", str(CMD_RATE),
                duration=LAT_SECONDS, workdir=workdir)[-1]  # fmt: skip
    top = bench(router, "run", "--rate", "max", "--cmd-rate", str(CMD_RATE), "--max-cap",
                str(CAP), duration=MAX_SECONDS, workdir=workdir)[-1]  # fmt: skip
    result = {"lat": lat, "max": top, "findmax": None, "findmax_row": None}
    if not top.get("ok"):
        return result
    # From CAP / 2**k, the first at or below half the unthrottled rate: the ladder then tries
    # the cap itself (and, for a cap of 400,000, exactly 100,000 on its way when it matters).
    k = max(0, math.ceil(math.log2(CAP / max(100.0, top["recv_rate"] / 2))))
    start = CAP / 2**k
    rows = bench(router, "findmax", "--start", repr(start), "--factor", "2", "--refine", "2",
                 "--max-loss-pct", "1e-9", "--max-cap", str(CAP),
                 duration=FINDMAX_SECONDS, workdir=workdir)  # fmt: skip
    summary = next((r for r in rows if r.get("mode") == "findmax-result"), None)
    result["findmax"] = summary
    if summary and summary.get("max_sustained"):
        best = int(summary["max_sustained"])
        passed = [r for r in rows if r.get("pass") and int(r["target_rate"]) == best]
        result["findmax_row"] = passed[-1] if passed else None
    return result


def ms(us: float | None) -> float | None:
    return None if us is None or (isinstance(us, float) and math.isnan(us)) else us / 1000.0


def ratio(value: float | None, base: float | None, what: str = "socat-raw") -> str:
    if value is None or not base:
        return ""
    return f"{value / base:.2g}x {what}"


def figures_for(router: str, m: dict, base: dict | None) -> list[Figure]:
    ours = router == ROBOTIDE
    out: list[Figure] = []

    def fig(name, value, unit, target="", ok=None, note=""):
        out.append(Rate(BENCH, f"{router}: {name}", value, unit, target, ok if ours else None,
                        note))  # fmt: skip

    def base_row(key):
        return base.get(key) if base else None

    # -- throughput
    fm, fm_row = m.get("findmax"), m.get("findmax_row")
    best = fm.get("max_sustained") if fm else None
    note = ""
    if fm is not None:
        note = (
            f"the ladder's first failing rung {fm['first_fail']:,.0f}"
            if fm.get("first_fail")
            else f"passed at the cap ({CAP:,}, GATEWAY_BENCH_CAP): at least this"
        )
        if fm_row:
            note += (f"; there: p99 {fm_row['lat_p99_us'] / 1000:.2f} ms, CPU"
                     f" {fm_row['router_cpu_pct']:.0f} %")  # fmt: skip
        base_fm = base_row("findmax")
        if router != BASELINE and base_fm and base_fm.get("max_sustained"):
            capped = "" if base_fm.get("first_fail") else " (at its cap)"
            note += "; " + ratio(best, base_fm["max_sustained"], f"socat-raw{capped}")
    fig("sustained, zero loss (findmax)", best, "msg/s", "≥ 100,000 msg/s",
        best is not None and best >= 100_000, note)  # fmt: skip

    top = m["max"]
    if not top.get("ok"):
        fig("unthrottled stream", None, "msg/s", note=trial_error(top))
    else:
        base_top = base_row("max")
        note = f"sent as fast as the pty drains; loss {top['lost']} ({top['loss_pct']:.3f} %)"
        if top["corrupt"]:
            note += f", {top['corrupt']} corrupt"
        if not top.get("router_alive", True):
            note += f"; the router EXITED during the trial ({top.get('router_log') or 'no log'})"
        if router != BASELINE and base_top and base_top.get("ok"):
            note += "; " + ratio(top["recv_rate"], base_top["recv_rate"])
        fig("unthrottled stream", top["recv_rate"], "msg/s", note=note)
        fig(
            "unthrottled: vehicle->GCS p99",
            ms(top["lat_p99_us"]),
            "ms",
            note=f"p50 {top['lat_p50_us'] / 1000:.2f} ms (queueing in the pty and router)",
        )
        lost_cmds = top["cmd_sent"] - top["cmd_recv"]
        fig("unthrottled: GCS->vehicle command p99", ms(top["cmd_p99_us"]), "ms", "< 5 ms",
            top["cmd_p99_us"] < 5000 and lost_cmds == 0,
            f"p50 {top['cmd_p50_us'] / 1000:.2f} ms; {top['cmd_recv']}/{top['cmd_sent']}"
            f" commands arrived")  # fmt: skip
        fig("unthrottled: CPU", top["router_cpu_pct"], "%")
        fig(
            "RSS (unthrottled, end)",
            top["router_rss_kb"] / 1024,
            "MB",
            note=f"VmHWM {top['router_hwm_kb'] / 1024:.1f} MB",
        )

    # -- latency at 1,000 msg/s
    lat = m["lat"]
    rate = f"{LAT_RATE // 1000}k msg/s"
    if not lat.get("ok"):
        fig(f"{rate}", None, "", note=trial_error(lat))
        return out
    base_lat = base_row("lat")
    base_ok = router != BASELINE and base_lat and base_lat.get("ok")
    note = f"{lat['loss_pct']:.3f} % of {lat['sent']:,}, {lat['corrupt']} corrupt"
    if not lat.get("router_alive", True):
        note += f"; the router EXITED during the trial ({lat.get('router_log') or 'no log'})"
    fig(f"{rate}: loss", lat["lost"], "", "0", lat["lost"] == 0 and lat["corrupt"] == 0, note)
    fig(
        f"{rate}: vehicle->GCS p50",
        ms(lat["lat_p50_us"]),
        "ms",
        note=f"socat-raw {base_lat['lat_p50_us'] / 1000:.2f} ms" if base_ok else "",
    )
    # The target is judged on the whole path (pty and UDP hops included), the stricter reading
    # of "added latency"; what the router adds over socat-raw is in the note.
    note = f"max {lat['lat_max_us'] / 1000:.2f} ms"
    if base_ok:
        added = (lat["lat_p99_us"] - base_lat["lat_p99_us"]) / 1000
        note = f"socat-raw {base_lat['lat_p99_us'] / 1000:.2f} ms ({added:+.2f} ms); " + note
    fig(f"{rate}: vehicle->GCS p99", ms(lat["lat_p99_us"]), "ms", "< 1 ms",
        lat["lat_p99_us"] < 1000, note)  # fmt: skip
    fig(
        f"{rate}: GCS->vehicle p50",
        ms(lat["cmd_p50_us"]),
        "ms",
        note=f"socat-raw {base_lat['cmd_p50_us'] / 1000:.2f} ms" if base_ok else "",
    )
    fig(
        f"{rate}: GCS->vehicle p99",
        ms(lat["cmd_p99_us"]),
        "ms",
        note=f"socat-raw {base_lat['cmd_p99_us'] / 1000:.2f} ms" if base_ok else "",
    )
    fig(
        f"{rate}: CPU",
        lat["router_cpu_pct"],
        "%",
        note=f"socat-raw {base_lat['router_cpu_pct']:.1f} %" if base_ok else "",
    )
    return out


def run() -> list[Figure]:
    if not SCRIPT.exists():
        raise FileNotFoundError(
            f"the shared router bench is not there: {SCRIPT} (set GATEWAY_BENCH_SCRIPT)"
        )
    routers = [r.strip() for r in ROUTERS.split(",") if r.strip()]
    # The baseline first: the others' notes compare with it.
    routers.sort(key=lambda r: r != BASELINE)
    say(
        f"gateway: {SCRIPT}; 1k msg/s for {LAT_SECONDS:g} s, unthrottled {MAX_SECONDS:g} s,"
        f" findmax trials {FINDMAX_SECONDS:g} s (cap {CAP:,} msg/s), {CMD_RATE:g} commands/s"
    )
    measured: dict[str, dict] = {}
    figures: list[Figure] = []
    skipped: list[Figure] = []
    with tempfile.TemporaryDirectory(prefix="robotide-bench-gateway-") as workdir:
        for router in routers:
            if router == "mavproxy" and importlib.util.find_spec("MAVProxy") is None:
                say(f"mavproxy: MAVProxy is not installed in {sys.prefix}; skipped. To measure"
                    f" it: {INSTALL}")  # fmt: skip
                skipped.append(Figure(BENCH, "mavproxy: skipped (reference)", None, "",
                                      note=f"MAVProxy not installed: {INSTALL}"))  # fmt: skip
                continue
            if router == BASELINE and shutil.which("socat") is None:
                say(f"socat-raw: socat is not installed; skipped, no ratios. To add it: {INSTALL}")
                skipped.append(Figure(BENCH, "socat-raw: skipped (baseline)", None, "",
                                      note=f"socat not installed: {INSTALL}"))  # fmt: skip
                continue
            say(f"-- {router}")
            try:
                measured[router] = measure(router, workdir)
            except Exception as exc:  # one router failing still reports the others
                if router == ROBOTIDE:
                    raise
                say(f"{router}: could not measure: {exc!r}")
                skipped.append(Figure(BENCH, f"{router}: could not run", None, "", note=repr(exc)))
    base = measured.get(BASELINE)
    for router in sorted(measured, key=lambda r: (r != ROBOTIDE, r != BASELINE)):
        figures += figures_for(router, measured[router], base)
    return figures + skipped


if __name__ == "__main__":
    print_table(run(), title="MAVLink router")
