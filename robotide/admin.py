from django.contrib import admin

from robotide.models import ApiToken
from robotide.security import AdminLoginForm

admin.site.login_form = AdminLoginForm  # throttled like the sign-in page


@admin.register(ApiToken)
class ApiTokenAdmin(admin.ModelAdmin):
    list_display = ["user", "name", "created", "last_used"]
    search_fields = ["user__username", "name"]
    readonly_fields = ["digest", "created", "last_used"]
