"""The program pages, through Django's test client (scripts-off browsers see just this)."""

import pytest
from django.contrib.auth.models import User
from django.core.files.uploadedfile import SimpleUploadedFile

from programs.models import Program, Run
from programs.signals import EXAMPLES
from robots.models import Robot

pytestmark = pytest.mark.django_db


@pytest.fixture
def alice(client):
    user = User.objects.create_user("alice", password="pw-alice-123")
    client.force_login(user)
    return user


@pytest.fixture
def bob():
    return User.objects.create_user("bob", password="pw-bob-123")


@pytest.fixture
def program(alice):
    program = Program.objects.create(owner=alice, name="hello", language="python")
    program.save_source("print('hello')\n", alice)
    return program


def test_new_accounts_get_the_examples(alice):
    names = set(Program.objects.filter(owner=alice).values_list("name", flat=True))
    assert names == set(EXAMPLES.values())
    assert {"Compass", "Drive a square", "Stop before the wall", "Wall and turn (Perl)"} <= names
    assert all(p.revisions.count() == 1 for p in Program.objects.filter(owner=alice))


def test_it_lists_only_my_programs(client, alice, bob):
    Program.objects.create(owner=bob, name="bobs secret", language="python")
    page = client.get("/programs/").content.decode()
    assert "Compass" in page and "bobs secret" not in page


def test_it_requires_sign_in(client):
    response = client.get("/programs/")
    assert response.status_code == 302 and "/accounts/login/" in response["Location"]


def test_create_opens_the_editor_with_the_language_template(client, alice):
    response = client.post("/programs/new", {"name": "mine", "language": "shell"})
    program = Program.objects.get(owner=alice, name="mine")
    assert response["Location"] == f"/programs/{program.pk}/"
    assert "robot sensors heading" in program.source
    page = client.get(response["Location"]).content.decode()
    assert 'data-editor-mode="shell"' in page and "<textarea" in page


def test_create_refuses_a_duplicate_name(client, alice, program):
    response = client.post("/programs/new", {"name": "hello", "language": "python"})
    assert response.status_code == 400
    assert "already have a program named" in response.content.decode()


def test_every_save_keeps_a_revision(client, alice, program):
    for text in ["print(1)\n", "print(2)\r\n"]:
        client.post(f"/programs/{program.pk}/", {"source": text, "language": "python"})
    program.refresh_from_db()
    assert program.source == "print(2)\n"  # browsers' CRLF stored as LF
    assert [r.number for r in program.revisions.all()] == [3, 2, 1]


def test_compare_and_restore_a_revision(client, alice, program):
    client.post(f"/programs/{program.pk}/", {"source": "print('new')\n", "language": "python"})
    page = client.get(f"/programs/{program.pk}/revisions/1/").content.decode()
    assert '<span class="del">-print(&#x27;hello&#x27;)</span>' in page
    assert '<span class="add">+print(&#x27;new&#x27;)</span>' in page
    client.post(f"/programs/{program.pk}/revisions/1/")
    program.refresh_from_db()
    assert program.source == "print('hello')\n" and program.revisions.first().number == 3


def test_save_as_makes_a_copy(client, alice, program):
    response = client.post(
        f"/programs/{program.pk}/",
        {
            "source": "print('copy')\n",
            "language": "python",
            "save_as": "hello 2",
            "action": "save_as",
        },  # fmt: skip
    )
    copy = Program.objects.get(owner=alice, name="hello 2")
    assert response["Location"] == f"/programs/{copy.pk}/"
    assert copy.source == "print('copy')\n"
    program.refresh_from_db()
    assert program.source == "print('hello')\n"  # the original is untouched


def test_save_as_needs_a_free_name(client, alice, program):
    response = client.post(
        f"/programs/{program.pk}/",
        {"source": "x", "language": "python", "save_as": "Compass", "action": "save_as"},
    )
    assert response.status_code == 400 and "already have" in response.content.decode()


def test_download_and_upload(client, alice, program):
    response = client.get(f"/programs/{program.pk}/download")
    assert response["Content-Disposition"] == 'attachment; filename="hello.py"'
    assert response.content == b"print('hello')\n"
    upload = SimpleUploadedFile("hello.sh", b"echo hi\r\n")
    response = client.post("/programs/upload", {"file": upload})
    new = Program.objects.get(owner=alice, language="shell", source="echo hi\n")
    assert new.name == "hello (2)"  # "hello" was taken
    assert response["Location"] == f"/programs/{new.pk}/"


def test_upload_refuses_unknown_types_and_binary(client, alice):
    bad = client.post("/programs/upload", {"file": SimpleUploadedFile("x.exe", b"MZ")})
    assert bad.status_code == 400 and "Choose a language" in bad.content.decode()
    binary = client.post("/programs/upload", {"file": SimpleUploadedFile("x.py", b"\xff\xfe\x00")})
    assert binary.status_code == 400 and "UTF-8" in binary.content.decode()


def test_delete_asks_first(client, alice, program):
    assert "Delete hello?" in client.get(f"/programs/{program.pk}/delete").content.decode()
    client.post(f"/programs/{program.pk}/delete")
    assert not Program.objects.filter(pk=program.pk).exists()


@pytest.mark.parametrize(
    "path",
    ["/programs/{}/", "/programs/{}/download", "/programs/{}/revisions/", "/programs/{}/delete"],
)
def test_another_users_program_is_not_found(client, alice, bob, path):
    theirs = Program.objects.create(owner=bob, name="theirs", language="python")
    assert client.get(path.format(theirs.pk)).status_code == 404
    posted = client.post(path.format(theirs.pk), {"source": "", "language": "python"})
    assert posted.status_code == 404
    assert Program.objects.filter(pk=theirs.pk, source="").exists()


def test_admins_see_everyones_programs(client, bob):
    admin = User.objects.create_user("root", password="pw-t-123", is_staff=True, is_superuser=True)
    Program.objects.create(owner=bob, name="bobs", language="python")
    client.force_login(admin)
    assert "bobs" in client.get("/programs/").content.decode()


def test_another_users_run_is_not_found(client, alice, bob):
    robot = Robot.objects.create(name="sim", url="sim://")
    program = Program.objects.create(owner=bob, name="b", language="python")
    run = Run.create_for(program, robot, bob)
    for path in [f"/runs/{run.pk}/", f"/runs/{run.pk}/log"]:
        assert client.get(path).status_code == 404
    assert client.post(f"/runs/{run.pk}/stop").status_code == 404
    assert f"#{run.pk}" not in client.get("/runs/").content.decode()


def test_program_names_and_output_are_escaped(client, alice, settings, tmp_path):
    robot = Robot.objects.create(name="sim", url="sim://")
    program = Program.objects.create(owner=alice, name="<b>bold</b>", language="python")
    run = Run.create_for(program, robot, alice)
    run.log_path.parent.mkdir(parents=True)
    run.log_path.write_bytes(b"o <script>alert(1)</script>\n")
    page = client.get(f"/runs/{run.pk}/").content.decode()
    assert "<script>alert(1)</script>" not in page and "&lt;script&gt;" in page
    assert "<b>bold</b>" not in page


def test_a_running_runs_page_does_not_wait_for_the_robots_agent(
    client, alice, program, monkeypatch
):
    """The robot beside the output is fetched once the page is shown: the page itself never
    asks the agent (1 s each time it is away, every 2 s a page without scripts reloads)."""
    robot = Robot.objects.create(name="arm", url="sim://")
    run = Run.create_for(program, robot, alice)

    def asked(*args, **kwargs):
        raise AssertionError("the run's page asked the robot's agent")

    monkeypatch.setattr("robots.views.ask_agent_sync", asked)
    page = client.get(f"/runs/{run.pk}/").content.decode()
    assert f'hx-get="/runs/{run.pk}/robot"' in page
    monkeypatch.undo()
    panel = client.get(f"/runs/{run.pk}/robot")  # no agent here: the panel says so
    assert panel.status_code == 200 and 'id="bench-robot"' in panel.content.decode()
    Run.objects.filter(pk=run.pk).update(state=Run.State.FINISHED)
    assert client.get(f"/runs/{run.pk}/robot").status_code == 204


def test_the_current_revision_is_not_offered_to_compare_with_itself(client, alice):
    program = Program.objects.create(owner=alice, name="hello", language="python")
    program.save_source("print('one')\n", alice)
    program.save_source("print('two')\n", alice)
    listing = client.get(f"/programs/{program.pk}/revisions/").content.decode()
    assert listing.count("Compare with current") == 1  # revision 1's row only
    current = client.get(f"/programs/{program.pk}/revisions/2/").content.decode()
    assert "This is the current revision" in current
    assert "Restore this revision" not in current and "Changes from revision" not in current
    older = client.get(f"/programs/{program.pk}/revisions/1/").content.decode()
    assert "Restore this revision" in older and "Changes from revision 1" in older


def test_a_reader_of_a_shared_program_is_not_offered_restore(client, alice):
    from programs.models import Share

    bob = User.objects.create_user("bob", password="pw-bob-123")
    program = Program.objects.create(owner=bob, name="bobs", language="python")
    program.save_source("print('one')\n", bob)
    program.save_source("print('two')\n", bob)
    Share.objects.create(program=program, user=alice)
    older = client.get(f"/programs/{program.pk}/revisions/1/").content.decode()
    assert "Changes from revision 1" in older and "Restore this revision" not in older
    page = client.get(f"/programs/{program.pk}/").content.decode()
    assert 'id="read-only-note"' in page and "bob shared this program with you" in page
    assert "readonly" in page.split('id="source"')[1].split(">")[0]


def test_example_names_have_no_doubled_brackets(alice):
    names = list(Program.objects.filter(owner=alice).values_list("name", flat=True))
    assert "Wall and turn (JavaScript)" in names
    assert not [name for name in names if "))" in name], names
