"""Sign-in with an OpenID Connect provider (Google Workspace, Microsoft Entra, Keycloak, gov.br)
beside local accounts and the directory.

Configured by ROBOTIDE_OIDC_* (robotide.settings.oidc_settings). Authlib is the client: it
reads the provider's discovery document on the first sign-in (a provider that is down neither
stops the start nor stays cached: the next sign-in asks again), sends PKCE (S256), and checks
the state, then the ID token's signature, issuer, audience and nonce. (mozilla-django-oidc, the
other choice, takes each endpoint as a setting of its own rather than the discovery document,
and finds accounts by e-mail unless told otherwise.)

An identity is the provider's (issuer, sub), kept in ProviderAccount: never a user name or an
e-mail, so a provider's user can never take over a local account. The account made on first
sign-in has no password (the sign-in page cannot let it in); its name, e-mail, classes,
teaching and staff flag come from the claims on every sign-in, as the directory's do from its
groups. Signing out signs out at the provider too (RP-initiated logout with id_token_hint).
"""

import fnmatch
import logging

import requests
from authlib.common.errors import AuthlibBaseError
from authlib.integrations.base_client import OAuthError
from authlib.integrations.django_client import OAuth
from django.conf import settings
from django.contrib import messages
from django.contrib.auth import get_user_model, login
from django.contrib.auth.backends import ModelBackend
from django.contrib.auth.views import LogoutView
from django.db import IntegrityError, transaction
from django.http import Http404
from django.shortcuts import redirect
from django.urls import resolve, reverse
from django.utils import timezone
from django.utils.http import url_has_allowed_host_and_scheme
from django.utils.translation import gettext as _
from joserfc.errors import JoseError

log = logging.getLogger(__name__)
NEXT_KEY, ID_TOKEN_KEY = "oidc_next", "oidc_id_token"
CLASS_NAME_MAX = 150  # a class is a Group: longer names from a claim are not classes
BACKEND = "robotide.oidc.ProviderBackend"
_clients: dict[str, object] = {}  # one per configuration: each keeps its discovery document


class Refused(Exception):
    """The provider's answer does not sign anyone in here; the message says why, to the user."""


def _config() -> dict:
    config = getattr(settings, "OIDC", None)
    if not config:
        raise Http404("OpenID Connect sign-in is not configured")
    return config


def client():
    config = _config()
    key = repr(sorted(config.items()))
    if key not in _clients:
        oauth = OAuth()
        _clients[key] = oauth.register(
            "provider",
            server_metadata_url=config["discovery_url"],
            client_id=config["client_id"],
            client_secret=config["client_secret"] or None,
            client_kwargs={
                "scope": config["scopes"],
                "code_challenge_method": "S256",
                "token_endpoint_auth_method": (
                    "client_secret_basic" if config["client_secret"] else "none"
                ),
                "default_timeout": 10,
            },
        )
    return _clients[key]


# -- views ----------------------------------------------------------------------------------------


def sign_in(request):
    """To the provider's sign-in, back at ``callback``."""
    next_url = request.GET.get("next", "")
    request.session[NEXT_KEY] = next_url if _is_safe(request, next_url) else ""
    redirect_uri = request.build_absolute_uri(reverse("oidc-callback"))
    try:
        return client().authorize_redirect(request, redirect_uri)
    except (requests.RequestException, ValueError, KeyError) as exc:
        return _unreachable(request, exc)


def callback(request):
    """The provider sends the browser back here with a code; signed in, or told why not."""
    app = client()
    try:
        token = app.authorize_access_token(request)
        claims = _claims(app, token)
        user = ProviderBackend().authenticate(request, claims=claims, issuer=claims["iss"])
    except (AuthlibBaseError, JoseError) as exc:  # state, code, PKCE, the ID token, its nonce
        log.warning("OpenID Connect sign-in refused: %s", exc)
        return _login_page(request, _refusal(exc), status=400)
    except Refused as exc:
        return _login_page(request, str(exc), status=403)
    except (requests.RequestException, ValueError) as exc:
        return _unreachable(request, exc)
    next_url = request.session.pop(NEXT_KEY, "")  # before login(), which may flush the session
    login(request, user, backend=BACKEND)
    request.session[ID_TOKEN_KEY] = token["id_token"]  # the hint that signs out at the provider
    return redirect(next_url or settings.LOGIN_REDIRECT_URL)


class SignOutView(LogoutView):
    """Signs out here, then at the provider when it signed this session in."""

    def post(self, request, *args, **kwargs):
        id_token = request.session.get(ID_TOKEN_KEY)
        response = super().post(request, *args, **kwargs)
        if not id_token or not getattr(settings, "OIDC", None):
            return response
        back = request.build_absolute_uri(reverse("login"))
        try:
            if not client().load_server_metadata().get("end_session_endpoint"):
                return response  # the provider has no sign-out to send the browser to
            return client().logout_redirect(
                request, post_logout_redirect_uri=back, id_token_hint=id_token,
                client_id=settings.OIDC["client_id"],
            )  # fmt: skip
        except (requests.RequestException, ValueError, OAuthError) as exc:
            log.warning("could not sign out at the OpenID Connect provider: %s", exc)
            return response


def _claims(app, token) -> dict:
    """The ID token's claims (checked by authlib), with the userinfo endpoint's: providers put
    scopes' claims (groups, roles) in one or the other."""
    if "userinfo" not in token:
        raise OAuthError(error="no_id_token", description="the provider sent no ID token")
    claims = dict(token["userinfo"])
    if app.load_server_metadata().get("userinfo_endpoint"):
        extra = app.userinfo(token=token)
        if extra.get("sub") != claims["sub"]:
            raise OAuthError(error="sub_mismatch", description="userinfo is someone else's")
        claims = {**extra, **claims}  # the signed ID token wins
    return claims


def _is_safe(request, url: str) -> bool:
    return bool(url) and url_has_allowed_host_and_scheme(
        url, allowed_hosts={request.get_host()}, require_https=request.is_secure()
    )


# OAuth 2.0's and OpenID Connect's error codes, and authlib's own: a code outside these is not
# shown (the callback's query is the attacker's to write, and so is its error_description).
KNOWN_ERRORS = {
    "invalid_request", "unauthorized_client", "unsupported_response_type", "invalid_scope",
    "server_error", "temporarily_unavailable", "interaction_required", "login_required",
    "account_selection_required", "consent_required", "invalid_grant", "invalid_client",
    "no_id_token", "sub_mismatch", "missing_claim", "invalid_claim", "bad_signature",
    "expired_token", "invalid_token",
}  # fmt: skip


def _refusal(exc: AuthlibBaseError | JoseError) -> str:
    name = settings.OIDC["name"]
    if exc.error == "mismatching_state":
        return _(
            "Sign-in refused: this answer from %(name)s does not belong to a sign-in started "
            "in this browser. Start again with the button below."
        ) % {"name": name}
    if exc.error == "access_denied":
        return _("%(name)s did not sign you in.") % {"name": name}
    if isinstance(exc, OAuthError):  # its words may be the callback's query: only the code
        code = exc.error if exc.error in KNOWN_ERRORS else "error"
        return _("Sign-in with %(name)s refused (%(code)s); the server's log says more.") % {
            "name": name,
            "code": code,
        }
    # The ID token's checks (signature, issuer, audience, nonce): the library's own words.
    return _("Sign-in with %(name)s refused: %(why)s") % {
        "name": name,
        "why": exc.description or exc.error,
    }


def _unreachable(request, exc):
    log.warning("OpenID Connect provider unreachable: %s", exc)
    message = _(
        "%(name)s cannot be reached just now; try again in a while, or sign in with a password."
    ) % {"name": settings.OIDC["name"]}
    return _login_page(request, message, status=502)


def _login_page(request, message: str, status: int):
    """The sign-in page, saying what went wrong (the login view, whatever urls.py makes it)."""
    messages.error(request, message)
    request.switcher_next = reverse("login")  # not this callback's URL, with its query
    response = resolve(reverse("login")).func(request)
    response.status_code = status
    return response


# -- accounts -------------------------------------------------------------------------------------


def _values(claims: dict, name: str) -> set[str]:
    """A claim as a set of strings: providers send a list, or one string."""
    value = claims.get(name) if name else None
    if isinstance(value, str):
        return {value}
    if isinstance(value, list | tuple):
        return {str(v) for v in value}
    return set()


def _classes(claims: dict, config: dict) -> tuple[set[str], bool]:
    """The classes the claims name, and whether their teacher (or else a member)."""
    named = _values(claims, config["classes_claim"])
    classes = {
        c for c in named
        if len(c) <= CLASS_NAME_MAX and fnmatch.fnmatchcase(c, config["class_pattern"])
    }  # fmt: skip
    teacher_claim, teacher_value = config["teacher"]
    return classes, teacher_value in _values(claims, teacher_claim)


class ProviderBackend(ModelBackend):
    """Signs in the account of a checked identity; called by ``callback`` alone."""

    def authenticate(self, request, claims=None, issuer=None, **kwargs):
        if claims is None or issuer is None:
            return None  # a password sign-in: not ours
        try:
            return self._sign_in(claims, issuer)
        except (Refused, IntegrityError):
            # A first sign-in of the same identity in another tab at the same moment made the
            # account (its row did not exist to be locked): sign in to that one.
            if not self._known(claims, issuer):
                raise
            return self._sign_in(claims, issuer)

    @staticmethod
    def _known(claims: dict, issuer: str) -> bool:
        from robotide.models import ProviderAccount

        return ProviderAccount.objects.filter(issuer=issuer, subject=claims["sub"]).exists()

    def _sign_in(self, claims: dict, issuer: str):
        from robotide.models import ProviderAccount

        config = settings.OIDC
        with transaction.atomic():
            account = (
                ProviderAccount.objects.select_for_update()
                .select_related("user")
                .filter(issuer=issuer, subject=claims["sub"])
                .first()
            )
            user = account.user if account else self._new_user(claims, config)
            if not self.user_can_authenticate(user):
                raise Refused(_("This account is disabled here; ask the lab's staff."))
            self._update(user, claims, config)
            account = account or ProviderAccount(user=user, issuer=issuer, subject=claims["sub"])
            account.last_sign_in = timezone.now()
            account.sync_classes(*_classes(claims, config))
        return user

    def _new_user(self, claims: dict, config: dict):
        User = get_user_model()
        username = str(claims.get(config["claims"]["username"]) or claims["sub"])[:150]
        taken = _(
            "An account named %(username)s exists here already and was not made by %(name)s; "
            "ask the lab's staff."
        ) % {"username": username, "name": config["name"]}
        # Someone here has that name already (a local account, say): never theirs.
        if User.objects.filter(username__iexact=username).exists():
            raise Refused(taken)
        user = User(username=username)
        user.set_unusable_password()  # signs in at the provider only
        try:
            with transaction.atomic():
                user.save()  # and programs.signals gives it the examples
        except IntegrityError:  # made by a sign-in at the same moment
            raise Refused(taken) from None
        return user

    def _update(self, user, claims: dict, config: dict) -> None:
        fields = ["first_name", "last_name", "email"]
        if claims.get("email_verified") is False:
            fields.remove("email")  # unverified: mail must not go out as from this address
        for field in fields:
            value = claims.get(config["claims"][field])
            if isinstance(value, str):
                setattr(user, field, value[: user._meta.get_field(field).max_length])
        staff_claim, staff_value = config["staff"]
        if staff_claim:
            user.is_staff = staff_value in _values(claims, staff_claim)
        user.save()
