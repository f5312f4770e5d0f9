"""Two trees' starts compared in one run, interleaved: for changes smaller than a busy machine's
drift between two runs of start_overhead.

    git worktree add /tmp/before HEAD~1
    .venv/bin/python -m benchmarks.ab_start /tmp/before . [ROUNDS]

Each tree's appliance runs at once (its own `robotide up`, its code from its tree through
PYTHONPATH), driven by a process of its own; the rounds alternate between them (ABBA...). A
round: 30 `GET /api/runs/{id}`, 3 `POST /api/programs/{id}/run` of a one-line shell program,
3 starts with the workbench's console open and 3 with the run's websocket opened after the
request (as start_overhead), and one websocket opened on an ended run. Medians and p90.
"""

import json
import os
import statistics
import subprocess
import sys
import time
from pathlib import Path

ROUNDS = 12
SOURCE = "echo $EPOCHREALTIME\n"


def drive(tree: str) -> None:
    """In a process of its own: this tree's appliance, one round per line on stdin."""
    sys.path.insert(0, tree)
    from benchmarks.common import api_client, appliance, browser_session
    from benchmarks.start_overhead import appliance_run, console_run, probe_connect

    names = ("get", "post", "console", "ws after", "ws open")
    rows: dict[str, list[float]] = {name: [] for name in names}
    with appliance("ab") as app:
        http, web = api_client(app), browser_session(app)
        program = app.create_program("ab", SOURCE, language="shell")["id"]
        ended = http.post(f"/api/programs/{program}/run", json={"robot": "sim"}).json()["id"]
        known: set[str] = {str(ended)}
        time.sleep(0.5)
        print("ready", flush=True)
        for _ in sys.stdin:
            for _ in range(30):
                began = time.perf_counter()
                http.get(f"/api/runs/{ended}").raise_for_status()
                rows["get"].append(time.perf_counter() - began)
            for _ in range(3):
                began = time.perf_counter()
                run = http.post(f"/api/programs/{program}/run", json={"robot": "sim"}).json()
                rows["post"].append(time.perf_counter() - began)
                known.add(str(run["id"]))
                while http.get(f"/api/runs/{run['id']}").json()["state"] in ("starting", "running"):
                    time.sleep(0.01)
                time.sleep(0.15)
            for _ in range(3):
                rows["console"].append(console_run(app, http, web, program, known)["console"])
                time.sleep(0.05)
                rows["ws after"].append(appliance_run(app, http, web, program, known)["ws"])
                time.sleep(0.05)
            rows["ws open"].append(probe_connect(app, http, web, ended)["first"])
            print("done", flush=True)
    print(json.dumps(rows), flush=True)


def compare(trees: list[str], rounds: int) -> None:
    drivers = {}
    for tree in trees:
        env = {**os.environ, "PYTHONPATH": tree}
        drivers[tree] = subprocess.Popen(
            [sys.executable, __file__, "--drive", tree],  # the tree may not have this file
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, cwd=tree, env=env,
        )  # fmt: skip
        if drivers[tree].stdout.readline().strip() != "ready":
            raise SystemExit(f"{tree}: its appliance did not start")
    for n in range(rounds):
        for tree in trees if n % 2 == 0 else trees[::-1]:
            drivers[tree].stdin.write("round\n")
            drivers[tree].stdin.flush()
            drivers[tree].stdout.readline()
    print(f"{rounds} rounds, interleaved; ms, median (p90, n)")
    for tree in trees:
        drivers[tree].stdin.close()
        rows = json.loads(drivers[tree].stdout.readline())
        drivers[tree].wait()
        print(tree)
        for name, values in rows.items():
            values = sorted(v for v in values if v is not None)
            p90 = values[int(len(values) * 0.9)] if values else float("nan")
            median = statistics.median(values) if values else float("nan")
            print(f"  {name:9} {median * 1000:7.2f} ({p90 * 1000:.2f}, {len(values)})")


def main(argv: list[str]) -> None:
    if argv[:1] == ["--drive"]:
        return drive(argv[1])
    if len(argv) not in (2, 3):
        raise SystemExit(__doc__)
    trees = [str(Path(t).resolve()) for t in argv[:2]]
    compare(trees, int(argv[2]) if len(argv) == 3 else ROUNDS)


if __name__ == "__main__":
    main(sys.argv[1:])
