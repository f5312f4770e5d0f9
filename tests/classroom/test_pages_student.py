"""The students' exercise pages: the list, an exercise, Start, an attempt's checklist and
replays, "Try on the real robot"; what a student never sees (a hidden variant's pose, its
replay, another student's attempt); the exercise text's Markdown sanitised."""

import json
from html.parser import HTMLParser

import pytest
from django.contrib.auth.models import Group, User
from django.test import Client
from django.utils import timezone

from classroom.markdown import render
from classroom.models import Attempt, AttemptRun, Exercise, Work
from programs.languages import BLOCKS_TEMPLATE
from programs.models import Program, Run
from robotide.models import ClassTeacher
from robots.models import Robot
from worlds.documents import builtin_worlds

pytestmark = pytest.mark.django_db

#: A hidden variant's pose: figures no other number on the pages spells.
HIDDEN = {"x": 1.2345, "y": -0.6789, "theta": 2.3456}
VISIBLE = {"x": -1.1, "y": -1.4, "theta": 1.5708}
HIDDEN_FIGURES = ("1.2345", "-0.6789", "2.3456", "1,2345", "0,6789", "2,3456")
STARTER = "import robot\n\nbot = robot.Robot()\n"


@pytest.fixture
def people():
    """alice and bob in class-a (taught by tina); carol in no class."""
    alice, bob, carol, tina = (
        User.objects.create_user(name, password=f"pw-{name}-123")
        for name in ("alice", "bob", "carol", "tina")
    )
    group = Group.objects.create(name="class-a")
    alice.groups.add(group)
    bob.groups.add(group)
    ClassTeacher.objects.create(group=group, user=tina)
    return {"alice": alice, "bob": bob, "carol": carol, "tina": tina, "group": group}


def signed_in(user) -> Client:
    client = Client()
    client.force_login(user)
    return client


@pytest.fixture
def exercise(people) -> Exercise:
    world = dict(builtin_worlds()["boxes"])
    # The world's own start put where the hidden variant is: the pages leave it out too.
    world["start"] = [dict(HIDDEN)]
    return Exercise.objects.create(
        owner=people["tina"],
        group=people["group"],
        title="Reach the kitchen",
        text="Drive to the **kitchen** without touching anything.",
        world="boxes",
        world_document=world,
        languages=["python"],
        variants=[{**VISIBLE, "hidden": False}, {**HIDDEN, "hidden": True}],
        checks=[
            {"kind": "reach_zone", "zone": "kitchen", "within_s": 30, "points": 2, "message": ""},
            {"kind": "no_contact", "points": 1, "message": "Use the range sensor!"},
        ],
        starter=STARTER,
        starter_language="python",
        due=timezone.now() - timezone.timedelta(days=1),
    )


def trace_for(run: Run, start: dict, contacts=()) -> None:
    poses = [[i * 0.5, start["x"], start["y"] + i * 0.1, start["theta"]] for i in range(10)]
    trace = {
        "version": 1, "speed": 5.0, "radius": 0.15, "start": start, "poses": poses,
        "contacts": list(contacts), "commands": [[0.0, 0.2, 0.0]], "said": [[1.0, "kitchen"]],
        "output": [[0.2, "going"]],
        "end": {"t": 4.5, "state": "finished", "exit_code": 0, "reason": "", "time_limit": False},
        "truncated": False,
    }  # fmt: skip
    run.directory.mkdir(parents=True, exist_ok=True)
    (run.directory / "trace.json").write_text(json.dumps(trace))


@pytest.fixture
def attempt(people, exercise) -> Attempt:
    """alice's first attempt, done: passed in the visible variant, failed in the hidden one."""
    alice = people["alice"]
    program = Program.objects.create(owner=alice, name="kitchen", language="python")
    revision = program.save_source("print('checked revision')\n", alice)
    Work.objects.create(exercise=exercise, student=alice, program=program)
    sim = Robot.objects.create(name="check-1", url="sim://", personal=True, owner=alice)
    attempt = Attempt.objects.create(
        exercise=exercise, student=alice, program=program, revision=revision,
        language="python", source=revision.source, revision_number=revision.number, number=1,
        state=Attempt.State.DONE, score=2, max_score=3, passed=False, finished=timezone.now(),
        results=[
            {"check": 0, "variant": 0, "passed": True, "why": "reached kitchen at 4.0 s",
             "points": 2},
            {"check": 0, "variant": 1, "passed": True, "why": "hidden variant 2: reached kitchen",
             "points": 2},
            {"check": 1, "variant": 0, "passed": True, "why": "no contact", "points": 1},
            {"check": 1, "variant": 1, "passed": False,
             "why": "hidden variant 2: touched a box at 3.5 s", "points": 1},
        ],
    )  # fmt: skip
    for index, variant in enumerate(exercise.variants):
        pose = {k: variant[k] for k in ("x", "y", "theta")}
        run = Run.create_for(program, sim, alice, source=revision.source, sealed=index == 1)
        Run.objects.filter(pk=run.pk).update(state=Run.State.FINISHED, exit_code=0)
        trace_for(run, pose, contacts=[[3.5, pose["x"], pose["y"]]] if index else [])
        AttemptRun.objects.create(
            attempt=attempt, variant=index, hidden=variant["hidden"], pose=pose, run=run,
            checked=True,
        )  # fmt: skip
    program.save_source("print('changed since')\n", alice)  # the program moved on
    return attempt


def no_hidden_figures(text: str) -> None:
    for figure in HIDDEN_FIGURES:
        assert figure not in text, f"{figure} (a hidden pose's) is on the page"


# -- Markdown ---------------------------------------------------------------------------------


class Tags(HTMLParser):
    """Every element of an HTML text, with its attributes, as a browser would parse them."""

    def __init__(self, html: str) -> None:
        super().__init__()
        self.found: list[tuple[str, dict]] = []
        self.feed(html)

    def handle_starttag(self, tag, attrs):
        self.found.append((tag, dict(attrs)))


def assert_safe(html: str) -> None:
    for tag, attrs in Tags(html).found:
        assert tag not in ("script", "style", "iframe", "object", "embed"), html
        assert not [name for name in attrs if name.startswith("on") or name == "style"], html
        for name in ("href", "src"):
            value = (attrs.get(name) or "").strip().lower()
            assert not value.startswith(("javascript:", "data:", "vbscript:")), html
        if tag == "a":
            assert "noopener" in attrs.get("rel", ""), html
        if tag == "img" and attrs.get("src"):
            assert attrs["src"].startswith("/") and not attrs["src"].startswith("//"), html


def test_markdown_is_sanitised():
    html = str(
        render(
            "# Title\n\n<script>alert(1)</script>\n\n<img src=x onerror=alert(2)>\n\n"
            "[bad](javascript:alert(3)) [BAD](JaVaScRiPt:alert(4)) [ok](https://example.org)"
            "\n\n![far](https://elsewhere.example/spy.png) ![near](/static/robotide/icon.svg)"
            " ![data](data:image/png;base64,AAAA) ![proto](//elsewhere.example/x.png)\n\n"
            '<a href="javascript:alert(5)" onclick="x()">raw</a> <style>*{}</style>'
        )
    )
    assert_safe(html)
    found = Tags(html).found
    assert ("h2", {}) in found and ("h1", {}) not in found  # the page has the h1
    links = [attrs["href"] for tag, attrs in found if tag == "a"]
    assert links == ["https://example.org"]  # the javascript: ones are text, not links
    images = [attrs.get("src") for tag, attrs in found if tag == "img"]
    assert images == [None, "/static/robotide/icon.svg", None, None]
    # What was raw HTML is shown as text, never run.
    assert "&lt;script&gt;alert(1)&lt;/script&gt;" in html


def test_exercise_text_is_rendered_sanitised(people, exercise):
    exercise.text = "Go **now** <script>alert(1)</script> [x](javascript:alert(2))"
    exercise.save()
    page = signed_in(people["alice"]).get(f"/exercises/{exercise.pk}/").content.decode()
    assert "<strong>now</strong>" in page
    assert "<script>alert(1)" not in page and 'href="javascript:' not in page


# -- the list and an exercise -----------------------------------------------------------------


def test_exercise_list_shows_class_exercises_score_and_lateness(people, exercise, attempt):
    page = signed_in(people["alice"]).get("/exercises/").content.decode()
    assert "Reach the kitchen" in page and "past due" in page
    assert f"/attempts/{attempt.pk}/" in page and "2 / 3" in page
    other = signed_in(people["carol"]).get("/exercises/").content.decode()
    assert "Reach the kitchen" not in other
    # Its teacher sees it too (and may edit it).
    assert f"/classroom/exercises/{exercise.pk}/edit" in (
        signed_in(people["tina"]).get("/exercises/").content.decode()
    )


def test_exercise_page_never_shows_a_hidden_pose(people, exercise):
    for who in ("alice", "tina"):
        response = signed_in(people[who]).get(f"/exercises/{exercise.pk}/")
        assert response.status_code == 200
        page = response.content.decode()
        no_hidden_figures(page)
        assert "and 1 hidden start pose" in page
        assert "-1.1" in page and "-1.4" in page  # the visible start is drawn
        assert "Reach the zone “kitchen” within 30 s" in page and "2 points" in page
        assert "Never touch a wall or a box" in page
    assert signed_in(people["carol"]).get(f"/exercises/{exercise.pk}/").status_code == 404


def test_start_makes_the_program_from_the_starter_once(people, exercise):
    alice = signed_in(people["alice"])
    response = alice.post(f"/exercises/{exercise.pk}/start")
    work = Work.objects.get(exercise=exercise, student=people["alice"])
    assert response.status_code == 302 and response["Location"] == f"/programs/{work.program_id}/"
    program = work.program
    assert (program.name, program.language, program.source) == (
        "Reach the kitchen", "python", STARTER,
    )  # fmt: skip
    assert program.revisions.count() == 1
    again = alice.post(f"/exercises/{exercise.pk}/start")
    assert again["Location"] == f"/programs/{work.program_id}/"
    assert Work.objects.filter(student=people["alice"]).count() == 1
    page = alice.get(f"/exercises/{exercise.pk}/").content.decode()
    assert "Open my program" in page and f"/programs/{work.program_id}/" in page
    # The workbench shows the exercise and its Check.
    bench = alice.get(f"/programs/{work.program_id}/").content.decode()
    assert 'id="check-button"' in bench and f"/exercises/{exercise.pk}/check" in bench
    assert "Reach the kitchen" in bench
    assert signed_in(people["carol"]).post(f"/exercises/{exercise.pk}/start").status_code == 404


def test_a_program_of_no_exercise_has_no_check(people):
    program = Program.objects.create(owner=people["alice"], name="free", language="python")
    page = signed_in(people["alice"]).get(f"/programs/{program.pk}/").content.decode()
    assert "check-button" not in page and "exercise-bench" not in page


# -- an attempt -------------------------------------------------------------------------------


def test_attempt_page_checklist_without_hidden_poses_or_runs(people, attempt):
    sealed = attempt.runs.get(variant=1).run
    page = signed_in(people["alice"]).get(f"/attempts/{attempt.pk}/").content.decode()
    assert "reached kitchen at 4.0 s" in page
    assert 'hidden start 2</span>: <span class="why">touched a box at 3.5 s' in page
    assert "Use the range sensor!" in page  # the teacher's message: the check failed
    assert "2 of 3 points" in page
    no_hidden_figures(page)
    assert f"/runs/{sealed.pk}/" not in page
    assert f"/attempts/{attempt.pk}/replay/1.json" not in page
    assert f"/attempts/{attempt.pk}/replay/0.json" in page
    teacher = signed_in(people["tina"]).get(f"/attempts/{attempt.pk}/").content.decode()
    assert f"/runs/{sealed.pk}/" in teacher and f"/attempts/{attempt.pk}/replay/1.json" in teacher


def test_replay_json_and_a_hidden_variants_404_to_its_student(people, attempt):
    alice = signed_in(people["alice"])
    replay = alice.get(f"/attempts/{attempt.pk}/replay/0.json")
    assert replay.status_code == 200
    data = replay.json()
    assert data["poses"][0] == [0.0, -1.1, -1.4, 1.5708] and len(data["poses"]) == 10
    assert data["said"] == [[1.0, "kitchen"]] and data["output"] == [[0.2, "going"]]
    assert data["world"]["size"] == {"width": 4.0, "height": 4.0} and data["world"]["start"] == []
    no_hidden_figures(replay.content.decode())
    hidden = alice.get(f"/attempts/{attempt.pk}/replay/1.json")
    assert hidden.status_code == 404
    no_hidden_figures(hidden.content.decode())
    assert alice.get(f"/attempts/{attempt.pk}/replay/7.json").status_code == 404
    # Its teacher sees the hidden one: where it started, the contact.
    shown = signed_in(people["tina"]).get(f"/attempts/{attempt.pk}/replay/1.json").json()
    assert shown["start"] == HIDDEN and shown["contacts"] == [[3.5, 1.2345, -0.6789]]


def test_another_students_attempt_is_404(people, attempt):
    for who in ("bob", "carol"):
        client = signed_in(people[who])
        for path in ("", "body", "checklist", "replay/0.json"):
            assert client.get(f"/attempts/{attempt.pk}/{path}").status_code == 404, (who, path)
        assert client.post(f"/attempts/{attempt.pk}/try").status_code == 404


# -- from sim to robot ------------------------------------------------------------------------


def real_robot(people, name="pioneer-1", url="pioneer:///dev/ttyUSB0") -> Robot:
    robot = Robot.objects.create(name=name, url=url)
    robot.groups.add(people["group"])
    return robot


def test_try_on_the_real_robot_queues_the_checked_revision(people, attempt):
    robot = real_robot(people)
    Robot.objects.create(name="class-sim", url="sim://").groups.add(people["group"])
    alice = signed_in(people["alice"])
    # Not passed: nothing offered, nothing run.
    assert "Try on" not in alice.get(f"/attempts/{attempt.pk}/").content.decode()
    alice.post(f"/attempts/{attempt.pk}/try", {"robot": robot.name})
    assert not Run.objects.filter(robot=robot).exists()

    Attempt.objects.filter(pk=attempt.pk).update(passed=True, score=3)
    page = alice.get(f"/attempts/{attempt.pk}/").content.decode()
    assert "Try on pioneer-1" in page and "class-sim" not in page
    # Its teacher is shown no such button: the run would be the teacher's.
    teacher = signed_in(people["tina"]).get(f"/attempts/{attempt.pk}/").content.decode()
    assert "try-button" not in teacher
    response = alice.post(f"/attempts/{attempt.pk}/try", {"robot": robot.name})
    run = Run.objects.get(robot=robot)
    assert response.status_code == 302 and response["Location"] == f"/runs/{run.pk}/"
    assert run.source == "print('checked revision')\n"  # not the program's text now
    assert run.owner == people["alice"] and run.program_id == attempt.program_id
    assert not run.sealed
    assert Program.objects.get(pk=attempt.program_id).source == "print('changed since')\n"


def test_try_refuses_a_robot_of_no_class_of_the_exercise(people, attempt):
    Attempt.objects.filter(pk=attempt.pk).update(passed=True, score=3)
    elsewhere = Robot.objects.create(name="other-class", url="pioneer:///dev/ttyUSB1")
    elsewhere.groups.add(Group.objects.create(name="class-b"))
    alice = signed_in(people["alice"])
    alice.post(f"/attempts/{attempt.pk}/try", {"robot": elsewhere.name})
    assert not Run.objects.filter(robot=elsewhere).exists()


# -- Check, from the workbench ----------------------------------------------------------------


def blocks_with_loop() -> str:
    source = json.loads(BLOCKS_TEMPLATE)
    body = source["blocks"]["blocks"][0]
    source["blocks"]["blocks"] = [{
        "type": "controls_repeat_ext", "id": "loop", "x": 10, "y": 10,
        "inputs": {"TIMES": {"shadow": {"type": "math_number", "id": "n", "fields": {"NUM": 3}}},
                   "DO": {"block": {k: v for k, v in body.items() if k not in "xy"}}},
    }]  # fmt: skip
    return json.dumps(source)


@pytest.fixture
def blocks_exercise(people) -> Exercise:
    """Static checks only: judged at once, no runs."""
    return Exercise.objects.create(
        owner=people["tina"], group=people["group"], title="Loop it", world="boxes",
        world_document=builtin_worlds()["boxes"], languages=["blocks"],
        variants=[{**VISIBLE, "hidden": False}],
        checks=[{"kind": "uses_block", "block": "loop", "points": 3, "message": "Repeat it!"},
                {"kind": "max_blocks", "count": 10, "points": 1, "message": ""}],
        starter=BLOCKS_TEMPLATE, starter_language="blocks",
    )  # fmt: skip


FETCH = {"HTTP_X_REQUESTED_WITH": "fetch"}


def test_check_from_the_workbench(people, blocks_exercise):
    alice = signed_in(people["alice"])
    url = f"/exercises/{blocks_exercise.pk}/check"
    # Not started: nothing to check.
    assert alice.post(url, **FETCH).status_code == 400
    alice.post(f"/exercises/{blocks_exercise.pk}/start")
    program = Work.objects.get(student=people["alice"]).program
    assert program.language == "blocks"
    # The workbench's script (it saved first): the checklist of the new attempt.
    response = alice.post(url, **FETCH)
    assert response.status_code == 200
    attempt = Attempt.objects.get(pk=response["X-Attempt"])
    html = response.content.decode()
    assert attempt.state == Attempt.State.DONE and not attempt.passed
    assert "not passed" in html and "Repeat it!" in html and "Use a loop block" in html
    assert 'hx-trigger="every 1s"' not in html  # done: no more polling
    # Scripts off: the editor's form posts its text here, saved then checked.
    response = alice.post(
        url, {"source": blocks_with_loop(), "language": "blocks", "base_revision": "1",
              "action": "check"},
    )  # fmt: skip
    assert response.status_code == 302 and response["Location"] == f"/programs/{program.pk}/"
    second = Attempt.objects.get(student=people["alice"], number=2)
    assert second.passed and second.score == 4 and second.revision_number == 2
    bench = alice.get(f"/programs/{program.pk}/").content.decode()
    assert f"/attempts/{second.pk}/" in bench and "4 of 4 points" in bench
    # Refused: a Python program for a blocks-only exercise, the why shown.
    Program.objects.filter(pk=program.pk).update(language="python")
    refused = alice.post(url, **FETCH)
    assert refused.status_code == 422
    assert refused.json()["error"] == "this exercise takes blocks programs only"
    page = alice.post(url, follow=True).content.decode()
    assert "this exercise takes blocks programs only" in page
    assert Attempt.objects.filter(student=people["alice"]).count() == 2
    # Only its student checks it.
    assert signed_in(people["bob"]).post(url, **FETCH).status_code == 400


def test_pages_in_portuguese(people, exercise, attempt):
    """Every page renders in the other language (its numbers with a decimal comma)."""
    alice = signed_in(people["alice"])
    alice.cookies["django_language"] = "pt-br"
    for path in ("/exercises/", f"/exercises/{exercise.pk}/", f"/attempts/{attempt.pk}/"):
        response = alice.get(path)
        assert response.status_code == 200, path
        assert 'lang="pt-br"' in response.content.decode(), path
        no_hidden_figures(response.content.decode())
