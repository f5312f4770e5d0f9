import time
from datetime import timedelta

import nh3
from django import template
from django.utils.formats import get_format
from django.utils.html import format_html
from django.utils.safestring import mark_safe
from django.utils.translation import gettext as _

from programs import watch_pass
from robots import fair_shares
from runlogs.notes import pruned_text, quota_words

register = template.Library()


@register.filter
def duration(value: timedelta | None) -> str:
    """1.2 s, 3 min 04 s, 2 h 05 min."""
    if value is None:
        return "—"
    seconds = value.total_seconds()
    if seconds < 60:
        return _decimal(f"{seconds:.1f}") + " s"
    minutes, secs = divmod(int(seconds), 60)
    if minutes < 60:
        return f"{minutes} min {secs:02d} s"
    hours, minutes = divmod(minutes, 60)
    return f"{hours} h {minutes:02d} min"


@register.filter
def running_clock(run) -> str:
    """A running run's duration so far, for its page's script to count on each second
    (robotide/run.js): when it started and the server's time now, in ms, so a browser's clock
    set wrong counts from the server's reading. Without scripts it stays as rendered."""
    started, now = round(run.started.timestamp() * 1000), round(time.time() * 1000)
    html = '<span class="clock" data-started-ms="{}" data-now-ms="{}">{}</span>'
    return format_html(html, started, now, duration(run.duration))


@register.filter
def reason_for(run, user) -> str:
    """A run's reason note as ``user`` reads it: a share wait said to its owner or about
    them, and a share wait's or a log quota's words (stored in English) in their language."""
    if fair_shares.is_share_wait(run.reason):
        return fair_shares.reason_shown(run.reason, getattr(user, "pk", None) == run.owner_id)
    return quota_words(run.reason_note)


@register.filter
def pruned_note(run) -> str:
    """A pruned log's note on its run's page: the words its download's 410 says."""
    return pruned_text(run)


@register.filter
def reading(value) -> str:
    """A sensor reading or shown value, numbers rounded for reading."""
    if isinstance(value, bool):
        return _("yes") if value else _("no")
    if isinstance(value, float):
        text = f"{value:.3f}".rstrip("0").rstrip(".") if abs(value) < 1e6 else f"{value:.3g}"
        return _decimal(text)
    if value is None:
        return "—"
    return str(value)


def _decimal(text: str) -> str:
    """A number written by Python, with the language's decimal mark (1,5 in pt-BR)."""
    return text.replace(".", get_format("DECIMAL_SEPARATOR"))


@register.filter
def plottable(value) -> str:
    """The number a plot takes from a reading, or "" for readings that are no number."""
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        return ""
    return repr(float(value)) if value == value and abs(value) != float("inf") else ""


@register.filter
def sanitized(html: str) -> str:
    """Staff-written HTML (a page) with scripts, event handlers, styles and javascript: links
    removed: safe to show even if the strict CSP were not there."""
    return mark_safe(nh3.clean(str(html)))


@register.simple_tag(takes_context=True)
def run_live(context, run, shown_up_to=None) -> str:
    """The run's websocket path for this page: its viewer's pass, the log offset shown."""
    return watch_pass.live_path(run, context.get("request"), shown_up_to)
