"""What people are told about a run's log storage: a pruned log, a user's quota in use."""

import re

from django.utils.formats import date_format, number_format
from django.utils.timezone import localtime
from django.utils.translation import gettext as _


def megabytes(size: int) -> str:
    """ "180 MB", "0.4 MB": whole megabytes, or one decimal below ten."""
    mb = size / (1024 * 1024)
    decimals = 0 if mb >= 10 or mb == 0 else 1
    # Rounded first: number_format cuts digits off (0.69 would be "0.6").
    return f"{number_format(round(mb, decimals), decimals, use_l10n=True)} MB"  # "0,4 MB" in pt-BR


def pruned_text(run) -> str:
    """Why ``run`` has no log any more, for a download that finds none."""
    when = date_format(localtime(run.log_pruned_at), "DATETIME_FORMAT", use_l10n=True)
    return _("This run's log was pruned on %(when)s: %(why)s.") % {
        "when": when,
        "why": quota_words(run.log_pruned_reason),
    }


def quota_words(reason: str) -> str:
    """A run's stored reason (runlogs.quota and the agent store it in English, like the run's
    log) in the reader's language: a log quota's, or robotide's other wordings
    (runlogs.system_words); any other reason as it is."""
    from runlogs.system_words import translated

    return translated(reason)


def quota_reason_words(reason: str) -> str | None:
    """A run log quota's reason in the reader's language; None for any other reason."""
    found = _QUOTA_STORED.fullmatch(reason)
    if found is None:
        return None
    if found[2] == "a user's":
        words = _("run log quota reached (%(size)s MB for a user's logs, the oldest pruned first)")
    else:
        words = _(
            "run log quota reached (%(size)s MB for all users' logs, the oldest pruned first)"
        )
    return words % {"size": number_format(found[1], use_l10n=True)}


# What runlogs.quota.user_reason and total_reason store.
_QUOTA_STORED = re.compile(
    r"run log quota reached \(([\d.]+) MB for (a user's|all users') logs, the oldest pruned first\)"
)
