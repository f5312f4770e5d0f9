"""What people are told about a run's log storage: a pruned log, a user's quota in use."""

from django.utils.formats import date_format
from django.utils.translation import gettext as _


def megabytes(size: int) -> str:
    """ "180 MB", "0.4 MB": whole megabytes, or one decimal below ten."""
    mb = size / (1024 * 1024)
    return f"{mb:.0f} MB" if mb >= 10 or mb == 0 else f"{mb:.1f} MB"


def pruned_text(run) -> str:
    """Why ``run`` has no log any more, for a download that finds none."""
    when = date_format(run.log_pruned_at, "DATETIME_FORMAT", use_l10n=True)
    return _("This run's log was pruned on %(when)s: %(why)s.") % {
        "when": when,
        "why": run.log_pruned_reason,
    }
