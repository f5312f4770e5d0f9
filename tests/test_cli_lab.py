"""The robotide command for a lab: accounts (`user add`), `export` and `import` of programs.

Most tests call `main(argv)` against the test database; the last runs the installed command.
"""

import io
import json
import os
import re
import subprocess
import sys
import zipfile
from datetime import date

import pytest
from django.contrib.auth import authenticate
from django.contrib.auth.models import Group, User

from programs.models import Program
from robotide.cli import main
from tests.appliance import ROBOTIDE

pytestmark = [pytest.mark.django_db, pytest.mark.usefixtures("keep_umask")]


@pytest.fixture
def stdin(monkeypatch):
    def feed(data: bytes):
        monkeypatch.setattr(sys, "stdin", io.TextIOWrapper(io.BytesIO(data)))

    return feed


@pytest.fixture
def alice():
    user = User.objects.create_user("alice", password="pw-alice-123")
    user.programs.all().delete()
    for name, language, source in [("Compass", "python", "print(1)\n"), ("Hi", "shell", "ls\n")]:
        Program.objects.create(owner=user, name=name, language=language).save_source(source, user)
    return user


# -- user add ------------------------------------------------------------------------------------


def test_user_add_prints_a_generated_password_once(capsys):
    assert main(["user", "add", "dave"]) == 0
    out = capsys.readouterr().out
    first, second = out.splitlines()
    password = re.fullmatch(r"Created user 'dave', password '(\S+)'", first).group(1)
    assert second == "(shown once; change it at /accounts/password/)"
    assert authenticate(username="dave", password=password) is not None
    dave = User.objects.get(username="dave")
    assert not dave.is_staff and not dave.groups.exists()
    assert dave.programs.filter(name="Compass").exists()  # the examples, as any new account


def test_user_add_staff_into_a_group_created_if_need_be(capsys):
    os.environ.pop("ROBOTIDE_USER_PASSWORD", None)
    assert main(["user", "add", "teacher", "--staff", "--group", "Class 3A"]) == 0
    assert "Created user 'teacher' (staff) in group 'Class 3A', password" in capsys.readouterr().out
    assert main(["user", "add", "pupil", "--group", "Class 3A"]) == 0
    group = Group.objects.get(name="Class 3A")
    assert set(group.user_set.values_list("username", flat=True)) == {"teacher", "pupil"}
    assert User.objects.get(username="teacher").is_staff


def test_user_add_refuses_an_existing_user(capsys, alice):
    assert main(["user", "add", "alice", "--staff"]) == 2
    assert capsys.readouterr().err == "robotide: a user named 'alice' exists already\n"
    alice.refresh_from_db()
    assert not alice.is_staff and alice.check_password("pw-alice-123")


def test_user_add_password_from_stdin_or_the_environment(capsys, stdin, monkeypatch):
    stdin(b"stdin-pass-4821\n")
    assert main(["user", "add", "erin", "--password-stdin"]) == 0
    monkeypatch.setenv("ROBOTIDE_USER_PASSWORD", "env-pass-9713")
    assert main(["user", "add", "fred"]) == 0
    out = capsys.readouterr().out
    assert out == "Created user 'erin'\nCreated user 'fred'\n"  # no password shown
    assert authenticate(username="erin", password="stdin-pass-4821") is not None
    assert authenticate(username="fred", password="env-pass-9713") is not None


@pytest.mark.parametrize(
    ("argv", "given", "error"),
    [
        (["user", "add", "gina", "--password-stdin"], b"short\n", "password refused: "),
        (["user", "add", "gina", "--password-stdin"], b"", "no password on standard input"),
        (["user", "add", "gi na"], b"", "Enter a valid username"),
        (["user", "add", "gina", "--group", "x" * 151], b"", "at most 150 characters"),
    ],
)
def test_user_add_refuses_clearly(capsys, stdin, argv, given, error):
    stdin(given)
    assert main(argv) == 2
    assert error in capsys.readouterr().err
    assert not User.objects.filter(username__startswith="gi").exists()
    assert not Group.objects.exists()


# -- export --------------------------------------------------------------------------------------


def zip_contents(data: bytes) -> dict:
    with zipfile.ZipFile(io.BytesIO(data)) as zf:
        return {name: zf.read(name).decode() for name in zf.namelist()}


def test_export_to_a_file(capsys, alice, tmp_path):
    target = tmp_path / "out.zip"
    assert main(["export", "alice", "-o", str(target)]) == 0
    files = zip_contents(target.read_bytes())
    assert files.keys() == {"compass.py", "hi.sh", "manifest.json"}
    assert {p["name"] for p in json.loads(files["manifest.json"])["programs"]} == {"Compass", "Hi"}
    assert capsys.readouterr().err == f"Exported 2 programs of alice to {target}\n"


def test_export_to_standard_output_when_it_is_not_a_terminal(capsysbinary, alice):
    assert main(["export", "alice"]) == 0
    captured = capsysbinary.readouterr()
    assert zip_contents(captured.out)["hi.sh"] == "ls\n"
    assert b"to standard output" in captured.err


def test_export_to_a_dated_file_when_standard_output_is_a_terminal(
    capsys, alice, tmp_path, monkeypatch
):
    monkeypatch.chdir(tmp_path)
    monkeypatch.setattr(sys.stdout, "isatty", lambda: True)
    assert main(["export", "alice"]) == 0
    written = tmp_path / f"robotide-alice-{date.today().isoformat()}.zip"
    assert "compass.py" in zip_contents(written.read_bytes())
    assert capsys.readouterr().out == ""


def test_export_errors(capsys, alice, tmp_path):
    assert main(["export", "nobody"]) == 2
    assert capsys.readouterr().err == "robotide: no user named 'nobody'\n"
    assert main(["export", "alice", "-o", str(tmp_path / "no" / "such" / "dir.zip")]) == 1
    assert "robotide: cannot write" in capsys.readouterr().err


# -- import --------------------------------------------------------------------------------------


@pytest.fixture
def exported(alice, tmp_path, capsys) -> str:
    path = tmp_path / "alice.zip"
    main(["export", "alice", "-o", str(path)])
    capsys.readouterr()
    return str(path)


def test_import_prints_the_report(capsys, exported):
    hal = User.objects.create_user("hal")
    hal.programs.exclude(name="Compass").delete()
    assert main(["import", "hal", exported]) == 0
    assert capsys.readouterr().out == (
        "created 'Compass (2)' from compass.py\n"
        "created 'Hi' from hi.sh\n"
        "2 created, 0 updated, 0 skipped for hal\n"
    )
    assert hal.programs.get(name="Hi").origin == "imported from alice.zip"


def test_import_replace_adds_revisions(capsys, alice, exported):
    compass = alice.programs.get(name="Compass")
    compass.save_source("print(2)\n", alice)
    assert main(["import", "alice", exported, "--replace"]) == 0
    assert capsys.readouterr().out == (
        "updated 'Compass' from compass.py\n"
        "skipped hi.sh: the same as 'Hi' already\n"
        "0 created, 1 updated, 1 skipped for alice\n"
    )
    assert [r.source for r in compass.revisions.all()] == ["print(1)\n", "print(2)\n", "print(1)\n"]


def test_import_from_standard_input(capsys, stdin, alice, exported):
    with open(exported, "rb") as zip_file:
        stdin(zip_file.read())
    assert main(["import", "alice", "-"]) == 0
    assert "2 created" in capsys.readouterr().out
    assert alice.programs.get(name="Hi (2)").origin == "imported from standard input"


def test_import_errors_import_nothing(capsys, alice, tmp_path):
    not_a_zip = tmp_path / "notes.zip"
    not_a_zip.write_text("hello")
    assert main(["import", "alice", str(not_a_zip)]) == 1
    assert capsys.readouterr().err == (
        "robotide: nothing imported: Not a zip file (File is not a zip file).\n"
    )
    assert main(["import", "alice", str(tmp_path / "missing.zip")]) == 2
    assert "robotide: cannot read" in capsys.readouterr().err
    assert main(["import", "nobody", str(not_a_zip)]) == 2
    assert alice.programs.count() == 2


# -- the installed command -----------------------------------------------------------------------


def test_the_installed_command_end_to_end(tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("REDIS_URL", "DATABASE_URL")}
    env.update(ROBOTIDE_DATA=str(tmp_path), ROBOTIDE_USER_PASSWORD="")

    def robotide(*args):
        return subprocess.run(
            [ROBOTIDE, *args], env=env, capture_output=True, text=True, timeout=60
        )

    assert robotide("manage", "migrate", "-v0").returncode == 0
    added = robotide("user", "add", "ivy", "--group", "3A")
    assert re.match(r"Created user 'ivy' in group '3A', password '\S+'", added.stdout)
    # robotide export ivy | robotide import ivy -   (both start at once: they take a while)
    exporter = subprocess.Popen([ROBOTIDE, "export", "ivy"], env=env, stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE)  # fmt: skip
    imported = subprocess.run(
        [ROBOTIDE, "import", "ivy", "-"], env=env, stdin=exporter.stdout, capture_output=True,
        text=True, timeout=60,
    )  # fmt: skip
    exporter.stdout.close()
    assert exporter.wait(timeout=60) == 0, exporter.stderr.read()
    assert imported.returncode == 0, imported.stderr
    assert "created 'Compass (2)' from compass.py" in imported.stdout
    assert imported.stdout.endswith("created, 0 updated, 0 skipped for ivy\n")
