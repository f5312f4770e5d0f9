"""classroom.access: who sees which classes, exercises and attempts (issue 31).

A school of two classes: class-a (alice, bob; taught by tina), class-b (dan; taught by tom);
carol in no class; sam is staff. The API's answers to the same questions are in
test_api_exercises.py and test_api_classes.py.
"""

import pytest
from django.contrib.auth.models import Group, User
from django.http import Http404

from classroom import access
from classroom.models import Attempt, Exercise
from robotide.models import ClassTeacher

pytestmark = pytest.mark.django_db

BOXES = {"title": "t", "world": "boxes"}


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


def exercise(owner, group, title="reach the kitchen"):
    return Exercise.objects.create(
        owner=owner, group=group, title=title, world="boxes",
        variants=[{"x": 0.0, "y": 0.0, "theta": 0.0, "hidden": False},
                  {"x": -1.0, "y": 1.0, "theta": 0.5, "hidden": True}],
    )  # fmt: skip


def attempt(exercise, student, number=1):
    return Attempt.objects.create(
        exercise=exercise, student=student, number=number, language="python"
    )


def test_students_see_their_classes_exercises_only(school):
    mine = exercise(school["tina"], school["a"])
    theirs = exercise(school["tom"], school["b"])
    draft = exercise(school["tina"], None, "draft")
    assert set(access.exercises_for_user(school["alice"])) == {mine}
    assert set(access.exercises_for_user(school["dan"])) == {theirs}
    assert set(access.exercises_for_user(school["carol"])) == set()
    assert set(access.exercises_for_user(school["tina"])) == {mine, draft}
    assert set(access.exercises_for_user(school["tom"])) == {theirs}
    assert set(access.exercises_for_user(school["sam"])) == {mine, theirs, draft}
    for who, pk in (("alice", theirs.pk), ("alice", draft.pk), ("tom", mine.pk)):
        with pytest.raises(Http404):
            access.get_exercise_for_user(school[who], pk)
    with pytest.raises(Http404):
        access.get_exercise_for_user(school["alice"], "not a number")


def test_only_authors_teachers_and_staff_change_and_see_hidden(school):
    mine = exercise(school["tina"], school["a"])
    assert access.can_edit_exercise(school["tina"], mine)
    assert access.can_edit_exercise(school["sam"], mine)
    assert not access.can_edit_exercise(school["alice"], mine)
    assert not access.can_edit_exercise(school["tom"], mine)
    assert access.sees_hidden(school["tina"], mine)
    assert not access.sees_hidden(school["alice"], mine)
    # A co-teacher of the class may.
    ClassTeacher.objects.create(group=school["a"], user=school["tom"])
    assert access.can_edit_exercise(school["tom"], mine)


def test_a_student_reads_only_their_own_attempts(school):
    mine = exercise(school["tina"], school["a"])
    alices, bobs = attempt(mine, school["alice"]), attempt(mine, school["bob"])
    assert access.get_attempt_for_user(school["alice"], alices.pk) == alices
    with pytest.raises(Http404):
        access.get_attempt_for_user(school["alice"], bobs.pk)
    assert set(access.attempts_for_user(school["alice"])) == {alices}
    assert set(access.attempts_for_user(school["tina"])) == {alices, bobs}
    assert set(access.attempts_for_user(school["sam"])) == {alices, bobs}
    with pytest.raises(Http404):
        access.get_attempt_for_user(school["tom"], bobs.pk)
    with pytest.raises(Http404):
        access.get_attempt_for_user(school["carol"], alices.pk)


def test_classes_of_a_teacher(school):
    assert list(access.classes_for_teacher(school["tina"])) == [school["a"]]
    assert list(access.classes_for_teacher(school["alice"])) == []
    assert set(access.classes_for_teacher(school["sam"])) == {school["a"], school["b"]}
    assert access.get_class_for_teacher(school["tom"], school["b"].pk) == school["b"]
    with pytest.raises(Http404):
        access.get_class_for_teacher(school["tom"], school["a"].pk)
    with pytest.raises(Http404):
        access.get_class_for_teacher(school["alice"], school["a"].pk)
    assert access.is_teacher(school["tina"]) and access.is_teacher(school["sam"])
    assert not access.is_teacher(school["alice"])


def test_exercises_only_for_classes_one_teaches(school):
    assert access.can_set_for_class(school["tina"], school["a"].pk)
    assert not access.can_set_for_class(school["tina"], school["b"].pk)
    assert not access.can_set_for_class(school["alice"], school["a"].pk)
    assert access.can_set_for_class(school["alice"], None)  # a draft: anyone signed in
    assert access.can_set_for_class(school["sam"], school["b"].pk)


def test_inactive_and_anonymous_see_nothing(school):
    from django.contrib.auth.models import AnonymousUser

    mine = exercise(school["tina"], school["a"])
    attempt(mine, school["alice"])
    school["alice"].is_active = False
    for who in (AnonymousUser(), school["alice"]):
        assert not access.exercises_for_user(who).exists()
        assert not access.attempts_for_user(who).exists()
        assert not access.classes_for_teacher(who).exists()
