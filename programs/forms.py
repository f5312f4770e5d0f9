from django import forms
from django.utils.translation import gettext
from django.utils.translation import gettext_lazy as _

from programs.languages import language_for_filename, language_options
from programs.models import MAX_SOURCE_BYTES, Program
from robotide import names

MAX_NAME = Program._meta.get_field("name").max_length


class NewProgramForm(forms.Form):
    name = forms.CharField(label=_("Name"), max_length=100, validators=[names.validate])
    language = forms.ChoiceField(label=_("Language"), choices=language_options)

    def __init__(self, *args, owner=None, **kwargs):
        super().__init__(*args, **kwargs)
        self.owner = owner

    def clean_name(self):
        return unique_name(self.owner, self.cleaned_data["name"])


class EditProgramForm(forms.Form):
    source = forms.CharField(label=_("Source"), required=False, widget=forms.Textarea, strip=False)
    language = forms.ChoiceField(label=_("Language"), choices=language_options)
    save_as = forms.CharField(
        max_length=100, required=False, label=_("Save as"), validators=[names.validate]
    )

    def clean_source(self):
        # Browsers send CRLF from textareas; programs keep Unix line ends.
        source = self.cleaned_data["source"].replace("\r\n", "\n")
        if len(source.encode()) > MAX_SOURCE_BYTES:
            raise forms.ValidationError(too_large())
        return source


class UploadForm(forms.Form):
    file = forms.FileField(label=_("File"))
    language = forms.ChoiceField(
        label=_("Language"),
        choices=[("", _("from the file name")), *language_options()],
        required=False,
    )

    def __init__(self, *args, owner=None, **kwargs):
        super().__init__(*args, **kwargs)
        self.owner = owner

    def clean(self):
        cleaned = super().clean()
        upload = cleaned.get("file")
        if upload is None:
            return cleaned
        if upload.size > MAX_SOURCE_BYTES:
            raise forms.ValidationError(too_large())
        language = cleaned.get("language") or getattr(
            language_for_filename(upload.name), "name", ""
        )
        if not language:
            raise forms.ValidationError(
                gettext("Choose a language: the file name does not tell it.")
            )
        try:
            source = upload.read().decode("utf-8")
        except UnicodeDecodeError:
            raise forms.ValidationError(gettext("The file is not UTF-8 text.")) from None
        stem = upload.name.rsplit("/", 1)[-1].rsplit(".", 1)[0][:100] or "uploaded"
        cleaned.update(language=language, source=source.replace("\r\n", "\n"))
        cleaned["name"] = free_name(self.owner, stem)
        return cleaned


def unique_name(owner, name: str) -> str:
    name = name.strip()
    if Program.objects.filter(owner=owner, name=name).exists():
        raise forms.ValidationError(already_named(name))
    return name


def already_named(name: str) -> str:
    return gettext("You already have a program named %(name)s.") % {"name": repr(name)}


def too_large() -> str:
    return gettext("Programs are limited to %(kb)s KB.") % {"kb": MAX_SOURCE_BYTES // 1024}


def free_name(owner, name: str) -> str:
    """`name`, or `name (2)`, `name (3)`... whichever the owner does not have yet. Made from
    what may not have been typed as a name (a file's, a zip member's, an old program's):
    without the characters a name may not hold."""
    name = (
        names.cleaned(name).strip()[: MAX_NAME - 8] or "program"
    )  # room for " (9999)" within the name's length
    taken = set(
        Program.objects.filter(owner=owner, name__startswith=name).values_list("name", flat=True)
    )
    candidate, n = name, 1
    while candidate in taken:
        n += 1
        candidate = f"{name} ({n})"
    return candidate
