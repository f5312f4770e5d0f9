from django import forms
from django.contrib import admin
from django.utils.text import format_lazy
from django.utils.translation import gettext
from django.utils.translation import gettext_lazy as _

from gateway import specs
from robots.bus import announce_robot_sync, reconfigure_sync, tell_agent_sync
from robots.driver_settings import current_values, option_field
from robots.forms import RobotConfigForm
from robots.models import RUN_SETTINGS, GatewayEndpoint, Robot, RobotStop, SerialBridge


class RobotAdminForm(RobotConfigForm):
    """The robot page's typed driver options, plus the name and the run settings as JSON."""

    run_settings = forms.JSONField(
        required=False,
        label=_("Run settings"),
        help_text=format_lazy(
            _("Settings of the programs run here, as JSON: {settings}"),
            settings=", ".join(RUN_SETTINGS),
        ),
    )

    class Meta(RobotConfigForm.Meta):
        fields = ["name", "url", "description", "owner", "groups", "drive_by", "estop_by"]

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.fields.pop("start_each_run", None)  # a run setting: in the JSON, as the others
        self.fields["run_settings"].initial = self._run_settings()

    def _run_settings(self) -> dict:
        if self.is_bound and hasattr(self, "cleaned_data"):
            given = self.cleaned_data.get("run_settings") or {}
            unknown = set(given) - set(RUN_SETTINGS)
            if unknown:
                self.add_error(
                    "run_settings",
                    gettext("not a run setting: %(names)s") % {"names": ", ".join(sorted(unknown))},
                )
            return {k: v for k, v in given.items() if k in RUN_SETTINGS}
        return super()._run_settings()


class EndpointForm(forms.ModelForm):
    class Meta:
        model = GatewayEndpoint
        fields = ["type", "mode", "address", "device", "baud", "read_only", "allow", "block"]

    def clean(self):
        data = super().clean()
        spec = {k: v for k, v in data.items() if v not in (None, "") and k != "robot"}
        spec["block"] = data.get("block") or []
        try:
            clean = specs.check(spec)
        except ValueError as exc:
            raise forms.ValidationError(str(exc)) from None
        self.instance.set_spec(clean)
        return data


class EndpointInline(admin.TabularInline):
    model = GatewayEndpoint
    form = EndpointForm
    extra = 0
    readonly_fields = ["role"]


class BridgeInline(admin.TabularInline):
    model = SerialBridge
    extra = 0


@admin.register(Robot)
class RobotAdmin(admin.ModelAdmin):
    form = RobotAdminForm
    list_display = ["name", "url", "description_shown", "owner", "isolation", "last_seen"]
    readonly_fields = ["isolation", "last_seen", "personal", "twin_of", "used", "reaped"]
    search_fields = ["name", "url", "description"]
    list_filter = ["groups", "personal", ("reaped", admin.EmptyFieldListFilter)]
    filter_horizontal = ["groups"]
    inlines = [EndpointInline, BridgeInline]

    @admin.display(description=_("description"), ordering="description")
    def description_shown(self, robot: Robot) -> str:
        """robotide's own description ("Simulated robot") in the reader's language."""
        return robot.description_shown

    def get_form(self, request, obj=None, change=False, **kwargs):
        # The admin lays out the fields a form class declares: declare this robot's options.
        if obj is not None:
            options = {
                f"option_{r['option'].name}": option_field(r["option"], r["value"])
                for r in current_values(obj)
            }
            kwargs["form"] = type("RobotOptionsAdminForm", (self.form,), options)
        return super().get_form(request, obj, change, **kwargs)

    def save_model(self, request, obj, form, change):
        super().save_model(request, obj, form, change)
        if change:
            reconfigure_sync(obj.name)
        else:
            announce_robot_sync(obj.name)

    def save_related(self, request, form, formsets, change):
        super().save_related(request, form, formsets, change)
        if change:  # the agent applies the rows as they are now
            tell_agent_sync(form.instance.name, "gateway.reload")
            tell_agent_sync(form.instance.name, "bridges.reload")


@admin.register(RobotStop)
class RobotStopAdmin(admin.ModelAdmin):
    """Emergency stops and resumes, as they were recorded: read only."""

    list_display = ["at", "robot", "kind", "username", "via", "ended", "note"]
    list_filter = ["kind", "robot"]
    search_fields = ["username", "robot__name"]
    date_hierarchy = "at"

    @admin.display(description=_("runs ended"))
    def ended(self, stop: RobotStop) -> str:
        return ", ".join(f"#{r['run']} {r['program']} ({r['owner']})" for r in stop.runs) or "—"

    def has_add_permission(self, request) -> bool:
        return False

    def has_change_permission(self, request, obj=None) -> bool:
        return False

    def has_delete_permission(self, request, obj=None) -> bool:
        return False
