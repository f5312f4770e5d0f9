import hashlib
import secrets
from datetime import timedelta

from django.conf import settings
from django.db import models
from django.utils import timezone

LAST_USED_RESOLUTION = timedelta(minutes=1)


def hash_token(token: str) -> str:
    return hashlib.sha256(token.encode()).hexdigest()


class ApiToken(models.Model):
    """A bearer token for the REST API. Only its hash is stored; the token is shown once."""

    user = models.ForeignKey(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="api_tokens"
    )
    name = models.CharField(max_length=100, blank=True)
    digest = models.CharField(max_length=64, unique=True, editable=False)
    created = models.DateTimeField(default=timezone.now)
    last_used = models.DateTimeField(null=True, blank=True)

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

    group = models.ForeignKey("auth.Group", on_delete=models.CASCADE, related_name="teachers")
    user = models.ForeignKey(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="teaching"
    )

    class Meta:
        constraints = [models.UniqueConstraint(fields=["group", "user"], name="one_teacher_row")]

    def __str__(self) -> str:
        return f"{self.user} teaches {self.group}"


class DirectoryAccount(models.Model):
    """An account the directory (LDAP) made or signs in; accounts without one are local.

    The classes it last gave are kept so a class the directory drops is dropped here too, while
    classes an admin added by hand stay.
    """

    user = models.OneToOneField(
        settings.AUTH_USER_MODEL, on_delete=models.CASCADE, related_name="directory_account"
    )
    dn = models.CharField("directory entry", max_length=500)
    classes = models.JSONField(default=list, blank=True)
    taught = models.JSONField(default=list, blank=True)
    last_sign_in = models.DateTimeField(default=timezone.now)

    def __str__(self) -> str:
        return self.dn

    def sync_classes(self, classes: set[str], teaches: bool) -> None:
        """Member of ``classes``, or their teacher when ``teaches``; a class is made on first
        sight. Only what the directory gave before is taken away."""
        from django.contrib.auth.models import Group

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
