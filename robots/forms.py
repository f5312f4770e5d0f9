import shlex
from urllib.parse import urlsplit

from django import forms
from django.utils.translation import gettext_lazy as _

from programs.access import programs_for_user
from robotide import names
from robots.driver_settings import add_option_fields, check_settings, known_driver, settings_from
from robots.models import RUN_SETTINGS, Robot, RobotButton
from robots.reset import SETTING as START_EACH_RUN
from robots.reset import can_reset_driver

WHO_FIELDS = ("drive_by", "estop_by")


class RobotConfigForm(forms.ModelForm):
    """A robot's URL, description and driver options, one typed field per option.

    The option fields are those of the driver the robot has now; when the URL names another
    driver, its options are cleared and the form comes back with the new driver's fields.
    """

    class Meta:
        model = Robot
        fields = ["url", "description", "drive_by", "estop_by"]
        labels = {"url": "URL", "drive_by": _("Who may drive it"), "estop_by": _("Who may stop it")}

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        for name in WHO_FIELDS:  # a form of old, or a script, that leaves them out keeps them
            self.fields[name].required = False
        self.driver_changed = False
        if self.instance.url:
            add_option_fields(self, self.instance)
        if can_reset_driver(self.instance.url or ""):  # a sim: its run setting
            self.fields[START_EACH_RUN] = forms.BooleanField(
                required=False,
                initial=self.instance.settings.get(START_EACH_RUN) is True,
                label=_("Each run starts at the world's start pose"),
                help_text=_(
                    "Before each run the robot is put back there (a Reset); else a run starts"
                    " where the last one left it. A Reset with a pose wins, for the next run."
                ),
            )

    def clean_drive_by(self):
        return self.cleaned_data.get("drive_by") or self.instance.drive_by or "everyone"

    def clean_estop_by(self):
        return self.cleaned_data.get("estop_by") or self.instance.estop_by or "everyone"

    def clean_url(self):
        try:
            return known_driver(self.cleaned_data["url"].strip())
        except ValueError as exc:
            raise forms.ValidationError(str(exc)) from None

    def clean(self):
        cleaned = super().clean()
        url = cleaned.get("url")
        if not url or self.errors:
            return cleaned
        base = Robot(url=url, settings=self._run_settings())
        if _scheme(url) != _scheme(self.instance.url or ""):
            self.driver_changed = True
            settings = base.settings  # the new driver starts from its defaults
        else:
            settings = settings_from(self, base, url)
        if not self.errors:
            try:
                check_settings(url, settings)
            except ValueError as exc:
                self.add_error(None, str(exc))
        if START_EACH_RUN in self.fields and not self.driver_changed:
            settings = {k: v for k, v in settings.items() if k != START_EACH_RUN}
            if cleaned.get(START_EACH_RUN):  # stored only when on: off is the default
                settings[START_EACH_RUN] = True
        self.instance.settings = settings
        return cleaned

    def _run_settings(self) -> dict:
        return {k: v for k, v in self.instance.settings.items() if k in RUN_SETTINGS}


def _scheme(url: str) -> str:
    return urlsplit(url).scheme.lower()


class ButtonForm(forms.ModelForm):
    """A manual command: its label, the program it runs and the arguments it passes."""

    arguments = forms.CharField(
        required=False,
        max_length=500,
        label=_("Arguments"),
        help_text=_('Passed to the program as its command-line arguments, e.g. 0.3 "slow turn"'),
    )

    class Meta:
        model = RobotButton
        fields = ["label", "program", "arguments", "position"]

    def __init__(self, *args, user, robot, **kwargs):
        super().__init__(*args, **kwargs)
        self.instance.robot = robot
        self.fields["program"].queryset = programs_for_user(user)
        if self.instance.pk:
            self.fields["arguments"].initial = self.instance.arguments

    def clean_arguments(self):
        try:
            return shlex.split(self.cleaned_data["arguments"])
        except ValueError as exc:  # an unclosed quote
            raise forms.ValidationError(_("arguments: %(why)s") % {"why": exc}) from None

    def clean_label(self):
        label = self.cleaned_data["label"].strip()
        names.validate(label)
        taken = RobotButton.objects.filter(robot=self.instance.robot, label=label)
        if taken.exclude(pk=self.instance.pk).exists():
            raise forms.ValidationError(_("This robot has a button with that label already."))
        return label

    def save(self, commit=True):
        self.instance.args = self.cleaned_data["arguments"]
        return super().save(commit)
