from django.conf import settings
from django.utils.functional import SimpleLazyObject


def menu_pages(request) -> dict:
    """The staff's pages (django.contrib.flatpages) for the menu; those for signed-in users
    only to them. Looked up only when a template shows the menu."""

    def pages() -> list:
        from django.contrib.flatpages.models import FlatPage

        found = FlatPage.objects.filter(sites__id=settings.SITE_ID).only("url", "title")
        if not request.user.is_authenticated:
            found = found.filter(registration_required=False)
        return list(found.order_by("title"))

    return {"menu_pages": SimpleLazyObject(pages)}
