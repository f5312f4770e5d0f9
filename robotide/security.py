"""Web security that Django and django-csp leave to the project (settings: "Web security").

- ``CSPMiddleware``: django-csp's, with this host's websocket origin added to connect-src.
- ``RequestSizeLimitMiddleware``: a request body over ``MAX_REQUEST_BYTES`` gets 413 unread;
  ``bad_request`` says which limit a body broke that Django refused while reading it.
- ``SameOriginWebsocket``: a websocket handshake from another origin's page is refused (the
  session cookie would otherwise let any page, even a program's web server on another port of
  this host, read the user's live streams).
- Login throttling: failed sign-ins are counted per (user name, address) pair and per address
  in the cache; while either is locked, ``ThrottledBackend`` refuses every sign-in (a right
  password too, local or directory) and ``ThrottledLoginMixin`` tells the user how long to wait.
"""

import hashlib
import ipaddress
import math
import re
import time
from urllib.parse import urlsplit

import csp.middleware
from channels.security.websocket import OriginValidator
from django import forms
from django.conf import settings
from django.contrib.admin.forms import AdminAuthenticationForm
from django.contrib.auth import get_user_model
from django.contrib.auth.backends import ModelBackend
from django.contrib.auth.forms import AuthenticationForm
from django.contrib.auth.signals import user_login_failed
from django.core.cache import cache
from django.core.exceptions import (
    DisallowedHost,
    PermissionDenied,
    RequestDataTooBig,
    TooManyFieldsSent,
    TooManyFilesSent,
)
from django.dispatch import receiver
from django.http import HttpResponse, JsonResponse
from django.utils import translation
from django.utils.translation import gettext as _
from django.utils.translation import ngettext
from django.views import defaults

# -- Content Security Policy ----------------------------------------------------------------------


def plain_number(text: str | None, digits: int = 9) -> int | None:
    """A number as a page, a form or a link carries it: ASCII digits, at most `digits` of
    them (9 fit any integer column), else None. str.isdigit() passes "²", which int()
    refuses, and "١٢", which it reads as 12; a long one overflows the database's integer."""
    if text and re.fullmatch(rf"[0-9]{{1,{digits}}}", text):
        return int(text)
    return None


class CSPMiddleware(csp.middleware.CSPMiddleware):
    def get_policy_parts(self, request, response, report_only=False):
        parts = super().get_policy_parts(request, response, report_only)
        try:
            host = request.get_host()
        except DisallowedHost:
            return parts
        # CSP 3 lets 'self' match ws:/wss: of the page's host; older browsers need it spelled out.
        scheme = "wss" if request.is_secure() else "ws"
        update = dict(parts.update or {})
        update["connect-src"] = [*update.get("connect-src", ()), f"{scheme}://{host}"]
        parts.update = update
        return parts


# -- Websockets -----------------------------------------------------------------------------------


class SameOriginWebsocket(OriginValidator):
    """Lets a browser's websocket in only from a page of this origin or CSRF_TRUSTED_ORIGINS.

    A handshake without Origin is not a browser's (browsers always send it): it is let through,
    as Django's CSRF check lets through a form post without Origin.
    """

    def __init__(self, application):
        super().__init__(application, settings.CSRF_TRUSTED_ORIGINS)

    async def __call__(self, scope, receive, send):
        headers = dict(scope.get("headers", []))
        origin, host = headers.get(b"origin"), headers.get(b"host")
        if origin is None or (host is not None and urlsplit(origin).netloc == host):
            return await self.application(scope, receive, send)
        return await super().__call__(scope, receive, send)


# -- Request size ---------------------------------------------------------------------------------


class RequestSizeLimitMiddleware:
    """Refuses an over-size body from its Content-Length, before anything reads it.

    Django limits form fields (DATA_UPLOAD_MAX_MEMORY_SIZE) but streams any size of uploaded file
    to disk; this caps the whole request.
    """

    def __init__(self, get_response):
        self.get_response = get_response

    def __call__(self, request):
        try:
            length = int(request.META.get("CONTENT_LENGTH") or 0)
        except ValueError:
            length = 0
        if length > settings.MAX_REQUEST_BYTES:
            return request_too_large(request)
        return self.get_response(request)


def request_too_large(request) -> HttpResponse:
    from programs.models import MAX_SOURCE_BYTES

    with _request_language(request):
        detail = _("Request too large: at most %(most)s KB (a program may be %(program)s KB).") % {
            "most": settings.MAX_REQUEST_BYTES // 1024,
            "program": MAX_SOURCE_BYTES // 1024,
        }
    return _refusal(request, detail, 413)


def _request_language(request):
    # Refusals come before LocaleMiddleware has run: the cookie's or browser's language.
    return translation.override(translation.get_language_from_request(request))


def bad_request(request, exception):
    """Django's 400 page, or what was too much when a body was too large to read."""
    limits = {
        RequestDataTooBig: (
            _("Request refused: form data over %(count)s KB."),
            settings.DATA_UPLOAD_MAX_MEMORY_SIZE // 1024,
        ),
        TooManyFieldsSent: (
            _("Request refused: more than %(count)s fields."),
            settings.DATA_UPLOAD_MAX_NUMBER_FIELDS,
        ),
        TooManyFilesSent: (
            _("Request refused: more than %(count)s files."),
            settings.DATA_UPLOAD_MAX_NUMBER_FILES,
        ),
    }
    for kind, (message, count) in limits.items():
        if isinstance(exception, kind):
            return _refusal(request, message % {"count": count}, 400)
    return defaults.bad_request(request, exception)


def _refusal(request, detail: str, status: int) -> HttpResponse:
    if request.path.startswith("/api/"):
        return JsonResponse({"detail": detail}, status=status)
    return HttpResponse(detail, status=status, content_type="text/plain; charset=utf-8")


# -- Login throttling -----------------------------------------------------------------------------
# Why not django-axes (issue 18; weighed against axes 8.3.1, its docs and its source):
# - One limit for every lockout parameter set. AXES_FAILURE_LIMIT is "the integer number of login
#   attempts allowed", or a callable of (request, credentials) that "returns an integer": it is not
#   told which set it judges, and the handlers compare the largest count over
#   AXES_LOCKOUT_PARAMETERS with that one number. [["username", "ip_address"], "ip_address"] at 5
#   locks a whole lab after five typos among its students; at 50 it allows 50 guesses at one
#   student's password.
# - AXES_RESET_ON_SUCCESS ("a successful login will reset the number of failed logins") resets
#   every parameter set: one's own sign-in from a shared address wipes that address's failures,
#   the (victim, address) ones with them. Tried: 20 guesses at another student's password,
#   signing in as oneself after every 4, were never locked. Ours forgives only the pair.
# - One time for two: AXES_COOLOFF_TIME "defines a period of inactivity after which old failed
#   login attempts will be cleared", so the counting window and the lock are one setting, counted
#   from the latest failure (ours: failures within 15 minutes, then a 5-minute lock).


def _address(request) -> str:
    # uvicorn has already put a trusted proxy's X-Forwarded-For here (FORWARDED_ALLOW_IPS).
    address = request.META.get("REMOTE_ADDR", "") if request is not None else ""
    try:
        ip = ipaddress.ip_address(address)
    except ValueError:
        return address
    if ip.version == 6:
        if ip.ipv4_mapped:
            return str(ip.ipv4_mapped)
        # One host commonly has a whole /64 to pick addresses from.
        return str(ipaddress.ip_network(f"{ip}/64", strict=False))
    return str(ip)


def _keys(request, username: str) -> list[tuple[str, str, int]]:
    """(counter key, lock key, failures allowed) for the pair and for the address."""
    limits = settings.LOGIN_THROTTLE
    address = _address(request)
    pair = hashlib.sha256(f"{(username or '').casefold()}\0{address}".encode()).hexdigest()
    by_address = "a" + hashlib.sha256(address.encode()).hexdigest()
    return [
        (f"login-failures:{pair}", f"login-lock:{pair}", limits["failures"]),
        (f"login-failures:{by_address}", f"login-lock:{by_address}", limits["address_failures"]),
    ]


def locked_for(request, username: str) -> int:
    """Seconds until this user name may sign in again from this address (0: it may now)."""
    locks = cache.get_many([lock for _, lock, _ in _keys(request, username)])
    until = max(locks.values(), default=0)
    return max(0, math.ceil(until - time.time()))


def record_failure(request, username: str) -> None:
    limits = settings.LOGIN_THROTTLE
    window, lock_seconds = limits["window_seconds"], limits["lock_seconds"]
    for counter, lock, allowed in _keys(request, username):
        # A counter's window starts at its first failure.
        cache.add(counter, 0, timeout=window)
        try:
            failures = cache.incr(counter)
        except ValueError:  # expired between add and incr
            cache.set(counter, 1, timeout=window)
            failures = 1
        if failures >= allowed:
            cache.set(lock, time.time() + lock_seconds, timeout=lock_seconds)
            cache.delete(counter)


def clear_failures(request, username: str) -> None:
    """A right password forgives the pair's failures, not the address's."""
    counter, _, _ = _keys(request, username)[0]
    cache.delete(counter)


def _username(credentials: dict) -> str:
    return credentials.get(get_user_model().USERNAME_FIELD) or credentials.get("username") or ""


@receiver(user_login_failed)
def _count_failed_login(sender, credentials, request=None, **kwargs):
    # Every password check that fails (sign-in page, admin) comes through here; refusals while
    # locked do too, and do not prolong the lock.
    if request is None:
        return
    username = _username(credentials)
    if not locked_for(request, username):
        record_failure(request, username)


class ThrottledBackend:
    """For an authentication backend class: refuses a locked sign-in, forgives on success.

    Each password backend (local, directory) has it, so none depends on another's place in
    AUTHENTICATION_BACKENDS to be throttled.
    """

    def authenticate(self, request, username=None, password=None, **kwargs):
        if username is None:
            username = kwargs.get(get_user_model().USERNAME_FIELD)
        if request is not None and locked_for(request, username):
            raise PermissionDenied("too many failed sign-ins")  # no other backend is tried
        user = super().authenticate(request, username=username, password=password, **kwargs)
        if user is not None and request is not None:
            clear_failures(request, username)
        return user


class ThrottledModelBackend(ThrottledBackend, ModelBackend):
    pass


def throttled_message(seconds: int) -> str:
    if seconds < 60:
        wait = ngettext("%(count)d second", "%(count)d seconds", seconds) % {"count": seconds}
    else:
        minutes = math.ceil(seconds / 60)
        wait = ngettext("%(count)d minute", "%(count)d minutes", minutes) % {"count": minutes}
    return _("Too many failed sign-ins; try again in %(wait)s.") % {"wait": wait}


class ThrottledLoginMixin:
    """For AuthenticationForm and its subclasses: says so when the sign-in is locked."""

    def get_invalid_login_error(self):
        wait = locked_for(self.request, self.cleaned_data.get("username") or "")
        if wait:
            return forms.ValidationError(throttled_message(wait), code="throttled")
        return super().get_invalid_login_error()


class LoginForm(ThrottledLoginMixin, AuthenticationForm):
    pass


class AdminLoginForm(ThrottledLoginMixin, AdminAuthenticationForm):
    pass
