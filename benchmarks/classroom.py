"""A classroom under attack: 30 students at their workbenches on sim robots, a teacher pressing
an e-stop, and one student trying to take the machine from the others (issue 28's figures).

    .venv/bin/python -m benchmarks.classroom [--quick] [--students N] [--seconds S] ...
    .venv/bin/python -m benchmarks classroom          # CLASSROOM_BENCH_QUICK=1 for --quick

One embedded appliance (`robotide up`, SQLite, agents in the server process) serves both
phases, one after the other: calm (the class alone), then attack (the class, and the attacker).
- The class: STUDENTS signed-in students (browser sessions), each with their program's
  workbench open and its console's websocket connected; each presses Run (the workbench's
  save-and-run request) every few seconds on one of ROBOTS sim robots (lab1..), follows the run
  on the console to its end, and between runs GETs the run's page, the program list and the
  workbench (THINK seconds between runs, split among the pages).
- A teacher (staff, API token) presses the e-stop of a robot of its own (`desk`, so the
  presses end no student's run) and resumes it, about once a second: e-stop and resume timed.
- The attacker (a student, on the built-in robot `sim`): (1) a blocks workspace of BLOCKS x
  `controls_if` with 1000 else-ifs each to the blocks-to-Python view, one request after
  another, and saved as a blocks program and run, one run after another; (2) HOGS runs asked
  at once, each holding HOG_MB for a quarter of the phase, asked again as they end; (3) log
  floods (`yes | head -c 200000000`), FLOODS_AT_ONCE at a time, FLOODS in all. The hogs end
  and come back so that a limit on runs at once shares the attacker's turns among all three,
  as his queue orders them. An attack the server refuses or queues is counted as handled; how
  each was answered is printed.
Measured per phase (SECONDS each, after WARM seconds of the class alone): page p50/p99, e-stop
p50/p99, runs' ask -> end, the server's RSS (sampled every 0.1 s: end and peak) and the runs'
(summed over the server's child processes, every second), CPU (% of one CPU) of the server, of
this process (all the clients) and of the machine. Ratios attack / calm in the same run.
Aims (printed, not asserted): e-stop p99 < 100 ms under attack, page p99 within 1.5x of the
calm phase's.
"""

from __future__ import annotations

import argparse
import asyncio
import contextlib
import json
import os
import random
import resource
import subprocess
import sys
import threading
import time
from collections import Counter
from dataclasses import dataclass
from pathlib import Path

from benchmarks.classroom_clients import (
    Attacker,
    AttackPlan,
    Record,
    Session,
    Student,
    teacher,
)
from benchmarks.common import (
    MB,
    ROOT,
    Figure,
    appliance,
    percentile,
    print_table,
    proc_cpu_seconds,
    proc_status,
    say,
)
from benchmarks.fleet import (
    CLK_TCK,
    children_map,
    descendants,
    machine_ticks,
    ready,
)

BENCH = "classroom"
PASSWORD = "class-pass-1234"
ATTACKER_ROBOT = "sim"  # the appliance's own sim robot: no student's runs queue behind his
ESTOP_ROBOT = "desk"

STUDENT_PROGRAM = """\
import time

import robot

bot = robot.Robot()
bot.drive(0.2, 0.0)
time.sleep(0.5)
bot.stop()
for step in range(5):
    print("step", step, "heading", round(bot.sensors()["heading"], 1), flush=True)
"""
HOG_PROGRAM = """\
import time

held = b"x" * ({mb} * 1024 * 1024)
print("holding {mb} MB", flush=True)
time.sleep({hold})
"""
FLOOD_PROGRAM = 'yes "a classroom log flood line" | head -c 200000000\n'
BIG_IF = {"type": "controls_if", "extraState": {"elseIfCount": 1000}}


@dataclass
class Options:
    students: int = 30
    robots: int = 6
    seconds: float = 60.0  # each phase's measured window
    warm: float = 10.0  # the class alone before the calm window
    think: tuple = (4.0, 8.0)  # s between a student's runs, split among the pages
    blocks: int = 300
    hogs: int = 8
    hog_mb: int = 800
    floods_at_once: int = 3
    floods: int = 20
    quick: bool = False


def options_from(argv: list[str] | None) -> Options:
    env = os.environ.get
    quick = env("CLASSROOM_BENCH_QUICK", "") not in ("", "0")
    parser = argparse.ArgumentParser(prog="python -m benchmarks.classroom", description=__doc__)
    parser.add_argument(
        "--quick", action="store_true", default=quick, help="8 students on 2 robots, 20 s phases"
    )
    parser.add_argument("--students", type=int, default=env("CLASSROOM_BENCH_STUDENTS"))
    parser.add_argument("--robots", type=int, default=env("CLASSROOM_BENCH_ROBOTS"))
    parser.add_argument("--seconds", type=float, default=env("CLASSROOM_BENCH_SECONDS"))
    parser.add_argument("--hogs", type=int, default=env("CLASSROOM_BENCH_HOGS"))
    parser.add_argument(
        "--hog-mb",
        type=int,
        default=env("CLASSROOM_BENCH_HOG_MB"),
        help="MB each hog holds (800, less if the machine lacks twice that)",
    )
    parser.add_argument("--floods", type=int, default=env("CLASSROOM_BENCH_FLOODS"))
    parser.add_argument("--blocks", type=int, default=env("CLASSROOM_BENCH_BLOCKS"))
    args = parser.parse_args(argv)
    options = Options(quick=args.quick)
    if args.quick:
        options.students, options.robots, options.seconds, options.warm = 8, 2, 20.0, 5.0
    for name in ("students", "robots", "seconds", "hogs", "hog_mb", "floods", "blocks"):
        value = getattr(args, name)
        if value is not None:
            setattr(options, name, type(getattr(options, name))(value))
    if args.hog_mb is None:
        options.hog_mb = affordable_hog_mb(options.hogs, options.hog_mb)
    return options


def hog_hold(options: Options) -> int:
    """Seconds a hog holds its memory: a quarter of the phase, so its turns come round."""
    return int(max(5, options.seconds // 4))


def affordable_hog_mb(hogs: int, wanted: int) -> int:
    """The hogs together take at most half the memory available now: the machine is shared,
    and what is measured is the server's answer, not the kernel's OOM killer."""
    return max(16, min(wanted, int(mem_available() / MB / 2 / max(hogs, 1))))


def mem_available() -> int:
    with open("/proc/meminfo") as f:
        for line in f:
            if line.startswith("MemAvailable:"):
                return int(line.split()[1]) * 1024
    return 0


# -- memory, sampled in a thread ---------------------------------------------------------------


class Sampler:
    """The server's VmRSS every 0.1 s; every second, the RSS summed over its child processes
    (the runs), and the machine's MemAvailable and busy CPU time.
    Samples are (wall-clock time, bytes or CPU seconds)."""

    def __init__(self, pid: int):
        self.pid = pid
        self.server: list[tuple[float, int]] = []
        self.runs: list[tuple[float, int]] = []
        self.machine_cpu: list[tuple[float, float]] = []
        self.available: list[tuple[float, int]] = []
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._loop, daemon=True)

    def __enter__(self) -> Sampler:
        self._thread.start()
        return self

    def __exit__(self, *exc) -> None:
        self._stop.set()
        self._thread.join()

    def _loop(self) -> None:
        tick = 0
        while not self._stop.is_set():
            now = time.time()
            with contextlib.suppress(OSError, KeyError):
                self.server.append((now, proc_status(self.pid)["VmRSS"]))
            if tick % 10 == 0:
                with contextlib.suppress(OSError):  # the server gone: the phases say so
                    self._each_second(now)
            tick += 1
            self._stop.wait(0.1)

    def _each_second(self, now: float) -> None:
        runs = descendants(self.pid, children_map())
        rss = 0
        for pid in runs:
            with contextlib.suppress(OSError, KeyError):
                rss += proc_status(pid).get("VmRSS", 0)
        self.runs.append((now, rss))
        self.machine_cpu.append((now, machine_ticks()[0] / CLK_TCK))
        self.available.append((now, mem_available()))


def cpu_share(samples: list[tuple[float, float]]) -> float | None:
    """% of one CPU over cumulative (time, CPU seconds) samples."""
    if len(samples) < 2 or samples[-1][0] <= samples[0][0]:
        return None
    return (samples[-1][1] - samples[0][1]) / (samples[-1][0] - samples[0][0]) * 100


def within(samples: list, window: tuple[float, float]) -> list:
    return [s for s in samples if window[0] <= s[0] < window[1]]


# -- setting the class up ------------------------------------------------------------------------


def make_users(app, names: list[str], staff: set[str]) -> dict[str, str]:
    """The users, in one `manage shell`; an API token each."""
    users = [(name, name in staff) for name in names]
    code = (
        "import json\n"
        "from django.contrib.auth import get_user_model\n"
        "from robotide.models import ApiToken\n"
        "tokens = {}\n"
        f"for name, staff in {users!r}:\n"
        f"    user = get_user_model().objects.create_user(name, password={PASSWORD!r},"
        " is_staff=staff)\n"
        "    tokens[name] = ApiToken.issue(user, 'classroom benchmark')[1]\n"
        "print('TOKENS ' + json.dumps(tokens))\n"
    )
    out = app.cli("manage", "shell", "-c", code)
    return json.loads(out.split("TOKENS ", 1)[1])


def add_robots(app, names: list[str]) -> None:
    for name in names:
        answer = app.api("POST", "/api/robots", {"name": name, "url": "sim://"})
        assert answer.status_code == 201, answer.text
    ready(app, ["sim", *names])


# -- the phases ----------------------------------------------------------------------------------


@dataclass
class Phase:
    name: str
    window: tuple[float, float]
    client_cpu: float  # % of one CPU this process used
    server_cpu: float
    load: float  # 1-minute load average at its start


class Classroom:
    def __init__(self, app, options: Options):
        self.app, self.options = app, options
        self.record = Record()
        self.phases: list[Phase] = []

    async def run(self, tokens: dict[str, str], students: list[str]) -> Attacker:
        app, options = self.app, self.options
        robots = [f"lab{n + 1}" for n in range(options.robots)]
        say(f"signing in {len(students)} students, the attacker, opening their consoles")
        class_ = await asyncio.gather(
            *(
                self.student(name, tokens[name], robots[i % len(robots)])
                for i, name in enumerate(students)
            )
        )
        attacker = await self.attacker(tokens["attacker"])
        stop_class, stop_attack = asyncio.Event(), asyncio.Event()
        work = [asyncio.create_task(s.work(stop_class, self.record)) for s in class_]
        presses = teacher(app.url, tokens["teacher"], ESTOP_ROBOT, stop_class, self.record)
        work.append(asyncio.create_task(presses))
        say(f"class at work: {options.warm:g} s warm-up, then {options.seconds:g} s calm")
        await asyncio.sleep(options.warm)
        await self.phase("calm", asyncio.sleep(options.seconds))
        say(f"attack: {options.seconds:g} s")
        attack = asyncio.create_task(attacker.attack(stop_attack))
        await self.phase("attack", asyncio.sleep(options.seconds))
        say("stopping: the class finishes what it was doing, the attacker's runs are stopped")
        stop_class.set()
        stop_attack.set()
        await finish(work + [attack], 120.0)
        await attacker.stop_runs()
        for student in class_:
            await student.close()
        await attacker.close()
        return attacker

    async def student(self, name: str, token: str, robot: str) -> Student:
        session = Session(self.app.url, name, PASSWORD)
        await session.sign_in()
        program = await create_program(session, token, f"{name}'s drive", STUDENT_PROGRAM)
        student = Student(session, program, STUDENT_PROGRAM, robot, self.options.think)
        await student.open_console(self.app.port)
        return student

    async def attacker(self, token: str) -> Attacker:
        options = self.options
        session = Session(self.app.url, "attacker", PASSWORD)
        await session.sign_in()
        view = await create_program(session, token, "Blocks pane", "print(1)\n")
        plan = AttackPlan(
            robot=ATTACKER_ROBOT,
            blocks_json=json.dumps(
                {"blocks": {"languageVersion": 0, "blocks": [BIG_IF] * options.blocks}}
            ),
            hog_source=HOG_PROGRAM.format(mb=options.hog_mb, hold=hog_hold(options)),
            hogs=options.hogs,
            flood_source=FLOOD_PROGRAM,
            floods_at_once=options.floods_at_once,
            floods=options.floods,
        )
        return Attacker(session, token, view, plan)

    async def phase(self, name: str, body) -> None:
        pid = self.app.server.pid
        load = os.getloadavg()[0]
        t0, own0, server0 = time.time(), own_cpu(), proc_cpu_seconds(pid)
        await body
        t1, own1, server1 = time.time(), own_cpu(), proc_cpu_seconds(pid)
        own, server = (own1 - own0) / (t1 - t0) * 100, (server1 - server0) / (t1 - t0) * 100
        self.phases.append(Phase(name, (t0, t1), own, server, load))


async def create_program(session: Session, token: str, name: str, source: str) -> int:
    body = {"name": name, "language": "python", "source": source}
    headers = {"Authorization": f"Bearer {token}"}
    answer = await session.http.post("/api/programs", json=body, headers=headers)
    assert answer.status_code == 201, answer.text
    return answer.json()["id"]


async def finish(tasks: list[asyncio.Task], timeout: float) -> None:
    done, pending = await asyncio.wait(tasks, timeout=timeout)
    for task in pending:
        task.cancel()
    for task in done:
        if task.exception() is not None:
            say(f"a client failed: {task.exception()!r}")


def own_cpu() -> float:
    usage = resource.getrusage(resource.RUSAGE_SELF)
    return usage.ru_utime + usage.ru_stime


# -- figures -------------------------------------------------------------------------------------


def ms_figures(samples: list, good=200) -> dict:
    """n, p50, p99 of (start, ms, answer, ...) samples; how many were answered otherwise than
    `good`, and every answer counted."""
    times = [s[1] for s in samples]
    answers = Counter(s[2] for s in samples)
    return {
        "n": len(times),
        "failed": len(times) - answers[good],
        "answers": answers,
        "p50": percentile(times, 50) if times else None,
        "p99": percentile(times, 99) if times else None,
    }


def others(figures: dict, good=200) -> str:
    """The answers other than `good`, counted: '2 x 502, 1 x ReadTimeout'."""
    counted = [(n, a) for a, n in figures["answers"].most_common() if a != good]
    return ", ".join(f"{n} x {a}" for n, a in counted)


def phase_figures(classroom: Classroom, memory: Sampler, phase: Phase) -> dict:
    record, window = classroom.record, phase.window
    server = [b for _, b in within(memory.server, window)]
    runs = [b for _, b in within(memory.runs, window)]
    available = [b for _, b in within(memory.available, window)]
    asked = within(record.runs, window)
    return {
        "pages": ms_figures(within(record.pages, window)),
        "estop": ms_figures(within(record.estops, window)),
        "resume": ms_figures(within(record.resumes, window)),
        "runs": ms_figures(asked, good="finished"),
        "server end": server[-1] / MB if server else None,
        "server peak": max(server) / MB if server else None,
        "runs peak": max(runs) / MB if runs else None,
        "available min": min(available) / MB if available else None,
        "machine cpu": cpu_share(within(memory.machine_cpu, window)),
    }


def figures_of(classroom: Classroom, memory: Sampler, after_mb: float | None) -> list:
    phases = {p.name: p for p in classroom.phases}
    calm, attack = (phase_figures(classroom, memory, phases[n]) for n in ("calm", "attack"))
    out = []
    for name, f in (("calm", calm), ("attack", attack)):
        out += figures_of_phase(name, f, phases[name])
    page_ratio = ratio(attack["pages"]["p99"], calm["pages"]["p99"])
    out += [
        Figure(BENCH, "ratio attack/calm: page p99", page_ratio, "x", "<= 1.5x",
               None if page_ratio is None else page_ratio <= 1.5),
        Figure(BENCH, "ratio attack/calm: e-stop p99",
               ratio(attack["estop"]["p99"], calm["estop"]["p99"]), "x"),
        Figure(BENCH, "ratio attack/calm: server RSS peak",
               ratio(attack["server peak"], calm["server peak"]), "x"),
        Figure(BENCH, "server growth: attack peak - calm end",
               diff(attack["server peak"], calm["server end"]), "MB"),
        Figure(BENCH, "server RSS 5 s after the attack", after_mb, "MB"),
    ]  # fmt: skip
    return out


def figures_of_phase(name: str, f: dict, phase: Phase) -> list[Figure]:
    pages, estop, runs = f["pages"], f["estop"], f["runs"]
    ended = ", ".join(f"{n} {state}" for state, n in runs["answers"].most_common())
    aim = ()
    if name == "attack":
        aim = ("< 100 ms", None if estop["p99"] is None else estop["p99"] < 100)
    return [
        Figure(BENCH, f"{name}: page p50", pages["p50"], "ms"),
        Figure(BENCH, f"{name}: page p99 ({pages['n']} GETs, {pages['failed']} not 200)",
               pages["p99"], "ms", note=others(pages)),
        Figure(BENCH, f"{name}: e-stop p50", estop["p50"], "ms"),
        Figure(BENCH, f"{name}: e-stop p99 ({estop['n']} presses, {estop['failed']} not 200)",
               estop["p99"], "ms", *aim, note=others(estop)),
        Figure(BENCH, f"{name}: resume p99 ({f['resume']['n']})", f["resume"]["p99"], "ms"),
        Figure(BENCH, f"{name}: run asked -> ended p50 ({runs['n']} runs)", runs["p50"], "ms"),
        Figure(BENCH, f"{name}: run asked -> ended p99 ({runs['failed']} not finished)",
               runs["p99"], "ms", note=ended),
        Figure(BENCH, f"{name}: server RSS at its end", f["server end"], "MB"),
        Figure(BENCH, f"{name}: server RSS peak", f["server peak"], "MB"),
        Figure(BENCH, f"{name}: runs' RSS peak (summed)", f["runs peak"], "MB"),
        Figure(BENCH, f"{name}: machine's MemAvailable, least", f["available min"], "MB"),
        Figure(BENCH, f"{name}: CPU of the server (% of one CPU)", phase.server_cpu, "%"),
        Figure(BENCH, f"{name}: CPU of all the clients (this process)", phase.client_cpu, "%"),
        Figure(BENCH, f"{name}: CPU of the machine, busy ({os.cpu_count()} CPUs)",
               f["machine cpu"], "%"),
        Figure(BENCH, f"{name}: load average (1 min) at its start", phase.load, ""),
    ]  # fmt: skip


def ratio(a, b):
    return a / b if a is not None and b else None


def diff(a, b):
    return a - b if a is not None and b is not None else None


def print_answers(attacker: Attacker, data_dir: Path) -> None:
    say("\nHow the server answered each attack (count x answer, seconds from request to answer):")
    for kind, answers in attacker.answers.items():
        say(f"  {kind}: {len(answers)} answered" + ("" if answers else " (none in the phase)"))
        took: dict[str, list[float]] = {}
        for said, seconds in answers:
            took.setdefault(said, []).append(seconds)
        for said, times in sorted(took.items(), key=lambda kv: -len(kv[1]))[:6]:
            span = f"{min(times):.2f}-{max(times):.2f}" if len(times) > 1 else f"{times[0]:.2f}"
            say(f"    {len(times)} x {said} [{span} s]")
    most = ", ".join(f"{kind} {n}" for kind, n in attacker.most_running.most_common())
    say(f"  most of the attacker's runs seen running at one look (each kind's own most): {most}")
    for reason, count in attacker.queued_reasons.most_common(4):
        say(f"  seen queued ({count} looks): {reason}")
    floods = [run for run, kind in attacker.kind_of.items() if kind == "flood"]
    say(
        f"  the attacker's flood runs' folders on disk: {disk_mb(data_dir, floods):.1f} MB for"
        f" {len(floods)} floods; all runs' folders: {disk_mb(data_dir, None):.1f} MB"
    )


def disk_mb(data_dir: Path, run_ids: list[int] | None) -> float:
    runs = data_dir / "runs"
    folders = [runs / str(r) for r in run_ids] if run_ids is not None else [runs]
    total = 0
    for folder in folders:
        for path in folder.rglob("*"):
            with contextlib.suppress(OSError):
                if path.is_file():
                    total += path.stat().st_size
    return total / MB


def tree_version() -> str:
    """The commit the server's code is from (this tree: see PYTHONPATH in the README), and
    whether the tree has changes beside it."""

    def git(*args) -> str:
        done = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True)
        return done.stdout.strip()

    changed = git("status", "--porcelain", "-uno", "--", ".", ":!benchmarks").splitlines()
    changes = f" + {len(changed)} changed files beside benchmarks/" if changed else ""
    return f"{ROOT} at {git('rev-parse', '--short', 'HEAD')}{changes}"


def run(argv: list[str] | None = None) -> list[Figure]:
    options = options_from(argv if argv is not None else [])
    load = os.getloadavg()
    say(f"classroom: the code of {tree_version()}")
    say(
        f"classroom: {options.students} students on {options.robots} sim robots, a teacher's"
        f" e-stop on {ESTOP_ROBOT!r}, the attacker on {ATTACKER_ROBOT!r}: {options.blocks} big"
        f" ifs, {options.hogs} x {options.hog_mb} MB held {hog_hold(options)} s,"
        f" {options.floods} log floods"
        f" ({options.floods_at_once} at once); phases of {options.seconds:g} s on one server"
        f" (calm, then attack); load average at the start {load[0]:.2f} {load[1]:.2f}"
        f" {load[2]:.2f} on {os.cpu_count()} CPUs (other work on the machine skews the figures)"
    )
    random.seed(28)
    students = [f"student{n + 1:02d}" for n in range(options.students)]
    started = time.monotonic()
    with appliance(BENCH) as app:
        tokens = make_users(app, [*students, "teacher", "attacker"], staff={"teacher"})
        add_robots(app, [f"lab{n + 1}" for n in range(options.robots)] + [ESTOP_ROBOT])
        say(f"appliance, users and robots ready in {time.monotonic() - started:.0f} s")
        classroom = Classroom(app, options)
        with Sampler(app.server.pid) as memory:
            attacker = asyncio.run(classroom.run(tokens, students))
            time.sleep(5.0)
            after = proc_status(app.server.pid)["VmRSS"] / MB
        print_answers(attacker, app.data_dir)
        return figures_of(classroom, memory, after)


if __name__ == "__main__":
    figures = run(sys.argv[1:])
    load = os.getloadavg()[0]
    print_table(figures, title=f"classroom under attack (load average now {load:.2f})")
