import hashlib
import secrets
from datetime import timedelta

from django.conf import settings
from django.db import models
from django.utils import timezone
from django.utils.translation import gettext_lazy as _

LAST_USED_RESOLUTION = timedelta(minutes=1)


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


class ApiToken(models.Model):
    """A bearer token for the REST API. Only its hash is stored; the token is shown once."""

    user = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        on_delete=models.CASCADE,
        related_name="api_tokens",
        verbose_name=_("user"),
    )
    name = models.CharField(_("name"), max_length=100, blank=True)
    digest = models.CharField(_("digest"), max_length=64, unique=True, editable=False)
    created = models.DateTimeField(_("created"), default=timezone.now)
    last_used = models.DateTimeField(_("last used"), null=True, blank=True)

    class Meta:
        verbose_name = _("API token")
        verbose_name_plural = _("API tokens")

    def __str__(self) -> str:
        return f"{self.user} {self.name or self.created:%Y-%m-%d}"

    @classmethod
    def issue(cls, user, name: str = "") -> tuple["ApiToken", str]:
        token = "rt_" + secrets.token_urlsafe(32)
        return cls.objects.create(user=user, name=name, digest=hash_token(token)), token

    @classmethod
    def user_for(cls, token: str):
        found = cls.objects.select_related("user").filter(digest=hash_token(token)).first()
        if found is None or not found.user.is_active:
            return None
        now = timezone.now()
        if found.last_used is None or now - found.last_used > LAST_USED_RESOLUTION:
            cls.objects.filter(pk=found.pk).update(last_used=now)  # not a write per request
        return found.user


class ClassTeacher(models.Model):
    """A teacher of a class: a group whose members' programs and runs they see and run."""

    group = models.ForeignKey(
        "auth.Group", on_delete=models.CASCADE, related_name="teachers", verbose_name=_("class")
    )
    user = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        on_delete=models.CASCADE,
        related_name="teaching",
        verbose_name=_("teacher"),
    )

    class Meta:
        verbose_name = _("class teacher")
        verbose_name_plural = _("class teachers")
        constraints = [models.UniqueConstraint(fields=["group", "user"], name="one_teacher_row")]

    def __str__(self) -> str:
        return _("%(user)s teaches %(group)s") % {"user": self.user, "group": self.group}


class DirectoryAccount(models.Model):
    """An account the directory (LDAP) made or signs in; accounts without one are local.

    The classes it last gave are kept so a class the directory drops is dropped here too, while
    classes an admin added by hand stay.
    """

    user = models.OneToOneField(
        settings.AUTH_USER_MODEL,
        on_delete=models.CASCADE,
        related_name="directory_account",
        verbose_name=_("user"),
    )
    dn = models.CharField(_("directory entry"), max_length=500)
    classes = models.JSONField(_("classes"), default=list, blank=True)
    taught = models.JSONField(_("classes taught"), default=list, blank=True)
    last_sign_in = models.DateTimeField(_("last sign-in"), default=timezone.now)

    class Meta:
        verbose_name = _("directory account")
        verbose_name_plural = _("directory accounts")

    def __str__(self) -> str:
        return self.dn

    def sync_classes(self, classes: set[str], teaches: bool) -> None:
        """Member of ``classes``, or their teacher when ``teaches``; a class is made on first
        sight. Only what the directory gave before is taken away."""
        from django.contrib.auth.models import Group

        # A group that grants permissions is an admin role made here, never a class.
        roles = set(
            Group.objects.filter(name__in=classes, permissions__isnull=False).values_list(
                "name", flat=True
            )
        )
        classes = set(classes) - roles
        member_of = set() if teaches else classes
        taught = classes if teaches else set()
        groups = {name: Group.objects.get_or_create(name=name)[0] for name in classes}
        user = self.user
        user.groups.add(*(groups[n] for n in member_of))
        user.groups.remove(*Group.objects.filter(name__in=set(self.classes) - member_of))
        for name in taught:
            ClassTeacher.objects.get_or_create(group=groups[name], user=user)
        ClassTeacher.objects.filter(user=user, group__name__in=set(self.taught) - taught).delete()
        self.classes, self.taught = sorted(member_of), sorted(taught)
        self.save()


class LanguagePreference(models.Model):
    """The language a user chose for the pages: it wins over their browser's Accept-Language."""

    user = models.OneToOneField(
        settings.AUTH_USER_MODEL,
        on_delete=models.CASCADE,
        related_name="language_preference",
        verbose_name=_("user"),
    )
    # No choices: the list is settings.LANGUAGES, checked when it is set (robotide.language).
    language = models.CharField(_("language"), max_length=15)

    class Meta:
        verbose_name = _("language preference")
        verbose_name_plural = _("language preferences")

    def __str__(self) -> str:
        return f"{self.user}: {self.language}"


class ProviderAccount(models.Model):
    """An account an OpenID Connect provider made and signs in (robotide.oidc).

    It is the provider's identity (issuer, sub): never found by user name or e-mail, which the
    provider's users may choose or share. Classes as a DirectoryAccount keeps them.
    """

    user = models.OneToOneField(
        settings.AUTH_USER_MODEL,
        on_delete=models.CASCADE,
        related_name="provider_account",
        verbose_name=_("user"),
    )
    issuer = models.CharField(_("provider"), max_length=500)
    subject = models.CharField(_("subject (sub)"), max_length=255)
    classes = models.JSONField(_("classes"), default=list, blank=True)
    taught = models.JSONField(_("classes taught"), default=list, blank=True)
    last_sign_in = models.DateTimeField(_("last sign-in"), default=timezone.now)

    class Meta:
        verbose_name = _("provider account")
        verbose_name_plural = _("provider accounts")
        constraints = [
            models.UniqueConstraint(fields=["issuer", "subject"], name="one_account_per_identity")
        ]

    def __str__(self) -> str:
        return f"{self.subject} @ {self.issuer}"

    sync_classes = DirectoryAccount.sync_classes  # the same rules, from claims
