"""What the students' pages and the workbench say about exercises: a check in words, a
variant's name, and the exercise a program is the work for (the workbench's include asks it
here, so the programs app needs not know the classroom)."""

from django import template
from django.template.loader import render_to_string
from django.utils.formats import number_format
from django.utils.translation import gettext as _
from django.utils.translation import ngettext

from classroom.access import attempts_for_user, exercises_for_user
from classroom.models import Work

register = template.Library()

LOOPS = "loop"
CONDITIONS = "condition"


def _number(value) -> str:
    """2, 2.5 (2,5 in pt-BR): a check's figure as people write it."""
    if isinstance(value, float) and value.is_integer():
        value = int(value)
    return number_format(value, use_l10n=True) if isinstance(value, (int, float)) else str(value)


@register.filter
def points(value) -> str:
    """'1 point', '2.5 points'."""
    number = float(value or 0)
    count = int(number) if number.is_integer() else 2  # ngettext's plural for 2.5 too
    return ngettext("%(n)s point", "%(n)s points", count) % {"n": _number(number)}


@register.filter
def check_words(check: dict) -> str:
    """What a check asks for, in the reader's language (its figures, zone names, pattern as
    the teacher wrote them)."""
    kind = check.get("kind", "")
    within = check.get("within_s")
    if kind == "reach_zone":
        if within:
            return _("Reach the zone “%(zone)s” within %(s)s s") % {
                "zone": check.get("zone", ""), "s": _number(within),
            }  # fmt: skip
        return _("Reach the zone “%(zone)s”") % {"zone": check.get("zone", "")}
    if kind == "zones_in_order":
        zones = " → ".join(str(zone) for zone in check.get("zones", []))
        if within:
            return _("Visit the zones %(zones)s in this order, within %(s)s s") % {
                "zones": zones, "s": _number(within),
            }  # fmt: skip
        return _("Visit the zones %(zones)s in this order") % {"zones": zones}
    if kind == "no_contact":
        return _("Never touch a wall or a box")
    if kind == "stop_near_wall":
        return _("Stop, at the end, between %(min)s m and %(max)s m from a wall or a box") % {
            "min": _number(check.get("min_m", 0)), "max": _number(check.get("max_m", 0)),
        }  # fmt: skip
    if kind == "ends_within":
        return _("End on its own (exit code 0) within %(s)s s") % {
            "s": _number(check.get("seconds", 0))
        }
    if kind == "output_matches" and "pattern" not in check:  # a student's: see SECRET_KEYS
        return _("Print or say the text the exercise asks for")
    if kind == "output_matches":
        return _("Print or say a text that matches %(pattern)s") % {
            "pattern": repr(check.get("pattern", ""))
        }
    if kind == "uses_block":
        block = check.get("block", "")
        if block == LOOPS:
            return _("Use a loop block")
        if block == CONDITIONS:
            return _("Use a condition block (if, if-else)")
        return _("Use the block %(block)s") % {"block": block}
    if kind == "max_blocks":
        return _("Use at most %(count)s blocks") % {"count": _number(check.get("count", 0))}
    return kind


@register.filter
def variant_name(index, hidden=False) -> str:
    """'start 1', 'hidden start 3' (numbered from 1, as the teacher's page numbers them)."""
    if index is None:
        return _("the program's text")
    if hidden:
        return _("hidden start %(n)s") % {"n": int(index) + 1}
    return _("start %(n)s") % {"n": int(index) + 1}


@register.simple_tag(takes_context=True)
def exercise_work(context, program):
    """The Work ``program`` is for, with its exercise, when the page's user may see that
    exercise; None else (most programs)."""
    user = getattr(context.get("request"), "user", None)
    if program is None or user is None or not user.is_authenticated:
        return None
    work = Work.objects.filter(program=program).select_related("exercise", "student").first()
    if work is None or not exercises_for_user(user).filter(pk=work.exercise_id).exists():
        return None
    return work


@register.simple_tag(takes_context=True)
def latest_attempt(context, work):
    """The latest attempt of the work's student at its exercise, or None."""
    user = getattr(context.get("request"), "user", None)
    if work is None or user is None:
        return None
    attempts = attempts_for_user(user).filter(exercise=work.exercise_id, student=work.student_id)
    return attempts.order_by("-created", "-pk").first()


@register.simple_tag(takes_context=True)
def attempt_checklist(context, attempt):
    """The attempt's checklist (classroom/_checklist.html), following it while it runs."""
    from classroom.views_student import checklist_context

    request = context.get("request")
    return render_to_string(
        "classroom/_checklist.html", checklist_context(attempt, request), request
    )
