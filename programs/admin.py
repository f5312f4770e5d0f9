from django.contrib import admin

from programs.models import AgentUnreachable, Program, Revision, Run, request_stop


class RevisionInline(admin.TabularInline):
    model = Revision
    extra = 0
    fields = ["number", "author", "created"]
    readonly_fields = fields
    show_change_link = True


@admin.register(Program)
class ProgramAdmin(admin.ModelAdmin):
    list_display = ["name", "owner", "language", "updated"]
    list_filter = ["language"]
    search_fields = ["name", "owner__username", "source"]
    inlines = [RevisionInline]


@admin.register(Revision)
class RevisionAdmin(admin.ModelAdmin):
    list_display = ["program", "number", "author", "created"]
    search_fields = ["program__name"]
    readonly_fields = ["program", "number", "author", "created"]


@admin.register(Run)
class RunAdmin(admin.ModelAdmin):
    list_display = [
        "pk",
        "program_name",
        "robot",
        "owner",
        "state",
        "exit_code",
        "started",
        "ended",
    ]
    list_filter = ["state", "robot", "language"]
    search_fields = ["program_name", "owner__username"]
    readonly_fields = [f.name for f in Run._meta.fields]
    actions = ["stop_runs"]

    @admin.action(description="Stop the selected runs")
    def stop_runs(self, request, queryset):
        runs = [run for run in queryset.select_related("robot") if run.active]
        for run in runs:
            try:
                request_stop(run)
            except AgentUnreachable as exc:
                self.message_user(request, str(exc), level="error")
        self.message_user(request, f"Asked {len(runs)} run(s) to stop.")
