"""Worlds as stored documents: a sim's arena (rhal.simulator's world format), versioned and
shared like programs (a user, a class, everyone; the teachers of its owner's classes see it).

The document is stored as rhal.simulator.world normalises it (worlds.documents.validated), so
what the API returns is what a sim loads.
"""

from django.conf import settings
from django.db import models, transaction
from django.utils import timezone
from django.utils.translation import gettext
from django.utils.translation import gettext_lazy as _

#: A world document's largest size, as compact JSON (the API and the import refuse larger).
MAX_DOCUMENT_BYTES = 256 * 1024


class World(models.Model):
    owner = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        on_delete=models.CASCADE,
        related_name="worlds",
        verbose_name=_("owner"),
    )
    # A slug: it goes into a sim's URL (sim://?world=NAME) and into file names.
    name = models.SlugField(_("name"), max_length=50)
    title = models.CharField(_("title"), max_length=200, blank=True)
    document = models.JSONField(_("document"), default=dict)
    created = models.DateTimeField(_("created"), default=timezone.now)
    updated = models.DateTimeField(_("updated"), default=timezone.now)

    class Meta:
        verbose_name = _("world")
        verbose_name_plural = _("worlds")
        ordering = ["name"]
        constraints = [models.UniqueConstraint(fields=["owner", "name"], name="unique_world_name")]

    def __str__(self) -> str:
        return self.name

    def save_document(self, document: dict, author) -> "WorldRevision":
        """Store a validated document: every save keeps the one before as a revision (an
        unchanged document adds none)."""
        with transaction.atomic():
            self.document = document
            self.updated = timezone.now()
            self.save()
            latest = self.revisions.first()
            if latest is not None and latest.document == document:
                return latest
            number = (latest.number + 1) if latest else 1
            return WorldRevision.objects.create(
                world=self, number=number, document=document, author=author
            )


class WorldRevision(models.Model):
    world = models.ForeignKey(
        World, on_delete=models.CASCADE, related_name="revisions", verbose_name=_("world")
    )
    number = models.PositiveIntegerField(_("number"))
    document = models.JSONField(_("document"), default=dict)
    author = models.ForeignKey(
        settings.AUTH_USER_MODEL, on_delete=models.SET_NULL, null=True, verbose_name=_("author")
    )
    created = models.DateTimeField(_("created"), default=timezone.now)

    class Meta:
        verbose_name = _("world revision")
        verbose_name_plural = _("world revisions")
        ordering = ["-number"]
        constraints = [
            models.UniqueConstraint(fields=["world", "number"], name="unique_world_revision")
        ]

    def __str__(self) -> str:
        return f"{self.world} r{self.number}"


class WorldShare(models.Model):
    """A world shared with one user, one group (a class), or everyone: programs.models.Share's
    targets. Only its owner changes it, so a share has no "may edit"."""

    world = models.ForeignKey(
        World, on_delete=models.CASCADE, related_name="shares", verbose_name=_("world")
    )
    user = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        null=True,
        blank=True,
        on_delete=models.CASCADE,
        related_name="worlds_shared_with_me",
        verbose_name=_("user"),
    )
    group = models.ForeignKey(
        "auth.Group",
        null=True,
        blank=True,
        on_delete=models.CASCADE,
        related_name="world_shares",
        verbose_name=_("class"),
    )
    everyone = models.BooleanField(_("everyone"), default=False)
    created_by = models.ForeignKey(
        settings.AUTH_USER_MODEL,
        null=True,
        on_delete=models.SET_NULL,
        related_name="+",
        verbose_name=_("created by"),
    )
    created = models.DateTimeField(_("created"), default=timezone.now)

    class Meta:
        verbose_name = _("world share")
        verbose_name_plural = _("world shares")
        ordering = ["created"]
        constraints = [
            models.CheckConstraint(
                name="world_share_has_one_target",
                condition=(
                    models.Q(user__isnull=False, group__isnull=True, everyone=False)
                    | models.Q(user__isnull=True, group__isnull=False, everyone=False)
                    | models.Q(user__isnull=True, group__isnull=True, everyone=True)
                ),
            ),
            models.UniqueConstraint(
                fields=["world", "user"], condition=models.Q(user__isnull=False),
                name="one_world_share_per_user",
            ),
            models.UniqueConstraint(
                fields=["world", "group"], condition=models.Q(group__isnull=False),
                name="one_world_share_per_group",
            ),
            models.UniqueConstraint(
                fields=["world"], condition=models.Q(everyone=True),
                name="one_world_share_with_everyone",
            ),
        ]  # fmt: skip

    def __str__(self) -> str:
        return f"{self.world} -> {self.target}"

    @property
    def target(self) -> str:
        if self.everyone:
            return gettext("everyone")
        if self.group_id:
            return gettext("group %(name)s") % {"name": self.group.name}
        return gettext("user %(name)s") % {"name": self.user.username}
