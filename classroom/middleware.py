"""An account with a one-time password (a teacher printed it on a sheet) chooses its own first.

While its user has a OneTimePassword row, every page sends them to the password change page;
only that page, signing out, the static files and the pages' script strings answer. The row
goes when the change succeeds (the change page's post answered with its redirect), and a
session that found no row does not ask again: a new one-time password changes the account's
password, which ends its sessions (Django's session auth hash), so its next sign-in asks anew.
"""

from django.conf import settings
from django.contrib import messages
from django.http import JsonResponse
from django.shortcuts import redirect
from django.urls import reverse
from django.utils.translation import gettext as _

CLEARED = "one_time_password_cleared"  # the session's note: this user has none (their pk)


class OneTimePasswordMiddleware:
    def __init__(self, get_response):
        self.get_response = get_response

    def __call__(self, request):
        user = getattr(request, "user", None)
        if user is None or not user.is_authenticated or request.session.get(CLEARED) == user.pk:
            return self.get_response(request)
        from classroom.models import OneTimePassword

        if not OneTimePassword.objects.filter(user=user).exists():
            request.session[CLEARED] = user.pk
            return self.get_response(request)
        change = reverse("password_change")
        if request.path == change:
            response = self.get_response(request)
            if request.method == "POST" and response.status_code in (301, 302, 303):
                OneTimePassword.objects.filter(user=user).delete()
                request.session[CLEARED] = user.pk
            return response
        if self._allowed(request.path):
            return self.get_response(request)
        message = _("Choose a password of your own: the one you were given works only once.")
        if request.path.startswith("/api/"):
            return JsonResponse({"detail": message}, status=403)
        messages.info(request, message)
        return redirect(change)

    @staticmethod
    def _allowed(path: str) -> bool:
        allowed = (reverse("logout"), reverse("javascript-catalog"), reverse("set_language"))
        static = "/" + settings.STATIC_URL.lstrip("/")
        return path in allowed or path.startswith(static) or path == "/favicon.ico"
