"""Idle memory of the whole appliance: the `robotide up` process (web server, agent, sim robot).

Read from /proc: VmRSS and VmHWM (/proc/PID/status) and PSS (/proc/PID/smaps_rollup, which
shares the pages of shared libraries among the processes that map them) just after start, then
after a signed-in page load of each main page and a couple of API calls, once ~5 s have let it
settle. The embedded appliance is one process (programs it runs are children, not counted; none
runs here). For context, same run: a bare `python3 -c` interpreter waiting on its stdin.

Target: under 120 MB RSS when idle.
"""

import subprocess
import sys
import time

from benchmarks.common import (
    MB,
    Figure,
    appliance,
    print_table,
    proc_rollup,
    proc_status,
    say,
    server_pid,
)

BENCH = "4 idle memory"
TARGET = 120 * MB
SETTLE = 5.0
PAGES = ("/programs/", "/programs/{program}/", "/runs/", "/robots/", "/robots/sim/")


def snapshot(pid: int) -> dict[str, int]:
    status, rollup = proc_status(pid), proc_rollup(pid)
    return {
        "rss": status["VmRSS"],
        "hwm": status["VmHWM"],
        "anon": status.get("RssAnon", 0),
        "pss": rollup.get("Pss", 0),
    }


def bare_interpreter() -> dict[str, int]:
    proc = subprocess.Popen(
        [sys.executable, "-c", "import sys; print(1, flush=True); sys.stdin.read()"],
        stdin=subprocess.PIPE,
        stdout=subprocess.PIPE,
    )
    try:
        proc.stdout.readline()
        return snapshot(proc.pid)
    finally:
        proc.stdin.close()
        proc.wait(timeout=5)
        proc.stdout.close()


def run() -> list[Figure]:
    with appliance("idle") as app:
        pid = server_pid(app)
        started = snapshot(pid)
        say(f"[{BENCH}] page loads and API calls, then {SETTLE:g} s to settle")
        program = app.create_program("bench idle", "print('hello')\n")["id"]
        client = app.session()
        for page in PAGES:
            client.get(page.format(program=program)).raise_for_status()
        client.close()
        for path in ("/api/programs", "/api/runs", "/api/robots/sim/sensors"):
            app.api("GET", path).raise_for_status()
        time.sleep(SETTLE)
        settled = snapshot(pid)
    bare = bare_interpreter()
    rss, pss = settled["rss"], settled["pss"]
    return [
        Figure(
            BENCH,
            "RSS of `robotide up`, idle after use",
            rss / MB,
            "MB",
            f"< {TARGET // MB} MB",
            rss < TARGET,
            f"anonymous {settled['anon'] / MB:.1f} MB; peak so far (VmHWM)"
            f" {settled['hwm'] / MB:.1f} MB",
        ),
        Figure(
            BENCH,
            "PSS of `robotide up`, idle after use",
            pss / MB,
            "MB",
            f"< {TARGET // MB} MB",
            pss < TARGET,
        ),
        Figure(BENCH, "RSS just after start", started["rss"] / MB, "MB"),
        Figure(BENCH, "PSS just after start", started["pss"] / MB, "MB"),
        Figure(
            BENCH,
            "baseline: bare Python interpreter RSS",
            bare["rss"] / MB,
            "MB",
            note=f"{sys.executable} -c, PSS {bare['pss'] / MB:.1f} MB",
        ),
    ]


if __name__ == "__main__":
    print_table(run())
