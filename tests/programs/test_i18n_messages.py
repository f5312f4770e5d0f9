"""The programs and robots apps speak Brazilian Portuguese: API errors (`detail`), form errors,
messages, admin labels and model names, through the real API and admin, and English without
an Accept-Language. Their catalogs are whole and compiled (make run does not compile them)."""

import ast
import gettext
import re
from pathlib import Path

import pytest
from django.contrib.auth.models import User
from django.test import Client
from django.utils import translation

from programs.admin import ProgramAdmin, RunAdmin
from programs.forms import NewProgramForm, UploadForm
from programs.models import Program, Run, in_line
from robotide.models import ApiToken
from robots.models import Robot, RobotStop

pytestmark = pytest.mark.django_db

ROOT = Path(__file__).resolve().parents[2]
CATALOGS = [ROOT / app / "locale/pt_BR/LC_MESSAGES/django" for app in ("programs", "robots")]
PT = {"HTTP_ACCEPT_LANGUAGE": "pt-BR"}


@pytest.fixture
def alice():
    return User.objects.create_user("alice", password="pw-alice-123")


@pytest.fixture
def api(alice):
    _, token = ApiToken.issue(alice)
    client = Client(HTTP_AUTHORIZATION=f"Bearer {token}")

    def call(method, path, body=None, **headers):
        send = getattr(client, method.lower())
        return send(path, body, content_type="application/json", **headers)

    return call


def detail(response) -> str:
    return response.json()["detail"]


@pytest.mark.django_db(transaction=True)  # each clash ends its own transaction
def test_api_conflict_in_portuguese_and_english(api, alice):
    Program.objects.create(owner=alice, name="p", language="python")
    body = {"name": "p", "language": "python"}
    assert detail(api("POST", "/api/programs", body, **PT)) == (
        "Você já tem um programa chamado 'p'."
    )
    assert detail(api("POST", "/api/programs", body)) == "You already have a program named 'p'."


def test_api_errors_in_portuguese_and_english(api):
    assert detail(api("GET", "/api/programs/999999", **PT)) == "Programa não encontrado."
    assert detail(api("GET", "/api/programs/999999")) == "No such program."
    assert detail(api("POST", "/api/robots", {"name": "r", "url": "sim://"}, **PT)) == (
        "Só a equipe pode adicionar robôs."
    )
    assert detail(api("GET", "/api/robots/nope", **PT)) == "Não há robô chamado 'nope'."
    assert detail(api("GET", "/api/robots/nope")) == "No robot named 'nope'."


def test_robot_settings_errors_in_portuguese():
    boss = User.objects.create_superuser("boss", password="pw")
    Robot.objects.create(name="rov", url="sim://")
    client = Client(HTTP_AUTHORIZATION=f"Bearer {ApiToken.issue(boss)[1]}", **PT)
    body = {"settings": {"speech": {"speed": 1000}}}
    bad = client.patch("/api/robots/rov", body, content_type="application/json")
    assert bad.status_code == 422
    assert detail(bad) == "configurações: speed deve ser um número inteiro de 80 a 450"
    unknown = client.patch("/api/robots/rov", {"url": "nope://"}, content_type="application/json")
    assert detail(unknown).startswith("não há driver de robô para 'nope://'; conhecidos: ")


def test_api_validation_errors_in_portuguese(api):
    def messages(response) -> str:
        assert response.status_code == 422
        return " ".join(error["msg"] for error in response.json()["detail"])

    blank = api("POST", "/api/programs", {"name": "  ", "language": "python"}, **PT)
    assert messages(blank) == "o nome não pode ficar em branco"  # no pydantic "Value error, "
    unknown = api("POST", "/api/programs", {"name": "x", "language": "cobol"}, **PT)
    assert "Linguagem desconhecida 'cobol'" in messages(unknown)
    english = api("POST", "/api/programs", {"name": "x", "language": "cobol"})
    assert "Unknown language 'cobol'" in messages(english)


def test_form_errors(alice):
    Program.objects.create(owner=alice, name="p", language="python")
    with translation.override("pt-br"):
        form = NewProgramForm({"name": "p", "language": "python"}, owner=alice)
        assert form.errors["name"] == ["Você já tem um programa chamado 'p'."]
        assert str(form.fields["language"].label) == "Linguagem"
    with translation.override("en"):
        form = NewProgramForm({"name": "p", "language": "python"}, owner=alice)
        assert form.errors["name"] == ["You already have a program named 'p'."]


def test_upload_error_through_the_page(alice):
    from django.core.files.uploadedfile import SimpleUploadedFile

    client = Client(**PT)
    client.force_login(alice)
    upload = SimpleUploadedFile("a.py", b"\xff\xfe\x00bad")
    page = client.post("/programs/upload", {"file": upload, "language": ""})
    assert page.status_code == 400 and "O arquivo não é texto UTF-8." in page.content.decode()
    with translation.override("pt-br"):
        form = UploadForm({"language": ""}, {"file": SimpleUploadedFile("a.xyz", b"x")})
        assert "Escolha uma linguagem" in form.errors["__all__"][0]


def test_model_and_admin_labels():
    with translation.override("pt-br"):
        assert str(Program._meta.verbose_name_plural) == "programas"
        assert str(Run._meta.get_field("exit_code").verbose_name) == "código de saída"
        assert str(Run.State.QUEUED.label) == "na fila"
        assert str(Robot._meta.verbose_name) == "robô"
        assert RobotStop(kind="estop").get_kind_display() == "parada de emergência"
        assert Robot(drive_by="owner").get_drive_by_display() == "seu dono e a equipe"
        assert str(RunAdmin.stop_runs.short_description) == "Parar as execuções selecionadas"
        assert str(ProgramAdmin.shares_count.short_description) == "compartilhamentos"
        assert in_line(2) == "2º na fila"
        assert Run(reason=Run.HELD).reason_shown == "retida após uma parada de emergência"
        assert RobotStop(via="the API").via_shown == "a API"
    with translation.override("en"):
        assert str(Run.State.QUEUED.label) == "queued"
        assert str(Robot._meta.verbose_name) == "robot"
        assert in_line(2) == "2nd in line" and in_line(11) == "11th in line"
        assert Run(reason=Run.HELD).reason_shown == Run.HELD


def test_admin_pages_in_portuguese(alice):
    boss = User.objects.create_superuser("boss", password="pw")
    robot = Robot.objects.create(name="rov", url="sim://")
    Run.create_for(Program.objects.create(owner=alice, name="p", language="python"), robot, alice)
    client = Client(**PT)
    client.force_login(boss)
    runs = client.get("/admin/programs/run/").content.decode()
    assert "Parar as execuções selecionadas" in runs and "código de saída" in runs.lower()
    assert "na fila" in client.get("/admin/programs/run/?state__exact=queued").content.decode()
    robot_page = client.get("/admin/robots/robot/add/").content.decode()
    assert "Quem pode pilotá-lo" in robot_page and "URL do driver" in robot_page
    english = Client()
    english.force_login(boss)
    assert "Stop selected runs" in english.get("/admin/programs/run/").content.decode()


def test_messages_in_portuguese(alice):
    program = Program.objects.create(owner=alice, name="Bússola", language="python")
    client = Client(**PT)
    client.force_login(alice)
    page = client.post(f"/programs/{program.pk}/delete", follow=True).content.decode()
    assert "Bússola excluído." in page


@pytest.mark.parametrize("catalog", CATALOGS, ids=lambda p: p.parts[-5])
def test_catalog_is_whole_and_compiled(catalog):
    po = catalog.with_suffix(".po").read_text()
    assert "#, fuzzy" not in po
    # An empty msgstr (after the header) is an untranslated entry.
    assert not re.search(r'^msgstr(\[\d\])? ""\n\n', po.split("\n\n", 1)[1], re.M)
    with catalog.with_suffix(".mo").open("rb") as mo:
        compiled = gettext.GNUTranslations(mo)._catalog
    entries = [_entry(block) for block in po.split("\n\n")[1:]]
    assert entries and all(compiled.get(key) == text for key, text in entries), (
        "the .mo is not the .po compiled: run compilemessages in the app's folder"
    )


def _entry(block: str) -> tuple:
    """(key, translation) of one .po entry, keyed as gettext's compiled catalog keys it."""
    fields, name = {}, None
    for line in block.splitlines():
        if line.startswith("#"):
            continue
        if not line.startswith('"'):
            name, line = line.split(" ", 1)
        fields[name] = fields.get(name, "") + ast.literal_eval(line)
    msgid = fields["msgid"]
    if "msgctxt" in fields:
        msgid = f"{fields['msgctxt']}\x04{msgid}"
    if "msgid_plural" in fields:
        return (msgid, 1), fields["msgstr[1]"]
    return msgid, fields["msgstr"]


def test_how_programs_are_boxed_in_the_readers_language():
    from robots.isolation_words import isolation_shown

    stored = "sandbox (bubblewrap), own OS account, seccomp, network loopback; cgroup v1 (memory+swap, pids, cpu)"  # noqa: E501
    with translation.override("pt-br"):
        shown = isolation_shown(stored)
    # Said again from its parts (robots.isolation_words; tests/robots/test_isolation_line.py).
    assert shown == (
        "numa sandbox (bubblewrap), cada um com sua própria conta do sistema, seccomp, rede só"
        " no loopback; cgroup v1 (memória+swap, processos, CPU)"
    )


def test_the_admin_names_its_sections_in_portuguese(alice):
    alice.is_staff = alice.is_superuser = True
    alice.save()
    client = Client(**PT)
    client.force_login(alice)
    page = client.get("/admin/").content.decode()
    assert "Programas" in page and "Robôs" in page
