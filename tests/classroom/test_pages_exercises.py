"""A teacher's exercise pages: the list, the editor (a form, and the document as JSON), its
errors beside their fields, who may open them, re-checking after an edit, a class's grid."""

import json
import math
import re
from datetime import timedelta

import pytest
from django.contrib.auth.models import Group, User
from django.test import Client
from django.utils import timezone

from classroom.models import Attempt, Exercise
from robotide.models import ClassTeacher

pytestmark = pytest.mark.django_db


@pytest.fixture
def people(db):
    """tina teaches class-a (alice, bob); tom teaches class-b (carol)."""
    users = {
        name: User.objects.create_user(name, password=f"pw-{name}-123", first_name=name.title())
        for name in ("alice", "bob", "carol", "tina", "tom")
    }
    class_a, class_b = Group.objects.create(name="class-a"), Group.objects.create(name="class-b")
    class_a.user_set.add(users["alice"], users["bob"])
    class_b.user_set.add(users["carol"])
    ClassTeacher.objects.create(group=class_a, user=users["tina"])
    ClassTeacher.objects.create(group=class_b, user=users["tom"])
    return {**users, "class_a": class_a, "class_b": class_b}


def signed_in(user) -> Client:
    client = Client()
    client.force_login(user)
    return client


def form(group=None, **changes) -> dict:
    """The editor's fields, as a browser posts them: one visible and one hidden start pose,
    two checks."""
    data = {
        "title": "Reach the kitchen",
        "class": str(group.pk) if group else "",
        "text": "Drive to the **kitchen**.",
        "world": "boxes",
        "starter": "",
        "starter_language": "python",
        "due": "",
        "attempts": "",
        "counts": "best",
        "speed": "5",
        "time_limit_s": "30",
        "variants-0-x": "0",
        "variants-0-y": "0",
        "variants-0-theta_deg": "90",
        "variants-3-x": "0,5",  # a comma for the decimal point, as pt-BR writes it
        "variants-3-y": "-1",
        "variants-3-theta_deg": "180",
        "variants-3-hidden": "on",
        "checks-0-kind": "reach_zone",
        "checks-0-zone": "kitchen",
        "checks-0-within_s": "20",
        "checks-0-points": "2",
        "checks-0-message": "Find the kitchen.",
        "checks-5-kind": "no_contact",
        "checks-5-zone": "ignored: not a field of this kind",
        "checks-5-points": "1",
        "checks-5-message": "",
        "action": "save",
    }
    data.update(changes)
    return {k: v for k, v in data.items() if v is not None}


def test_a_teacher_creates_an_exercise_with_the_form(people):
    tina = signed_in(people["tina"])
    page = tina.get("/classroom/exercises/new")
    assert page.status_code == 200
    text = page.content.decode()
    assert 'name="title"' in text and "class-a" in text and "class-b" not in text
    # Her only class is chosen already; the class a page asks for, if hers.
    assert re.search(rf'<option value="{people["class_a"].pk}" selected>', text)
    other = tina.get(f"/classroom/exercises/new?class={people['class_b'].pk}").content.decode()
    assert re.search(rf'<option value="{people["class_a"].pk}" selected>', other)
    data = form(people["class_a"], text="Drive to the **kitchen**.\r\n\r\nNow.",
                due="2026-12-20T18:00", attempts="3")  # fmt: skip
    response = tina.post("/classroom/exercises/new", data)
    exercise = Exercise.objects.get()
    assert response.status_code == 302 and response["Location"] == (
        f"/classroom/exercises/{exercise.pk}/edit"
    )
    assert exercise.owner == people["tina"] and exercise.group == people["class_a"]
    assert exercise.world == "boxes" and exercise.world_document["zones"]
    assert exercise.variants == [
        {"x": 0.0, "y": 0.0, "theta": pytest.approx(math.pi / 2, abs=1e-6), "hidden": False},
        {"x": 0.5, "y": -1.0, "theta": pytest.approx(math.pi, abs=1e-6), "hidden": True},
    ]
    kinds = [(c["kind"], c.get("zone"), c["points"], c["message"]) for c in exercise.checks]
    assert kinds == [("reach_zone", "kitchen", 2, "Find the kitchen."), ("no_contact", None, 1, "")]
    assert exercise.checks[0]["within_s"] == 20
    assert exercise.time_limit_s == 30 and exercise.text == "Drive to the **kitchen**.\n\nNow."
    # Opened again, the form shows what was saved: degrees, the hidden box ticked.
    text = tina.get(f"/classroom/exercises/{exercise.pk}/edit").content.decode()
    assert 'name="variants-1-theta_deg" value="180"' in text
    assert re.search(r'name="variants-1-hidden"[^>]*checked', text)
    assert 'name="checks-0-zone" value="kitchen"' in text
    # The due date in the server's time zone, as typed.
    assert timezone.localtime(exercise.due).strftime("%Y-%m-%d %H:%M") == "2026-12-20 18:00"
    assert 'name="due" value="2026-12-20T18:00"' in text and exercise.attempts_allowed == 3


def test_saving_unchanged_keeps_the_version(people):
    """Degrees shown rounded are not a change: the stored radians are kept."""
    tina = signed_in(people["tina"])
    tina.post("/classroom/exercises/new", form(people["class_a"], **{
        "variants-0-theta_deg": "33.3333"}))  # fmt: skip
    exercise = Exercise.objects.get()
    page = tina.get(f"/classroom/exercises/{exercise.pk}/edit").content.decode()
    fields = dict(re.findall(r'name="([\w-]+)" value="([^"]*)"', page))
    assert fields["variants-0-theta_deg"] == "33.33"
    data = form(people["class_a"], **{k: v for k, v in fields.items() if k.startswith("variants")})
    data.pop("variants-3-x"), data.pop("variants-3-y"), data.pop("variants-3-theta_deg")
    data.pop("variants-3-hidden")
    data["variants-1-hidden"] = "on"
    assert tina.post(f"/classroom/exercises/{exercise.pk}/edit", data).status_code == 302
    exercise.refresh_from_db()
    assert exercise.version == 1
    data["variants-0-theta_deg"] = "45"
    tina.post(f"/classroom/exercises/{exercise.pk}/edit", data)
    exercise.refresh_from_db()
    assert exercise.version == 2 and exercise.variants[0]["theta"] == pytest.approx(math.pi / 4)


def test_an_error_is_shown_beside_its_field(people):
    tina = signed_in(people["tina"])
    # A zone the world does not have: classroom.documents names checks[1].zone.
    data = form(people["class_a"], **{"checks-5-kind": "reach_zone", "checks-5-zone": "attic"})
    response = tina.post("/classroom/exercises/new", data)
    assert response.status_code == 422 and not Exercise.objects.exists()
    text = response.content.decode()
    field = re.search(r'<input[^>]*name="checks-1-zone"[^>]*>', text).group(0)
    assert 'value="attic"' in field and 'aria-invalid="true"' in field
    error = re.search(r'id="checks-1-zone-error">([^<]*)<', text).group(1)
    assert "attic" in error
    # What was typed is all still there (the hidden pose too).
    assert 'value="Find the kitchen."' in text and 'name="variants-1-x" value="0,5"' in text
    # A number that is not one: said by the form, by its field, nothing saved.
    response = tina.post("/classroom/exercises/new", form(people["class_a"], speed="fast"))
    text = response.content.decode()
    assert response.status_code == 422
    assert re.search(r'id="ex-speed-error">[^<]*fast', text)
    # A class the teacher does not teach.
    response = tina.post("/classroom/exercises/new", form(people["class_b"]))
    assert re.search(r'id="ex-class-error">[^<]*teach', response.content.decode())
    assert not Exercise.objects.exists()


def test_rows_are_added_and_removed_without_scripts(people):
    tina = signed_in(people["tina"])
    text = tina.post("/classroom/exercises/new", form(action="add-check")).content.decode()
    assert 'name="checks-2-kind"' in text and not Exercise.objects.exists()
    text = tina.post("/classroom/exercises/new", form(action="remove-variant-0")).content.decode()
    assert 'name="variants-0-x" value="0,5"' in text and 'name="variants-1-x"' not in text
    text = tina.post("/classroom/exercises/new", form(action="preview")).content.decode()
    assert "<strong>kitchen</strong>" in text


def test_the_text_preview_is_sanitised(people):
    tina = signed_in(people["tina"])
    response = tina.post("/classroom/exercises/preview", {"text": "*hi* <script>x()</script>"})
    assert (
        "<em>hi</em>" in response.content.decode() and "<script>" not in response.content.decode()
    )


def test_edit_as_json(people):
    tina = signed_in(people["tina"])
    tina.post("/classroom/exercises/new", form(people["class_a"]))
    exercise = Exercise.objects.get()
    url = f"/classroom/exercises/{exercise.pk}/edit"
    page = tina.get(f"{url}?as=json").content.decode()
    shown = re.search(r'<textarea id="ex-document"[^>]*>(.*?)</textarea>', page, re.S).group(1)
    document = json.loads(shown.replace("&quot;", '"').replace("&#x27;", "'").replace("&amp;", "&"))
    assert document["variants"][1]["hidden"] is True and "x" in document["variants"][1]
    document["title"] = "Reach the lab"
    document["checks"][0]["zone"] = "lab"
    response = tina.post(
        f"/classroom/exercises/{exercise.pk}/edit",
        {"mode": "json", "document": json.dumps(document)},
    )
    assert response.status_code == 302
    exercise.refresh_from_db()
    assert exercise.title == "Reach the lab" and exercise.checks[0]["zone"] == "lab"
    document["checks"][0]["zone"] = "attic"
    response = tina.post(
        f"/classroom/exercises/{exercise.pk}/edit",
        {"mode": "json", "document": json.dumps(document)},
    )
    assert response.status_code == 422
    assert "<code>checks[0].zone</code>" in response.content.decode()
    response = tina.post(
        f"/classroom/exercises/{exercise.pk}/edit", {"mode": "json", "document": "{"}
    )
    assert response.status_code == 422 and "not JSON" in response.content.decode()


def test_a_stored_world_and_a_new_exercise_as_json(people):
    from tests.worlds.documents import corridor
    from worlds.documents import validated
    from worlds.models import World

    document = validated(corridor(), "corridor")
    world = World.objects.create(owner=people["tina"], name="corridor", title="Corridor")
    world.save_document(document, people["tina"])
    tina = signed_in(people["tina"])
    page = tina.get("/classroom/exercises/new").content.decode()
    assert f'<option value="{world.pk}">Corridor</option>' in page
    # Its own start pose, its zones: what the form offers for this world.
    start = document["start"][0]
    posted = form(people["class_a"], world=str(world.pk), **{
        "variants-0-x": str(start["x"]), "variants-0-y": str(start["y"]),
        "variants-3-x": None, "variants-3-y": None, "variants-3-theta_deg": None,
        "variants-3-hidden": None, "checks-0-kind": "no_contact"})  # fmt: skip
    response = tina.post("/classroom/exercises/new", posted)
    assert response.status_code == 302, response.content.decode()
    exercise = Exercise.objects.get()
    assert exercise.world == str(world.pk) and exercise.world_document == world.document
    page = tina.get(f"/classroom/exercises/{exercise.pk}/edit").content.decode()
    assert re.search(rf'<option value="{world.pk}" selected>Corridor</option>', page)
    # Another teacher's world is not offered, nor taken.
    tom = signed_in(people["tom"])
    assert "Corridor" not in tom.get("/classroom/exercises/new").content.decode()
    response = tom.post("/classroom/exercises/new", {**posted, "class": ""})
    assert response.status_code == 422 and Exercise.objects.count() == 1
    assert re.search(r'id="ex-world-error">[^<]*no world', response.content.decode())
    # A new exercise written as JSON.
    page = tina.get("/classroom/exercises/new?as=json").content.decode()
    assert "&quot;world&quot;: &quot;boxes&quot;" in page
    new = {"title": "By JSON", "world": "maze", "class": people["class_a"].pk,
           "checks": [{"kind": "reach_zone", "zone": "goal"}]}  # fmt: skip
    response = tina.post("/classroom/exercises/new", {"mode": "json", "document": json.dumps(new)})
    made = Exercise.objects.get(title="By JSON")
    assert response["Location"] == f"/classroom/exercises/{made.pk}/edit"
    assert made.checks[0]["zone"] == "goal" and made.variants[0]["hidden"] is False


def test_a_teacher_cannot_edit_another_teachers_exercise(people):
    signed_in(people["tina"]).post("/classroom/exercises/new", form(people["class_a"]))
    exercise = Exercise.objects.get()
    tom = signed_in(people["tom"])
    assert tom.get(f"/classroom/exercises/{exercise.pk}/edit").status_code == 404
    assert (
        tom.post(f"/classroom/exercises/{exercise.pk}/edit", form(title="Mine")).status_code == 404
    )
    assert tom.post(f"/classroom/exercises/{exercise.pk}/recheck").status_code == 404
    assert tom.get(f"/classroom/{people['class_a'].pk}/grid").status_code == 404
    assert "Reach the kitchen" not in tom.get("/classroom/exercises/").content.decode()
    exercise.refresh_from_db()
    assert exercise.title == "Reach the kitchen"


def test_a_student_cannot_open_these_pages(people):
    signed_in(people["tina"]).post("/classroom/exercises/new", form(people["class_a"]))
    exercise = Exercise.objects.get()
    alice = signed_in(people["alice"])
    for url in ("/classroom/exercises/", "/classroom/exercises/new",
                f"/classroom/exercises/{exercise.pk}/edit",
                f"/classroom/exercises/{exercise.pk}/edit?as=json",
                f"/classroom/{people['class_a'].pk}/grid"):  # fmt: skip
        assert alice.get(url).status_code in (403, 404), url
    assert alice.post("/classroom/exercises/new", form()).status_code == 403
    assert alice.post(f"/classroom/exercises/{exercise.pk}/recheck").status_code in (403, 404)
    assert alice.post("/classroom/exercises/preview", {"text": "x"}).status_code == 403
    assert Exercise.objects.count() == 1
    assert Client().get("/classroom/exercises/").status_code == 302  # to sign in


def attempt(exercise, student, number, score, *, passed=False, late=False, state="done", ago=0):
    return Attempt.objects.create(
        exercise=exercise, student=student, number=number, language="python", score=score,
        max_score=exercise.max_score, passed=passed, late=late, state=state,
        exercise_version=exercise.version, created=timezone.now() - timedelta(minutes=ago),
    )  # fmt: skip


def test_the_list_counts_attempts_and_passes(people):
    tina = signed_in(people["tina"])
    tina.post("/classroom/exercises/new", form(people["class_a"]))
    tina.post("/classroom/exercises/new", form(title="A draft"))
    exercise = Exercise.objects.get(title="Reach the kitchen")
    attempt(exercise, people["alice"], 1, 1)
    attempt(exercise, people["alice"], 2, 3, passed=True)
    attempt(exercise, people["bob"], 1, 0)
    text = tina.get("/classroom/exercises/").content.decode()
    row = re.search(r"<tr>\s*<td><a[^>]*>Reach the kitchen</a>.*?</tr>", text, re.S).group(0)
    assert "3 attempts" in row and "1 of 2 passed" in row and "class-a" in row  # 2 students
    assert "A draft" in text and "draft</span>" in text


def test_the_grid_shows_each_students_counted_attempt(people):
    tina = signed_in(people["tina"])
    tina.post("/classroom/exercises/new", form(people["class_a"]))
    tina.post("/classroom/exercises/new", form(people["class_a"], title="Latest counts",
                                               counts="latest"))  # fmt: skip
    kitchen = Exercise.objects.get(title="Reach the kitchen")
    latest = Exercise.objects.get(title="Latest counts")
    best = attempt(kitchen, people["alice"], 1, 3, passed=True, ago=30)
    attempt(kitchen, people["alice"], 2, 1, ago=10)
    attempt(latest, people["alice"], 1, 3, passed=True, ago=30)
    last = attempt(latest, people["alice"], 2, 2, late=True, ago=5)
    attempt(kitchen, people["bob"], 1, 0, state="running")
    response = tina.get(f"/classroom/{people['class_a'].pk}/grid")
    assert response.status_code == 200
    text = response.content.decode()
    body = re.search(r"<tbody>.*</tbody>", text, re.S).group(0)
    rows = {
        m.group(1): m.group(0)
        for m in re.finditer(r'<tr>\s*<th scope="row"[^>]*><a[^>]*>(\w+).*?</tr>', body, re.S)
    }
    assert set(rows) == {"Alice", "Bob"}  # the teacher is no row
    alice = re.findall(r"<td class=\"grid-cell([^\"]*)\".*?</td>", rows["Alice"], re.S)
    assert alice == [" tried late", " passed"]  # by title: "Latest counts" first
    assert f'href="/attempts/{best.pk}/"' in rows["Alice"] and "✔" in rows["Alice"]
    assert "3/3" in rows["Alice"] and "2 attempts" in rows["Alice"]
    assert f'href="/attempts/{last.pk}/"' in rows["Alice"] and "2/3" in rows["Alice"]
    assert "not checked yet" in rows["Bob"] and "1 attempt" in rows["Bob"]
    group = people["class_a"].pk
    assert f'href="/classroom/{group}/students/{people["alice"].pk}/"' in rows["Alice"]
    assert f'href="/api/classes/{people["class_a"].pk}/grades.csv"' in text
    # Under each exercise, how many passed: "Latest counts" none (her latest did not).
    foot = re.search(r"<tfoot>.*</tfoot>", text, re.S).group(0)
    assert re.findall(r"<td>([^<]*)</td>", foot) == ["0 of 2", "1 of 2"]


THREE_BLOCKS = json.dumps(
    {"blocks": {"languageVersion": 0, "blocks": [
        {"type": "robot_drive", "next": {"block": {"type": "robot_wait", "next": {
            "block": {"type": "robot_stop"}}}}}]}}
)  # fmt: skip


def test_recheck_is_offered_after_a_change_and_posts(people):
    """A blocks exercise's "at most N blocks" made stricter: the attempt that passed it is
    offered to be checked again, and is, on its stored program (a static check: no run)."""
    tina = signed_in(people["tina"])

    def blocks(count: str) -> dict:
        data = form(people["class_a"], languages="blocks", **{
            "checks-0-kind": "max_blocks", "checks-0-count": count})  # fmt: skip
        return {k: v for k, v in data.items() if not k.startswith("checks-5-")}

    tina.post("/classroom/exercises/new", blocks("5"))
    exercise = Exercise.objects.get()
    assert exercise.languages == ["blocks"] and exercise.checks[0]["count"] == 5
    Attempt.objects.create(
        exercise=exercise, student=people["alice"], number=1, language="blocks",
        source=THREE_BLOCKS, state="done", score=2, max_score=2, passed=True,
        results=[{"check": 0, "variant": None, "passed": True, "why": "", "points": 2}],
    )  # fmt: skip
    url = f"/classroom/exercises/{exercise.pk}/edit"
    assert "Re-check everyone" not in tina.get(url).content.decode()
    # Saved unchanged: nothing to re-check.
    response = tina.post(url, blocks("5"), follow=True)
    assert "Re-check everyone" not in response.content.decode()
    response = tina.post(url, blocks("2"), follow=True)
    exercise.refresh_from_db()
    assert exercise.version == 2
    text = response.content.decode()
    assert "Re-check everyone" in text and "One attempt was checked before" in text
    assert tina.get(f"/classroom/exercises/{exercise.pk}/recheck").status_code == 405
    response = tina.post(f"/classroom/exercises/{exercise.pk}/recheck", follow=True)
    assert response.status_code == 200
    text = response.content.decode()
    assert "1 attempt is being checked again" in text and "Re-check everyone" not in text
    checked = Attempt.objects.get()
    assert checked.exercise_version == 2
    assert (checked.passed, checked.score) == (False, 0)


def test_recheck_is_offered_for_counted_attempts_only(people):
    """An attempt that does not count (a worse one, the best counts) is not re-checked: once
    the counted ones are, nothing is offered any more."""
    tina = signed_in(people["tina"])
    data = form(people["class_a"], languages="blocks", **{
        "checks-0-kind": "max_blocks", "checks-0-count": "5"})  # fmt: skip
    data = {k: v for k, v in data.items() if not k.startswith("checks-5-")}
    tina.post("/classroom/exercises/new", data)
    exercise = Exercise.objects.get()
    for number, passed in ((1, True), (2, False)):
        Attempt.objects.create(
            exercise=exercise, student=people["alice"], number=number, language="blocks",
            source=THREE_BLOCKS, state="done", score=2 if passed else 0, max_score=2,
            passed=passed,
        )  # fmt: skip
    url = f"/classroom/exercises/{exercise.pk}/edit"
    text = tina.post(url, {**data, "checks-0-count": "4"}, follow=True).content.decode()
    assert "One attempt was checked before" in text  # alice's counted one, not two
    text = tina.post(f"/classroom/exercises/{exercise.pk}/recheck", follow=True).content.decode()
    assert "1 attempt is being checked again" in text and "Re-check everyone" not in text
    versions = dict(Attempt.objects.values_list("number", "exercise_version"))
    assert versions == {1: 2, 2: 1}
