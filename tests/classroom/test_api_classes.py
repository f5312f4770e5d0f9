"""Classes through the API (issue 31): POST /api/classes with its students' accounts and their
one-time passwords (answered once), adding students, pasted lists and CSV rows, the grid as
CSV, and who may do each (a teacher only their classes; a student none)."""

import csv
import io

import pytest
from django.contrib.auth.models import Group, User
from django.test import Client

from classroom.accounts import (
    JOIN_ALPHABET,
    PASSWORD_LENGTH,
    Entry,
    create_students,
    entries_from_text,
)
from classroom.models import Classroom, OneTimePassword
from robotide.models import ApiToken, ClassTeacher

pytestmark = pytest.mark.django_db


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


def test_a_class_with_its_students_and_their_one_time_passwords(api, school):
    made = api["tina"]("POST", "/api/classes", {"name": "7B", "students": [
        "Ana Maria Silva", "João Núñez", "carol", {"username": "zeca", "name": "Zé Carlos"},
    ]})  # fmt: skip
    assert made.status_code == 201, made.content
    body = made.json()
    assert set(body) == {"id", "name", "join_code", "students"}
    assert body["name"] == "7B"
    assert len(body["join_code"]) == 8 and set(body["join_code"]) <= set(JOIN_ALPHABET)
    by_name = {s["username"]: s for s in body["students"]}
    assert list(by_name) == ["ana-maria-silva", "joao-nunez", "carol", "zeca"]
    assert by_name["carol"] == {"username": "carol", "name": "", "password": None,
                                "created": False}  # fmt: skip
    assert by_name["zeca"]["name"] == "Zé Carlos" and by_name["zeca"]["created"]
    group = Group.objects.get(pk=body["id"])
    assert ClassTeacher.objects.filter(group=group, user=school["tina"]).exists()
    assert Classroom.objects.get(group=group).created_by == school["tina"]
    assert set(group.user_set.values_list("username", flat=True)) == set(by_name)
    for username in ("ana-maria-silva", "joao-nunez", "zeca"):
        password = by_name[username]["password"]
        assert len(password) == PASSWORD_LENGTH and set(password) <= set(JOIN_ALPHABET)
        user = User.objects.get(username=username)
        assert password not in user.password  # stored hashed
        assert Client().login(username=username, password=password)
        assert OneTimePassword.objects.get(user=user).issued_by == school["tina"]
    ana = User.objects.get(username="ana-maria-silva")
    assert (ana.first_name, ana.last_name) == ("Ana", "Maria Silva")
    assert not OneTimePassword.objects.filter(user=school["carol"]).exists()
    # The passwords were shown once: never again.
    again = api["tina"]("GET", f"/api/classes/{group.pk}")
    assert again.status_code == 200
    assert again.json()["students"][0] == {"username": "ana-maria-silva",
                                           "name": "Ana Maria Silva"}  # fmt: skip
    for username in ("ana-maria-silva", "joao-nunez", "zeca"):
        assert by_name[username]["password"] not in again.content.decode()
    listed = api["tina"]("GET", "/api/classes").json()
    assert [c["name"] for c in listed] == ["7B", "class-a"]
    assert listed[0]["students"] == 4 and listed[0]["teachers"] == ["tina"]


def test_the_same_list_again_makes_no_accounts(api, school):
    names = ["Ana Silva", "Bruno Costa"]
    first = api["tina"]("POST", f"/api/classes/{school['a'].pk}/students", {"students": names})
    assert [s["created"] for s in first.json()["students"]] == [True, True]
    again = api["tina"]("POST", f"/api/classes/{school['a'].pk}/students", {"students": names})
    assert again.status_code == 200
    assert again.json()["students"] == [
        {"username": "ana-silva", "name": "Ana Silva", "password": None, "created": False},
        {"username": "bruno-costa", "name": "Bruno Costa", "password": None, "created": False},
    ]
    assert User.objects.filter(username__startswith="ana-silva").count() == 1
    # Another class's Ana Silva is another student: a username of her own.
    other = api["tom"]("POST", f"/api/classes/{school['b'].pk}/students", {"students": names})
    assert [s["username"] for s in other.json()["students"]] == ["ana-silva-2", "bruno-costa-2"]


def test_a_teacher_adds_students_only_to_their_classes(api, school):
    response = api["tom"]("POST", f"/api/classes/{school['a'].pk}/students",
                          {"students": ["carol", "Eve Intruder"]})  # fmt: skip
    assert response.status_code == 404
    assert not school["a"].user_set.filter(username="carol").exists()
    assert not User.objects.filter(username="eve-intruder").exists()
    for who in ("alice", "carol"):
        assert api[who]("POST", f"/api/classes/{school['a'].pk}/students",
                        {"students": ["x"]}).status_code == 404  # fmt: skip
        assert api[who]("GET", f"/api/classes/{school['a'].pk}").status_code == 404
        assert api[who]("GET", f"/api/classes/{school['a'].pk}/grades.csv").status_code == 404
        assert api[who]("GET", "/api/classes").json() == []
    assert api["tom"]("GET", f"/api/classes/{school['a'].pk}").status_code == 404
    # Staff see every class.
    assert {c["name"] for c in api["sam"]("GET", "/api/classes").json()} == {"class-a", "class-b"}
    assert api["sam"]("GET", f"/api/classes/{school['a'].pk}").status_code == 200


def test_only_teachers_and_staff_make_classes(api, school):
    """Else a student would make a class of her classmates and read their programs."""
    for who in ("alice", "carol"):
        response = api[who]("POST", "/api/classes", {"name": "mine", "students": ["bob"]})
        assert response.status_code == 403
    assert not Group.objects.filter(name="mine").exists()
    assert api["sam"]("POST", "/api/classes", {"name": "staff's"}).status_code == 201


def test_teachers_and_staff_cannot_be_made_students(api, school):
    """A class's teachers read its students' programs: tina adding tom (a teacher) or sam
    (staff) to her class would read theirs."""
    for who in ("tom", "sam"):
        response = api["tina"]("POST", f"/api/classes/{school['a'].pk}/students",
                               {"students": ["New One", who]})  # fmt: skip
        assert response.status_code == 422, response.content
        [error] = response.json()["detail"]
        assert error["path"] == "students[1]" and who in error["msg"]
        assert not school["a"].user_set.filter(username=who).exists()
        assert not User.objects.filter(username="new-one").exists()  # all or nothing


@pytest.mark.parametrize(
    "body, path",
    [
        ({"name": "class-a"}, "name"),  # taken
        ({"name": "   "}, "name"),
        ({"name": "7C", "students": ["ok", ""]}, "students[1]"),
        ({"name": "7C", "students": [{"username": "bad name!", "name": "X"}]}, "students[0]"),
    ],
)
def test_class_errors_say_where(api, body, path):
    response = api["tina"]("POST", "/api/classes", body)
    assert response.status_code == 422, response.content
    [error] = response.json()["detail"]
    assert error["path"] == path and error["msg"]
    assert not Group.objects.filter(name="7C").exists()


def test_pasted_lists_and_csv_rows():
    assert entries_from_text("Ana\n\n  Bruno Costa \nCarla\n") == [
        Entry(name="Ana"),
        Entry(name="Bruno Costa"),
        Entry(name="Carla"),
    ]
    assert entries_from_text("\ufeffusername,full name\nzeca,Zé Carlos\nmia,Mia Lee\n") == [
        Entry(username="zeca", name="Zé Carlos"),
        Entry(username="mia", name="Mia Lee"),
    ]
    assert entries_from_text('nome\n"Silva, Ana"\nBruno\n') == [
        Entry(name="Silva, Ana"),
        Entry(name="Bruno"),
    ]
    assert entries_from_text("usuario;nome\nana;Ana Silva\n") == [
        Entry(username="ana", name="Ana Silva")
    ]
    assert entries_from_text("") == []


def test_csv_rows_make_accounts(school):
    made = create_students(
        school["a"], entries_from_text("username,full name\nzeca,Zé Carlos\nalice,Alice A\n"),
        school["tina"],
    )  # fmt: skip
    assert [(a.username, a.created) for a in made] == [("zeca", True), ("alice", False)]
    assert made[1].password is None
    assert User.objects.get(username="zeca").get_full_name() == "Zé Carlos"


def test_grades_csv_is_an_attachment(api, school):
    response = api["tina"]("GET", f"/api/classes/{school['a'].pk}/grades.csv")
    assert response.status_code == 200
    assert response["Content-Type"].startswith("text/csv")
    assert response["Content-Disposition"].startswith("attachment;")
    assert "grades-class-a.csv" in response["Content-Disposition"]
    rows = list(csv.reader(io.StringIO(response.content.decode())))
    assert rows == [["username", "name"], ["alice", ""], ["bob", ""]]
