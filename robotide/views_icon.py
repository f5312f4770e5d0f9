"""/favicon.ico: pages name their icon, but the admin, API docs and browsers' own guesses
still ask for the old default. Resolved per request: the static manifest exists only after
collectstatic."""

from django.http import HttpResponsePermanentRedirect
from django.templatetags.static import static
from django.views.decorators.cache import cache_control


@cache_control(max_age=86400, public=True)
def favicon(request):
    return HttpResponsePermanentRedirect(static("robotide/icon.svg"))
