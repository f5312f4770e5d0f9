"""The pages' language: a signed-in user's stored choice, else Django's LocaleMiddleware's
(the language cookie the menu's switcher sets, then the browser's Accept-Language).

The stored choice is read once per session, at sign-in, and kept in the session: a page or a
websocket then needs no database trip for it (a run's first line waits for its websocket)."""

from django.conf import settings
from django.utils import translation
from django.views.i18n import set_language as django_set_language

from robotide.models import LanguagePreference

SESSION_KEY = "robotide_language"  # the account's language, "" for none


def supported(code: str | None) -> bool:
    return bool(code) and code in dict(settings.LANGUAGES)


def set_language(request):
    """Django's set_language (the cookie, back to `next`), also kept on a signed-in account so
    it follows the user to any browser and wins over that browser's own language."""
    response = django_set_language(request)
    code = request.POST.get("language")
    if request.method == "POST" and request.user.is_authenticated and supported(code):
        LanguagePreference.objects.update_or_create(user=request.user, defaults={"language": code})
        request.session[SESSION_KEY] = code
    return response


def remember_on_sign_in(sender, request, user, **kwargs):
    """user_logged_in: the account's language into its new session (any sign-in: password,
    directory, OpenID Connect)."""
    if request is not None and hasattr(request, "session"):
        request.session[SESSION_KEY] = stored_language(user) or ""


class UserLanguageMiddleware:
    """After LocaleMiddleware and AuthenticationMiddleware: the account's language wins."""

    def __init__(self, get_response):
        self.get_response = get_response

    def __call__(self, request):
        code = session_language(request)
        if code:
            translation.activate(code)
            request.LANGUAGE_CODE = code
        return self.get_response(request)


def session_language(request) -> str | None:
    if request.user.is_authenticated and SESSION_KEY not in request.session:
        # A session from before sign-ins kept it: kept now, for its next pages.
        request.session[SESSION_KEY] = stored_language(request.user) or ""
    return account_language(request.session, request.user)


def stored_language(user) -> str | None:
    if not user.is_authenticated:
        return None
    code = LanguagePreference.objects.filter(user=user).values_list("language", flat=True).first()
    return code if supported(code) else None


def language_from_headers(headers: dict[str, str]) -> str:
    """The language LocaleMiddleware would choose for a page (the switcher's cookie, then
    Accept-Language, then the default), for a websocket, which has no HttpRequest."""
    from django.http import HttpRequest
    from django.http.cookie import parse_cookie

    request = HttpRequest()
    request.COOKIES = parse_cookie(headers.get("cookie", ""))
    request.META["HTTP_ACCEPT_LANGUAGE"] = headers.get("accept-language", "")
    return translation.get_language_from_request(request)


def account_language(session, user) -> str | None:
    """The account's language: as sign-in kept it in the session (a websocket's was loaded
    already to find its user), else as stored."""
    if not user.is_authenticated:
        return None
    code = session.get(SESSION_KEY)
    if code is None:  # a session from before sign-ins kept it
        return stored_language(user)
    return code if supported(code) else None


class WebsocketLanguage:
    """A websocket's fragments in its page's language: the browser's here (its switcher's
    cookie, then Accept-Language), activated for the connection's whole task; the account's
    wins once its user is read (robotide.ws_user)."""

    def __init__(self, inner):
        self.inner = inner

    async def __call__(self, scope, receive, send):
        headers = {k.decode("latin-1"): v.decode("latin-1") for k, v in scope.get("headers", [])}
        translation.activate(language_from_headers(headers))
        return await self.inner(scope, receive, send)
