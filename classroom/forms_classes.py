"""The classroom pages' forms: a new class, students added in bulk, sign-up with a join code,
and the filters of a student's page."""

from django import forms
from django.contrib.auth import get_user_model
from django.contrib.auth.forms import UserCreationForm
from django.utils.translation import gettext as _
from django.utils.translation import gettext_lazy

from classroom.accounts import MAX_STUDENTS, Entry, entries_from_text
from classroom.models import JOIN_LENGTH
from robotide import names

#: A CSV of a class is a few KB; a spreadsheet's export of a whole school is not what this is for.
MAX_CSV_BYTES = 256 * 1024


class NewClassForm(forms.Form):
    name = forms.CharField(
        label=gettext_lazy("Name"),
        max_length=150,
        validators=[names.validate],
        help_text=gettext_lazy("As students will know it, e.g. “7B robotics 2026”"),
    )


class AddStudentsForm(forms.Form):
    """A list pasted (a name a line) or a CSV file; both may be given, their entries added."""

    names = forms.CharField(
        label=gettext_lazy("Names, one a line"),
        required=False,
        widget=forms.Textarea(attrs={"rows": 8, "spellcheck": "false"}),
        help_text=gettext_lazy(
            "A name makes an account (its username from the name); an existing username puts"
            " that account in the class. “username, full name” chooses the username."
        ),
    )
    file = forms.FileField(
        label=gettext_lazy("or a CSV file"),
        required=False,
        help_text=gettext_lazy(
            "One student a row: a name, or a username and a name; a header row is skipped."
        ),
    )

    def clean_file(self):
        upload = self.cleaned_data.get("file")
        if upload is None:
            return None
        if upload.size > MAX_CSV_BYTES:
            raise forms.ValidationError(
                _("A CSV file of at most %(kb)s KB.") % {"kb": MAX_CSV_BYTES // 1024}
            )
        data = upload.read()
        for encoding in ("utf-8-sig", "cp1252"):  # spreadsheets on Windows save the latter
            try:
                return data.decode(encoding)
            except UnicodeDecodeError:
                continue
        raise forms.ValidationError(_("This is not a text (CSV) file."))

    def clean(self):
        data = super().clean()
        entries: list[Entry] = entries_from_text(data.get("names") or "")
        if data.get("file"):
            entries += entries_from_text(data["file"])
        if not entries and not self.errors:
            raise forms.ValidationError(_("Paste names (one a line) or choose a CSV file."))
        if len(entries) > MAX_STUDENTS:
            raise forms.ValidationError(
                _("At most %(max)s students at once; this list has %(count)s.")
                % {"max": MAX_STUDENTS, "count": len(entries)}
            )
        for entry in entries:
            if why := names.problem(entry.name) or names.problem(entry.username):
                raise forms.ValidationError(
                    _("%(name)s: %(why)s") % {"name": entry.username or entry.name, "why": why}
                )
        data["entries"] = entries
        return data


def normal_code(code: str) -> str:
    """A join code as typed (spaces, dashes, lower case) as stored."""
    return "".join(char for char in code.upper() if char.isalnum())


class JoinCodeField(forms.CharField):
    def __init__(self, **kwargs):
        super().__init__(
            label=gettext_lazy("Join code"),
            max_length=JOIN_LENGTH + 8,
            help_text=gettext_lazy("The code your teacher gave the class"),
            widget=forms.TextInput(attrs={"autocomplete": "off", "autocapitalize": "characters"}),
            **kwargs,
        )

    def clean(self, value):
        return normal_code(super().clean(value))


class JoinForm(UserCreationForm):
    """Sign-up: a join code, then the new account's username, name and password."""

    code = JoinCodeField()
    full_name = forms.CharField(label=gettext_lazy("Your name"), max_length=150)

    field_order = ["code", "username", "full_name", "password1", "password2"]

    class Meta(UserCreationForm.Meta):
        model = get_user_model()
        fields = ("username",)

    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self.fields["username"].widget.attrs.pop("autofocus", None)
        self.fields["code"].widget.attrs["autofocus"] = True
        self.fields["full_name"].validators.append(names.validate)
        self.fields["username"].validators.append(names.validate)

    def save(self, commit=True):
        user = super().save(commit=False)
        first, _sep, last = self.cleaned_data["full_name"].strip().partition(" ")
        user.first_name, user.last_name = first[:150], last.strip()[:150]
        if commit:
            user.save()
        return user


class JoinSignedInForm(forms.Form):
    """Someone signed in joins one more class."""

    code = JoinCodeField()


class StudentFilterForm(forms.Form):
    """What a teacher sees of a student's programs: changed since, one exercise's work, and
    the untouched examples every account starts with (hidden unless asked for)."""

    since = forms.DateField(
        label=gettext_lazy("Changed since"),
        required=False,
        widget=forms.DateInput(attrs={"type": "date"}, format="%Y-%m-%d"),
    )
    exercise = forms.TypedChoiceField(
        label=gettext_lazy("Exercise"), required=False, coerce=int, empty_value=None
    )
    examples = forms.BooleanField(label=gettext_lazy("Untouched examples too"), required=False)

    def __init__(self, *args, exercises=(), **kwargs):
        super().__init__(*args, **kwargs)
        self.fields["exercise"].choices = [("", _("any")), *((e.pk, e.title) for e in exercises)]
