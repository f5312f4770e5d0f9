"""The account page and /api/tokens: API tokens created (shown once) and revoked."""

import pytest
from django.contrib.auth.models import User
from django.test import Client

from robotide.models import ApiToken

pytestmark = pytest.mark.django_db


@pytest.fixture
def alice(client):
    user = User.objects.create_user("alice", password="pw-alice-123")
    client.force_login(user)
    return user


def bearer(token: str) -> Client:
    return Client(HTTP_AUTHORIZATION=f"Bearer {token}")


def test_the_account_page_needs_a_sign_in():
    response = Client().get("/accounts/")
    assert response.status_code == 302 and "/accounts/login/" in response["Location"]


def test_the_header_links_to_the_account_page(client, alice):
    page = client.get("/accounts/").content.decode()
    assert '<a href="/accounts/" aria-current="page">alice</a>' in page
    assert 'href="/accounts/password/"' in page  # the password change stays at hand


def test_an_institution_account_is_not_offered_a_password_it_does_not_have(client):
    # Directory and OpenID Connect accounts have no usable password here.
    user = User.objects.create_user("dana")
    user.set_unusable_password()
    user.save()
    client.force_login(user)
    page = client.get("/accounts/").content.decode()
    assert 'href="/accounts/password/"' not in page
    assert "its password is changed there" in page


def test_a_token_is_shown_once_and_works(client, alice):
    created = client.post("/accounts/", {"name": "laptop"}, follow=True)
    token = ApiToken.objects.get(user=alice)
    secret = created.context["new_token"]["secret"]
    assert secret in created.content.decode() and token.name == "laptop"
    again = client.get("/accounts/").content.decode()
    assert secret not in again and "laptop" in again and "never" in again
    response = bearer(secret).get("/api/programs")
    assert response.status_code == 200
    token.refresh_from_db()
    assert token.last_used is not None


def test_revoking_a_token_stops_it_at_once(client, alice):
    token, secret = ApiToken.issue(alice, "old")
    assert bearer(secret).get("/api/programs").status_code == 200
    response = client.post(f"/accounts/tokens/{token.pk}/revoke", follow=True)
    assert b"revoked" in response.content
    assert not ApiToken.objects.filter(pk=token.pk).exists()
    assert bearer(secret).get("/api/programs").status_code == 401


def test_revoking_needs_a_post(client, alice):
    token, _ = ApiToken.issue(alice)
    assert client.get(f"/accounts/tokens/{token.pk}/revoke").status_code == 405
    assert ApiToken.objects.filter(pk=token.pk).exists()


def test_another_users_token_cannot_be_revoked(client, alice):
    bob = User.objects.create_user("bob", password="pw-bob-1234")
    token, secret = ApiToken.issue(bob)
    assert client.post(f"/accounts/tokens/{token.pk}/revoke").status_code == 404
    assert "bob" not in client.get("/accounts/").content.decode().split("<main>")[1]
    assert bearer(secret).get("/api/programs").status_code == 200


# -- /api/tokens -------------------------------------------------------------------------------


def test_api_lists_creates_and_revokes_tokens(client, alice):
    created = client.post("/api/tokens", {"name": "ci"}, content_type="application/json")
    assert created.status_code == 201
    body = created.json()
    assert body["name"] == "ci" and body["token"].startswith("rt_")
    listed = bearer(body["token"]).get("/api/tokens").json()
    assert [t["id"] for t in listed] == [body["id"]] and "token" not in listed[0]
    assert "digest" not in listed[0]
    gone = bearer(body["token"]).delete(f"/api/tokens/{body['id']}")
    assert gone.status_code == 204
    assert bearer(body["token"]).get("/api/tokens").status_code == 401


def test_a_token_cannot_mint_tokens(alice):
    _, secret = ApiToken.issue(alice)
    response = bearer(secret).post("/api/tokens", {"name": "x"}, content_type="application/json")
    assert response.status_code == 401
    assert ApiToken.objects.filter(user=alice).count() == 1


def test_api_cannot_revoke_another_users_token(alice):
    bob = User.objects.create_user("bob", password="pw-bob-1234")
    token, _ = ApiToken.issue(bob)
    _, secret = ApiToken.issue(alice)
    assert bearer(secret).delete(f"/api/tokens/{token.pk}").status_code == 404
    assert ApiToken.objects.filter(pk=token.pk).exists()
    assert token.pk not in [t["id"] for t in bearer(secret).get("/api/tokens").json()]


def test_session_requests_need_csrf_to_create():
    user = User.objects.create_user("carol", password="pw-carol-123")
    client = Client(enforce_csrf_checks=True)
    client.force_login(user)
    response = client.post("/api/tokens", {"name": "x"}, content_type="application/json")
    assert response.status_code in (401, 403)
    assert not ApiToken.objects.filter(user=user).exists()
