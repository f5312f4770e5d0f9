"""Who may see and change classes, exercises and attempts: the one place that decides it.

Pages and the API fetch these objects only through the helpers here (as programs.access does
for programs and runs), so a page and its API answer alike.

- a class's teachers: its robotide.ClassTeacher rows; staff (``is_staff``) see every class;
- an exercise: its author; the teachers of its class; the students of its class (members of
  the group, and only once it has a class: ``group=None`` is a draft); staff;
- to change an exercise (and see its hidden variants): its author, its class's teachers,
  staff;
- to set an exercise for a class: who teaches that class, or staff (anyone signed in may make
  drafts);
- an attempt: its student; the teachers of its exercise's class or of a class its student is
  in; its exercise's author; staff.
"""

from django.contrib.auth.models import Group
from django.db.models import Q, QuerySet
from django.http import Http404
from django.utils.translation import gettext as _

from classroom.models import Attempt, Exercise
from programs.access import taught_groups

__all__ = [
    "attempts_for_user",
    "can_edit_exercise",
    "can_set_for_class",
    "classes_for_teacher",
    "exercises_for_user",
    "get_attempt_for_user",
    "get_class_for_teacher",
    "get_exercise_for_user",
    "is_teacher",
    "sees_hidden",
    "teaches",
]


def _signed_in(user) -> bool:
    return user is not None and user.is_authenticated and user.is_active


def is_teacher(user) -> bool:
    """Teaches a class, or is staff: what the classroom's teacher pages need."""
    if not _signed_in(user):
        return False
    return user.is_staff or taught_groups(user).exists()


def classes_for_teacher(user) -> QuerySet:
    """The classes (auth Groups) ``user`` teaches; staff: every class."""
    if not _signed_in(user):
        return Group.objects.none()
    if user.is_staff:
        return Group.objects.all().order_by("name")
    return taught_groups(user).order_by("name")


def get_class_for_teacher(user, group_id) -> Group:
    """The class, if ``user`` teaches it (or is staff): 404 else."""
    try:
        return classes_for_teacher(user).get(pk=group_id)
    except (Group.DoesNotExist, ValueError, TypeError):
        raise Http404(_("No such class.")) from None


def teaches(user, group_id) -> bool:
    """Whether ``user`` teaches the class numbered ``group_id`` (staff: any class)."""
    if group_id is None or not _signed_in(user):
        return False
    return classes_for_teacher(user).filter(pk=group_id).exists()


def can_set_for_class(user, group_id) -> bool:
    """Whether ``user`` may give an exercise to the class ``group_id`` (None: a draft, anyone
    signed in)."""
    if group_id is None:
        return _signed_in(user)
    return teaches(user, group_id)


def exercises_for_user(user) -> QuerySet:
    """The exercises ``user`` may see: their own (drafts too), their classes' as teacher, and
    as student those set for a class they are in; staff: all."""
    if not _signed_in(user):
        return Exercise.objects.none()
    qs = Exercise.objects.select_related("owner", "group")
    if user.is_staff:
        return qs
    taught = taught_groups(user)
    member = Q(group__isnull=False, group__in=user.groups.all())
    return qs.filter(Q(owner=user) | Q(group__in=taught) | member).distinct()


def get_exercise_for_user(user, pk) -> Exercise:
    """The exercise: 404 if ``user`` may not see it."""
    try:
        return exercises_for_user(user).get(pk=pk)
    except (Exercise.DoesNotExist, ValueError, TypeError):
        raise Http404(_("No such exercise.")) from None


def can_edit_exercise(user, exercise: Exercise) -> bool:
    """Its author, its class's teachers, staff."""
    if not _signed_in(user):
        return False
    if user.is_staff or exercise.owner_id == user.pk:
        return True
    return exercise.group_id is not None and teaches(user, exercise.group_id)


def sees_hidden(user, exercise: Exercise) -> bool:
    """Whether ``user`` may see the exercise's hidden variants' poses (who may change it)."""
    return can_edit_exercise(user, exercise)


def attempts_for_user(user) -> QuerySet:
    """The attempts ``user`` may see: their own; as teacher, those of the exercises of the
    classes they teach and of the students in them; their exercises'; staff: all."""
    if not _signed_in(user):
        return Attempt.objects.none()
    qs = Attempt.objects.select_related("exercise", "student")
    if user.is_staff:
        return qs
    taught = taught_groups(user)
    return qs.filter(
        Q(student=user)
        | Q(exercise__owner=user)
        | Q(exercise__group__in=taught)
        | Q(student__groups__in=taught)
    ).distinct()


def get_attempt_for_user(user, pk) -> Attempt:
    """The attempt: 404 if ``user`` may not see it."""
    try:
        # Its student's own, the common case: one plain query first.
        if _signed_in(user) and not user.is_staff:
            own = (
                Attempt.objects.select_related("exercise", "student")
                .filter(pk=pk, student=user)
                .first()
            )
            if own is not None:
                return own
        return attempts_for_user(user).get(pk=pk)
    except (Attempt.DoesNotExist, ValueError, TypeError):
        raise Http404(_("No such attempt.")) from None
