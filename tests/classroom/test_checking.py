"""Checking an exercise (classroom.checking, robots.check_sims): a student's Check runs the
program's revision once per variant, each on a fresh check sim with a real agent (embedded
mode's AgentManager, as the web process runs them), each run boxed and logged; the runs'
traces are judged and the attempt is DONE with a row a check and variant. A hidden variant's
run is sealed (its page and log 404 to its student, 200 to the teacher); the check sims are
gone once their runs ended; refusals say why; the server's check-run cap queues runs, saying
so; 25 students' Checks at once all complete.

On the code before this issue there is no classroom.checking, no check sims and no sealed
runs: the tests of them cannot run there (ImportError), see the report."""

import asyncio
import json
import math

import pytest
from asgiref.sync import sync_to_async
from django.contrib.auth.models import Group, User
from django.test import Client

from classroom import checking
from classroom.models import Attempt, AttemptRun, Exercise
from programs.models import Program, Run
from robotide.models import ClassTeacher
from robots import fair_shares, stops
from robots.bus import announce_robot
from robots.models import Robot
from tests.waiting import until
from worlds.documents import builtin_worlds

NORTH = math.pi / 2
# Boxes' kitchen: x -1..0, y 1.4..2.0 (the north wall at 2.0). Each variant faces north below
# it; a hidden one starts further south, where driving a fixed time falls short.
VARIANTS = [
    {"x": -0.5, "y": 0.0, "theta": NORTH, "hidden": False},
    {"x": -0.25, "y": -0.05, "theta": NORTH, "hidden": False},
    {"x": -0.6, "y": -0.6, "theta": NORTH, "hidden": True},
]
CHECKS = [
    {"kind": "reach_zone", "zone": "kitchen", "points": 2, "message": "Get to the kitchen"},
    {"kind": "no_contact", "points": 1, "message": "Do not touch anything"},
]
# Reads its range sensor: stops before the north wall, inside the kitchen, from anywhere (0.5 m
# from the wall, 0.35 m before its body would touch it: a second of sim time to see it in).
PASSES = """\
import time
import robot
bot = robot.Robot()
bot.drive(0.3, 0.0)
while bot.sensors()["range"] > 0.5:
    time.sleep(0.02)
bot.stop()
print("stopped before the wall", flush=True)
"""
# Drives a fixed time: right from the visible variants, short of the kitchen from the hidden.
FIXED_TIME = """\
import time
import robot
bot = robot.Robot()
bot.drive(0.3, 0.0)
time.sleep(5.5)
bot.stop()
"""
# Waits until the test lets it end (a file in its home): how long it runs is the test's.
HOLDS = """\
import os, time
print('going', flush=True)
while not os.path.exists(os.path.expanduser('~/done')):
    time.sleep(0.05)
"""
# Sleeps 30 s of its clock (the sim's: 3 real s at 10x) before it signs in on the Robot API,
# as a slow start would (a busy server's box, its interpreter's imports), then ends at once.
SLOW_START = """\
import time
print("starting", flush=True)
time.sleep(30)
import robot
robot.Robot()
print("signed in", flush=True)
"""
DONE = Attempt.State.DONE


def make_class(students: int | list[str] = ("ana", "ben")):
    """A class taught by tess, its students, and an exercise on the boxes world."""
    group = Group.objects.create(name="class-7a")
    tess = User.objects.create_user("tess")
    ClassTeacher.objects.create(group=group, user=tess)
    names = [f"s{i:02}" for i in range(students)] if isinstance(students, int) else students
    people = [User.objects.create_user(name) for name in names]
    for person in people:
        person.groups.add(group)
    return tess, people, group


def make_exercise(tess, group, **fields) -> Exercise:
    defaults = {
        "owner": tess, "group": group, "title": "Reach the kitchen without touching anything",
        "world": "boxes", "world_document": builtin_worlds()["boxes"], "languages": [],
        "variants": VARIANTS, "checks": CHECKS, "speed": 10.0, "time_limit_s": 30.0,
    }  # fmt: skip
    return Exercise.objects.create(**{**defaults, **fields})


def program(user, source: str, language: str = "python", name: str = "kitchen") -> Program:
    made = Program.objects.create(owner=user, name=name, language=language)
    made.save_source(source, user)
    return made


def signed_in(user) -> Client:
    client = Client()
    client.force_login(user)
    return client


async def done(attempt: Attempt, timeout: float = 180.0) -> Attempt:
    async def finished():
        await sync_to_async(attempt.refresh_from_db)()
        return attempt.state in (DONE, Attempt.State.ERROR)

    await until(finished, timeout=timeout)
    assert attempt.state == DONE, (attempt.state, attempt.error)
    return attempt


def tess_as_staff(tess):
    """The teacher, staff for the lab robot's stop (its default: staff and its owner)."""
    tess.is_staff = True
    tess.save(update_fields=["is_staff"])
    return tess


def live_check_sims() -> int:
    return Robot.objects.filter(checking=True, reaped__isnull=True).count()


def by_check_and_variant(attempt: Attempt) -> dict:
    return {(row["check"], row["variant"]): row for row in attempt.results}


# -- a Check, its runs, its results ---------------------------------------------------------------


@pytest.mark.django_db(transaction=True)
async def test_a_check_runs_every_variant_and_judges_its_trace(agents):
    tess, (ana, ben), group = await sync_to_async(make_class)()
    # Twice real time: a program that reads its sensors to stop in time has room for a busy
    # machine's latency (at 10x, 50 ms of it is 15 cm).
    exercise = await sync_to_async(make_exercise)(tess, group, speed=2.0)
    good = await sync_to_async(program)(ana, PASSES)
    fixed = await sync_to_async(program)(ben, FIXED_TIME)
    start = sync_to_async(checking.start_attempt)
    attempts = [await start(exercise, good, ana), await start(exercise, fixed, ben)]
    assert [a.state for a in attempts] == ["queued", "queued"]
    passed, failed = [await done(attempt) for attempt in attempts]

    # Ana's reads its range sensor: every check in every variant.
    assert passed.passed and passed.score == passed.max_score == 3.0, passed.results
    assert len(passed.results) == 6 and all(row["passed"] for row in passed.results)
    assert passed.number == 1 and passed.revision_number == 1 and not passed.late
    # Ben's drives 5.5 s: the kitchen from the visible variants, not from the hidden one;
    # it touches nothing anywhere. The hidden one's why says so without its pose.
    rows = by_check_and_variant(failed)
    assert not failed.passed and failed.score == 1.0, json.dumps(failed.results, indent=1)
    assert rows[(0, 0)]["passed"] and rows[(0, 1)]["passed"], failed.results
    hidden = rows[(0, 2)]
    assert not hidden["passed"] and hidden["why"].startswith("hidden variant 3: "), hidden
    assert "-0.6" not in hidden["why"] and "kitchen" in hidden["why"], hidden
    assert all(rows[(1, j)]["passed"] for j in range(3)), failed.results
    assert [row["points"] for row in failed.results] == [2.0] * 3 + [1.0] * 3

    # Each run was boxed and logged as any run, on a check sim of its own, now removed.
    runs = await sync_to_async(
        lambda: list(AttemptRun.objects.filter(attempt=failed).select_related("run__robot"))
    )()
    assert [ar.run.sealed for ar in runs] == [False, False, True]
    assert len({ar.run.robot.name for ar in runs}) == 3
    assert all(ar.run.robot.checking and ar.run.owner_id == ben.pk for ar in runs)
    assert all(ar.run.state == "finished" and ar.run.source == FIXED_TIME for ar in runs)
    trace = json.loads((runs[2].run.directory / "trace.json").read_text())
    assert trace["end"]["state"] == "finished" and not trace["end"]["time_limit"], trace["end"]
    assert trace["start"]["y"] == pytest.approx(-0.6) and trace["speed"] == 2.0
    await until(sync_to_async(lambda: live_check_sims() == 0), timeout=60)
    await until(lambda: not any(name.startswith("check-") for name in agents.agents), timeout=60)

    # The hidden variant's run: not to Ben (page, log, API, its robot), to his teacher yes.
    sealed, shown = runs[2].run, runs[0].run
    student, teacher = await sync_to_async(signed_in)(ben), await sync_to_async(signed_in)(tess)
    for path in (f"/runs/{sealed.pk}/", f"/runs/{sealed.pk}/log", f"/api/runs/{sealed.pk}"):
        got = await sync_to_async(student.get)(path)
        assert got.status_code == 404, (path, got.status_code)
        assert (await sync_to_async(teacher.get)(path)).status_code == 200, path
    assert (await sync_to_async(student.get)(f"/runs/{shown.pk}/")).status_code == 200
    robot_page = f"/robots/{sealed.robot.name}/"
    assert (await sync_to_async(student.get)(robot_page)).status_code == 404
    listed = (await sync_to_async(student.get)("/runs/")).content.decode()
    assert f"/runs/{sealed.pk}/" not in listed and f"/runs/{shown.pk}/" in listed


@pytest.mark.django_db(transaction=True)
async def test_a_program_stopped_at_the_time_limit_fails_ends_within(agents):
    """The agent stops a check run when its sim time is up: the trace ends there, says so."""
    tess, (ana,), group = await sync_to_async(make_class)(["ana"])
    exercise = await sync_to_async(make_exercise)(
        tess, group, variants=VARIANTS[:1], time_limit_s=5.0,
        checks=[{"kind": "ends_within", "seconds": 5, "points": 1, "message": ""}],
    )  # fmt: skip
    spins = await sync_to_async(program)(ana, "import time\nwhile True:\n    time.sleep(0.1)\n")
    attempt = await done(await sync_to_async(checking.start_attempt)(exercise, spins, ana))
    (row,) = attempt.results
    assert not row["passed"] and row["why"], row
    run = await sync_to_async(lambda: attempt.runs.get().run)()
    trace = json.loads((run.directory / "trace.json").read_text())
    assert trace["end"]["time_limit"] and trace["end"]["state"] == "stopped", trace["end"]
    assert 5.0 <= trace["end"]["t"] < 8.0, trace["end"]
    assert run.reason.startswith("time limit reached: 5 s of sim time"), run.reason


@pytest.mark.django_db(transaction=True)
async def test_a_check_runs_time_counts_from_its_programs_sign_in_not_its_launch(agents):
    """What a program does before it first signs in on the Robot API (its box's and its
    interpreter's start: real time, which a sim faster than real time multiplies) is not in its
    trace's time nor its time limit's: the robot cannot move before. This one starts 30 s of
    sim time before it signs in, then ends at once: within 20 s, and its lines printed before
    are at time 0. (Before, the trace began before its launch: it ended 30 s late or more.)"""
    tess, (ana,), group = await sync_to_async(make_class)(["ana"])
    exercise = await sync_to_async(make_exercise)(
        tess, group, variants=VARIANTS[:1], time_limit_s=90.0,
        checks=[{"kind": "ends_within", "seconds": 20, "points": 1, "message": ""},
                {"kind": "output_matches", "pattern": "^signed in$", "points": 1,
                 "message": ""}],
    )  # fmt: skip
    slow = await sync_to_async(program)(ana, SLOW_START)
    attempt = await done(await sync_to_async(checking.start_attempt)(exercise, slow, ana))
    run = await sync_to_async(lambda: attempt.runs.get().run)()
    trace = json.loads((run.directory / "trace.json").read_text())
    assert attempt.passed and attempt.score == 2.0, (attempt.results, trace["end"])
    assert trace["end"]["state"] == "finished" and not trace["end"]["time_limit"], trace["end"]
    assert trace["end"]["t"] < 20.0, trace["end"]
    starting, signed = trace["output"]
    assert starting == [0, "starting"], trace["output"]
    assert signed[1] == "signed in" and signed[0] <= trace["end"]["t"], trace["output"]
    assert trace["start"]["y"] == pytest.approx(0.0) and trace["poses"][0][0] == 0, trace


# -- refusals ----------------------------------------------------------------------------------


@pytest.mark.django_db
def test_a_blocks_only_exercise_refuses_a_python_program():
    tess, (ana,), group = make_class(["ana"])
    exercise = make_exercise(tess, group, languages=["blocks"])
    with pytest.raises(checking.CheckRefused) as refused:
        checking.start_attempt(exercise, program(ana, PASSES), ana)
    assert refused.value.status == 422
    assert refused.value.message == "this exercise takes blocks programs only"
    assert not Attempt.objects.exists() and not Robot.objects.filter(checking=True).exists()


@pytest.mark.django_db
def test_a_second_check_while_one_is_going_is_refused_and_others_programs_too():
    tess, (ana, ben), group = make_class()
    exercise = make_exercise(tess, group)
    first = checking.start_attempt(exercise, program(ana, PASSES), ana)
    assert first.state == "queued" and first.runs.count() == 3
    other = make_exercise(tess, group, title="Another")
    with pytest.raises(checking.CheckRefused) as refused:
        checking.start_attempt(other, program(ana, PASSES, name="other"), ana)
    assert refused.value.status == 409 and "still going" in refused.value.message
    with pytest.raises(checking.CheckRefused) as refused:
        checking.start_attempt(exercise, Program.objects.get(owner=ana, name="kitchen"), ben)
    assert refused.value.status == 403
    assert Attempt.objects.count() == 1


@pytest.mark.django_db
def test_the_check_sims_cap_refuses_with_a_clear_message(settings):
    settings.CHECK_SIMS_MAX = 4
    tess, (ana, ben), group = make_class()
    exercise = make_exercise(tess, group)
    checking.start_attempt(exercise, program(ana, PASSES), ana)  # 3 sims
    with pytest.raises(checking.CheckRefused) as refused:
        checking.start_attempt(exercise, program(ben, PASSES), ben)
    assert refused.value.status == 429 and "try again" in refused.value.message
    assert live_check_sims() == 3 and Attempt.objects.filter(student=ben).count() == 0


@pytest.mark.django_db
def test_check_sims_are_in_no_list_nor_cap_and_only_teachers_see_them(settings):
    from robots import sims
    from robots.models import get_robot_for_user, robots_for_user

    settings.SIMS_PER_USER, settings.SIMS_MAX = 1, 1
    tess, (ana, ben), group = make_class()
    staff = User.objects.create_user("staff", is_staff=True)
    checking.start_attempt(make_exercise(tess, group), program(ana, PASSES), ana)
    name = Robot.objects.filter(checking=True).first().name
    assert not sims.sims_of(ana).exists()
    for who in (ana, tess, staff):
        assert name not in robots_for_user(who).values_list("name", flat=True)
    for who in (tess, staff):
        assert get_robot_for_user(who, name).checking
    from django.http import Http404

    for who in (ana, ben):
        with pytest.raises(Http404):
            get_robot_for_user(who, name)
    assert sims.create(ana).personal  # her own sim still fits under both caps


# -- the server's cap of check runs ---------------------------------------------------------------


@pytest.mark.django_db(transaction=True)
async def test_check_runs_beyond_the_servers_cap_wait_queued_saying_why(agents, settings):
    settings.CHECK_RUNS_AT_ONCE = 1
    tess, (ana,), group = await sync_to_async(make_class)(["ana"])
    exercise = await sync_to_async(make_exercise)(tess, group, checks=CHECKS[1:])
    holds = await sync_to_async(program)(ana, HOLDS)
    attempt = await sync_to_async(checking.start_attempt)(exercise, holds, ana)
    runs = await sync_to_async(lambda: [ar.run for ar in attempt.runs.select_related("run")])()

    async def states():
        fresh = await sync_to_async(
            lambda: list(Run.objects.filter(attempt_runs__attempt=attempt))
        )()
        return sorted(run.state for run in fresh), fresh

    await until(lambda: _states_are(states, ["queued", "queued", "running"]), timeout=120)
    _, fresh = await states()
    waiting = [run for run in fresh if run.state == "queued"]
    for run in waiting:
        assert run.reason == "waiting: the server runs at most 1 check run at once", run.reason
        assert fair_shares.reason_shown(run.reason, mine=True) == (
            "waiting: the server checks at most 1 run at once, everyone's"
        )
    await sync_to_async(attempt.refresh_from_db)()
    assert attempt.state == "running"
    # Each let end in turn: the next starts, and the attempt is judged once all ended.
    ids = {run.pk for run in runs}
    for _ in runs:
        agent, run_id = await until(lambda: _one_running(agents, ids), timeout=120)
        active = agent.runs[run_id]
        # its home made (the box is up before its program is in it)
        await until(lambda a=active: a.process.box.folder and a.process.box.folder.is_dir(), 60)
        (active.process.box.folder / "done").write_text("")
        await until(lambda a=agent, r=run_id: r not in a.runs, timeout=60)
    attempt = await done(attempt)
    assert attempt.passed and attempt.score == 1.0, attempt.results


@pytest.mark.django_db(transaction=True)
async def test_a_checks_variants_run_together_whatever_the_students_own_run_limit(agents, settings):
    """A Check's runs are paced by the server's count, not by its student's RUNS_PER_USER:
    with a limit of 1 run a student, the three variants still run at once (they took three
    rounds: a Check of a 20 s exercise took three times 20 s)."""
    settings.RUNS_PER_USER, settings.CHECK_RUNS_AT_ONCE = 1, 3
    tess, (ana,), group = await sync_to_async(make_class)(["ana"])
    exercise = await sync_to_async(make_exercise)(tess, group, checks=CHECKS[1:])
    holds = await sync_to_async(program)(ana, HOLDS)
    attempt = await sync_to_async(checking.start_attempt)(exercise, holds, ana)

    async def settled():
        runs = await sync_to_async(
            lambda: list(Run.objects.filter(attempt_runs__attempt=attempt))
        )()
        waiting = [run.reason for run in runs if run.reason.startswith("waiting: ")]
        return waiting or sorted(run.state for run in runs) == ["running"] * 3

    assert await until(settled, timeout=120) is True, "a variant waited for a share"
    ids = set(await sync_to_async(lambda: [ar.run_id for ar in attempt.runs.all()])())
    for _ in ids:
        agent, run_id = await until(lambda: _one_running(agents, ids), timeout=120)
        active = agent.runs[run_id]
        await until(lambda a=active: a.process.box.folder and a.process.box.folder.is_dir(), 60)
        (active.process.box.folder / "done").write_text("")
        await until(lambda a=agent, r=run_id: r not in a.runs, timeout=60)
    attempt = await done(attempt)
    assert attempt.passed, attempt.results


async def _states_are(states, expected) -> bool:
    return (await states())[0] == expected


def _one_running(manager, run_ids: set[int]):
    """(agent, run id) of a run of ``run_ids`` an agent runs now, or None."""
    for agent, _task in list(manager.agents.values()):
        for run_id in list(agent.runs):
            if run_id in run_ids:
                return agent, run_id
    return None


# -- a class at once -----------------------------------------------------------------------------


@pytest.mark.django_db(transaction=True)
async def test_25_students_checks_submitted_at_once_all_complete(agents, settings):
    """25 Checks at once (one variant each, speed 10, a tiny program): every attempt recorded
    and judged, none lost, every check sim gone after; meanwhile the lab's real robot (a
    shared robot, not a check sim) still answers its emergency stop."""
    tess, students, group = await sync_to_async(make_class)(25)
    exercise = await sync_to_async(make_exercise)(
        tess, group, variants=VARIANTS[:1], checks=CHECKS[1:]
    )
    lab = await sync_to_async(Robot.objects.create)(name="lab", url="sim://")
    await announce_robot("lab")
    await until(lambda: "lab" in agents.agents, timeout=60)
    programs = [await sync_to_async(program)(s, "print('hi')\n") for s in students]
    # Asked together, as a web server's sync views run them: one after the other on its thread
    start = sync_to_async(checking.start_attempt)
    attempts = await asyncio.gather(
        *(start(exercise, p, s) for p, s in zip(programs, students, strict=True))
    )
    staff = await sync_to_async(tess_as_staff)(tess)
    pressed = await sync_to_async(stops.press)(staff, lab, "test")
    assert agents.agents["lab"][0].lease.estopped, "the lab robot's e-stop did not hold"
    assert pressed.kind == "estop"
    finished = [await done(attempt, timeout=600) for attempt in attempts]
    assert all(a.passed and a.score == 1.0 for a in finished), [a.results for a in finished]
    count = sync_to_async(lambda: Attempt.objects.filter(exercise=exercise, state=DONE).count())
    assert await count() == 25
    await until(sync_to_async(lambda: live_check_sims() == 0), timeout=120)


# -- the teacher changes the exercise; which attempt counts ------------------------------------


@pytest.mark.django_db(transaction=True)
async def test_recheck_judges_stored_traces_for_checks_and_runs_again_for_poses(agents):
    tess, (ana,), group = await sync_to_async(make_class)(["ana"])
    exercise = await sync_to_async(make_exercise)(
        tess, group, variants=VARIANTS[:1], checks=CHECKS[1:]
    )
    says_hi = await sync_to_async(program)(ana, "print('hi', flush=True)\n")
    first = await done(await sync_to_async(checking.start_attempt)(exercise, says_hi, ana))
    assert first.passed and first.score == 1.0 and first.exercise_version == 1
    runs = sync_to_async(lambda: Run.objects.filter(owner=ana).count())
    assert await runs() == 1

    # A check added: judged on the stored trace, no run.
    def add_check():
        exercise.checks = [*CHECKS[1:], {"kind": "output_matches", "pattern": "^bye$"}]
        exercise.version += 1
        exercise.save()
        return checking.recheck(exercise)

    touched = await sync_to_async(add_check)()
    assert [a.pk for a in touched] == [first.pk] and await runs() == 1
    await sync_to_async(first.refresh_from_db)()
    assert first.state == DONE and first.exercise_version == 2, first.results
    assert first.score == 1.0 and first.max_score == 2.0 and not first.passed
    assert [row["passed"] for row in first.results] == [True, False]

    # A start pose moved: run again, on a new check sim, and judged again.
    def move_start():
        exercise.variants = [{**VARIANTS[0], "x": -0.4}]
        exercise.checks = CHECKS[1:]
        exercise.version += 1
        exercise.save()
        return checking.recheck(exercise)

    assert [a.pk for a in await sync_to_async(move_start)()] == [first.pk]
    first = await done(first)
    assert first.passed and first.exercise_version == 3 and await runs() == 2
    assert await sync_to_async(checking.recheck)(exercise) == []  # nothing older: untouched


@pytest.mark.django_db
def test_the_counted_attempt_is_the_best_or_the_latest_among_the_first_n():
    tess, (ana,), group = make_class(["ana"])
    exercise = make_exercise(tess, group)
    for number, score in ((1, 1.0), (2, 3.0), (3, 2.0), (4, 0.0)):
        Attempt.objects.create(
            exercise=exercise, student=ana, number=number, state=DONE, score=score
        )
    Attempt.objects.create(exercise=exercise, student=ana, number=5, state="error")
    counted = lambda: checking.counted_attempt(exercise, ana).number  # noqa: E731
    assert counted() == 2
    exercise.counts = Exercise.Counts.LATEST
    assert counted() == 4
    exercise.attempts_allowed = 1
    assert counted() == 1
    exercise.counts, exercise.attempts_allowed = Exercise.Counts.BEST, 3
    assert counted() == 2
    assert checking.counted_attempt(exercise, tess) is None
