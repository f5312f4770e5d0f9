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
