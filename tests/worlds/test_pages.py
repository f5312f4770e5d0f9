"""The worlds' pages: the list (mine, shared, everyone's, built-ins), export as a JSON file
(/worlds/<id>.json) and import of it, sharing."""

import io
import json

import pytest
from django.test import Client

from tests.worlds.documents import corridor
from worlds.models import World

pytestmark = pytest.mark.django_db


def signed_in(user) -> Client:
    client = Client()
    client.force_login(user)
    return client


def stored(owner, **changes) -> World:
    from worlds.documents import validated

    document = validated(corridor(**changes), changes.get("name", "corridor"))
    world = World.objects.create(owner=owner, name=document["name"], title=document["title"])
    world.save_document(document, owner)
    return world


def upload(client, data: bytes, name="world.json"):
    file = io.BytesIO(data)
    file.name = name
    return client.post("/worlds/import", {"file": file}, follow=True)


def test_export_import_round_trip(people):
    alice = signed_in(people["alice"])
    world = stored(people["alice"])
    exported = alice.get(f"/worlds/{world.pk}.json")
    assert exported.status_code == 200 and exported["Content-Type"] == "application/json"
    assert 'attachment; filename="corridor.json"' == exported["Content-Disposition"]
    assert json.loads(exported.content) == world.document

    page = upload(alice, exported.content, "corridor.json")
    assert "corridor-2" in page.content.decode()
    copy = World.objects.get(owner=people["alice"], name="corridor-2")
    assert copy.document == {**world.document, "name": "corridor-2"}
    # Someone else imports it under its own name.
    upload(signed_in(people["bob"]), exported.content)
    assert World.objects.get(owner=people["bob"], name="corridor").document == world.document


def test_revision_export(people):
    world = stored(people["alice"])
    first = world.document
    world.save_document({**first, "title": "Changed"}, people["alice"])
    alice = signed_in(people["alice"])
    old = alice.get(f"/worlds/{world.pk}.json?revision=1")
    assert json.loads(old.content) == first and "corridor-r1.json" in old["Content-Disposition"]
    assert alice.get(f"/worlds/{world.pk}.json?revision=9").status_code == 404


def test_import_errors_say_what_and_where(people):
    alice = signed_in(people["alice"])
    text = upload(alice, b"{nope").content.decode()
    assert "Nothing was imported from world.json" in text and "not a JSON file" in text
    outside = corridor(walls=[{"from": [0.0, 0.0], "to": [9.0, 0.0], "thickness": 0.05}])
    text = upload(alice, json.dumps(outside).encode()).content.decode()
    assert "walls[0]" in text
    assert not World.objects.exists()
    text = upload(alice, b" " * (300 * 1024)).content.decode()
    assert "256 KB" in text


def test_export_follows_access(people):
    world = stored(people["alice"])
    assert signed_in(people["carol"]).get(f"/worlds/{world.pk}.json").status_code == 404
    assert signed_in(people["carol"]).get("/worlds/builtin/maze.json").status_code == 200
    assert signed_in(people["carol"]).get("/worlds/builtin/nowhere.json").status_code == 404


def test_list_groups_worlds(people):
    from worlds.shares import add_share

    mine = stored(people["bob"], name="bobs")
    classes = stored(people["alice"], name="for-class")
    add_share(classes, people["alice"], group="class-a")
    public = stored(people["carol"], name="for-all")
    add_share(public, people["carol"], everyone=True)
    hidden = stored(people["carol"], name="carols-own")
    page = signed_in(people["bob"]).get("/worlds/")
    assert page.status_code == 200
    html = page.content.decode()
    mine_at, shared_at = html.index('id="worlds-mine"'), html.index('id="worlds-shared"')
    public_at, builtin_at = html.index('id="worlds-public"'), html.index('id="worlds-builtin"')
    assert mine_at < html.index(f"/worlds/{mine.pk}/edit") < shared_at
    assert shared_at < html.index(f"/worlds/{classes.pk}/edit") < public_at
    assert public_at < html.index(f"/worlds/{public.pk}/edit") < builtin_at
    assert f"/worlds/{hidden.pk}/" not in html
    assert "/worlds/builtin/maze.json" in html and 'action="/worlds/new"' in html
    assert 'href="/worlds/builtin/maze"' in html  # the editor's page, to read
    assert 'href="/worlds/"' in html  # the site menu


def test_share_page(people):
    world = stored(people["alice"])
    alice = signed_in(people["alice"])
    assert signed_in(people["bob"]).get(f"/worlds/{world.pk}/shares/").status_code == 404
    page = alice.post(f"/worlds/{world.pk}/shares/", {"target": "group:class-a"}, follow=True)
    assert "Shared with group class-a" in page.content.decode()
    assert signed_in(people["bob"]).get(f"/worlds/{world.pk}.json").status_code == 200
    share = world.shares.get()
    alice.post(f"/worlds/{world.pk}/shares/{share.pk}/delete")
    assert signed_in(people["bob"]).get(f"/worlds/{world.pk}.json").status_code == 404
    page = alice.post(f"/worlds/{world.pk}/shares/", {"target": "everyone"}, follow=True)
    assert "Shared with everyone" in page.content.decode()
    assert signed_in(people["carol"]).get(f"/worlds/{world.pk}.json").status_code == 200
    refused = alice.post(f"/worlds/{world.pk}/shares/", {"target": "user:alice"}, follow=True)
    assert "always shared with its owner" in refused.content.decode()


def test_delete_page(people):
    world = stored(people["alice"])
    assert signed_in(people["bob"]).post(f"/worlds/{world.pk}/delete").status_code == 404
    alice = signed_in(people["alice"])
    assert alice.get(f"/worlds/{world.pk}/delete").status_code == 200
    alice.post(f"/worlds/{world.pk}/delete")
    assert not World.objects.exists()
