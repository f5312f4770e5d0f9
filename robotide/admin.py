from django import forms
from django.contrib import admin, messages
from django.contrib.admin.helpers import ACTION_CHECKBOX_NAME
from django.contrib.auth import admin as auth_admin
from django.contrib.auth import get_user_model
from django.contrib.auth.models import Group
from django.db import transaction
from django.db.models import Count
from django.template.response import TemplateResponse
from django.utils.translation import gettext as _
from django.utils.translation import gettext_lazy, ngettext

from robotide import names
from robotide.models import ApiToken, ClassTeacher, DirectoryAccount, ProviderAccount
from robotide.security import AdminLoginForm

admin.site.login_form = AdminLoginForm  # throttled like the sign-in page

User = get_user_model()


def action_with_form(
    model_admin, request, queryset, form_class, apply, *, action, title, submit_label,
    explanation="",
):  # fmt: skip
    """An admin action that asks first: an intermediate page with ``form_class``; once it is
    posted back valid, ``apply(form, objects)`` does the work and the change list comes back."""
    objects = list(queryset)
    if "apply" in request.POST:
        form = form_class(request.POST)
        if form.is_valid():
            apply(form, objects)
            return None  # back to the change list
    else:
        form = form_class()
    context = {
        **model_admin.admin_site.each_context(request),
        "opts": model_admin.model._meta,
        "title": title,
        "explanation": explanation,
        "objects": objects,
        "form": form,
        "action": action,
        "submit_label": submit_label,
        "action_checkbox_name": ACTION_CHECKBOX_NAME,
    }
    return TemplateResponse(request, "admin/action_form.html", context)


class NamesChecked:
    """A ModelAdmin mixin: its ``name`` field refuses what the pages and the API refuse in a
    name (robotide.names), without a validator on the model (that would be a migration)."""

    def formfield_for_dbfield(self, db_field, request, **kwargs):
        field = super().formfield_for_dbfield(db_field, request, **kwargs)
        if field is not None and db_field.name == "name":
            field.validators.append(names.validate)
        return field


@admin.register(ApiToken)
class ApiTokenAdmin(NamesChecked, admin.ModelAdmin):
    list_display = ["user", "name", "created", "last_used"]
    search_fields = ["user__username", "name"]
    readonly_fields = ["digest", "created", "last_used"]


# -- classes (groups) and their teachers, users and what they teach ---------------------------


class TeacherInline(admin.TabularInline):
    model = ClassTeacher
    extra = 0
    autocomplete_fields = ["user"]
    verbose_name = gettext_lazy("teacher")
    verbose_name_plural = gettext_lazy("teachers")


class TeachingInline(admin.TabularInline):
    model = ClassTeacher
    fk_name = "user"
    extra = 0
    autocomplete_fields = ["group"]
    verbose_name = gettext_lazy("class taught")
    verbose_name_plural = gettext_lazy("classes taught")


admin.site.unregister(Group)


@admin.register(Group)
class GroupAdmin(NamesChecked, auth_admin.GroupAdmin):
    list_display = ["name", "members", "teacher_names"]
    inlines = [TeacherInline]

    def get_queryset(self, request):
        return (
            super()
            .get_queryset(request)
            .annotate(_members=Count("user", distinct=True))
            .prefetch_related("teachers__user")
        )

    @admin.display(description=gettext_lazy("members"), ordering="_members")
    def members(self, obj):
        return obj._members

    @admin.display(description=gettext_lazy("teachers"))
    def teacher_names(self, obj):
        return ", ".join(t.user.username for t in obj.teachers.all())


class TakeAccessForm(forms.Form):
    robot = forms.ModelChoiceField(
        queryset=None,
        label=gettext_lazy("Robot"),
        help_text=gettext_lazy("The robot they may no longer use"),
    )

    def __init__(self, *args, **kwargs):
        from robots.models import Robot

        super().__init__(*args, **kwargs)
        self.fields["robot"].queryset = Robot.objects.order_by("name")


TAKE_ACCESS_EXPLANATION = gettext_lazy(
    "A robot is used by the members and teachers of its classes, or by everyone when it has "
    "no class. The selected users are taken out of the chosen robot's classes (as members and "
    "as teachers), which also takes away the other robots and shared programs of those "
    "classes. If the robot is open to everyone, it is restricted to a new class named "
    "“<robot>-users” holding every current user but those selected; users created later "
    "must be added to that class to use it. Superusers keep every robot."
)


def take_away_access(robot, users) -> str:
    """Take ``robot`` away from ``users``; says what was done."""
    users = list(users)
    ids = [u.pk for u in users]
    with transaction.atomic():
        groups = list(robot.groups.all())
        if groups:
            for group in groups:
                group.user_set.remove(*users)
            ClassTeacher.objects.filter(group__in=groups, user__in=ids).delete()
            names = ", ".join(g.name for g in groups)
            done = ngettext(
                "Took %(count)d user out of %(robot)s's classes (%(names)s).",
                "Took %(count)d users out of %(robot)s's classes (%(names)s).",
                len(users),
            ) % {"count": len(users), "robot": robot.name, "names": names}
        else:
            group, _created = Group.objects.get_or_create(name=f"{robot.name}-users"[:150])
            group.user_set.add(*User.objects.exclude(pk__in=ids))
            group.user_set.remove(*users)
            robot.groups.set([group])
            done = ngettext(
                "%(robot)s was open to everyone: it is now for the class %(class)s, every "
                "user but the %(count)d selected.",
                "%(robot)s was open to everyone: it is now for the class %(class)s, every "
                "user but the %(count)d selected.",
                len(users),
            ) % {"robot": robot.name, "class": group.name, "count": len(users)}
    if any(u.is_superuser for u in users):
        done += " " + _("Superusers among them still use every robot.")
    return done


class DirectoryAccountInline(admin.StackedInline):
    model = DirectoryAccount
    can_delete = False
    readonly_fields = ["dn", "classes", "taught", "last_sign_in"]
    verbose_name = verbose_name_plural = gettext_lazy("from the directory (LDAP)")

    def has_add_permission(self, request, obj=None):
        return False


class ProviderAccountInline(admin.StackedInline):
    model = ProviderAccount
    can_delete = False
    readonly_fields = ["issuer", "subject", "classes", "taught", "last_sign_in"]
    verbose_name = verbose_name_plural = gettext_lazy("from the OpenID Connect provider")

    def has_add_permission(self, request, obj=None):
        return False


class OriginFilter(admin.SimpleListFilter):
    title = gettext_lazy("origin")
    parameter_name = "origin"

    def lookups(self, request, model_admin):
        return [
            ("directory", _("directory (LDAP)")),
            ("provider", _("OpenID Connect")),
            ("local", _("local")),
        ]

    def queryset(self, request, queryset):
        if self.value() == "directory":
            return queryset.filter(directory_account__isnull=False)
        if self.value() == "provider":
            return queryset.filter(provider_account__isnull=False)
        if self.value() == "local":
            return queryset.filter(directory_account__isnull=True, provider_account__isnull=True)
        return queryset


admin.site.unregister(User)


@admin.register(User)
class UserAdmin(auth_admin.UserAdmin):
    inlines = [
        *auth_admin.UserAdmin.inlines,
        DirectoryAccountInline,
        ProviderAccountInline,
        TeachingInline,
    ]
    # Which identity inlines belong to whom: a local account has no directory or provider
    # identity, and an empty read-only block for each read as if it had.
    IDENTITIES = {
        DirectoryAccountInline: "directory_account",
        ProviderAccountInline: "provider_account",
    }
    list_display = [*auth_admin.UserAdmin.list_display, "origin"]
    list_filter = [*auth_admin.UserAdmin.list_filter, OriginFilter, "teaching__group"]
    list_select_related = ["directory_account", "provider_account"]
    actions = ["take_robot_access"]

    def get_inlines(self, request, obj):
        return [
            inline
            for inline in super().get_inlines(request, obj)
            if inline not in self.IDENTITIES or hasattr(obj, self.IDENTITIES[inline])
        ]

    @admin.display(description=gettext_lazy("origin"), ordering="directory_account")
    def origin(self, obj):
        if hasattr(obj, "provider_account"):
            return _("OpenID Connect")
        return _("directory") if hasattr(obj, "directory_account") else _("local")

    @admin.action(description=gettext_lazy("Take away access to a robot…"))
    def take_robot_access(self, request, queryset):
        def apply(form, users):
            robot = form.cleaned_data["robot"]
            self.message_user(request, take_away_access(robot, users), messages.SUCCESS)

        return action_with_form(
            self,
            request,
            queryset,
            TakeAccessForm,
            apply,
            action="take_robot_access",
            title=_("Take away access to a robot"),
            submit_label=_("Take away access"),
            explanation=TAKE_ACCESS_EXPLANATION,
        )


class _LanguagesOnIndex:
    """The admin's index lists the languages programs can be written in, and what they need."""

    def __init__(self, index):
        self.index = index

    def __call__(self, request, extra_context=None):
        from programs.languages import availability

        return self.index(request, {**(extra_context or {}), "languages": availability()})


admin.site.index_template = "admin/robotide_index.html"
admin.site.index = _LanguagesOnIndex(admin.site.index)
