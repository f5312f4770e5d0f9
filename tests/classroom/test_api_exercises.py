"""Exercises through the API (issue 31): the document's shape, validation errors that name the
field, version bumps, who reads and changes which exercise, hidden variants never shown to a
student (exercise, list, attempts), attempts of others unreadable, and POST .../check.

class-a (alice, bob; taught by tina), class-b (dan; taught by tom), carol in no class, sam
staff. Checks whose results need runs on check sims are the pipeline's tests
(test_checking*.py); here a Check of a blocks-only exercise with static checks only, which is
judged at once, goes the whole way through the API.
"""

import json

import pytest
from django.contrib.auth.models import Group, User
from django.test import Client

from classroom.models import Attempt, AttemptRun, Exercise
from programs.languages import BLOCKS_TEMPLATE
from programs.models import Program
from robotide.models import ApiToken, ClassTeacher

pytestmark = pytest.mark.django_db

# A hidden pose no visible number spells: found in an answer, it leaked.
HIDDEN = {"x": -1.2345, "y": 1.3579, "theta": 2.4681, "hidden": True}
VISIBLE = {"x": 0.0, "y": -1.0, "theta": 1.5707963267948966, "hidden": False}
KEYS = {
    "id", "title", "text", "world", "class", "languages", "variants", "checks", "starter",
    "starter_language", "due", "attempts", "counts", "speed", "time_limit_s", "version",
    "owner", "created", "updated",
}  # fmt: skip
ATTEMPT_KEYS = {
    "id", "exercise", "student", "number", "state", "score", "max_score", "passed", "late",
    "revision", "created", "finished", "results", "error", "program", "exercise_version",
    "runs",
}  # fmt: skip


@pytest.fixture
def school(db):
    people = {
        name: User.objects.create_user(name, password=f"pw-{name}-123")
        for name in ("alice", "bob", "carol", "dan", "tina", "tom", "sam")
    }
    people["sam"].is_staff = True
    people["sam"].save()
    a, b = Group.objects.create(name="class-a"), Group.objects.create(name="class-b")
    people["alice"].groups.add(a)
    people["bob"].groups.add(a)
    people["dan"].groups.add(b)
    ClassTeacher.objects.create(group=a, user=people["tina"])
    ClassTeacher.objects.create(group=b, user=people["tom"])
    return {**people, "a": a, "b": b}


def api_of(user):
    _, token = ApiToken.issue(user)
    client = Client(HTTP_AUTHORIZATION=f"Bearer {token}")

    def call(method, path, body=None):
        return getattr(client, method.lower())(path, body, content_type="application/json")

    return call


@pytest.fixture
def api(school):
    return {name: api_of(user) for name, user in school.items() if isinstance(user, User)}


def kitchen(group=None, **change):
    return {
        "title": "Reach the kitchen without touching anything",
        "text": "Drive to the **kitchen**.",
        "world": "boxes",
        "class": group.pk if group is not None else None,
        "variants": [VISIBLE, HIDDEN],
        "checks": [
            {
                "kind": "reach_zone",
                "zone": "kitchen",
                "within_s": 30,
                "points": 2,
                "message": "Find the kitchen's landmark first.",
            },
            {"kind": "no_contact"},
        ],  # fmt: skip
        "languages": ["python"],
        "starter": "from robot import Robot\n",
        "due": "2026-12-24T18:00:00Z",
        **change,
    }


def posted(api, who, document):
    response = api[who]("POST", "/api/exercises", document)
    assert response.status_code == 201, response.content
    return response.json()


def leaks(text: str) -> bool:
    return any(str(HIDDEN[k]) in text for k in ("x", "y", "theta"))


def test_shape_round_trip_and_defaults(api, school):
    exercise = posted(api, "tina", kitchen(school["a"]))
    assert set(exercise) == KEYS
    assert exercise["world"] == "boxes" and exercise["class"] == school["a"].pk
    assert exercise["variants"] == [VISIBLE, HIDDEN]
    assert exercise["checks"][0]["zone"] == "kitchen" and exercise["checks"][0]["points"] == 2
    assert exercise["checks"][1]["points"] == 1  # defaults filled in
    assert exercise["owner"] == "tina" and exercise["version"] == 1
    assert exercise["starter_language"] == "python" and exercise["counts"] == "best"
    assert exercise["due"].startswith("2026-12-24T18:00:00")
    assert (exercise["speed"], exercise["time_limit_s"], exercise["attempts"]) == (5.0, 60.0, None)
    assert api["tina"]("GET", f"/api/exercises/{exercise['id']}").json() == exercise
    stored = Exercise.objects.get(pk=exercise["id"])
    assert stored.world_document["name"] == "boxes" and stored.world_document["zones"]
    # The least a draft needs: a title and a world; its variant is the world's start.
    draft = posted(api, "carol", {"title": "mine", "world": "builtin:boxes"})
    assert draft["class"] is None and draft["checks"] == []
    assert draft["variants"] == [{"x": 0.0, "y": 0.0, "theta": 1.5707963267948966,
                                  "hidden": False}]  # fmt: skip


def test_a_stored_world_resolved_as_its_author_may_use_it(api, school):
    from tests.worlds.documents import corridor

    world = api["tina"]("POST", "/api/worlds", corridor()).json()
    exercise = posted(api, "tina", {"title": "corridor", "world": world["id"],
                                    "variants": [{"x": -1.5, "y": 1.0}]})  # fmt: skip
    assert exercise["world"] == world["id"]
    assert Exercise.objects.get(pk=exercise["id"]).world_document == world["document"]
    # Not shared with tom: he cannot set it.
    response = api["tom"]("POST", "/api/exercises", {"title": "x", "world": world["id"]})
    assert response.status_code == 422 and response.json()["detail"][0]["path"] == "world"


@pytest.mark.parametrize(
    "change, path, words",
    [
        ({"world": "atlantis"}, "world", "atlantis"),
        ({"variants": [VISIBLE, {"x": 1.05, "y": 0.75}]}, "variants[1]", "box"),
        ({"variants": [{"x": 1.95, "y": 0.0}]}, "variants[0]", "wall"),
        ({"variants": [VISIBLE, {"x": 9.0, "y": 0.0}]}, "variants[1]", "arena"),
        ({"variants": [{"x": "0", "y": 0}]}, "variants[0].x", "number"),
        ({"variants": [HIDDEN]}, "variants", "visible"),
        ({"variants": [VISIBLE] * 11}, "variants", "10"),
        ({"checks": [{"kind": "no_contact"}] * 31}, "checks", "30"),
        ({"checks": [{"kind": "reach_zone", "zone": "attic"}]}, "checks[0].zone", "attic"),
        ({"checks": [{"kind": "teleport"}]}, "checks[0].kind", "teleport"),
        ({"languages": ["cobol"]}, "languages[0]", "cobol"),
        ({"languages": ["blocks"], "starter_language": "python"}, "starter_language", "python"),
        ({"text": "x" * 20_001}, "text", "20000"),
        ({"title": " "}, "title", ""),
        ({"due": "next friday"}, "due", "ISO"),
        ({"attempts": 0}, "attempts", ""),
        ({"counts": "worst"}, "counts", "best"),
        ({"speed": 50}, "speed", "10"),
        ({"time_limit_s": -1}, "time_limit_s", ""),
        ({"class": "a"}, "class", ""),
        ({"varaints": []}, "varaints", "unknown"),
    ],
)  # fmt: skip
def test_validation_errors_name_the_field(api, school, change, path, words):
    response = api["tina"]("POST", "/api/exercises", kitchen(school["a"], **change))
    assert response.status_code == 422, response.content
    [error] = response.json()["detail"]
    assert error["path"] == path, error
    assert error["loc"][0] == "body" and words in error["msg"], error
    assert not Exercise.objects.exists()


def test_the_body_must_be_an_object(api):
    for body in ('"x"', "3", "[1]"):
        response = api["tina"]("POST", "/api/exercises", body)
        assert response.status_code == 422 and "JSON object" in response.text


def test_version_bumps_when_what_decides_a_result_changes(api, school):
    """And recheck (none checked yet here: nothing to check again)."""
    exercise = posted(api, "tina", kitchen(school["a"]))
    url = f"/api/exercises/{exercise['id']}"

    def put(change):
        response = api["tina"]("PUT", url, change)
        assert response.status_code == 200, response.content
        return response.json()

    # Words, the due date, the starter: the same version. Keys left out keep their values.
    same = put({"title": "Kitchen!", "text": "new words", "due": None, "starter": "# go\n"})
    assert same["version"] == 1 and same["variants"] == [VISIBLE, HIDDEN]
    assert same["checks"] == exercise["checks"] and same["title"] == "Kitchen!"
    # A document read back can be put back as it is.
    assert put(same)["version"] == 1
    assert put({"variants": [VISIBLE]})["version"] == 2
    assert put({"checks": [{"kind": "no_contact"}]})["version"] == 3
    assert put({"time_limit_s": 30})["version"] == 4
    assert put({"speed": 2})["version"] == 5
    assert put({"world": "square", "variants": [VISIBLE], "checks": []})["version"] == 6
    # An invalid save keeps it as it was.
    assert api["tina"]("PUT", url, {"variants": [HIDDEN]}).status_code == 422
    assert api["tina"]("GET", url).json()["version"] == 6
    assert api["tina"]("POST", f"{url}/recheck").json() == {"attempts": 0}


def test_a_student_never_reads_a_hidden_pose(api, school):
    exercise = posted(api, "tina", kitchen(school["a"]))
    url = f"/api/exercises/{exercise['id']}"
    read = api["alice"]("GET", url)
    assert read.status_code == 200
    assert read.json()["variants"] == [VISIBLE, {"hidden": True}]
    listed = api["alice"]("GET", "/api/exercises")
    assert listed.json()[0]["variants"] == [VISIBLE, {"hidden": True}]
    # Her attempt with its runs, one per variant: the hidden one's run not hers to read.
    stored = Exercise.objects.get(pk=exercise["id"])
    attempt = Attempt.objects.create(
        exercise=stored, student=school["alice"], number=1, language="python",
        state=Attempt.State.DONE, results=[
            {"check": 0, "variant": 0, "passed": True, "why": "reached the kitchen at 4.2 s",
             "points": 2},
            {"check": 0, "variant": 1, "passed": False,
             "why": "hidden variant 2: never reached the kitchen (30 s)", "points": 2},
        ],
    )  # fmt: skip
    runs = [
        AttemptRun.objects.create(attempt=attempt, variant=i, hidden=v["hidden"],
                                  pose={k: v[k] for k in ("x", "y", "theta")})
        for i, v in enumerate([VISIBLE, HIDDEN])
    ]  # fmt: skip
    from programs.models import Run
    from robots.models import Robot

    robot = Robot.objects.create(name="check-sim", url="sim://")
    for attempt_run in runs:
        attempt_run.run = Run.objects.create(
            owner=school["alice"], robot=robot, program_name="p", language="python",
            sealed=attempt_run.hidden,
        )  # fmt: skip
        attempt_run.save()
    mine = api["alice"]("GET", f"/api/attempts/{attempt.pk}")
    assert mine.status_code == 200 and set(mine.json()) == ATTEMPT_KEYS
    assert mine.json()["runs"] == [
        {"variant": 0, "hidden": False, "run": runs[0].run_id, "checked": False},
        {"variant": 1, "hidden": True, "run": None, "checked": False},
    ]
    assert "hidden variant 2" in mine.json()["results"][1]["why"]
    all_mine = api["alice"]("GET", f"{url}/attempts")
    for response in (read, listed, mine, all_mine):
        assert not leaks(response.content.decode()), response.content
    # Her teacher reads the poses and the hidden run.
    assert api["tina"]("GET", url).json()["variants"] == [VISIBLE, HIDDEN]
    theirs = api["tina"]("GET", f"/api/attempts/{attempt.pk}").json()
    assert theirs["runs"][1]["run"] == runs[1].run_id


def test_students_read_only_their_classes_exercises(api, school):
    a = posted(api, "tina", kitchen(school["a"]))
    b = posted(api, "tom", kitchen(school["b"], title="class b's"))
    draft = posted(api, "tina", kitchen(title="tina's draft"))
    assert [e["id"] for e in api["alice"]("GET", "/api/exercises").json()] == [a["id"]]
    assert [e["id"] for e in api["dan"]("GET", "/api/exercises").json()] == [b["id"]]
    assert api["carol"]("GET", "/api/exercises").json() == []
    ids = {e["id"] for e in api["tina"]("GET", "/api/exercises").json()}
    assert ids == {a["id"], draft["id"]}
    assert {e["id"] for e in api["sam"]("GET", "/api/exercises").json()} >= {
        a["id"],
        b["id"],
        draft["id"],
    }
    assert [e["id"] for e in api["tina"]("GET", f"/api/exercises?class={school['a'].pk}")
            .json()] == [a["id"]]  # fmt: skip
    for who, exercise in (("alice", b), ("alice", draft), ("dan", a), ("carol", a),
                          ("tom", a), ("tom", draft)):  # fmt: skip
        url = f"/api/exercises/{exercise['id']}"
        assert api[who]("GET", url).status_code == 404, (who, exercise["title"])
        assert api[who]("GET", f"{url}/attempts").status_code == 404
        assert api[who]("PUT", url, {"title": "mine now"}).status_code == 404
        assert api[who]("DELETE", url).status_code == 404
        assert api[who]("POST", f"{url}/check", {"program": 1}).status_code == 404
    assert Exercise.objects.get(pk=a["id"]).title == a["title"]


def test_a_student_cannot_change_her_classes_exercise(api, school):
    exercise = posted(api, "tina", kitchen(school["a"]))
    url = f"/api/exercises/{exercise['id']}"
    response = api["alice"]("PUT", url, {"variants": [VISIBLE]})
    assert response.status_code == 403
    assert api["alice"]("DELETE", url).status_code == 403
    assert api["alice"]("POST", f"{url}/recheck").status_code == 403
    assert Exercise.objects.get(pk=exercise["id"]).variants == [VISIBLE, HIDDEN]


def test_exercises_only_for_classes_one_teaches(api, school):
    for who, group in (("tina", "b"), ("tom", "a"), ("alice", "a"), ("carol", "a")):
        response = api[who]("POST", "/api/exercises", kitchen(school[group]))
        assert response.status_code == 422, (who, group)
        [error] = response.json()["detail"]
        assert error["path"] == "class"
    assert not Exercise.objects.exists()
    # Nor move one to such a class.
    exercise = posted(api, "tina", kitchen(school["a"]))
    response = api["tina"]("PUT", f"/api/exercises/{exercise['id']}", {"class": school["b"].pk})
    assert response.status_code == 422
    assert Exercise.objects.get(pk=exercise["id"]).group == school["a"]
    # Staff may set one for any class; anyone may keep a draft.
    assert posted(api, "sam", kitchen(school["b"]))["class"] == school["b"].pk
    assert posted(api, "alice", kitchen())["class"] is None


def test_a_student_reads_only_her_own_attempts(api, school):
    exercise = posted(api, "tina", kitchen(school["a"]))
    stored = Exercise.objects.get(pk=exercise["id"])
    alices, bobs = (
        Attempt.objects.create(exercise=stored, student=school[who], number=1, language="python")
        for who in ("alice", "bob")
    )
    assert api["alice"]("GET", f"/api/attempts/{alices.pk}").status_code == 200
    assert api["alice"]("GET", f"/api/attempts/{bobs.pk}").status_code == 404
    assert api["dan"]("GET", f"/api/attempts/{alices.pk}").status_code == 404
    assert api["tom"]("GET", f"/api/attempts/{alices.pk}").status_code == 404
    url = f"/api/exercises/{exercise['id']}/attempts"
    assert [a["student"] for a in api["alice"]("GET", url).json()] == ["alice"]
    assert api["alice"]("GET", f"{url}?student=bob").json() == []
    assert {a["student"] for a in api["tina"]("GET", url).json()} == {"alice", "bob"}
    assert [a["student"] for a in api["tina"]("GET", f"{url}?student=bob").json()] == ["bob"]


def blocks_program(owner, loop: bool) -> Program:
    source = json.loads(BLOCKS_TEMPLATE)
    if loop:
        body = source["blocks"]["blocks"][0]
        source["blocks"]["blocks"] = [{
            "type": "controls_repeat_ext", "id": "loop", "x": 10, "y": 10,
            "inputs": {"TIMES": {"shadow": {"type": "math_number", "id": "n",
                                            "fields": {"NUM": 3}}},
                       "DO": {"block": {k: v for k, v in body.items() if k not in "xy"}}},
        }]  # fmt: skip
    program = Program.objects.create(owner=owner, name=f"loop {loop}", language="blocks")
    program.save_source(json.dumps(source), owner)
    return program


def test_a_check_of_a_blocks_exercise_through_the_api(api, school):
    """Static checks only: the attempt is judged at once (no runs); the answer is 202."""
    exercise = posted(api, "tina", kitchen(
        school["a"], languages=["blocks"], starter_language="blocks", starter=BLOCKS_TEMPLATE,
        checks=[{"kind": "uses_block", "block": "loop", "points": 3,
                 "message": "Repeat it: use a loop."},
                {"kind": "max_blocks", "count": 10}],
    ))  # fmt: skip
    url = f"/api/exercises/{exercise['id']}/check"
    looping = blocks_program(school["alice"], loop=True)
    response = api["alice"]("POST", url, {"program": looping.pk})
    assert response.status_code == 202, response.content
    attempt = response.json()
    assert set(attempt) == ATTEMPT_KEYS
    assert attempt["student"] == "alice" and attempt["number"] == 1
    assert attempt["exercise"] == exercise["id"] and attempt["revision"] == 1
    read = api["alice"]("GET", f"/api/attempts/{attempt['id']}").json()
    assert read["state"] == "done" and read["passed"] and read["score"] == read["max_score"] == 4
    assert [(r["check"], r["variant"], r["passed"]) for r in read["results"]] == [
        (0, None, True),
        (1, None, True),
    ]
    # Bob's program without a loop fails the first, with the teacher's words.
    plain = blocks_program(school["bob"], loop=False)
    bobs = api["bob"]("POST", url, {"program": plain.pk}).json()
    assert not bobs["passed"] and bobs["score"] == 1
    assert bobs["results"][0]["why"]
    assert api["alice"]("GET", f"/api/attempts/{bobs['id']}").status_code == 404
    # Refused: a Python program (blocks only), someone else's program (one she cannot see,
    # one she can: her student's).
    python = Program.objects.create(owner=school["alice"], name="p", language="python")
    refused = api["alice"]("POST", url, {"program": python.pk})
    assert refused.status_code == 422 and "blocks" in refused.json()["detail"]
    assert api["alice"]("POST", url, {"program": plain.pk}).status_code == 404
    assert api["tina"]("POST", url, {"program": plain.pk}).status_code == 403
    assert Attempt.objects.count() == 2


# -- a Check with runs, through the API ----------------------------------------------------------


@pytest.mark.django_db(transaction=True)
async def test_a_check_through_the_api_never_shows_a_hidden_pose(agents):
    """A student's Check on check sims with real agents (the pipeline's fixture): 202, then
    the attempt at GET /api/attempts/{id} until done; the hidden variant failed, said so
    without its pose, and its run is not hers to read."""
    from asgiref.sync import sync_to_async

    from tests.classroom.test_checking import FIXED_TIME, NORTH
    from tests.waiting import until

    def setup():
        tess = User.objects.create_user("tess")
        group = Group.objects.create(name="class-7a")
        ClassTeacher.objects.create(group=group, user=tess)
        ben = User.objects.create_user("ben")
        ben.groups.add(group)
        return api_of(tess), api_of(ben), ben, group

    teacher, student, ben, group = await sync_to_async(setup)()
    hidden = {"x": -0.6123, "y": -0.6047, "theta": NORTH, "hidden": True}
    document = {
        "title": "kitchen", "world": "boxes", "class": group.pk, "speed": 2, "time_limit_s": 30,
        "variants": [{"x": -0.5, "y": 0.0, "theta": NORTH, "hidden": False}, hidden],
        "checks": [{"kind": "reach_zone", "zone": "kitchen", "points": 2}],
    }  # fmt: skip
    call = sync_to_async(lambda who, *args: who(*args))
    exercise = (await call(teacher, "POST", "/api/exercises", document)).json()
    mine = await sync_to_async(program_of)(ben, FIXED_TIME)
    checked = await call(student, "POST", f"/api/exercises/{exercise['id']}/check",
                         {"program": mine.pk})  # fmt: skip
    assert checked.status_code == 202, checked.content
    url = f"/api/attempts/{checked.json()['id']}"

    async def finished():
        response = await call(student, "GET", url)
        return response if response.json()["state"] in ("done", "error") else None

    response = await until(finished, timeout=180)
    attempt = response.json()
    assert attempt["state"] == "done", attempt
    rows = {(r["check"], r["variant"]): r for r in attempt["results"]}
    assert rows[(0, 0)]["passed"] and not rows[(0, 1)]["passed"], attempt["results"]
    assert rows[(0, 1)]["why"].startswith("hidden variant 2: "), rows[(0, 1)]
    assert attempt["score"] == 0 and not attempt["passed"]
    assert [r["run"] is None for r in attempt["runs"]] == [False, True]
    answers = [response, await call(student, "GET", f"/api/exercises/{exercise['id']}"),
               await call(student, "GET", f"/api/exercises/{exercise['id']}/attempts")]  # fmt: skip
    for answer in answers:
        text = answer.content.decode()
        assert not any(s in text for s in ("-0.6123", "-0.6047", "-0.61", "-0.60")), text
    # Her teacher reads the hidden run; the student gets 404 for it.
    theirs = (await call(teacher, "GET", url)).json()
    sealed = theirs["runs"][1]["run"]
    assert sealed is not None
    assert (await call(student, "GET", f"/api/runs/{sealed}")).status_code == 404
    assert (await call(teacher, "GET", f"/api/runs/{sealed}")).status_code == 200


def program_of(owner, source: str) -> Program:
    made = Program.objects.create(owner=owner, name="kitchen", language="python")
    made.save_source(source, owner)
    return made


def test_a_student_never_reads_an_output_pattern(api, school, client):
    """An output check's pattern is often the answer (the landmark's name): a student reads
    that a text is asked for, never which; her teacher reads it."""
    answer = {"kind": "output_matches", "pattern": "Kitchen-42", "message": "Say the room."}
    exercise = posted(api, "tina", kitchen(school["a"], checks=[answer]))
    url = f"/api/exercises/{exercise['id']}"
    assert "Kitchen-42" not in api["alice"]("GET", url).content.decode()
    assert "Kitchen-42" not in api["alice"]("GET", "/api/exercises").content.decode()
    assert api["alice"]("GET", url).json()["checks"][0]["message"] == "Say the room."
    assert api["tina"]("GET", url).json()["checks"][0]["pattern"] == "Kitchen-42"
    client.force_login(school["alice"])
    page = client.get(f"/exercises/{exercise['id']}/")
    assert page.status_code == 200 and "Kitchen-42" not in page.content.decode()
