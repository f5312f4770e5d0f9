"""The Languages page (/languages/): each language's row, and its Debugger column (issue 32):
which languages have robotide's debugger, and for the others what of their own could serve
later, said as not there yet."""

import re

import pytest
from django.contrib.auth.models import User
from django.utils import translation

from programs.languages import LANGUAGES

pytestmark = pytest.mark.django_db


@pytest.fixture
def page(client) -> str:
    client.force_login(User.objects.create_user("lin", password="pw-lin-12345"))
    return client.get("/languages/").content.decode()


def rows(page: str) -> dict[str, str]:
    """Each language's row, by its API name (the row's <code>)."""
    body = page.split('<table class="list" id="languages">', 1)[1].split("</table>", 1)[0]
    found = {}
    for row in re.findall(r"<tr>(.*?)</tr>", body.split("<tbody>", 1)[1], re.S):
        name = re.search(r"<td><code>([a-z]+)</code></td>", row).group(1)
        found[name] = row
    return found


def debugger_cell(row: str) -> str:
    return re.search(r'<td class="debugger">(.*?)</td>', row, re.S).group(1)


def test_it_asks_to_sign_in(client):
    assert client.get("/languages/").status_code == 302


def test_every_language_has_a_row_with_a_debugger_column(page):
    assert "<th>Debugger</th>" in page
    assert set(rows(page)) == set(LANGUAGES)
    assert all(debugger_cell(row).strip() for row in rows(page).values())


def test_python_and_blocks_have_the_debugger(page):
    found = rows(page)
    for name in ("python", "blocks"):
        cell = debugger_cell(found[name])
        assert '<span class="state finished">Debugger</span>' in cell, name
        assert "no debugger yet" not in cell
    assert "on the Python made of the blocks" in debugger_cell(found["blocks"])


# What each language's own debugger (or what could make one) is called on its row.
LATER = {
    "javascript": ["node --inspect", "Chrome DevTools Protocol"],
    "perl": ["perl -d", "perl5db.pl", "PERLDB_OPTS"],
    "ruby": ["debug gem", "rdbg", "Ruby 3.1"],
    "lua": ["debug.sethook"],
    "tcl": ["none built in", "trace add execution"],
    "shell": ["bash -x", "bashdb"],
}


def test_the_others_say_none_yet_and_what_could_serve_later(page):
    found = rows(page)
    assert set(LATER) == {name for name, lang in LANGUAGES.items() if not lang.debuggable}
    for name, words in LATER.items():
        cell = debugger_cell(found[name])
        assert "no debugger yet" in cell and "None in robotide yet" in cell, name
        assert "state finished" not in cell, name
        for word in words:
            assert word in cell, (name, word)


def test_the_notes_are_translatable():
    """Marked for translation (gettext_lazy), so the i18n pass finds them: a lazy string
    resolves in the active language, not at import."""
    for lang in LANGUAGES.values():
        assert lang.debugger_note, lang.name
        assert type(lang.debugger_note) is not str, lang.name
        with translation.override("en"):
            assert str(lang.debugger_note)
