"""Worlds in the administration: to find and look at, share or delete. The document is shown,
not edited here: it is changed through the editor or the API, which validate it."""

from django.contrib import admin

from worlds.models import World, WorldRevision, WorldShare
from worlds.resolve import tell_robots


class WorldRevisionInline(admin.TabularInline):
    model = WorldRevision
    extra = 0
    fields = ["number", "author", "created"]
    readonly_fields = fields
    can_delete = False

    def has_add_permission(self, request, obj=None):
        return False


class WorldShareInline(admin.TabularInline):
    model = WorldShare
    extra = 0
    fields = ["user", "group", "everyone", "created_by", "created"]
    readonly_fields = ["created_by", "created"]
    autocomplete_fields = ["user", "group"]


@admin.register(World)
class WorldAdmin(admin.ModelAdmin):
    list_display = ["name", "title", "owner", "updated"]
    search_fields = ["name", "title", "owner__username"]
    list_select_related = ["owner"]
    readonly_fields = ["document", "created", "updated"]
    inlines = [WorldShareInline, WorldRevisionInline]

    def has_add_permission(self, request):
        return False  # a world is made in the editor, or posted to the API: validated there

    def save_related(self, request, form, formsets, change):
        super().save_related(request, form, formsets, change)
        tell_robots(form.instance)  # shares changed: the sims in it may use it, or no longer
