"""Sign-in through an institution's directory: a real OpenLDAP slapd (tests/ldap_server.py),
started on a free port with a directory of a student, a teacher and a staff member and their
groups, and the settings robotide.settings builds from ROBOTIDE_LDAP_* for it."""

import pytest
from django.contrib.auth.models import Group, User
from django.core.cache import cache
from django.test import Client

from programs.models import Program
from programs.signals import EXAMPLES
from robotide.models import ClassTeacher, DirectoryAccount
from tests.ldap_server import (
    PEOPLE,
    add_entries,
    as_directory_admin,
    ldap_env,
    person,
    running_slapd,
)

pytestmark = pytest.mark.django_db


@pytest.fixture(scope="module")
def slapd(tmp_path_factory):
    with running_slapd(tmp_path_factory.mktemp("slapd")) as uri:
        yield uri


@pytest.fixture
def directory(slapd, settings, monkeypatch):
    """The settings robotide.settings makes of these ROBOTIDE_LDAP_* for the test's slapd."""
    from robotide.settings import ldap_settings

    for name, value in ldap_env(slapd).items():
        monkeypatch.setenv(name, value)
    for name, value in ldap_settings().items():
        setattr(settings, name, value)
    cache.clear()  # the sign-in throttle's counters
    settings.AUTHENTICATION_BACKENDS = [
        "robotide.security.ThrottledModelBackend",
        "robotide.directory.DirectoryBackend",
    ]
    return slapd


def sign_in(username: str, password: str) -> tuple[Client, str]:
    client = Client()
    response = client.post(
        "/accounts/login/", {"username": username, "password": password}, follow=True
    )
    return client, response.content.decode()


def signed_in_as(client: Client) -> str | None:
    user_id = client.session.get("_auth_user_id")
    return User.objects.get(pk=user_id).username if user_id else None


def test_a_student_signs_in_and_gets_their_class(directory):
    client, _ = sign_in("stu", "stu-pass-1")
    assert signed_in_as(client) == "stu"
    stu = User.objects.get(username="stu")
    assert (stu.first_name, stu.last_name, stu.email) == ("Sam", "Student", "stu@uni.test")
    assert [g.name for g in stu.groups.all()] == ["class-robotics1"]  # not the chess club
    assert not stu.is_staff and not stu.has_usable_password()
    assert DirectoryAccount.objects.get(user=stu).dn == f"uid=stu,{PEOPLE}"
    assert client.get("/accounts/").status_code == 200


def test_an_account_from_the_directory_gets_the_examples(directory):
    sign_in("stu", "stu-pass-1")
    names = set(Program.objects.filter(owner__username="stu").values_list("name", flat=True))
    assert names == set(EXAMPLES.values())


def test_the_teacher_teaches_the_class(directory):
    client, _ = sign_in("tea", "tea-pass-1")
    assert signed_in_as(client) == "tea"
    taught = ClassTeacher.objects.filter(user__username="tea")
    assert [t.group.name for t in taught] == ["class-robotics1"]
    assert not User.objects.get(username="tea").groups.exists()  # a teacher, not a member


def test_staff_is_staff(directory):
    client, _ = sign_in("sta", "sta-pass-1")
    assert signed_in_as(client) == "sta"
    assert User.objects.get(username="sta").is_staff
    assert client.get("/admin/").status_code == 200


def test_a_class_is_made_once_and_left_when_the_directory_says_so(directory):
    sign_in("stu", "stu-pass-1")
    sign_in("stu", "stu-pass-1")
    assert Group.objects.filter(name="class-robotics1").count() == 1
    by_hand = Group.objects.create(name="lab-extra")
    stu = User.objects.get(username="stu")
    stu.groups.add(by_hand)
    account = DirectoryAccount.objects.get(user=stu)
    account.classes = ["class-robotics1", "class-old"]
    account.save()
    stu.groups.add(Group.objects.create(name="class-old"))
    sign_in("stu", "stu-pass-1")
    names = sorted(stu.groups.values_list("name", flat=True))
    assert names == ["class-robotics1", "lab-extra"]  # the one added by hand stays


def test_a_wrong_password_is_refused(directory):
    client, page = sign_in("stu", "not-the-password")
    assert signed_in_as(client) is None
    assert "enter a correct username and password" in page


def test_a_student_removed_from_the_directory_can_no_longer_sign_in(directory):
    client, _ = sign_in("stu", "stu-pass-1")
    assert signed_in_as(client) == "stu"
    with as_directory_admin(directory) as conn:
        conn.delete_s(f"uid=stu,{PEOPLE}")
        try:
            client, page = sign_in("stu", "stu-pass-1")
            assert signed_in_as(client) is None
            assert "enter a correct username and password" in page
        finally:
            add_entries(conn, person("stu", "Sam", "Student", "stu-pass-1"))


def test_local_admin_still_signs_in(directory):
    User.objects.create_superuser("admin", password="admin-pass-1")
    client, _ = sign_in("admin", "admin-pass-1")
    assert signed_in_as(client) == "admin"
    assert not DirectoryAccount.objects.filter(user__username="admin").exists()


def test_a_directory_entry_does_not_take_over_a_local_account(directory):
    User.objects.create_user("stu", password="local-pass-1")
    client, _ = sign_in("stu", "stu-pass-1")
    assert signed_in_as(client) is None
    client, _ = sign_in("stu", "local-pass-1")
    assert signed_in_as(client) == "stu"


def test_sign_in_throttling_still_locks_out(directory, settings):
    settings.LOGIN_THROTTLE = {**settings.LOGIN_THROTTLE, "failures": 3}
    for _ in range(3):
        sign_in("stu", "wrong")
    client, page = sign_in("stu", "stu-pass-1")
    assert signed_in_as(client) is None
    assert "Too many failed sign-ins" in page


def guess_five_times(username: str) -> None:
    for attempt in range(5):
        _, page = sign_in(username, f"guess {attempt}")
        expected = "Too many failed sign-ins" if attempt == 4 else "enter a correct username"
        assert expected in page, f"guess {attempt + 1}"


def test_a_directory_password_guessed_5_times_locks_the_user_from_the_address(directory, settings):
    # Guessing a student's directory password is the bigger risk: the same 5 as a local one.
    settings.LOGIN_THROTTLE = {**settings.LOGIN_THROTTLE, "failures": 5}
    guess_five_times("stu")
    client, page = sign_in("stu", "stu-pass-1")  # the right directory password waits too
    assert signed_in_as(client) is None and "Too many failed sign-ins" in page
    client, _ = sign_in("tea", "tea-pass-1")  # others from this address are not locked
    assert signed_in_as(client) == "tea"


def test_the_directory_backend_is_throttled_on_its_own(directory, settings):
    # Not only behind the local accounts' backend: a site may list the directory alone or first.
    settings.AUTHENTICATION_BACKENDS = ["robotide.directory.DirectoryBackend"]
    settings.LOGIN_THROTTLE = {**settings.LOGIN_THROTTLE, "failures": 5}
    guess_five_times("stu")
    client, page = sign_in("stu", "stu-pass-1")
    assert signed_in_as(client) is None and "Too many failed sign-ins" in page


def test_the_admin_shows_where_an_account_comes_from(directory):
    sign_in("stu", "stu-pass-1")
    User.objects.create_user("guest", password="guest-pass-1")
    admin = Client()
    admin.force_login(User.objects.create_superuser("root", password="root-pass-1"))
    page = admin.get("/admin/auth/user/").content.decode()
    assert "column-origin" in page
    assert page.count(">directory<") == 1 and page.count(">local<") >= 2
    local = admin.get("/admin/auth/user/?origin=local").content.decode()
    assert "guest" in local and ">stu<" not in local
    stu = User.objects.get(username="stu")
    change = admin.get(f"/admin/auth/user/{stu.pk}/change/").content.decode()
    assert "From the directory (LDAP)" in change and f"uid=stu,{PEOPLE}" in change


def test_without_a_uri_ldap_is_off(monkeypatch):
    from robotide.settings import ldap_settings

    monkeypatch.delenv("ROBOTIDE_LDAP_URI", raising=False)
    assert ldap_settings() == {}


def test_a_half_configured_directory_fails_loudly(monkeypatch):
    from robotide.settings import ldap_settings

    monkeypatch.setenv("ROBOTIDE_LDAP_URI", "ldap://127.0.0.1:1")
    monkeypatch.delenv("ROBOTIDE_LDAP_USER_BASE", raising=False)
    with pytest.raises(ValueError, match="ROBOTIDE_LDAP_USER_BASE"):
        ldap_settings()
    monkeypatch.setenv("ROBOTIDE_LDAP_USER_BASE", PEOPLE)
    monkeypatch.setenv("ROBOTIDE_LDAP_CLASS_FILTER", "(cn=class-*)")
    monkeypatch.delenv("ROBOTIDE_LDAP_GROUP_BASE", raising=False)
    with pytest.raises(ValueError, match="ROBOTIDE_LDAP_GROUP_BASE"):
        ldap_settings()
    monkeypatch.setenv("ROBOTIDE_LDAP_ATTRS", "phone=telephoneNumber")
    with pytest.raises(ValueError, match="ROBOTIDE_LDAP_ATTRS"):
        ldap_settings()
