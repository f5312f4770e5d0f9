"""The pages' language: a signed-in user's stored choice, else Django's LocaleMiddleware's
(the language cookie the menu's switcher sets, then the browser's Accept-Language)."""

from django.conf import settings
from django.utils import translation
from django.views.i18n import set_language as django_set_language

from robotide.models import LanguagePreference


def supported(code: str | None) -> bool:
    return bool(code) and code in dict(settings.LANGUAGES)


def set_language(request):
    """Django's set_language (the cookie, back to `next`), also kept on a signed-in account so
    it follows the user to any browser and wins over that browser's own language."""
    response = django_set_language(request)
    code = request.POST.get("language")
    if request.method == "POST" and request.user.is_authenticated and supported(code):
        LanguagePreference.objects.update_or_create(user=request.user, defaults={"language": code})
    return response


class UserLanguageMiddleware:
    """After LocaleMiddleware and AuthenticationMiddleware: the account's language wins."""

    def __init__(self, get_response):
        self.get_response = get_response

    def __call__(self, request):
        code = stored_language(request.user)
        if code:
            translation.activate(code)
            request.LANGUAGE_CODE = code
        return self.get_response(request)


def stored_language(user) -> str | None:
    if not user.is_authenticated:
        return None
    code = LanguagePreference.objects.filter(user=user).values_list("language", flat=True).first()
    return code if supported(code) else None
