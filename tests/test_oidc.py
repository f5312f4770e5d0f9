"""Sign-in with an OpenID Connect provider, through Django's test client against a real provider
(node's oidc-provider, tests/oidc_provider.py): accounts and claims, the attacks a callback can
carry (state, nonce, PKCE), takeovers, and settings. The browser's side: tests/browser/test_oidc.py.
"""

from urllib.parse import parse_qs, urlencode, urlsplit

import pytest
from django.contrib.auth.models import User
from django.core.exceptions import ImproperlyConfigured
from django.test import Client

from programs.models import Program
from programs.signals import EXAMPLES
from robotide.models import ClassTeacher, ProviderAccount
from tests.oidc_provider import ACCOUNTS, Provider

pytestmark = pytest.mark.django_db
CALLBACK = "http://testserver/accounts/oidc/callback/"


@pytest.fixture(scope="module")
def provider(tmp_path_factory):
    where = tmp_path_factory.mktemp("oidc")
    running = Provider(where, [CALLBACK], ["http://testserver/accounts/login/"]).start()
    yield running
    running.stop()


@pytest.fixture
def oidc(provider, settings, monkeypatch):
    """robotide's settings from the provider's ROBOTIDE_OIDC_*; its accounts as ACCOUNTS says."""
    from robotide.settings import oidc_settings

    for name, value in provider.env().items():
        monkeypatch.setenv(name, value)
    settings.OIDC = oidc_settings()
    settings.AUTHENTICATION_BACKENDS = [
        "robotide.security.ThrottledModelBackend",
        "robotide.oidc.ProviderBackend",
    ]
    provider.accounts = {k: dict(v) for k, v in ACCOUNTS.items()}
    provider.save_accounts()
    return provider


def to_provider(client: Client, query: str = "") -> str:
    """Starts a sign-in: the provider's authorization URL robotide sends the browser to."""
    response = client.get(f"/accounts/oidc/login/{query}")
    assert response.status_code == 302, response.content
    return response["Location"]


def callback(client: Client, url: str):
    parts = urlsplit(url)
    return client.get(parts.path, parse_qs(parts.query))


def sign_in(provider, login: str, password: str | None = None) -> tuple[Client, object]:
    client = Client()
    password = password or ACCOUNTS[login]["password"]
    back = provider.sign_in_elsewhere(to_provider(client), login, password)
    assert back is not None, f"the provider refused {login}"
    return client, callback(client, back)


def signed_in_as(client: Client) -> str | None:
    user_id = client.session.get("_auth_user_id")
    return User.objects.get(pk=user_id).username if user_id else None


# -- accounts and claims ----------------------------------------------------------------------


def test_a_student_signs_in_with_their_class_and_the_examples(oidc):
    client, response = sign_in(oidc, "ana")
    assert response.status_code == 302 and response["Location"] == "/programs/"
    assert signed_in_as(client) == "ana"
    ana = User.objects.get(username="ana")
    assert (ana.first_name, ana.last_name, ana.email) == ("Ana", "Aluna", "ana@uni.test")
    assert [g.name for g in ana.groups.all()] == ["class-robotics1"]  # not the chess club
    assert not ana.is_staff and not ana.has_usable_password()
    account = ProviderAccount.objects.get(user=ana)
    assert (account.issuer, account.subject) == (oidc.issuer, "ana")
    names = set(Program.objects.filter(owner=ana).values_list("name", flat=True))
    assert names == set(EXAMPLES.values())


def test_a_group_that_grants_permissions_here_is_never_joined_as_a_class(oidc):
    # A provider where users name their own groups: one named like the lab's admin role.
    from django.contrib.auth.models import Group, Permission

    admins = Group.objects.create(name="class-admins")
    admins.permissions.add(Permission.objects.get(codename="change_user"))
    oidc.accounts["ana"]["claims"]["groups"] = ["class-robotics1", "class-admins"]
    oidc.save_accounts()
    sign_in(oidc, "ana")
    ana = User.objects.get(username="ana")
    assert [g.name for g in ana.groups.all()] == ["class-robotics1"]
    assert not ana.has_perm("auth.change_user")


def test_the_page_asked_for_comes_next_if_it_is_here(oidc):
    for asked, comes in [
        ("/runs/", "/runs/"), ("https://evil.test/", "/programs/"),
        ("//evil.test/", "/programs/"), ("/\\evil.test/", "/programs/"),
    ]:  # fmt: skip
        client = Client()
        start = to_provider(client, "?" + urlencode({"next": asked}))
        response = callback(client, oidc.sign_in_elsewhere(start, "ana", "ana-pass-1"))
        assert response["Location"] == comes


def test_the_teacher_teaches_the_class_and_staff_is_staff(oidc):
    client, _ = sign_in(oidc, "tom")
    assert signed_in_as(client) == "tom"
    taught = ClassTeacher.objects.filter(user__username="tom")
    assert [t.group.name for t in taught] == ["class-robotics1"]
    assert not User.objects.get(username="tom").groups.exists()  # a teacher, not a member
    client, _ = sign_in(oidc, "sia")
    sia = User.objects.get(username="sia")
    assert sia.is_staff and sia.email == ""  # an address the provider has not verified
    assert client.get("/admin/").status_code == 200


def test_claims_are_read_again_on_every_sign_in(oidc):
    sign_in(oidc, "ana")
    oidc.accounts["ana"]["claims"] = {**ACCOUNTS["ana"]["claims"], "groups": ["class-robotics2"]}
    oidc.save_accounts()
    sign_in(oidc, "ana")
    ana = User.objects.get(username="ana")
    assert [g.name for g in ana.groups.all()] == ["class-robotics2"]
    assert User.objects.filter(username="ana").count() == 1


def test_an_account_made_by_the_provider_has_no_password_here(oidc):
    sign_in(oidc, "ana")
    for password in ("", "ana-pass-1", "!"):
        client = Client()
        client.post("/accounts/login/", {"username": "ana", "password": password})
        assert signed_in_as(client) is None


def test_an_account_disabled_at_the_provider_can_no_longer_sign_in(oidc):
    client, _ = sign_in(oidc, "dora")
    assert signed_in_as(client) == "dora"
    oidc.accounts["dora"]["disabled"] = True
    oidc.save_accounts()
    client = Client()
    assert oidc.sign_in_elsewhere(to_provider(client), "dora", "dora-pass-1") is None
    assert signed_in_as(client) is None


def test_an_account_disabled_here_cannot_sign_in(oidc):
    sign_in(oidc, "ana")
    User.objects.filter(username="ana").update(is_active=False)
    client, response = sign_in(oidc, "ana")
    assert response.status_code == 403 and signed_in_as(client) is None
    assert "This account is disabled here" in response.content.decode()


# -- no takeover ------------------------------------------------------------------------------


def test_a_provider_identity_never_takes_over_a_local_account(oidc):
    User.objects.create_superuser("admin", email="admin@uni.test", password="admin-pass-1")
    client, response = sign_in(oidc, "mallory")  # preferred_username "admin"
    assert response.status_code == 403 and signed_in_as(client) is None
    assert "An account named admin exists here already" in response.content.decode()
    assert not ProviderAccount.objects.exists()


def test_an_identity_is_its_sub_not_its_e_mail(oidc):
    User.objects.create_user("ana.local", email="ana@uni.test", password="local-pass-1")
    client, _ = sign_in(oidc, "ana")
    assert signed_in_as(client) == "ana"  # an account of its own, not ana.local's
    assert not ProviderAccount.objects.filter(user__username="ana.local").exists()


# -- attacks on the callback ------------------------------------------------------------------


def test_a_callback_with_a_wrong_state_is_refused(oidc):
    client = Client()
    back = oidc.sign_in_elsewhere(to_provider(client), "ana", "ana-pass-1")
    query = parse_qs(urlsplit(back).query)
    tampered = {**query, "state": "forged-state"}
    response = client.get("/accounts/oidc/callback/", tampered)
    assert response.status_code == 400 and signed_in_as(client) is None
    assert "does not belong to a sign-in started in this browser" in response.content.decode()
    assert callback(client, back).status_code == 302  # the untouched one still signs in
    assert signed_in_as(client) == "ana"


def test_a_code_taken_to_another_browser_is_refused(oidc):
    victim = Client()
    back = oidc.sign_in_elsewhere(to_provider(victim), "ana", "ana-pass-1")
    attacker = Client()
    attacker.get("/accounts/oidc/login/")  # a sign-in of its own, whose state differs
    response = callback(attacker, back)
    assert response.status_code == 400 and signed_in_as(attacker) is None


def _stored_state(client: Client) -> tuple[str, dict]:
    session = client.session
    key = next(k for k in session.keys() if k.startswith("_state_"))
    return key, session


def test_an_id_token_for_another_nonce_is_refused(oidc):
    client = Client()
    back = oidc.sign_in_elsewhere(to_provider(client), "ana", "ana-pass-1")
    key, session = _stored_state(client)
    session[key]["data"]["nonce"] = "someone-elses-nonce"  # as a replayed ID token would carry
    session.save()
    response = callback(client, back)
    assert response.status_code == 400 and signed_in_as(client) is None
    assert "nonce" in response.content.decode()


def test_a_code_without_its_pkce_verifier_is_refused(oidc):
    client = Client()
    authorize = to_provider(client)
    assert parse_qs(urlsplit(authorize).query)["code_challenge_method"] == ["S256"]
    back = oidc.sign_in_elsewhere(authorize, "ana", "ana-pass-1")
    key, session = _stored_state(client)
    session[key]["data"]["code_verifier"] = "x" * 64  # an intercepted code, without the verifier
    session.save()
    response = callback(client, back)
    assert response.status_code == 400 and signed_in_as(client) is None
    assert "refused (invalid_grant)" in response.content.decode()


def test_a_refusal_at_the_provider_says_so(oidc):
    client = Client()
    to_provider(client)
    key, _ = _stored_state(client)
    state = key.rsplit("_", 1)[1]
    query = urlencode({"error": "access_denied", "state": state})
    response = client.get(f"/accounts/oidc/callback/?{query}")
    assert (
        response.status_code == 400 and "Uni Login did not sign you in" in response.content.decode()
    )


def test_a_callback_cannot_put_its_own_words_on_the_sign_in_page(oidc):
    client = Client()
    to_provider(client)
    key, _ = _stored_state(client)
    state = key.rsplit("_", 1)[1]
    said = "Your account is locked: call 555-0100 and give your password"
    for error in ("server_error", "call_555-0100"):
        query = urlencode({"error": error, "error_description": said, "state": state})
        page = client.get(f"/accounts/oidc/callback/?{query}").content.decode()
        assert "555-0100" not in page and "give your password" not in page
        assert "Sign-in with Uni Login refused" in page


# -- sign-out, the sign-in page, an unreachable provider ----------------------------------------


def test_signing_out_signs_out_at_the_provider(oidc):
    client, _ = sign_in(oidc, "ana")
    id_token = client.session["oidc_id_token"]
    response = client.post("/accounts/logout/")
    assert signed_in_as(client) is None
    end = urlsplit(response["Location"])
    assert f"{end.scheme}://{end.netloc}{end.path}" == f"{oidc.issuer}/session/end"
    query = parse_qs(end.query)
    assert query["id_token_hint"] == [id_token]
    assert query["post_logout_redirect_uri"] == ["http://testserver/accounts/login/"]


def test_a_local_account_signs_out_here_only(oidc):
    User.objects.create_user("guest", password="guest-pass-1")
    client = Client()
    client.post("/accounts/login/", {"username": "guest", "password": "guest-pass-1"})
    assert signed_in_as(client) == "guest"
    response = client.post("/accounts/logout/")
    assert response["Location"] == "/accounts/login/"


def test_the_sign_in_page_offers_the_provider(oidc):
    page = Client().get("/accounts/login/?next=/runs/").content.decode()
    assert 'href="/accounts/oidc/login/?next=/runs/"' in page
    assert "Sign in with Uni Login" in page


def test_an_unreachable_provider_is_a_clear_page_not_a_crash(settings, monkeypatch):
    from robotide.settings import oidc_settings

    monkeypatch.setenv("ROBOTIDE_OIDC_DISCOVERY_URL", "http://127.0.0.1:9/")  # discard: refused
    monkeypatch.setenv("ROBOTIDE_OIDC_CLIENT_ID", "robotide")
    monkeypatch.setenv("ROBOTIDE_OIDC_NAME", "Uni Login")
    settings.OIDC = oidc_settings()  # asks nothing of the provider
    client = Client()
    assert client.get("/accounts/login/").status_code == 200
    response = client.get("/accounts/oidc/login/")
    assert response.status_code == 502
    assert "Uni Login cannot be reached just now" in response.content.decode()


# -- settings ---------------------------------------------------------------------------------


def test_without_a_discovery_url_oidc_is_off(monkeypatch):
    from robotide.settings import oidc_settings

    for name in ("DISCOVERY_URL", "CLIENT_ID", "CLIENT_SECRET", "NAME"):
        monkeypatch.delenv(f"ROBOTIDE_OIDC_{name}", raising=False)
    assert oidc_settings() == {}
    assert "Sign in with" not in Client().get("/accounts/login/").content.decode()
    assert Client().get("/accounts/oidc/login/").status_code == 404


def test_a_half_configured_provider_fails_loudly(monkeypatch):
    from robotide.settings import oidc_settings

    monkeypatch.setenv("ROBOTIDE_OIDC_CLIENT_ID", "robotide")
    monkeypatch.delenv("ROBOTIDE_OIDC_DISCOVERY_URL", raising=False)
    with pytest.raises(ImproperlyConfigured, match="ROBOTIDE_OIDC_DISCOVERY_URL"):
        oidc_settings()
    monkeypatch.setenv("ROBOTIDE_OIDC_DISCOVERY_URL", "https://id.uni.test")
    monkeypatch.delenv("ROBOTIDE_OIDC_CLIENT_ID")
    with pytest.raises(ImproperlyConfigured, match="ROBOTIDE_OIDC_CLIENT_ID"):
        oidc_settings()
    monkeypatch.setenv("ROBOTIDE_OIDC_CLIENT_ID", "robotide")
    monkeypatch.setenv("ROBOTIDE_OIDC_TEACHER_CLAIM", "roles")
    with pytest.raises(ImproperlyConfigured, match="ROBOTIDE_OIDC_TEACHER_VALUE"):
        oidc_settings()
    monkeypatch.delenv("ROBOTIDE_OIDC_TEACHER_CLAIM")
    monkeypatch.setenv("ROBOTIDE_OIDC_ATTRS", "phone=phone_number")
    with pytest.raises(ImproperlyConfigured, match="ROBOTIDE_OIDC_ATTRS"):
        oidc_settings()
    monkeypatch.delenv("ROBOTIDE_OIDC_ATTRS")
    monkeypatch.setenv("ROBOTIDE_OIDC_SCOPES", "email profile")
    with pytest.raises(ImproperlyConfigured, match="openid"):
        oidc_settings()
    monkeypatch.delenv("ROBOTIDE_OIDC_SCOPES")
    monkeypatch.setenv("ROBOTIDE_OIDC_CLASSES_CLAIM", "groups")
    monkeypatch.delenv("ROBOTIDE_OIDC_CLASS_PATTERN", raising=False)
    with pytest.raises(ImproperlyConfigured, match="ROBOTIDE_OIDC_CLASS_PATTERN"):
        oidc_settings()
    monkeypatch.delenv("ROBOTIDE_OIDC_CLASSES_CLAIM")
    config = oidc_settings()
    assert config["discovery_url"] == "https://id.uni.test/.well-known/openid-configuration"


def test_the_admin_shows_an_account_from_the_provider(oidc):
    sign_in(oidc, "ana")
    User.objects.create_user("guest", password="guest-pass-1")
    admin = Client()
    admin.force_login(User.objects.create_superuser("root", password="root-pass-1"))
    page = admin.get("/admin/auth/user/?origin=provider").content.decode()
    assert ">ana<" in page and "guest" not in page and ">OpenID Connect<" in page
    local = admin.get("/admin/auth/user/?origin=local").content.decode()
    assert "guest" in local and ">ana<" not in local
    ana = User.objects.get(username="ana")
    change = admin.get(f"/admin/auth/user/{ana.pk}/change/").content.decode()
    assert "From the OpenID Connect provider" in change and oidc.issuer in change
