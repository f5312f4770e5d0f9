"""Exercises the portal checks (issue 31): Check to checklist, and 25 students checking at once.

    .venv/bin/python -m benchmarks.checks [--quick] [--modes embedded fleet] [--students 25]
        [--repeats 3] [--sims-agents 1] [--runs-at-once N] [--env NAME=VALUE ...]

A 20-second exercise on the boxes world with 3 variants (start poses): the program drives a
circle of 0.33 m for 20 s of its clock, reading sensors() 20 times a second, and ends; the
checks are `no_contact` and `ends_within` 30 s (both pass in every variant; the second's why
says when the program ended, in sim s: what is beyond 20 is its start, on the sim's clock).
A Check runs the program once per variant, each on a fresh check sim of its own, at the
exercise's speed.

1. Check -> checklist, one student alone, at speed 1 (real time), 5 and 10 (the check sims'
   clock and the program's, faster than real time): `POST /api/exercises/{id}/check` (the
   student's API token) -> the attempt `done` with its results (`GET /api/attempts/{id}` every
   20 ms), and -> its first variant's run started; REPEATS times each, median and max.
2. STUDENTS students (made by `POST /api/classes`, each with an API token and a program of
   their own) press Check at once (threads released together) on the exercise at speed 5:
   time from the first request to the last attempt `done` (the teacher's
   `GET /api/exercises/{id}/attempts` every 0.2 s), every attempt recorded and checked (none
   lost, none in error); the server's CPU (% of one CPU) over that window and the machine's,
   the server's peak RSS (VmRSS sampled every 20 ms; fleet: each agent process's too).
   Meanwhile a teacher presses the e-stop of the lab's shared sim (`sim`, not a check sim,
   a program of the teacher's driving it as a real robot would be) and resumes it, once a
   second: `POST /api/robots/sim/estop` -> its answer (the agent answers once the robot has
   stopped), p50 and max, for CALM seconds before the checks and while they run.
Two ways, one after the other: the embedded default (`robotide up` alone: SQLite, in-memory
channel layer, every agent in the server's process) and fleet mode (`robotide up` on this
machine's PostgreSQL and Redis, and two agent processes: the lab sim's, `robotide agent sim`,
and the personal and check sims', `robotide agent --personal-sims`; `--sims-agents 2` starts
two of the latter, which the docs do not provide for: each then serves every check sim).
`--quick`: 10 students, speeds 1 and 10 once each.
Figures are printed, nothing is asserted.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field
from pathlib import Path

import httpx

from benchmarks.common import (
    MB,
    Figure,
    RssSampler,
    median,
    parse_api_time,
    percentile,
    print_table,
    proc_cpu_seconds,
    proc_status,
    say,
)
from benchmarks.fleet import machine_ticks
from tests.appliance import Appliance

BENCH = "checks"
PASSWORD = "check-pass-1234"
SECONDS = 20.0  # the exercise's program runs this long (its own clock: the sim's)
VARIANTS = [  # a circle of 0.33 m from each clears the boxes world's walls and boxes
    {"x": 0.0, "y": 0.0, "theta": math.pi / 2, "hidden": False},
    {"x": 0.6, "y": -0.9, "theta": 0.0, "hidden": True},
    {"x": -0.2, "y": 1.0, "theta": math.pi, "hidden": True},
]
CHECKS = [
    {"kind": "no_contact", "points": 1, "message": "Keep clear of the walls and boxes."},
    {"kind": "ends_within", "seconds": SECONDS + 10, "points": 1},
]
ENDS = 1  # the index of the ends_within check: its why says when the program ended (sim s)
PROGRAM = """\
import time

import robot

bot = robot.Robot()
bot.drive(0.2, 0.6)
end = time.monotonic() + {seconds}
while time.monotonic() < end:
    bot.sensors()
    time.sleep(0.05)
bot.stop()
print("round and round, done")
"""
# The teacher's program on the lab's shared sim: it drives as a class's real robot would.
LAB_PROGRAM = """\
import time

import robot

bot = robot.Robot()
while True:
    bot.drive(0.2, 0.6)
    bot.sensors()
    time.sleep(0.05)
"""
DONE = ("done", "error")
POLL = 0.02  # s between a lone attempt's looks
CLASS_POLL = 0.2  # s between the class's looks
TIMEOUT = 600.0  # s: a deadline for the checks to end, not how long they take


@dataclass
class Options:
    modes: tuple = ("embedded", "fleet")
    students: int = 25
    speeds: tuple = (1, 5, 10)
    repeats: int = 3
    class_speed: float = 5
    calm: float = 8.0  # s of e-stops before the checks
    sims_agents: int = 1  # fleet: `robotide agent --personal-sims` processes
    runs_at_once: int | None = None  # CHECK_RUNS_AT_ONCE (None: the default, 2 x CPUs)
    env: dict = field(default_factory=dict)  # more settings for the appliance
    quick: bool = False


def options_from(argv: list[str] | None) -> Options:
    parser = argparse.ArgumentParser(prog="python -m benchmarks.checks", description=__doc__)
    parser.add_argument("--quick", action="store_true",
                        help="10 students, speeds 1 and 10 once each, 4 s calm")  # fmt: skip
    parser.add_argument("--modes", nargs="+", choices=["embedded", "fleet"])
    parser.add_argument("--students", type=int)
    parser.add_argument("--repeats", type=int)
    parser.add_argument(
        "--sims-agents", type=int, default=1,
        help="fleet: personal sims' agent processes (the docs say one a fleet)",
    )  # fmt: skip
    parser.add_argument("--runs-at-once", type=int, help="CHECK_RUNS_AT_ONCE (2 x CPUs)")
    parser.add_argument(
        "--env", action="append", default=[], metavar="NAME=VALUE",
        help="a setting for the appliance, e.g. ROBOTIDE_RUNS_PER_USER=3",
    )  # fmt: skip
    args = parser.parse_args(argv)
    options = Options()
    if args.quick or os.environ.get("CHECKS_BENCH_QUICK"):
        options = Options(students=10, speeds=(1, 10), repeats=1, calm=4.0, quick=True)
    if args.modes:
        options.modes = tuple(args.modes)
    if args.students:
        options.students = args.students
    if args.repeats:
        options.repeats = args.repeats
    options.sims_agents = args.sims_agents
    options.runs_at_once = args.runs_at_once
    options.env = dict(item.split("=", 1) for item in args.env)
    return options


# -- an appliance, either way ----------------------------------------------------------------


class Setup:
    """A started appliance (embedded or fleet) and the processes whose CPU and memory count."""

    def __init__(self, mode: str, sims_agents: int = 1, env: dict | None = None):
        self.mode, self.sims_agents = mode, sims_agents
        self.data = Path(tempfile.mkdtemp(prefix=f"robotide-bench-checks-{mode}-"))
        self.data.chmod(0o711)
        split = "embedded" if mode == "embedded" else "split"
        self.app = Appliance(self.data, mode=split, extra_env=env)
        self.agents: list = []  # fleet: the personal (and check) sims' agent processes

    def __enter__(self) -> Setup:
        try:
            self.app.start()
            if self.mode == "fleet":
                self.agents = [
                    self.app._spawn("agent", "--personal-sims") for _ in range(self.sims_agents)
                ]
                deadline = time.monotonic() + 120
                # The first serves; any other stands by (robots.agent_lock: one a fleet)
                while not self._agents_up():
                    if time.monotonic() > deadline or self.app._ended():
                        raise RuntimeError("the personal sims' agents did not come up")
                    time.sleep(0.2)
        except Exception:
            print(self.app.logs(), file=sys.stderr)
            self.app.stop()
            shutil.rmtree(self.data, ignore_errors=True)
            raise
        return self

    def _agents_up(self) -> bool:
        first, *others = [log.read_text() for log in self.agent_logs()]
        return "running" in first and all("standing by" in log for log in others)

    def agent_logs(self) -> list[Path]:
        return [self.data / f"agent-{self.app.processes.index(p)}.log" for p in self.agents]

    def __exit__(self, *exc) -> None:
        self.app.stop()
        shutil.rmtree(self.data, ignore_errors=True)

    @property
    def server(self) -> int:
        return self.app.server.pid

    def processes(self) -> dict[str, int]:
        """name -> pid of the processes measured: the server, and fleet's agents."""
        found = {"server": self.server}
        if self.mode == "fleet":
            found["agent sim"] = self.app.agent.pid
            for number, proc in enumerate(self.agents, 1):
                found[f"sims agent {number}"] = proc.pid
        return found


def admin(app: Appliance) -> httpx.Client:
    return httpx.Client(
        base_url=app.url, headers={"Authorization": f"Bearer {app.token}"}, timeout=30
    )


def as_user(app: Appliance, token: str) -> httpx.Client:
    return httpx.Client(base_url=app.url, headers={"Authorization": f"Bearer {token}"},
                        timeout=30)  # fmt: skip


TOKENS = """\
import json
from django.contrib.auth import get_user_model
from classroom.models import OneTimePassword
from robotide.models import ApiToken
names = {names!r}
users = get_user_model().objects.filter(username__in=names)
OneTimePassword.objects.filter(user__in=users).delete()  # signed in, password changed
for user in users:
    user.set_password({password!r})
    user.save()
print("TOKENS " + json.dumps({{u.username: ApiToken.issue(u, "bench")[1] for u in users}}))
"""


def make_class(app: Appliance, teacher: httpx.Client, count: int) -> tuple[int, dict[str, str]]:
    """A class of `count` students made by the API; its id and each student's token."""
    names = [f"Student {number:02d}" for number in range(1, count + 1)]
    answer = teacher.post("/api/classes", json={"name": f"Bench {count}", "students": names})
    answer.raise_for_status()
    made = answer.json()
    usernames = [student["username"] for student in made["students"]]
    out = app.cli("manage", "shell", "-c", TOKENS.format(names=usernames, password=PASSWORD))
    tokens = json.loads(out.split("TOKENS ", 1)[1])
    return made["id"], tokens


def make_exercise(teacher: httpx.Client, group: int, speed: float) -> int:
    body = {
        "title": f"Round and round at speed {speed:g}",
        "text": "Drive in a circle for 20 seconds without touching anything, then stop.",
        "world": "boxes",
        "class": group,
        "languages": ["python"],
        "variants": VARIANTS,
        "checks": CHECKS,
        "starter": "",
        "starter_language": "python",
        "speed": speed,
        "time_limit_s": SECONDS + 20,
    }
    answer = teacher.post("/api/exercises", json=body)
    if answer.status_code != 201:
        raise RuntimeError(f"exercise refused: {answer.status_code} {answer.text}")
    return answer.json()["id"]


def make_program(student: httpx.Client, name: str) -> int:
    body = {"name": name, "language": "python",
            "source": PROGRAM.format(seconds=SECONDS)}  # fmt: skip
    answer = student.post("/api/programs", json=body)
    answer.raise_for_status()
    return answer.json()["id"]


def check(student: httpx.Client, exercise: int, program: int) -> dict:
    answer = student.post(f"/api/exercises/{exercise}/check", json={"program": program})
    if answer.status_code not in (200, 201, 202):
        raise RuntimeError(f"Check refused: {answer.status_code} {answer.text}")
    return answer.json()


# -- 1. Check -> checklist, alone ------------------------------------------------------------


def attempt_runs(teacher: httpx.Client, owner: str, since: float) -> list[dict]:
    """The owner's runs asked since `since` (the teacher is staff: sealed ones too), as
    seconds after `since`: created, started, ended."""
    rows = []
    for run in teacher.get("/api/runs", params={"limit": 200}).json():
        created = parse_api_time(run["created"])
        if run["owner"] == owner and created >= since - 0.5:
            started, ended = parse_api_time(run["started"]), parse_api_time(run["ended"])
            rows.append({
                "created": created - since,
                "started": None if started is None else started - since,
                "ended": None if ended is None else ended - since,
                "state": run["state"],
            })  # fmt: skip
    return sorted(rows, key=lambda row: row["created"])


def one_check(teacher, student: httpx.Client, owner: str, exercise: int, program: int) -> dict:
    wall0, t0 = time.time(), time.perf_counter()
    attempt = check(student, exercise, program)
    answered = time.perf_counter() - t0
    while attempt["state"] not in DONE:
        if time.perf_counter() - t0 > TIMEOUT:
            raise RuntimeError(f"attempt {attempt['id']} still {attempt['state']}")
        time.sleep(POLL)
        attempt = student.get(f"/api/attempts/{attempt['id']}").json()
    done = time.perf_counter() - t0
    runs = attempt_runs(teacher, owner, wall0)
    starts = [run["started"] for run in runs if run["started"] is not None]
    return {
        "answered": answered,
        "done": done,
        "started": min(starts) if starts else None,
        "runs": runs,
        "state": attempt["state"],
        "passed": attempt.get("passed"),
        "results": len(attempt.get("results") or []),
        "error": attempt.get("error") or "",
        "whys": failed_whys([attempt]),
        "attempt": attempt,
    }


def failed_whys(attempts: list[dict]) -> list[str]:
    """The distinct reasons of the checks that failed (numbers masked, so alike ones merge)."""
    whys = set()
    for attempt in attempts:
        for result in attempt.get("results") or []:
            if not result["passed"]:
                whys.add(re.sub(r"\d+(\.\d+)?", "N", result.get("why") or "?"))
    return sorted(whys)


def end_times(attempts: list[dict]) -> list[float]:
    """When each variant's program ended, in sim s from its run's start (the ends_within
    check's why): beyond SECONDS is the program's start (an interpreter, the Robot API's
    sign-in), on the sim's clock."""
    found = []
    for attempt in attempts:
        for result in attempt.get("results") or []:
            match = re.search(r"after (\d+(?:\.\d+)?) s", result.get("why") or "")
            if result["check"] == ENDS and match:
                found.append(float(match.group(1)))
    return found


def ended(attempts: list[dict]) -> str:
    times = end_times(attempts)
    if not times:
        return "programs' ends: none said"
    return (f"programs ended after {min(times):.1f}-{max(times):.1f} sim s"
            f" (median {median(times):.1f}; {SECONDS:g} s of driving)")  # fmt: skip


def spans(runs: list[dict]) -> str:
    """Each run's start -> end, in s after the Check."""
    shown = []
    for run in runs:
        start = "-" if run["started"] is None else f"{run['started']:.1f}"
        end = "-" if run["ended"] is None else f"{run['ended']:.1f}"
        shown.append(f"{start}->{end}")
    return ", ".join(shown)


def alone(setup: Setup, options: Options, teacher, group, tokens) -> list[Figure]:
    figures = []
    name, token = next(iter(tokens.items()))
    with as_user(setup.app, token) as student:
        program = make_program(student, "Round and round, alone")
        for speed in options.speeds:
            exercise = make_exercise(teacher, group, speed)
            rows = [one_check(teacher, student, name, exercise, program)
                    for _ in range(options.repeats)]  # fmt: skip
            done = [row["done"] for row in rows]
            starts = [row["started"] for row in rows if row["started"] is not None]
            states = sorted({f"{row['state']}{'' if row['passed'] else ' (not passed)'}"
                             for row in rows})  # fmt: skip
            errors = sorted({row["error"] for row in rows if row["error"]})
            errors += sorted({why for row in rows for why in row["whys"]})
            shown = ", ".join(f"{d:.2f}" for d in done)
            say(f"  {setup.mode} speed {speed:g}: Check -> done {shown} s; {states} {errors or ''};"
                f" runs {spans(rows[-1]['runs'])}")  # fmt: skip
            note = (f"{len(rows)} checks, max {max(done):.2f} s, {', '.join(states)}; runs"
                    f" (start->end s after the Check): {spans(rows[-1]['runs'])};"
                    f" {ended([row['attempt'] for row in rows])}")  # fmt: skip
            if errors:
                note += f"; errors: {'; '.join(errors)}"
            figures += [
                Figure(BENCH, f"{setup.mode}: speed {speed:g}: Check -> checklist (median)",
                       median(done), "s", note=note),
                Figure(BENCH, f"{setup.mode}: speed {speed:g}: Check -> first run started",
                       median(starts) if starts else None, "s"),
            ]  # fmt: skip
    return figures


# -- 2. the class at once, and the e-stop meanwhile ---------------------------------------------


@dataclass
class Presses:
    """E-stop presses: (when, ms to the answer, status) each."""

    samples: list = field(default_factory=list)
    stop: threading.Event = field(default_factory=threading.Event)

    def run(self, app: Appliance) -> None:
        with admin(app) as client:
            while not self.stop.is_set():
                began, t = time.time(), time.perf_counter()
                try:
                    status = client.post("/api/robots/sim/estop").status_code
                except httpx.HTTPError as exc:
                    status = type(exc).__name__
                self.samples.append((began, (time.perf_counter() - t) * 1000, status))
                if self.stop.wait(0.4):
                    break
                client.post("/api/robots/sim/resume")
                self.stop.wait(max(0.0, began + 1.0 - time.time()))
            client.post("/api/robots/sim/resume")

    def within(self, t0: float, t1: float) -> list[float]:
        return [ms for began, ms, _ in self.samples if t0 <= began <= t1]

    def refused(self) -> list:
        return [status for _, _, status in self.samples if status != 200]


def keep_lab_program_running(app: Appliance, stop: threading.Event) -> None:
    """The teacher's program on `sim`: each e-stop ends it; it is asked again after a resume."""
    with admin(app) as client:
        program = client.post("/api/programs", json={
            "name": "Lab robot at work", "language": "python", "source": LAB_PROGRAM,
        }).json()["id"]  # fmt: skip
        while not stop.is_set():
            answer = client.post(f"/api/programs/{program}/run", json={"robot": "sim"})
            if answer.status_code == 201:
                run = answer.json()["id"]
                while not stop.is_set():
                    if client.get(f"/api/runs/{run}").json().get("ended"):
                        break
                    stop.wait(0.2)
            else:
                stop.wait(0.3)  # held by the e-stop: asked again after the resume
        for run in client.get("/api/runs?state=running").json():
            client.post(f"/api/runs/{run['id']}/stop")


def at_once(setup: Setup, options: Options, teacher, group, tokens) -> list[Figure]:
    app = setup.app
    exercise = make_exercise(teacher, group, options.class_speed)
    students = {name: as_user(app, token) for name, token in tokens.items()}
    programs = {name: make_program(client, "Round and round") for name, client in students.items()}
    presses, lab_stop = Presses(), threading.Event()
    pressing = threading.Thread(target=presses.run, args=(app,), daemon=True)
    lab = threading.Thread(target=keep_lab_program_running, args=(app, lab_stop), daemon=True)
    lab.start()
    calm0 = time.time()
    pressing.start()
    time.sleep(options.calm)  # e-stops with the lab's program alone
    calm1 = time.time()

    pids = setup.processes()
    samplers = {name: RssSampler(pid) for name, pid in pids.items()}
    for sampler in samplers.values():
        sampler.__enter__()
    before_rss = {name: proc_status(pid)["VmRSS"] for name, pid in pids.items()}
    cpu0 = {name: proc_cpu_seconds(pid) for name, pid in pids.items()}
    machine0 = machine_ticks()
    release = threading.Barrier(len(students) + 1)
    asked: dict[str, dict] = {}
    refused: dict[str, str] = {}

    def press_check(name: str) -> None:
        release.wait()
        try:
            asked[name] = check(students[name], exercise, programs[name])
        except Exception as exc:
            refused[name] = str(exc)

    threads = [threading.Thread(target=press_check, args=(name,)) for name in students]
    for thread in threads:
        thread.start()
    release.wait()
    t0, wall0 = time.perf_counter(), time.time()
    for thread in threads:
        thread.join()
    all_asked = time.perf_counter() - t0
    rows: list[dict] = []
    while time.perf_counter() - t0 < TIMEOUT:
        rows = teacher.get(f"/api/exercises/{exercise}/attempts").json()
        if len(rows) >= len(asked) and all(row["state"] in DONE for row in rows):
            break
        time.sleep(CLASS_POLL)
    last = time.perf_counter() - t0
    wall1 = time.time()
    cpu = {name: 100 * (proc_cpu_seconds(pid) - cpu0[name]) / last for name, pid in pids.items()}
    busy1, _ = machine_ticks()
    machine = 100 * (busy1 - machine0[0]) / os.sysconf("SC_CLK_TCK") / last
    for sampler in samplers.values():
        sampler.__exit__(None, None, None)
    presses.stop.set()
    lab_stop.set()
    pressing.join(10)
    lab.join(30)
    for client in students.values():
        client.close()

    states: dict[str, int] = {}
    for row in rows:
        key = row["state"] + ("" if row["state"] != "done" else
                              (", passed" if row["passed"] else ", not passed"))  # fmt: skip
        states[key] = states.get(key, 0) + 1
    results = sum(len(row.get("results") or []) for row in rows)
    errors = sorted({row.get("error") for row in rows if row.get("error")})
    errors += failed_whys(rows)
    calm, busy = presses.within(calm0, calm1), presses.within(wall0, wall1)
    mode = setup.mode
    say(f"  {mode}: {len(asked)} checks asked in {all_asked:.2f} s, {len(refused)} refused;"
        f" last done after {last:.1f} s; {states};"
        f" e-stops calm {len(calm)}, busy {len(busy)}")  # fmt: skip
    recorded = (f"{len(rows)} attempts recorded of {len(students)} asked ({len(refused)} refused"
                f"{': ' + '; '.join(sorted(set(refused.values())))[:300] if refused else ''});"
                f" {', '.join(f'{v} {k}' for k, v in sorted(states.items()))}; {results} results"
                f" (checks x variants: {len(CHECKS) * len(VARIANTS)} each); {ended(rows)}"
                + (f"; errors: {'; '.join(errors)[:300]}" if errors else ""))  # fmt: skip
    n = len(students)
    figures = [
        Figure(BENCH, f"{mode}: {n} checks at once: all asked (answers)", all_asked, "s"),
        Figure(BENCH, f"{mode}: {n} checks at once: first ask -> last result", last, "s",
               note=recorded),
        Figure(BENCH, f"{mode}: {n} checks: server CPU (% of one CPU)", cpu["server"], "%"),
        Figure(BENCH, f"{mode}: {n} checks: machine CPU (% of one CPU, 2 = 200)", machine, "%"),
        Figure(BENCH, f"{mode}: {n} checks: server RSS before", before_rss["server"] / MB, "MB"),
        Figure(BENCH, f"{mode}: {n} checks: server RSS peak", samplers["server"].peak / MB, "MB"),
    ]  # fmt: skip
    for name in pids:
        if name != "server":
            figures += [
                Figure(BENCH, f"{mode}: {n} checks: {name} CPU", cpu[name], "%"),
                Figure(BENCH, f"{mode}: {n} checks: {name} RSS before -> peak",
                       samplers[name].peak / MB, "MB",
                       note=f"before {before_rss[name] / MB:.1f} MB"),
            ]  # fmt: skip
    not_200 = presses.refused()
    figures += [
        Figure(BENCH, f"{mode}: e-stop calm p50 ({len(calm)} presses)", pct(calm, 50), "ms"),
        Figure(BENCH, f"{mode}: e-stop calm max", max(calm) if calm else None, "ms"),
        Figure(BENCH, f"{mode}: e-stop during the checks p50 ({len(busy)} presses)",
               pct(busy, 50), "ms"),
        Figure(BENCH, f"{mode}: e-stop during the checks max", max(busy) if busy else None, "ms",
               note=f"{len(not_200)} presses not 200: {sorted(set(map(str, not_200)))}"
               if not_200 else ""),
    ]  # fmt: skip
    return figures


def pct(values: list[float], p: float) -> float | None:
    return percentile(values, p) if values else None


# -- all of it -------------------------------------------------------------------------------


def measure(mode: str, options: Options) -> list[Figure]:
    say(f"== {BENCH}: {mode}")
    env = dict(options.env)
    if options.runs_at_once:
        env["ROBOTIDE_CHECK_RUNS_AT_ONCE"] = str(options.runs_at_once)
    with Setup(mode, options.sims_agents, env) as setup, admin(setup.app) as teacher:
        group, tokens = make_class(setup.app, teacher, options.students)
        figures = []
        for part in (alone, at_once):
            try:
                figures += part(setup, options, teacher, group, tokens)
            except Exception as exc:
                figures.append(Figure(BENCH, f"{mode}: {part.__name__}: could not run", None, "",
                                      note=repr(exc)))  # fmt: skip
                say(f"  {mode}: {part.__name__} could not run: {exc!r}")
    return figures


def run(argv: list[str] | None = None) -> list[Figure]:
    options = options_from(argv)
    load = os.getloadavg()
    say(f"{BENCH}: {os.cpu_count()} CPUs, load {load[0]:.2f}; modes {', '.join(options.modes)};"
        f" {options.students} students; speeds {options.speeds} x {options.repeats};"
        f" check runs at once {options.runs_at_once or 'default'};"
        f" personal sims' agents (fleet) {options.sims_agents};"
        f" settings {options.env}")  # fmt: skip
    figures = []
    for mode in options.modes:
        try:
            figures += measure(mode, options)
        except Exception as exc:
            figures.append(Figure(BENCH, f"{mode}: could not run", None, "", note=repr(exc)))
            say(f"  {mode}: could not run: {exc!r}")
    return figures


def main(argv: list[str] | None = None) -> int:
    figures = run(argv)
    load = os.getloadavg()
    print_table(figures, title=f"checks (load average now {load[0]:.2f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
