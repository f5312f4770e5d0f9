from django import forms
from django.contrib import admin, messages
from django.contrib.auth.models import Group
from django.db.models import Count
from django.utils.translation import gettext_lazy as _
from django.utils.translation import ngettext

from programs.models import Program, Revision, Run, Share
from programs.shares import add_share
from robotide.admin import NamesChecked, action_with_form
from robots.runs import AgentUnreachable, request_stop


class RevisionInline(admin.TabularInline):
    model = Revision
    extra = 0
    fields = ["number", "author", "created"]
    readonly_fields = fields
    show_change_link = True
    can_delete = False

    def has_add_permission(self, request, obj=None):
        return False


class ShareInline(admin.TabularInline):
    model = Share
    extra = 0
    fields = ["user", "group", "everyone", "can_edit", "created_by", "created"]
    readonly_fields = ["created_by", "created"]
    autocomplete_fields = ["user", "group"]


class ShareWithGroupForm(forms.Form):
    group = forms.ModelChoiceField(
        Group.objects.order_by("name"), label=_("Group"), help_text=_("The class")
    )
    can_edit = forms.BooleanField(
        required=False, label=_("Can edit"), help_text=_("Its members may edit them too")
    )


@admin.register(Program)
class ProgramAdmin(NamesChecked, admin.ModelAdmin):
    list_display = ["name", "owner", "language", "updated", "shares_count"]
    list_filter = ["language", ("owner__groups", admin.RelatedOnlyFieldListFilter)]
    search_fields = ["name", "owner__username", "source"]
    list_select_related = ["owner"]
    inlines = [ShareInline, RevisionInline]
    actions = ["share_with_group"]

    def get_queryset(self, request):
        return super().get_queryset(request).annotate(_shares=Count("shares", distinct=True))

    @admin.display(description=_("shares"), ordering="_shares")
    def shares_count(self, obj):
        return obj._shares

    def save_formset(self, request, form, formset, change):
        for share in formset.save(commit=False):
            if isinstance(share, Share) and share.created_by_id is None:
                share.created_by = request.user
            share.save()
        for gone in formset.deleted_objects:
            gone.delete()
        formset.save_m2m()

    @admin.action(description=_("Share with a group…"))
    def share_with_group(self, request, queryset):
        def apply(form, programs):
            group, can_edit = form.cleaned_data["group"], form.cleaned_data["can_edit"]
            for program in programs:
                add_share(program, request.user, group=group.name, can_edit=can_edit)
            # English says "program(s)" for any count; other languages may say it per count.
            if can_edit:
                said = ngettext(
                    "Shared %(count)s program(s) with %(group)s: its members may edit them.",
                    "Shared %(count)s program(s) with %(group)s: its members may edit them.",
                    len(programs),
                )
            else:
                said = ngettext(
                    "Shared %(count)s program(s) with %(group)s: its members may read and run"
                    " them.",
                    "Shared %(count)s program(s) with %(group)s: its members may read and run"
                    " them.",
                    len(programs),
                )
            said %= {"count": len(programs), "group": group.name}
            self.message_user(request, said, messages.SUCCESS)

        return action_with_form(
            self,
            request,
            queryset,
            ShareWithGroupForm,
            apply,
            action="share_with_group",
            title=_("Share programs with a group"),
            submit_label=_("Share"),
            explanation=_(
                "The members of the class you choose will see these programs "
                "(sharing again with the same class only changes whether they may edit)."
            ),
        )


@admin.register(Revision)
class RevisionAdmin(admin.ModelAdmin):
    list_display = ["program", "number", "author", "created"]
    list_filter = ["program__language"]
    search_fields = ["program__name", "author__username"]
    list_select_related = ["program", "author"]
    readonly_fields = ["program", "number", "source", "author", "created"]

    def has_add_permission(self, request):
        return False

    def has_change_permission(self, request, obj=None):
        return False


@admin.register(Share)
class ShareAdmin(admin.ModelAdmin):
    list_display = ["program", "shared_with", "can_edit", "created_by", "created"]
    list_filter = ["can_edit", "everyone", "group"]
    search_fields = ["program__name", "program__owner__username", "user__username", "group__name"]
    list_select_related = ["program", "user", "group", "created_by"]
    autocomplete_fields = ["program", "user", "group"]
    readonly_fields = ["created_by", "created"]

    @admin.display(description=_("shared with"))
    def shared_with(self, share: Share) -> str:
        return share.target

    def save_model(self, request, obj, form, change):
        if obj.created_by_id is None:
            obj.created_by = request.user
        super().save_model(request, obj, form, change)


@admin.register(Run)
class RunAdmin(admin.ModelAdmin):
    list_display = [
        "pk",
        "program_name",
        "owner",
        "robot",
        "state",
        "exit_code",
        "started",
        "ended",
    ]
    list_display_links = ["pk", "program_name"]
    list_filter = ["state", "robot", "language"]
    search_fields = ["program_name", "owner__username", "robot__name", "reason"]
    list_select_related = ["owner", "robot"]
    readonly_fields = [f.name for f in Run._meta.fields]
    actions = ["stop_runs"]

    def has_add_permission(self, request):
        return False

    @admin.action(description=_("Stop selected runs"))
    def stop_runs(self, request, queryset):
        runs = [run for run in queryset.select_related("robot") if run.ongoing]
        asked = 0
        for run in runs:
            try:
                request_stop(run)
            except AgentUnreachable as exc:
                self.message_user(
                    request, _("Run %(id)s: %(why)s") % {"id": run.pk, "why": exc}, messages.ERROR
                )
            else:
                asked += 1
        skipped = queryset.count() - len(runs)
        note = ""
        if skipped:
            note = ngettext(
                " (%(count)s had already ended)", " (%(count)s had already ended)", skipped
            ) % {"count": skipped}
        said = ngettext(
            "Asked %(count)s run(s) to stop%(note)s.",
            "Asked %(count)s run(s) to stop%(note)s.",
            asked,
        ) % {"count": asked, "note": note}
        self.message_user(request, said, messages.SUCCESS)
