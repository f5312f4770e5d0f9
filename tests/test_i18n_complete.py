"""Portuguese complete: a page shown in pt-BR carries no English string of the catalogs.

Every main page is rendered for a pt-BR account (the Django test client) and its visible text
(tags, scripts, styles and program text removed; titles, labels and placeholders kept) is
searched for every msgid of every catalog whose pt-BR msgstr differs from it: a msgid found
there is English a pt-BR reader was shown (a string not marked for translation, one
translated at import time, a stored English wording shown as it is). The run's page shows a
log with robotide's own lines ("[robotide] failed: exit status 1", written in English by the
supervisor when the run ended), the robot list the sim's "Simulated robot".

Also here: the examples a pt-BR account gets are the Portuguese ones, and follow the
account's language while untouched; a downloaded log's robotide lines are in Portuguese.
"""

import re
from html.parser import HTMLParser
from pathlib import Path

import polib
import pytest
from django.conf import settings
from django.contrib.auth.models import User
from django.test import Client

from programs.models import Program, Run
from programs.signals import EXAMPLES
from robotide import catalogs
from robotide.models import LanguagePreference
from robots.models import Robot

pytestmark = pytest.mark.django_db

ROOT = Path(settings.BASE_DIR)
PORTUGUESE = {"HTTP_ACCEPT_LANGUAGE": "pt-BR,pt;q=0.9"}
# Placeholders: Python's %(name)s and %s, Django's {{ name }} once made a msgid's %(name)s.
PLACEHOLDER = re.compile(r"%\(\w+\)[sdif]|%[sdif]|\{\w*\}")
MIN_LETTERS = 4  # a shorter English word ("Run", "Log", "no") may be a Portuguese one
# Kept in English in Portuguese too: a name (docs/glossary-pt-br.md), a word of the share
# syntax a user types ("user:bob, group:turma-a ou everyone").
KEPT = re.compile(r"\bRobot API\b|\beveryone\b")
# Text a page shows that is not robotide's words: program text, paths, code.
NOT_WORDS = {"script", "style", "textarea", "code"}
VISIBLE_ATTRIBUTES = ("title", "placeholder", "aria-label", "alt")

LOG = """\
o Olá, robô!
e Traceback (most recent call last):
e ZeroDivisionError: division by zero
s [robotide] it came up to its memory limit (1024 MB)
s [robotide] failed: exit status 1
"""


class VisibleText(HTMLParser):
    """The words a reader sees (or hears from a screen reader) on a page."""

    def __init__(self):
        super().__init__(convert_charrefs=True)
        self.parts: list[str] = []
        self.hidden = 0  # depth inside an element whose text is no words of ours

    def handle_starttag(self, tag, attrs):
        attrs = dict(attrs)
        if tag in NOT_WORDS or "code" in (attrs.get("class") or "").split():
            self.hidden += 1
        if tag == "input" and attrs.get("type") in ("submit", "button", "reset"):
            self.parts.append(attrs.get("value") or "")
        self.parts += [attrs[name] or "" for name in VISIBLE_ATTRIBUTES if name in attrs]

    def handle_endtag(self, tag):
        if tag in NOT_WORDS or (tag == "pre" and self.hidden):
            self.hidden = max(0, self.hidden - 1)

    def handle_data(self, data):
        if not self.hidden:
            self.parts.append(data)

    @classmethod
    def of(cls, html: str) -> str:
        parser = cls()
        parser.feed(html)
        return " ".join(" ".join(parser.parts).split())


def english_patterns() -> dict[str, re.Pattern]:
    """msgid -> a pattern finding it in a page's text, for each msgid (and plural) of the
    pt-BR catalogs that its translation changes; placeholders match any short text."""
    patterns = {}
    for folder in catalogs.locale_dirs(ROOT):
        for po_path in folder.glob("pt_BR/LC_MESSAGES/*.po"):
            for entry in polib.pofile(str(po_path)):
                if entry.obsolete or entry.fuzzy:
                    continue
                translations = set(entry.msgstr_plural.values()) | {entry.msgstr}
                for english in filter(None, (entry.msgid, entry.msgid_plural)):
                    if english not in translations and (found := _pattern(english)):
                        patterns[english] = found
    return patterns


def _pattern(msgid: str) -> re.Pattern | None:
    words = " ".join(msgid.split())
    literals = PLACEHOLDER.split(words)
    if sum(c.isalpha() for part in literals for c in part) < MIN_LETTERS:
        return None
    # One lowercase word alone ("stop", "range", "kind"), or with placeholders ("runs
    # %(name)s"), is as often a name from code the pages quote (the Robot API's stop(), its
    # sensors, its fields) as a label: labels are capitalised, or phrases.
    said = " ".join(literals).split()
    if len(said) == 1 and (len(literals) > 1 or said[0].islower()):
        return None
    body = r".{1,80}?".join(re.escape(part) for part in literals)
    # Whole words, not a piece of an address, a file name, a token or a call ("other-robot:8000",
    # "user:bob", "robot.py", "Robot::Error", "stop()"): those are no sentence of ours.
    return re.compile(rf"(?<![\w@/:.-]){body}(?![\w@/(-]|[:.][\w:])")


def english_in(text: str, patterns: dict[str, re.Pattern]) -> list[str]:
    text = KEPT.sub(" ", text)
    return sorted(msgid for msgid, pattern in patterns.items() if pattern.search(text))


@pytest.fixture
def bia():
    """A student whose account speaks Portuguese, with a robot of hers, a program and an ended
    run."""
    user = User.objects.create_user("bia", password="pw-bia-123")
    LanguagePreference.objects.create(user=user, language="pt-br")
    robot, _ = Robot.objects.get_or_create(
        name="sim", defaults={"url": "sim://", "description": "Simulated robot", "owner": user}
    )
    program = Program.objects.create(owner=user, name="Olá robô", language="python")
    program.save_source("print('Olá, robô!')\n1 / 0\n", user)
    run = Run.create_for(program, robot, user)
    Run.mark_ended(run.pk, Run.State.FAILED, 1, "exit status 1")
    run.refresh_from_db()
    run.log_path.parent.mkdir(parents=True, exist_ok=True)
    run.log_path.write_text(LOG)
    return user


def pages(user) -> list[str]:
    program = Program.objects.get(owner=user, name="Olá robô")
    blocks = Program.objects.filter(owner=user, language="blocks").first()
    run = Run.objects.get(owner=user)
    return [
        "/programs/",
        f"/programs/{program.pk}/",
        f"/programs/{blocks.pk}/",
        f"/programs/{program.pk}/revisions/",
        f"/programs/{program.pk}/revisions/1/",
        "/robots/",
        "/robots/sim/",
        "/runs/",
        f"/runs/{run.pk}/",
        "/accounts/",
        "/accounts/password/",
        "/languages/",
        "/help/robot-api/",
        "/worlds/new",
        "/worlds/builtin/boxes",
    ]


def signed_in(user) -> Client:
    client = Client(**PORTUGUESE)
    client.force_login(user)
    return client


def test_no_page_shown_in_portuguese_carries_an_english_string_of_the_catalogs(bia):
    patterns = english_patterns()
    assert "Programs" in patterns and "exit status %(code)s" in patterns  # the catalogs read
    prof = User.objects.create_superuser("prof", password="pw-prof-123")
    LanguagePreference.objects.create(user=prof, language="pt-br")
    # The driver's options, a robot's buttons, the administration's robots and runs.
    staff_pages = [
        "/robots/sim/settings",
        "/robots/sim/buttons/",
        "/admin/",
        "/admin/robots/robot/",
        f"/admin/robots/robot/{Robot.objects.get(name='sim').pk}/change/",
        "/admin/programs/run/",
    ]
    found = {}
    for user, url in [*((bia, url) for url in pages(bia)), *((prof, url) for url in staff_pages)]:
        page = signed_in(user).get(url)
        assert page.status_code == 200, url
        assert page["Content-Language"] == "pt-br", url
        text = VisibleText.of(page.content.decode())
        assert "Sair" in text or "Encerrar sessão" in text, url  # the menu: the text was read
        if english := english_in(text, patterns):
            found[url] = english
    assert not found, "English shown in pt-BR:\n" + "\n".join(
        f"{url}: {english}" for url, english in found.items()
    )


def test_the_checker_finds_english():
    """What the test above relies on: an English msgid in a page's text is found, in a
    title too; Portuguese, and code, are not."""
    patterns = english_patterns()
    html = (
        '<p title="Sign out">Olá</p><textarea>print("Sign out")</textarea>'
        "<pre class='log'><div>[robotide] failed: exit status 1</div></pre>"
        '<script>alert("Programs")</script><code>Programs</code>'
    )
    text = VisibleText.of(html)
    assert english_in(text, patterns) == ["Sign out", "exit status %(code)s"]
    assert english_in(VisibleText.of("<p>Sair; código de saída 1</p>"), patterns) == []


def test_a_downloaded_log_says_robotides_lines_in_portuguese(bia):
    run = Run.objects.get(owner=bia)
    log = signed_in(bia).get(f"/runs/{run.pk}/log")
    text = b"".join(log.streaming_content).decode()
    assert "[robotide] falhou: código de saída 1" in text
    assert "[robotide] ela chegou ao seu limite de memória (1024 MB)" in text
    assert "Olá, robô!" in text and "ZeroDivisionError: division by zero" in text  # as printed
    english = Client()
    english.force_login(User.objects.create_user("teacher", is_staff=True, is_superuser=True))
    english_log = b"".join(english.get(f"/runs/{run.pk}/log").streaming_content).decode()
    assert "[robotide] failed: exit status 1" in english_log  # the file keeps English


# -- the examples, per language ----------------------------------------------------------------


def names_of(user) -> set[str]:
    return set(Program.objects.filter(owner=user).values_list("name", flat=True))


def portuguese_names() -> set[str]:
    from programs.signals import example_name

    return {example_name(filename, "pt-br") for filename in EXAMPLES}


def test_an_account_made_in_portuguese_gets_the_portuguese_examples():
    client = Client(**PORTUGUESE)
    admin = User.objects.create_superuser("prof", password="pw-prof-123")
    LanguagePreference.objects.create(user=admin, language="pt-br")
    client.force_login(admin)
    assert names_of(admin) == portuguese_names()  # swapped at its first sign-in
    assert {"Bússola", "Andar em quadrado", "Até a parede e virar (Python)"} <= names_of(admin)
    compass = Program.objects.get(owner=admin, name="Bússola")
    assert "Meu rumo é" in compass.source and "My heading" not in compass.source
    wall = Program.objects.get(owner=admin, name="Parar antes da parede (Blocos)")
    assert '"Parei a "' in wall.source and "Stopped" not in wall.source


def test_untouched_examples_follow_the_language_and_touched_ones_stay():
    ana = User.objects.create_user("ana", password="pw-ana-123")  # made in English
    assert names_of(ana) == set(EXAMPLES.values())
    square = Program.objects.get(owner=ana, name="Drive a square")
    square.save_source(square.source + "# mine\n", ana)

    client = Client()
    client.force_login(ana)
    client.post("/i18n/setlang/", {"language": "pt-br", "next": "/programs/"})

    names = names_of(ana)
    assert "Bússola" in names and "Compass" not in names
    assert "Drive a square" in names and "Andar em quadrado" not in names  # hers now
    page = VisibleText.of(client.get("/programs/").content.decode())
    assert "Bússola" in page and "Compass" not in page

    client.post("/i18n/setlang/", {"language": "en", "next": "/programs/"})
    assert "Compass" in names_of(ana) and "Bússola" not in names_of(ana)


def test_a_browser_in_portuguese_at_the_first_sign_in_gets_portuguese_examples():
    """An account a teacher made in English, whose student signs in from a pt-BR browser."""
    User.objects.create_user("caio", password="pw-caio-123")
    client = Client(**PORTUGUESE)
    client.post("/accounts/login/", {"username": "caio", "password": "pw-caio-123"})
    assert names_of(User.objects.get(username="caio")) == portuguese_names()


# -- the sim's picture ---------------------------------------------------------------------------


def test_the_sim_draws_its_words_in_its_language():
    """The room names and the panel's labels; one picture for all its viewers, so in the
    robot's `language` option (sim://?language=pt-br, or its settings page)."""
    import asyncio

    import rhal
    from rhal import sim_words

    assert {code for code, _name in settings.LANGUAGES} <= set(sim_words.LANGUAGES)
    assert sim_words.word("pt-br", "home") == "casa" and sim_words.word("en", "home") == "home"

    async def picture(url: str) -> bytes:
        robot = rhal.connect(url)
        await robot.open()
        return await robot.camera_jpeg()

    english = asyncio.run(picture("sim://"))
    portuguese = asyncio.run(picture("sim://?language=pt-br"))
    assert portuguese != english and portuguese == asyncio.run(picture("sim://?language=pt-br"))
    with pytest.raises(ValueError, match="unknown language 'xx'"):
        rhal.connect("sim://?language=xx")


# -- the Robot API's help ------------------------------------------------------------------------


def test_every_text_of_the_robot_api_description_is_translated():
    """programs/robot_api_spec.py is plain data; its texts are msgids in robot_api_words.py: a
    text written or changed in the description and not there would be shown in English."""
    from django.utils import translation

    from programs.robot_api_spec import CALLS, CLIENTS
    from programs.robot_api_words import TEXTS

    texts = {text for client in CLIENTS.values() for text in (client.values, client.errors)}
    for call in CALLS:
        texts |= {call.group, call.summary, call.doc, call.returns}
        texts |= {*call.notes.values(), *call.absent.values()}
        texts |= {text for p in call.params for text in (p.meaning, p.default) if text}
    said = {text for text in texts if any(c.isalpha() for c in text) and text not in UNITS}
    assert not said - set(TEXTS), "not in programs/robot_api_words.py"
    with translation.override("pt-br"):
        assert [text for text in TEXTS if translation.gettext(text) == text] == []


UNITS = {"m/s", "rad/s", "s"}


def test_every_robot_drivers_option_help_is_translated():
    """rhal's option help (a robot's page, its settings form): msgids in robots/driver_words.py."""
    import importlib

    import rhal
    from robots.driver_words import TEXTS

    helps = set()
    for module, name in rhal.DRIVERS.values():
        helps |= set(getattr(importlib.import_module(module), name).option_help.values())
    assert not {text for text in helps if text and text not in TEXTS} - SAME_IN_PORTUGUESE


SAME_IN_PORTUGUESE = {"cia402: m"}


# -- robotide's own lines about a run ------------------------------------------------------------

# What runbox.supervisor, runbox.watch, runbox.cgroups, runlogs and the agent write (examples of
# each wording), stored in English: the log file and Run.reason keep them so.
WORDINGS = [
    "failed: exit status 1",
    "finished: exit status 0",
    "failed: killed by SIGSEGV",
    "failed: CPU time limit reached",
    "failed: file size limit reached",
    "stopped by user: sending SIGTERM",
    "emergency stop: sending SIGKILL",
    "did not stop within 3 s: sending SIGKILL",
    "stopped: stopped by user",
    "stopped: stopped by user before it started",
    "stopped: robot agent shutting down",
    "stopped: it no longer waited to start",
    "failed: could not start: internal error (see the server's log)",
    "failed: could not start: The Perl interpreter is not installed on this robot computer",
    "its box could not be made: its box ended before the run began",
    "output size limit (64 MB) reached; further output was discarded",
    "failed: wall-clock time limit (600 s) reached",
    "failed: CPU time limit (30 s) reached",
    "failed: memory limit (1024 MB) reached: the kernel killed 2 of its processes",
    "failed: the memory limit of all runs together (4096 MB) reached: the kernel killed 1 of"
    " this run's processes",
    "process limit (64 processes) reached",
    "it reached its process limit (64 processes)",
    "it reached its open files limit (256)",
    "it came up to its memory limit (1024 MB)",
    "it filled its folder (100 MB)",
    "it reached its file size limit (16 MB a file)",
    "stopped: its turn on the shared robot ended (120 s)",
    "failed: could not start: the agent of robot 'sim' is not taking commands",
    "failed: run log quota reached (180 MB for a user's logs, the oldest pruned first); further"
    " output was discarded",
]
# English left in a Portuguese line: a few of its words (names and numbers are kept).
ENGLISH = re.compile(r"\b(stopped|failed|finished|sending|reached|limit|its|could|start|the)\b")


@pytest.mark.parametrize("wording", WORDINGS)
def test_robotides_lines_are_said_in_portuguese(wording):
    from django.utils import translation

    from runlogs.system_words import line

    with translation.override("pt-br"):
        said = line(f"[robotide] {wording}")
    assert said.startswith("[robotide] ") and not ENGLISH.search(said[len("[robotide] ") :])
    with translation.override("en"):
        assert line(f"[robotide] {wording}") == f"[robotide] {wording}"


# -- the Portuguese examples read and run --------------------------------------------------------

PT_EXAMPLES = ROOT / "programs" / "examples" / "pt_BR"
# A syntax check per file kind, with the language's own tool (no program is run).
CHECKS = {
    ".sh": ["sh", "-n"],
    ".js": ["node", "--check"],
    ".rb": ["ruby", "-c"],
    ".pl": ["perl", "-c", "-I", str(ROOT / "programs" / "clients" / "perl")],
    ".lua": ["luac", "-p"],
}


@pytest.mark.parametrize("example", sorted(EXAMPLES))
def test_each_example_has_its_portuguese_one_and_it_reads(example):
    import shutil
    import subprocess

    from programs.languages import language_for_filename

    assert {p.name for p in PT_EXAMPLES.iterdir()} <= set(EXAMPLES)  # none of its own
    path, suffix = PT_EXAMPLES / example, Path(example).suffix
    assert path.exists()  # the same file name as its English one
    source = path.read_text()
    if suffix == ".py":
        compile(source, example, "exec")
    elif suffix == ".json":  # blocks: the Python they are made into
        _name, python = language_for_filename(example).program_file(example, source)
        compile(python, example, "exec")
    elif suffix in CHECKS and shutil.which(CHECKS[suffix][0]):
        checked = subprocess.run([*CHECKS[suffix], str(path)], capture_output=True, text=True)
        assert checked.returncode == 0, checked.stderr


@pytest.fixture
async def admitted(agent):
    from tests.robot_api_server import admit

    admit(agent, "good-token", 7)
    return agent


@pytest.mark.django_db(transaction=True)
async def test_the_portuguese_wall_turn_drives_and_says_its_heading(admitted, tmp_path):
    import asyncio

    from programs.languages import LANGUAGES
    from runbox import launcher

    python = LANGUAGES["python"]
    api = {"ROBOT_API": admitted.server.url, "ROBOT_TOKEN": "good-token"}
    process = await asyncio.create_subprocess_exec(
        *python.command(str(PT_EXAMPLES / "wall_turn.py")),
        env=launcher.environment(python, tmp_path, api),
        cwd=tmp_path,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )
    out, err = await asyncio.wait_for(process.communicate(), 60)
    assert process.returncode == 0, err.decode()
    assert re.fullmatch(r"rumo: -?\d+\.\d\n", out.decode())
    assert admitted.shows["rumo"]["value"] == float(out.decode().split()[1])


@pytest.mark.django_db(transaction=True)
async def test_a_live_robotide_line_reaches_a_portuguese_viewer_in_portuguese(tmp_path):
    """The run's live stream (its page, the workbench's console): a line the supervisor sends
    as the run ends is rendered in the viewer's language, like the page's tail."""
    from channels.db import database_sync_to_async
    from channels.layers import get_channel_layer
    from channels.testing import WebsocketCommunicator

    from programs.consumers import RunConsumer
    from robotide.language import WebsocketLanguage
    from robots.bus import run_group

    @database_sync_to_async
    def a_run():
        ana = User.objects.create_user("ana-live")
        robot = Robot.objects.create(name="sim", url="sim://")
        program = Program.objects.create(owner=ana, name="p", language="python")
        run = Run.create_for(program, robot, ana)
        run.log_path.parent.mkdir(parents=True)
        run.log_path.write_bytes(b"o Ol\xc3\xa1\n")
        return ana, run

    ana, run = await a_run()
    app = WebsocketLanguage(RunConsumer.as_asgi())
    portuguese = [(b"accept-language", b"pt-BR")]
    comm = WebsocketCommunicator(app, f"/ws/runs/{run.pk}/", headers=portuguese)
    comm.scope["user"] = ana
    comm.scope["url_route"] = {"kwargs": {"run_id": run.pk}}
    assert (await comm.connect())[0]
    await comm.receive_from(30)  # the tail
    await comm.receive_from(30)  # the state
    lines = [[7, "s", "[robotide] failed: exit status 1"]]  # after the 7 bytes of the tail
    message = {"type": "run.output", "run_id": run.pk, "lines": lines, "skipped": 0}
    await get_channel_layer().group_send(run_group(run.pk), message)
    html = await comm.receive_from(30)
    while "ln s" not in html:
        html = await comm.receive_from(30)
    assert "[robotide] falhou: código de saída 1" in html and "exit status" not in html
    await comm.disconnect()
