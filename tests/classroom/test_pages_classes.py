"""The classroom's class pages through Django's test client: a teacher's classes and a new
one, students added in bulk (pasted, CSV), the sheet of one-time passwords shown once, sign-up
with a join code (and a wrong one, throttled), the one-time password forcing a change, a
student's page and its filters, and who may open what."""

import io
from datetime import timedelta

import pytest
from django.contrib.auth.models import Group, User
from django.core.cache import cache
from django.test import Client
from django.utils import timezone

from classroom.accounts import create_class
from classroom.models import Classroom, Exercise, OneTimePassword, Work
from classroom.views_classes import SHEET_KEY, untouched_examples
from programs.models import Program, Run
from robotide.models import ClassTeacher, DirectoryAccount
from robots.models import Robot
from worlds.models import World, WorldShare

pytestmark = pytest.mark.django_db
PASSWORD = "a long enough passphrase"


@pytest.fixture(autouse=True)
def _fresh_throttle():
    cache.clear()  # sign-in and join-code failures are counted in the cache
    yield
    cache.clear()


def signed_in(user) -> Client:
    client = Client()
    client.force_login(user)
    return client


@pytest.fixture
def tina():
    return User.objects.create_user("tina", password=PASSWORD, first_name="Tina")


@pytest.fixture
def class_a(tina):
    return create_class("Class 7B", tina)


@pytest.fixture
def ana(class_a):
    user = User.objects.create_user("ana", password=PASSWORD, first_name="Ana", last_name="Lima")
    user.groups.add(class_a)
    return user


def page(response) -> str:
    return response.content.decode()


def sheet_passwords(client, group) -> dict[str, str]:
    """username -> one-time password, as the sheet shows them."""
    import re

    text = page(client.get(f"/classroom/{group.pk}/sheet"))
    usernames = re.findall(r'class="sheet-username">([^<]+)<', text)
    passwords = re.findall(r'class="sheet-password">([^<]+)<', text)
    return dict(zip(usernames, passwords, strict=True))


# -- the classes ---------------------------------------------------------------------------


def test_create_class(tina):
    ClassTeacher.objects.create(group=Group.objects.create(name="old class"), user=tina)
    client = signed_in(tina)
    listing = page(client.get("/classroom/"))
    assert "old class" in listing and "New class" in listing
    response = client.post("/classroom/", {"name": "8A robots"})
    group = Group.objects.get(name="8A robots")
    assert response["Location"] == f"/classroom/{group.pk}/"
    assert ClassTeacher.objects.filter(group=group, user=tina).exists()
    code = Classroom.objects.get(group=group).join_code
    assert code and len(code) == 8
    shown = page(client.get(response["Location"]))
    assert "8A robots" in shown and code in shown and "No students yet" in shown
    listing = page(client.get("/classroom/"))
    assert "8A robots" in listing and "0 students" in listing
    again = client.post("/classroom/", {"name": "8a ROBOTS"})
    assert again.status_code == 400 and "already" in page(again)


def test_bulk_add_from_a_pasted_list(tina, class_a):
    client = signed_in(tina)
    names = "Ana Maria Silva\n\nBruno Costa\n  Célia Dias  \n"
    response = client.post(f"/classroom/{class_a.pk}/students/add", {"names": names})
    assert response["Location"] == f"/classroom/{class_a.pk}/sheet"
    students = {u.username: u for u in class_a.user_set.all()}
    assert set(students) == {"ana-maria-silva", "bruno-costa", "celia-dias"}
    assert students["celia-dias"].get_full_name() == "Célia Dias"
    assert OneTimePassword.objects.filter(user__in=students.values()).count() == 3
    # The session keeps them encrypted, never in clear; the key is the teacher's cookie.
    stored = client.session[SHEET_KEY]
    shown = sheet_passwords(client, class_a)
    assert set(shown) == set(students)
    for username, password in shown.items():
        assert password not in stored and len(password) == 10
        assert students[username].check_password(password)
    # The class's page lists them, each waiting to choose a password.
    detail = page(client.get(f"/classroom/{class_a.pk}/"))
    assert "Bruno Costa" in detail and detail.count("one-time password</span>") == 3


def test_bulk_add_from_a_csv(tina, class_a, ana):
    """A spreadsheet's export (Windows' encoding, a header row); an existing username joins."""
    upload = io.BytesIO("Nome\nDóra Reis\nana\n".encode("cp1252"))
    upload.name = "turma.csv"
    client = signed_in(tina)
    response = client.post(f"/classroom/{class_a.pk}/students/add", {"file": upload})
    assert response.status_code == 302, page(response)
    assert set(class_a.user_set.values_list("username", flat=True)) == {"ana", "dora-reis"}
    shown = sheet_passwords(client, class_a)
    assert list(shown) == ["dora-reis"]  # ana existed: in the class, no new password
    assert User.objects.get(username="dora-reis").first_name == "Dóra"
    # Rows of username and name choose the username; pasted and uploaded lists add up.
    upload = io.BytesIO(b"username,name\nedu7,Eduardo Melo\n")
    upload.name = "more.csv"
    client.post(f"/classroom/{class_a.pk}/students/add", {"file": upload, "names": "Fabi"})
    assert set(sheet_passwords(client, class_a)) == {"edu7", "fabi"}


def test_bulk_add_refuses_what_it_cannot_make(tina, class_a):
    staff = User.objects.create_user("sam", password=PASSWORD, is_staff=True)
    client = signed_in(tina)
    nothing = client.post(f"/classroom/{class_a.pk}/students/add", {"names": "  \n"})
    assert nothing.status_code == 400 and "Paste names" in page(nothing)
    refused = client.post(f"/classroom/{class_a.pk}/students/add", {"names": "Eva\nsam"})
    assert refused.status_code == 400
    assert "line 2 (sam)" in page(refused) and "Nobody was added" in page(refused)
    assert not class_a.user_set.exists() and not staff.groups.exists()
    assert not User.objects.filter(username="eva").exists()


def test_the_sheet_is_shown_once(tina, class_a):
    client = signed_in(tina)
    client.post(f"/classroom/{class_a.pk}/students/add", {"names": "Ana\nBia"})
    first = client.get(f"/classroom/{class_a.pk}/sheet")
    assert first.status_code == 200 and "no-store" in first["Cache-Control"]
    assert page(first).count('class="sheet-password"') == 2
    assert SHEET_KEY not in client.session
    second = client.get(f"/classroom/{class_a.pk}/sheet")
    assert second.status_code == 410 and 'class="sheet-password"' not in page(second)
    assert "shown once" in page(second)


def test_the_sheet_needs_the_browser_that_made_it(tina, class_a):
    """The session alone (the database's row) cannot show the passwords."""
    client = signed_in(tina)
    client.post(f"/classroom/{class_a.pk}/students/add", {"names": "Ana"})
    client.cookies.pop("classroom_sheet_key")
    assert client.get(f"/classroom/{class_a.pk}/sheet").status_code == 410


def test_new_one_time_password_for_a_student(tina, class_a, ana):
    client = signed_in(tina)
    response = client.post(f"/classroom/{class_a.pk}/students/{ana.pk}/password")
    assert response["Location"] == f"/classroom/{class_a.pk}/sheet"
    password = sheet_passwords(client, class_a)["ana"]
    ana.refresh_from_db()
    assert ana.check_password(password) and not ana.check_password(PASSWORD)
    assert OneTimePassword.objects.filter(user=ana, issued_by=tina).exists()


def test_a_directory_student_keeps_their_password(tina, class_a, ana):
    DirectoryAccount.objects.create(user=ana, dn="uid=ana,ou=people,dc=school")
    client = signed_in(tina)
    response = client.post(f"/classroom/{class_a.pk}/students/{ana.pk}/password", follow=True)
    assert "directory" in page(response)
    ana.refresh_from_db()
    assert ana.check_password(PASSWORD) and not OneTimePassword.objects.filter(user=ana).exists()


def test_a_directory_class_shows(tina):
    """A class LDAP made at a teacher's sign-in (no Classroom row) is on their page, and gets
    a join code when it is turned on."""
    tina_dir = DirectoryAccount.objects.create(user=tina, dn="uid=tina,dc=school")
    tina_dir.sync_classes({"lab-2026"}, teaches=True)
    group = Group.objects.get(name="lab-2026")
    client = signed_in(tina)
    assert "lab-2026" in page(client.get("/classroom/"))
    detail = page(client.get(f"/classroom/{group.pk}/"))
    assert "Joining by code is off" in detail
    client.post(f"/classroom/{group.pk}/join-code", {"action": "on"})
    assert Classroom.objects.get(group=group).join_code


def test_join_code_on_off_new(tina, class_a):
    client = signed_in(tina)
    old = Classroom.objects.get(group=class_a).join_code
    client.post(f"/classroom/{class_a.pk}/join-code", {"action": "new"})
    new = Classroom.objects.get(group=class_a).join_code
    assert new and new != old
    client.post(f"/classroom/{class_a.pk}/join-code", {"action": "off"})
    assert Classroom.objects.get(group=class_a).join_code is None
    assert "Joining by code is off" in page(client.get(f"/classroom/{class_a.pk}/"))


def test_robots_given_and_taken(tina, class_a):
    lab = Robot.objects.create(name="lab-1", url="sim://", owner=tina)
    other = Robot.objects.create(name="lab-2", url="sim://")  # everyone's, not tina's
    client = signed_in(tina)
    detail = page(client.get(f"/classroom/{class_a.pk}/"))
    assert '<option value="lab-1">' in detail and "lab-2" not in detail
    client.post(f"/classroom/{class_a.pk}/robots", {"robot": "lab-1", "action": "give"})
    assert list(lab.groups.all()) == [class_a]
    refused = client.post(
        f"/classroom/{class_a.pk}/robots", {"robot": "lab-2", "action": "give"}, follow=True
    )
    assert "not yours to give" in page(refused) and not other.groups.exists()
    taken = client.post(
        f"/classroom/{class_a.pk}/robots", {"robot": "lab-1", "action": "take"}, follow=True
    )
    assert "everyone may use it" in page(taken) and not lab.groups.exists()


def test_worlds_shared_with_the_class(tina, class_a):
    world = World.objects.create(owner=tina, name="maze-2", title="Maze two")
    client = signed_in(tina)
    client.post(f"/classroom/{class_a.pk}/worlds", {"world": world.pk, "action": "share"})
    assert WorldShare.objects.filter(world=world, group=class_a).exists()
    assert "Maze two" in page(client.get(f"/classroom/{class_a.pk}/"))
    client.post(f"/classroom/{class_a.pk}/worlds", {"world": world.pk, "action": "unshare"})
    assert not WorldShare.objects.filter(world=world).exists()
    theirs = World.objects.create(owner=User.objects.create_user("wes"), name="w", title="W")
    response = client.post(f"/classroom/{class_a.pk}/worlds", {"world": theirs.pk})
    assert response.status_code == 404 and not WorldShare.objects.filter(world=theirs).exists()


# -- who may open what ---------------------------------------------------------------------


def test_a_teacher_cannot_open_another_teachers_class(tina, class_a, ana):
    tom = User.objects.create_user("tom", password=PASSWORD)
    create_class("tom's class", tom)
    client = signed_in(tom)
    assert "Class 7B" not in page(client.get("/classroom/"))
    base = f"/classroom/{class_a.pk}"
    for url in (f"{base}/", f"{base}/sheet", f"{base}/students/{ana.pk}/"):
        assert client.get(url).status_code == 404, url
    for url, data in [
        (f"{base}/students/add", {"names": "Mallory"}),
        (f"{base}/join-code", {"action": "new"}),
        (f"{base}/students/{ana.pk}/password", {}),
        (f"{base}/students/{ana.pk}/remove", {}),
    ]:
        assert client.post(url, data).status_code == 404, url
    assert not User.objects.filter(username="mallory").exists()
    assert ana.groups.filter(pk=class_a.pk).exists() and ana.check_password(PASSWORD)


def test_a_student_cannot_open_the_classroom(ana, class_a):
    client = signed_in(ana)
    assert client.get("/classroom/").status_code == 403
    assert client.get(f"/classroom/{class_a.pk}/").status_code == 403
    assert client.post("/classroom/", {"name": "mine"}).status_code == 403
    assert not Group.objects.filter(name="mine").exists()
    menu = page(client.get("/programs/"))
    assert 'href="/classroom/"' not in menu and 'href="/exercises/"' in menu


def test_a_student_of_another_class_is_not_on_this_ones_page(tina, class_a):
    stranger = User.objects.create_user("zed")
    client = signed_in(tina)
    assert client.get(f"/classroom/{class_a.pk}/students/{stranger.pk}/").status_code == 404


def test_signed_out_goes_to_sign_in(class_a):
    response = Client().get("/classroom/")
    assert response.status_code == 302 and "/accounts/login/" in response["Location"]


def test_menu_admin_link_only_for_who_sees_something(tina, class_a):
    staff_teacher = User.objects.create_user("stella", password=PASSWORD, is_staff=True)
    menu = page(signed_in(staff_teacher).get("/programs/"))
    assert 'href="/classroom/"' in menu and 'href="/admin/"' not in menu
    menu = page(signed_in(tina).get("/programs/"))
    assert 'href="/classroom/"' in menu and 'href="/admin/"' not in menu
    from django.contrib.auth.models import Permission

    staff_teacher.user_permissions.add(Permission.objects.get(codename="view_robot"))
    assert 'href="/admin/"' in page(signed_in(staff_teacher).get("/programs/"))
    boss = User.objects.create_superuser("boss", password=PASSWORD)
    assert 'href="/admin/"' in page(signed_in(boss).get("/programs/"))


# -- sign-up with a join code --------------------------------------------------------------


def join_form(code, username="nina", **more):
    return {
        "code": code, "username": username, "full_name": "Nina Paz",
        "password1": PASSWORD, "password2": PASSWORD, **more,
    }  # fmt: skip


def test_join_with_a_code(class_a):
    code = Classroom.objects.get(group=class_a).join_code
    client = Client()
    assert "Join code" in page(client.get("/accounts/join/"))
    typed = code.lower()[:4] + "-" + code.lower()[4:]  # as read off a board
    response = client.post("/accounts/join/", join_form(typed))
    assert response.status_code == 302, page(response)
    nina = User.objects.get(username="nina")
    assert nina.get_full_name() == "Nina Paz" and list(nina.groups.all()) == [class_a]
    assert not OneTimePassword.objects.filter(user=nina).exists()
    welcome = page(client.get(response["Location"], follow=True))
    assert "Sign out" in welcome and "Class 7B" in welcome


def test_join_with_a_wrong_code(class_a):
    client = Client()
    response = client.post("/accounts/join/", join_form("ABCD2345"))
    assert response.status_code == 400
    assert "No class has this join code" in page(response)
    assert not User.objects.filter(username="nina").exists()


def test_join_codes_are_throttled_like_sign_ins(class_a, settings):
    settings.LOGIN_THROTTLE = {**settings.LOGIN_THROTTLE, "failures": 3}
    code = Classroom.objects.get(group=class_a).join_code
    client = Client()
    for _ in range(3):
        client.post("/accounts/join/", join_form("WRONG234"))
    locked = client.post("/accounts/join/", join_form(code))
    assert locked.status_code == 400 and "Too many wrong join codes" in page(locked)
    assert not User.objects.filter(username="nina").exists()
    # Another name from the same address is counted apart (as sign-ins are, per pair).
    other = client.post("/accounts/join/", join_form(code, username="otto"))
    assert other.status_code == 302


def test_join_when_off_or_signed_in(class_a, ana):
    classroom = Classroom.objects.get(group=class_a)
    code = classroom.join_code
    other = create_class("8C", User.objects.create_user("ted"))
    other_code = Classroom.objects.get(group=other).join_code
    client = signed_in(ana)
    assert "signed in as" in page(client.get("/accounts/join/"))
    assert client.post("/accounts/join/", {"code": other_code}).status_code == 302
    assert set(ana.groups.all()) == {class_a, other}
    classroom.join_code = None
    classroom.save()
    assert Client().post("/accounts/join/", join_form(code)).status_code == 400


def test_join_refuses_a_weak_password_or_a_taken_name(class_a, ana):
    code = Classroom.objects.get(group=class_a).join_code
    weak = Client().post("/accounts/join/", join_form(code, password1="123", password2="123"))
    assert weak.status_code == 400 and "too short" in page(weak)
    taken = Client().post("/accounts/join/", join_form(code, username="ANA"))
    assert taken.status_code == 400 and "already exists" in page(taken)


# -- one-time passwords --------------------------------------------------------------------


def test_a_one_time_password_must_be_changed(tina, class_a):
    client = signed_in(tina)
    client.post(f"/classroom/{class_a.pk}/students/add", {"names": "Rui Sá"})
    password = sheet_passwords(client, class_a)["rui-sa"]
    rui = Client()
    assert rui.login(username="rui-sa", password=password)
    for url in ("/programs/", "/classroom/", "/accounts/", "/runs/"):
        response = rui.get(url)
        assert response.status_code == 302 and response["Location"] == "/accounts/password/"
    assert rui.get("/api/programs").status_code == 403
    assert rui.get("/accounts/password/").status_code == 200
    assert rui.get("/i18n/js/").status_code == 200
    changed = rui.post(
        "/accounts/password/",
        {"old_password": password, "new_password1": PASSWORD, "new_password2": PASSWORD},
    )
    assert changed.status_code == 302
    assert not OneTimePassword.objects.filter(user__username="rui-sa").exists()
    assert rui.get("/programs/").status_code == 200
    # A wrong old password changes nothing, and the page still insists.
    again = Client()
    client.post(
        f"/classroom/{class_a.pk}/students/{User.objects.get(username='rui-sa').pk}/password"
    )
    fresh = sheet_passwords(client, class_a)["rui-sa"]
    assert again.login(username="rui-sa", password=fresh)
    wrong = again.post(
        "/accounts/password/",
        {"old_password": "nope", "new_password1": PASSWORD, "new_password2": PASSWORD},
    )
    assert wrong.status_code == 200 and OneTimePassword.objects.filter(user__username="rui-sa")
    assert again.get("/programs/")["Location"] == "/accounts/password/"
    assert again.post("/accounts/logout/").status_code == 302


# -- a student's page ----------------------------------------------------------------------


def test_student_page_filters(tina, class_a, ana):
    robot = Robot.objects.create(name="sim-ana-1", url="sim://", personal=True, owner=ana)
    mine = Program.objects.create(owner=ana, name="my maze", language="python")
    mine.save_source("print('maze')\n", ana)
    old = Program.objects.create(owner=ana, name="old one", language="python")
    old.save_source("print('old')\n", ana)
    Program.objects.filter(pk=old.pk).update(updated=timezone.now() - timedelta(days=30))
    run = Run.objects.create(
        program=mine, program_name=mine.name, language="python", robot=robot, owner=ana
    )
    exercise = Exercise.objects.create(owner=tina, group=class_a, title="Reach the kitchen",
                                       world="boxes")  # fmt: skip
    Work.objects.create(exercise=exercise, student=ana, program=mine)
    client = signed_in(tina)
    url = f"/classroom/{class_a.pk}/students/{ana.pk}/"

    shown = page(client.get(url))
    assert "my maze" in shown and "old one" in shown and "Reach the kitchen" in shown
    assert f'href="/programs/{mine.pk}/"' in shown and f'href="/runs/{run.pk}/"' in shown
    assert 'href="/robots/sim-ana-1/"' in shown
    assert "Compass" not in shown  # the untouched examples are hidden by default
    untouched = len(untouched_examples(Program.objects.filter(owner=ana)))
    assert untouched == Program.objects.filter(owner=ana).count() - 2
    assert f"{untouched} examples they got with the account" in shown

    assert "Compass" in page(client.get(url, {"examples": "on"}))
    since = (timezone.now() - timedelta(days=3)).date().isoformat()
    recent = page(client.get(url, {"since": since}))
    assert "my maze" in recent and "old one" not in recent
    by_exercise = page(client.get(url, {"exercise": exercise.pk}))
    assert "my maze" in by_exercise and "old one" not in by_exercise
    # An example run once is no longer untouched: it shows.
    compass = Program.objects.get(owner=ana, name="Compass")
    Run.objects.create(program=compass, program_name="Compass", language="python",
                       robot=robot, owner=ana)  # fmt: skip
    assert "Compass" in page(client.get(url))
    bad = client.get(url, {"since": "yesterday"})
    assert bad.status_code == 200 and "Enter a valid date" in page(bad)


def test_class_page_counts(tina, class_a, ana):
    robot = Robot.objects.create(name="sim-ana-1", url="sim://", personal=True, owner=ana)
    program = Program.objects.filter(owner=ana).first()
    for _ in range(2):
        Run.objects.create(program=program, program_name=program.name, language="python",
                           robot=robot, owner=ana)  # fmt: skip
    ana.last_login = timezone.now() - timedelta(hours=2)
    ana.save()
    client = signed_in(tina)
    row = page(client.get(f"/classroom/{class_a.pk}/")).split("Ana Lima", 1)[1].split("</tr>")[0]
    assert "2\xa0hours ago" in row and "</span> 0 programs</td>" in row
    assert "Runs:</span> 2</td>" in row and "Sims:</span> 1</td>" in row
    program.save_source(program.source + "\n# mine now\n", ana)  # an example changed
    row = page(client.get(f"/classroom/{class_a.pk}/")).split("Ana Lima", 1)[1].split("</tr>")[0]
    assert "</span> 1 program</td>" in row


def test_remove_a_student(tina, class_a, ana):
    client = signed_in(tina)
    client.post(f"/classroom/{class_a.pk}/students/{ana.pk}/remove")
    assert not ana.groups.exists() and User.objects.filter(pk=ana.pk).exists()


def test_staff_see_every_class_but_roles(tina, class_a, ana):
    from django.contrib.auth.models import Permission

    role = Group.objects.create(name="lab admins")
    role.permissions.add(Permission.objects.get(codename="view_robot"))
    stella = User.objects.create_user("stella", password=PASSWORD, is_staff=True)
    client = signed_in(stella)
    listing = page(client.get("/classroom/"))
    assert "Class 7B" in listing and "lab admins" not in listing
    shown = page(client.get(f"/classroom/{class_a.pk}/students/{ana.pk}/"))
    assert "You do not teach this class" in shown
    assert "You do not teach" not in page(
        signed_in(tina).get(f"/classroom/{class_a.pk}/students/{ana.pk}/")
    )


def test_odd_robot_names_are_refused(tina, class_a):
    client = signed_in(tina)
    response = client.post(
        f"/classroom/{class_a.pk}/robots", {"robot": "lab\x00", "action": "give"}, follow=True
    )
    assert response.status_code == 200 and "No robot named" in page(response)
