from django.contrib import admin

from robots.bus import announce_robot_sync
from robots.models import Robot


@admin.register(Robot)
class RobotAdmin(admin.ModelAdmin):
    list_display = ["name", "url", "description", "isolation", "last_seen"]
    readonly_fields = ["isolation", "last_seen"]
    search_fields = ["name", "url", "description"]

    def save_model(self, request, obj, form, change):
        super().save_model(request, obj, form, change)
        if not change:
            announce_robot_sync(obj.name)
