"""{% oidc_provider as provider %}: the OpenID Connect provider's button (name, url), or None."""

from django import template
from django.conf import settings
from django.urls import reverse

register = template.Library()


@register.simple_tag
def oidc_provider():
    config = getattr(settings, "OIDC", None)
    if not config:
        return None
    return {"name": config["name"], "url": reverse("oidc-login")}
