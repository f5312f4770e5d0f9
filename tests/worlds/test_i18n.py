"""The worlds' pages in Portuguese: no English string of the catalogs shown to a pt-BR account
(the check of tests/test_i18n_complete.py, over these pages), and the API's errors in it."""

import pytest
from django.contrib.auth.models import User

from robotide.models import LanguagePreference
from tests.test_i18n_complete import VisibleText, english_in, english_patterns, signed_in
from tests.worlds.documents import corridor
from worlds.documents import validated
from worlds.models import World
from worlds.shares import add_share

pytestmark = pytest.mark.django_db


@pytest.fixture
def bia():
    user = User.objects.create_user("bia", password="pw-bia-123")
    LanguagePreference.objects.create(user=user, language="pt-br")
    return user


def test_worlds_pages_in_portuguese(bia):
    document = validated(corridor(), "corridor")
    world = World.objects.create(owner=bia, name="corridor", title=document["title"])
    world.save_document(document, bia)
    add_share(world, bia, everyone=True)
    other = User.objects.create_user("caio")
    theirs = World.objects.create(owner=other, name="theirs", title="Theirs", document=document)
    add_share(theirs, other, everyone=True)
    patterns = english_patterns()
    found = {}
    for url in ["/worlds/", f"/worlds/{world.pk}/shares/", f"/worlds/{world.pk}/delete"]:
        page = signed_in(bia).get(url)
        assert page.status_code == 200 and page["Content-Language"] == "pt-br", url
        text = VisibleText.of(page.content.decode())
        assert "Mundos" in text, url
        if url == "/worlds/":  # the built-in worlds' titles too
            assert "Labirinto" in text and "Pista de linha" in text
        if english := english_in(text, patterns):
            found[url] = english
    assert not found, found


def test_api_errors_in_portuguese(bia):
    client = signed_in(bia)  # Accept-Language: pt-BR

    def call(method, path, body=None):
        return getattr(client, method)(path, body, content_type="application/json")

    assert call("get", "/api/worlds/999").json()["detail"] == "Mundo não encontrado."
    too_large = call("post", "/api/worlds", corridor(padding="x" * 300_000))
    assert "no máximo 256 KB" in too_large.json()["detail"]
    clash = call("post", "/api/worlds", corridor(name="maze")).json()["detail"][0]
    assert clash["msg"] == "maze é o nome de um mundo pronto: dê outro nome ao seu"
