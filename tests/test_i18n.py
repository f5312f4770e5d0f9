"""Languages: every catalog complete for pt-BR, the language chosen from the browser, the
menu's switcher, and a signed-in user's stored choice."""

import shutil
import subprocess
from pathlib import Path

import polib
import pytest
from django.conf import settings
from django.contrib.auth.models import User
from django.test import Client

from robotide import catalogs
from robotide.language import language_from_headers
from robotide.models import LanguagePreference
from tests.conftest import in_ci

pytestmark = pytest.mark.django_db

ROOT = Path(settings.BASE_DIR)
LOCALES = catalogs.translated_locales()  # every language offered but English: pt_BR


def need_gettext():
    if shutil.which("msgfmt") and shutil.which("xgettext"):
        return
    message = "GNU gettext is missing: apt-get install gettext (scripts/install-test-deps.sh)"
    if in_ci():
        pytest.fail(message, pytrace=False)
    pytest.skip(message)


def copy_of_the_tree(to: Path) -> Path:
    """The sources and catalogs, not what makemessages ignores: makemessages writes here."""

    def ignored(folder, names):
        return [n for n in names if catalogs._ignored(Path(folder) / n, ROOT)]

    shutil.copytree(ROOT, to, ignore=ignored, symlinks=True)
    return to


def entries(catalog) -> dict:
    return {(e.msgctxt, e.msgid): e.msgstr_plural or e.msgstr for e in catalog if not e.obsolete}


def test_pt_br_is_offered():
    assert "pt_BR" in LOCALES


@pytest.mark.parametrize("locale", LOCALES)
def test_every_catalog_is_complete(tmp_path, locale):
    """makemessages over a copy of the tree: every string of the templates, the Python code and
    the scripts is in a catalog, translated, and none is fuzzy (a guess msgmerge made)."""
    need_gettext()
    tree = copy_of_the_tree(tmp_path / "tree")
    catalogs.make_messages(tree, locale)

    folders = catalogs.locale_dirs(tree)
    assert tree / "locale" in folders
    problems = []
    for folder in folders:
        django_po = folder / locale / "LC_MESSAGES" / "django.po"
        if not django_po.exists():
            problems.append(f"{django_po.relative_to(tree)}: missing")
        for po_path in sorted((folder / locale / "LC_MESSAGES").glob("*.po")):
            po = polib.pofile(str(po_path))
            name = po_path.relative_to(tree)
            problems += [f"{name}: untranslated {e.msgid!r}" for e in po.untranslated_entries()]
            problems += [f"{name}: fuzzy {e.msgid!r}" for e in po.fuzzy_entries()]
    assert not problems, "\n".join(problems)


@pytest.mark.parametrize("locale", LOCALES)
def test_the_committed_mo_files_are_their_po_compiled(tmp_path, locale):
    """Serving reads the .mo files (make run needs no gettext): each says what its .po says."""
    need_gettext()
    pos = [p for d in catalogs.locale_dirs(ROOT) for p in d.glob(f"{locale}/LC_MESSAGES/*.po")]
    assert pos
    for po_path in pos:
        mo_path = po_path.with_suffix(".mo")
        assert mo_path.exists(), f"{mo_path.relative_to(ROOT)}: not compiled"
        fresh = tmp_path / "fresh.mo"
        subprocess.run(["msgfmt", "--check", "-o", fresh, po_path], check=True)
        committed = entries(polib.mofile(str(mo_path)))
        assert committed == entries(polib.mofile(str(fresh))), (
            f"{mo_path.relative_to(ROOT)} is out of date: python -m robotide.catalogs"
        )


# -- the language a page is in ------------------------------------------------------------------


@pytest.fixture
def alice():
    return User.objects.create_user("alice", password="pw-alice-123")


def sign_in(client: Client, password="pw-alice-123"):
    return client.post("/accounts/login/", {"username": "alice", "password": password})


def test_a_portuguese_browser_gets_the_sign_in_page_in_portuguese():
    page = Client(HTTP_ACCEPT_LANGUAGE="pt-BR,pt;q=0.9,en;q=0.5").get("/accounts/login/")
    html = page.content.decode()
    assert page["Content-Language"] == "pt-br" and '<html lang="pt-br">' in html
    assert "<h1>Entrar</h1>" in html and "Nome de usuário" in html and "Senha" in html
    assert "Sign in" not in html and "User name" not in html


def test_an_english_browser_or_none_gets_english():
    for client in (Client(HTTP_ACCEPT_LANGUAGE="en-GB,en;q=0.8"), Client()):
        html = client.get("/accounts/login/").content.decode()
        assert '<html lang="en">' in html and "<h1>Sign in</h1>" in html
        assert "Entrar" not in html


def test_the_switcher_sets_the_language_of_an_anonymous_visitor():
    client = Client(HTTP_ACCEPT_LANGUAGE="en")
    switched = client.post("/i18n/setlang/", {"language": "pt-br", "next": "/accounts/login/"})
    assert switched.status_code == 302 and switched["Location"] == "/accounts/login/"
    assert "<h1>Entrar</h1>" in client.get("/accounts/login/").content.decode()
    assert not LanguagePreference.objects.exists()  # nobody to keep it for


def test_the_menu_has_the_switcher_named_for_screen_readers():
    html = Client().get("/accounts/login/").content.decode()
    assert '<form class="language-switcher" method="post" action="/i18n/setlang/">' in html
    assert '<label for="language-choice" class="visually-hidden">Show the pages in</label>' in html
    assert '<option value="pt-br" lang="pt-br">Português (Brasil)</option>' in html


def test_a_signed_in_users_choice_wins_over_the_browser_on_the_next_sign_in(alice):
    client = Client(HTTP_ACCEPT_LANGUAGE="en")
    sign_in(client)
    client.post("/i18n/setlang/", {"language": "pt-br", "next": "/accounts/"})
    assert LanguagePreference.objects.get(user=alice).language == "pt-br"

    elsewhere = Client(HTTP_ACCEPT_LANGUAGE="en-US,en;q=0.9")  # another browser, no cookie
    assert "<h1>Sign in</h1>" in elsewhere.get("/accounts/login/").content.decode()
    signed_in = sign_in(elsewhere)
    assert signed_in.status_code == 302
    page = elsewhere.get("/accounts/").content.decode()
    assert "Sua conta" in page and "Sair" in page and "Sign out" not in page
    assert '<option value="pt-br" lang="pt-br" selected>' in page


def test_switching_back_is_kept_too(alice):
    LanguagePreference.objects.create(user=alice, language="pt-br")
    client = Client(HTTP_ACCEPT_LANGUAGE="pt-BR")
    sign_in(client)
    client.post("/i18n/setlang/", {"language": "en", "next": "/accounts/"})
    assert LanguagePreference.objects.get(user=alice).language == "en"
    assert "Sign out" in client.get("/accounts/").content.decode()  # over the browser's pt-BR


def test_a_language_not_offered_is_not_stored(alice):
    client = Client()
    sign_in(client)
    client.post("/i18n/setlang/", {"language": "xx", "next": "/accounts/"})
    assert not LanguagePreference.objects.exists()


def test_the_scripts_strings_come_in_the_pages_language():
    catalog = Client(HTTP_ACCEPT_LANGUAGE="pt-BR").get("/i18n/js/").content.decode()
    assert "Salvando" in catalog and "Mudan\\u00e7as n\\u00e3o salvas" in catalog


def test_dates_and_api_details_follow_the_language(alice):
    client = Client(HTTP_ACCEPT_LANGUAGE="pt-BR")
    sign_in(client)
    client.post("/accounts/", {"name": "notebook"})
    page = client.get("/accounts/").content.decode()
    assert "Criado em" in page and "nunca" in page
    from django.utils import timezone

    assert timezone.localtime().strftime("%d/%m/%Y") in page  # pt-BR's short date
    detail = Client(HTTP_ACCEPT_LANGUAGE="pt-BR").get("/api/runs").json()["detail"]
    assert detail.startswith("Autenticação necessária")


def test_a_websocket_speaks_its_browsers_language():
    assert language_from_headers({"accept-language": "pt-BR,pt;q=0.9"}) == "pt-br"
    assert language_from_headers({"accept-language": "de-DE"}) == "en"
    cookie = {"cookie": "csrftoken=x; django_language=pt-br", "accept-language": "en"}
    assert language_from_headers(cookie) == "pt-br"


def test_a_signed_in_page_asks_the_database_nothing_more_for_the_language(alice):
    from django.db import connection
    from django.test.utils import CaptureQueriesContext

    # The account's language is read at sign-in and kept in the session (a run's first line
    # waits for its websocket, which would otherwise take a database trip for it).
    LanguagePreference.objects.create(user=alice, language="pt-br")
    client = Client(HTTP_ACCEPT_LANGUAGE="en")
    sign_in(client)
    client.get("/programs/")
    with CaptureQueriesContext(connection) as counted:
        assert "Sair" in client.get("/programs/").content.decode()
    asked = " ".join(query["sql"] for query in counted.captured_queries)
    assert "languagepreference" not in asked


def test_a_websocket_reads_the_language_from_the_loaded_session(django_assert_num_queries):
    """The session was loaded to find the user: the language costs no query (tests/test_ws_user.py
    has the websockets themselves)."""
    from robotide.language import SESSION_KEY, account_language

    carla = User(username="carla", pk=7)
    with django_assert_num_queries(0):
        assert account_language({SESSION_KEY: "pt-br"}, carla) == "pt-br"
        assert account_language({SESSION_KEY: ""}, carla) is None  # none chosen
        assert account_language({SESSION_KEY: "xx"}, carla) is None  # not offered


def test_the_scripts_catalog_is_not_rebuilt_for_every_page():
    first = Client(HTTP_ACCEPT_LANGUAGE="pt-BR").get("/i18n/js/?l=pt-br")
    assert first.status_code == 200 and first["Last-Modified"]
    again = Client(HTTP_ACCEPT_LANGUAGE="pt-BR").get(
        "/i18n/js/?l=pt-br", HTTP_IF_MODIFIED_SINCE=first["Last-Modified"]
    )
    assert again.status_code == 304
