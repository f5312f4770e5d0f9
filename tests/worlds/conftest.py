import pytest
from django.contrib.auth.models import Group, User
from django.test import Client

from robotide.models import ApiToken, ClassTeacher


@pytest.fixture
def people(db):
    """alice and bob in class-a (taught by tina); carol in no class."""
    alice, bob, carol, tina = (
        User.objects.create_user(name, password=f"pw-{name}-123")
        for name in ("alice", "bob", "carol", "tina")
    )
    group = Group.objects.create(name="class-a")
    alice.groups.add(group)
    bob.groups.add(group)
    ClassTeacher.objects.create(group=group, user=tina)
    return {"alice": alice, "bob": bob, "carol": carol, "tina": tina}


def api_of(user):
    """The API as ``user``, with a bearer token: call(method, path, body) -> response."""
    _, token = ApiToken.issue(user)
    client = Client(HTTP_AUTHORIZATION=f"Bearer {token}")

    def call(method, path, body=None):
        return getattr(client, method.lower())(path, body, content_type="application/json")

    return call


@pytest.fixture
def api(people):
    return {name: api_of(user) for name, user in people.items()}
