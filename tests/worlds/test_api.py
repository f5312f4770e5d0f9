"""Worlds as stored documents (issue 30): /api/worlds round trip, revisions, validation errors
with their place in the document, size caps, sharing as programs are shared, built-ins."""

import pytest

from tests.worlds.documents import corridor, normalised
from worlds.models import MAX_DOCUMENT_BYTES

pytestmark = pytest.mark.django_db


def test_round_trip_and_revisions(api):
    alice = api["alice"]
    posted = normalised(corridor())
    created = alice("POST", "/api/worlds", posted)
    assert created.status_code == 201, created.content
    world = created.json()
    assert world["name"] == "corridor" and world["title"] == "A corridor"
    assert world["owner"] == "alice" and world["revision"] == 1
    assert world["visibility"] == "private" and world["builtin"] is False
    got = alice("GET", f"/api/worlds/{world['id']}").json()
    assert got["document"] == posted

    moved = normalised(corridor(start=[{"x": -1.5, "y": 1.0, "theta": 0.0}]))
    saved = alice("PUT", f"/api/worlds/{world['id']}", moved)
    assert saved.status_code == 200, saved.content
    assert saved.json()["revision"] == 2
    assert alice("GET", f"/api/worlds/{world['id']}").json()["document"] == moved
    first = alice("GET", f"/api/worlds/{world['id']}?revision=1").json()
    assert first["revision"] == 1 and first["document"] == posted
    assert alice("GET", f"/api/worlds/{world['id']}?revision=3").status_code == 404
    numbers = [r["number"] for r in alice("GET", f"/api/worlds/{world['id']}/revisions").json()]
    assert numbers == [2, 1]
    # The same document again adds no revision.
    assert alice("PUT", f"/api/worlds/{world['id']}", moved).json()["revision"] == 2


def test_stored_document_is_normalised(api):
    """What a sim loads: defaults filled in, named as the stored world."""
    sparse = corridor()
    del sparse["boxes"], sparse["landmarks"]
    world = api["alice"]("POST", "/api/worlds", sparse).json()
    assert world["document"] == normalised(sparse)
    assert world["document"]["boxes"] == []


@pytest.mark.parametrize(
    "change, path, words",
    [
        ({"walls": [{"from": [0.0, 0.0], "to": [2.4, 0.0], "thickness": 0.05}]},
         "walls[0]", "arena"),
        ({"start": [{"x": 1.2, "y": 0.8, "theta": 0.0}]}, "start[0]", "box"),
        ({"size": {"width": 80.0, "height": 3.0}}, "size", "50"),
        ({"walls": "many"}, "walls", ""),
    ],
)  # fmt: skip
def test_validation_errors_say_where(api, change, path, words):
    response = api["alice"]("POST", "/api/worlds", corridor(**change))
    assert response.status_code == 422, response.content
    [error] = response.json()["detail"]
    assert error["path"].startswith(path), error
    assert error["loc"][0] == "body" and error["msg"]
    assert words in error["msg"], error


def test_invalid_save_keeps_the_world(api):
    alice = api["alice"]
    world = alice("POST", "/api/worlds", corridor()).json()
    outside = corridor(boxes=[{"x": 5.0, "y": 0.0, "width": 0.3, "height": 0.3}])
    response = alice("PUT", f"/api/worlds/{world['id']}", outside)
    assert response.status_code == 422 and response.json()["detail"][0]["path"].startswith(
        "boxes[0]"
    )
    assert alice("GET", f"/api/worlds/{world['id']}").json()["revision"] == 1


def test_body_caps_and_shapes(api):
    alice = api["alice"]
    huge = corridor(title="x" * 100, padding="y" * (MAX_DOCUMENT_BYTES + 10))
    too_large = alice("POST", "/api/worlds", huge)
    assert too_large.status_code == 413 and "256 KB" in too_large.json()["detail"]
    for body in ('"x"', "3", "[1]"):
        response = alice("POST", "/api/worlds", body)
        assert response.status_code == 422 and "JSON object" in response.text


def test_names(api):
    alice = api["alice"]
    assert alice("POST", "/api/worlds", corridor()).status_code == 201
    clash = alice("POST", "/api/worlds", corridor())
    assert clash.status_code == 409 and "corridor" in clash.json()["detail"]
    # Bob may have his own corridor.
    assert api["bob"]("POST", "/api/worlds", corridor()).status_code == 201
    builtin = alice("POST", "/api/worlds", corridor(name="maze"))
    assert builtin.status_code == 422 and builtin.json()["detail"][0]["path"] == "name"
    slug = alice("POST", "/api/worlds", corridor(name="Our Maze #2")).json()
    assert slug["name"] == "our-maze-2" and slug["document"]["name"] == "our-maze-2"
    digits = alice("POST", "/api/worlds", corridor(name="12")).json()
    assert digits["name"] == "world-12"  # never read as an id in sim://?world=
    renamed = alice("PUT", f"/api/worlds/{slug['id']}", corridor(name="hall")).json()
    assert renamed["name"] == "hall"
    taken = alice("PUT", f"/api/worlds/{slug['id']}", corridor(name="corridor"))
    assert taken.status_code == 409


def test_builtins_are_listed_and_read_only(api):
    from rhal.simulator.worlds import BUILTIN

    alice = api["alice"]
    listed = {w["id"]: w for w in alice("GET", "/api/worlds").json()}
    for name in ("boxes", "square", "maze", "line", "rooms"):
        assert listed[f"builtin:{name}"]["builtin"] is True
        assert listed[f"builtin:{name}"]["visibility"] == "builtin"
    maze = alice("GET", "/api/worlds/builtin:maze").json()
    assert maze["document"] == BUILTIN["maze"] and maze["owner"] is None
    assert alice("PUT", "/api/worlds/builtin:maze", BUILTIN["maze"]).status_code == 403
    assert alice("DELETE", "/api/worlds/builtin:maze").status_code == 403
    assert alice("GET", "/api/worlds/builtin:nowhere").status_code == 404
    assert all(not w["builtin"] for w in alice("GET", "/api/worlds?builtin=false").json())
    # An exported built-in imported: under another name (a sim's URL names the built-in).
    copy = dict(BUILTIN["maze"], name="my-maze")
    assert alice("POST", "/api/worlds", copy).status_code == 201


def test_private_world_is_not_found_by_others(api):
    world = api["alice"]("POST", "/api/worlds", corridor()).json()
    for name in ("bob", "carol"):
        assert api[name]("GET", f"/api/worlds/{world['id']}").status_code == 404
        assert world["id"] not in [w["id"] for w in api[name]("GET", "/api/worlds").json()]
        assert api[name]("PUT", f"/api/worlds/{world['id']}", corridor()).status_code == 404
    # The teacher of alice's class sees it, and may not change it.
    assert api["tina"]("GET", f"/api/worlds/{world['id']}").status_code == 200
    assert api["tina"]("PUT", f"/api/worlds/{world['id']}", corridor()).status_code == 403


def test_class_and_everyone_shares(api):
    alice = api["alice"]
    world = alice("POST", "/api/worlds", corridor()).json()
    path = f"/api/worlds/{world['id']}"
    share = alice("POST", f"{path}/shares", {"group": "class-a"})
    assert share.status_code == 201 and share.json()["group"] == "class-a"
    assert alice("GET", path).json()["visibility"] == "class"
    assert api["bob"]("GET", path).status_code == 200
    assert api["carol"]("GET", path).status_code == 404
    assert api["bob"]("PUT", path, corridor()).status_code == 403  # only its owner changes it
    assert api["bob"]("POST", f"{path}/shares", {"everyone": True}).status_code == 403

    everyone = alice("POST", f"{path}/shares", {"everyone": True}).json()
    assert api["carol"]("GET", path).json()["document"]["name"] == "corridor"
    assert world["id"] in [w["id"] for w in api["carol"]("GET", "/api/worlds").json()]
    assert alice("DELETE", f"{path}/shares/{everyone['id']}").status_code == 204
    assert api["carol"]("GET", path).status_code == 404
    assert [s["group"] for s in alice("GET", f"{path}/shares").json()] == ["class-a"]

    refused = alice("POST", f"{path}/shares", {"user": "nobody"})
    assert refused.status_code == 422 and "nobody" in refused.json()["detail"]
    assert alice("POST", f"{path}/shares", {"user": "bob", "group": "class-a"}).status_code == 422


def test_delete(api):
    alice = api["alice"]
    world = alice("POST", "/api/worlds", corridor()).json()
    assert api["bob"]("DELETE", f"/api/worlds/{world['id']}").status_code == 404
    assert alice("DELETE", f"/api/worlds/{world['id']}").status_code == 204
    assert alice("GET", f"/api/worlds/{world['id']}").status_code == 404


def test_openapi_documents_the_routes(client):
    spec = client.get("/api/openapi.json").json()
    assert {"/api/worlds", "/api/worlds/{world_id}"} <= set(spec["paths"])
    post = spec["paths"]["/api/worlds"]["post"]
    assert {"201", "409", "413", "422"} <= set(post["responses"])
    assert post["requestBody"]["content"]["application/json"]["schema"] == {
        "$ref": "#/components/schemas/WorldDocument"
    }
    document = spec["components"]["schemas"]["WorldDocument"]
    assert {"size", "walls", "start"} <= set(document["properties"])
    assert "256 KB" in document["description"]


def test_list_reads_no_documents_and_a_few_queries(api, people, django_assert_max_num_queries):
    alice = api["alice"]
    for n in range(8):
        world = alice("POST", "/api/worlds", corridor(name=f"w{n}")).json()
        alice("PUT", f"/api/worlds/{world['id']}", corridor(name=f"w{n}", title="again"))
    with django_assert_max_num_queries(8) as queries:
        listed = alice("GET", "/api/worlds?builtin=false").json()
    assert [w["revision"] for w in listed] == [2] * 8 and "document" not in listed[0]
    assert not any('"document"' in q["sql"] for q in queries), queries.captured_queries
