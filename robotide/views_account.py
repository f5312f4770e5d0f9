"""The account page: the user's API tokens, created (the secret shown once) and revoked."""

from django import forms
from django.contrib import messages
from django.contrib.auth.decorators import login_required
from django.shortcuts import get_object_or_404, redirect, render
from django.utils.formats import date_format
from django.utils.translation import gettext as _
from django.utils.translation import gettext_lazy
from django.views.decorators.cache import never_cache
from django.views.decorators.http import require_POST

from robotide import names
from robotide.models import ApiToken
from runlogs.quota import usage_of

NEW_TOKEN_KEY = "account_new_token"


class TokenForm(forms.Form):
    name = forms.CharField(
        label=gettext_lazy("Name"),
        max_length=100,
        required=False,
        help_text=gettext_lazy("What it is for, e.g. “laptop” or “CI”"),
        validators=[names.validate],
    )


@never_cache  # the new token's secret is on it once: no copy kept by a cache
@login_required
def account(request):
    if request.method == "POST":
        form = TokenForm(request.POST)
        if form.is_valid():
            token, secret = ApiToken.issue(request.user, form.cleaned_data["name"])
            # Shown on the next page only: popped from the session as it is shown.
            request.session[NEW_TOKEN_KEY] = {"id": token.pk, "secret": secret}
            return redirect("account")
    else:
        form = TokenForm()
    new = request.session.pop(NEW_TOKEN_KEY, None)
    return render(
        request,
        "account/account.html",
        {
            "form": form,
            "tokens": request.user.api_tokens.order_by("-created"),
            "new_token": new,
            "log_usage": usage_of(request.user),
        },
    )


@login_required
@require_POST
def token_revoke(request, token_id: int):
    token = get_object_or_404(ApiToken, pk=token_id, user=request.user)
    created = date_format(token.created, "SHORT_DATETIME_FORMAT", use_l10n=True)
    label = token.name or _("created %(when)s") % {"when": created}
    token.delete()
    messages.success(request, _("Token %(label)s revoked: it no longer works.") % {"label": label})
    return redirect("account")
