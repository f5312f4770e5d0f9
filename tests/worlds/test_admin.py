"""Worlds in the administration: listed and shown to staff (the document read-only there)."""

import pytest
from django.contrib.auth.models import User
from django.test import Client

from tests.worlds.documents import corridor
from worlds.documents import validated
from worlds.models import World

pytestmark = pytest.mark.django_db


def test_admin_lists_and_shows_a_world():
    admin = User.objects.create_superuser("root", password="pw-root-123")
    document = validated(corridor(), "corridor")
    world = World.objects.create(owner=admin, name="corridor", title="A corridor")
    world.save_document(document, admin)
    client = Client()
    client.force_login(admin)
    assert "corridor" in client.get("/admin/worlds/world/").content.decode()
    page = client.get(f"/admin/worlds/world/{world.pk}/change/")
    assert page.status_code == 200 and "walls" in page.content.decode()
    assert client.get("/admin/worlds/world/add/").status_code == 403
