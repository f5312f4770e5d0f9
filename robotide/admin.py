from django.contrib import admin

from robotide.models import ApiToken
from robotide.security import AdminLoginForm

admin.site.login_form = AdminLoginForm  # throttled like the sign-in page


@admin.register(ApiToken)
class ApiTokenAdmin(admin.ModelAdmin):
    list_display = ["user", "name", "created", "last_used"]
    search_fields = ["user__username", "name"]
    readonly_fields = ["digest", "created", "last_used"]


class _LanguagesOnIndex:
    """The admin's index lists the languages programs can be written in, and what they need."""

    def __init__(self, index):
        self.index = index

    def __call__(self, request, extra_context=None):
        from programs.languages import availability

        return self.index(request, {**(extra_context or {}), "languages": availability()})


admin.site.index_template = "admin/robotide_index.html"
admin.site.index = _LanguagesOnIndex(admin.site.index)
