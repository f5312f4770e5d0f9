"""The one place that decides who may see and use a program or a run.

Views, API endpoints and consumers fetch objects only through these helpers.
"""

from django.http import Http404

from programs.models import Program, Run


def programs_for_user(user):
    if not user.is_authenticated:
        return Program.objects.none()
    qs = Program.objects.select_related("owner")
    return qs if user.is_staff else qs.filter(owner=user)


def runs_for_user(user):
    if not user.is_authenticated:
        return Run.objects.none()
    qs = Run.objects.select_related("robot", "owner")
    return qs if user.is_staff else qs.filter(owner=user)


def get_program_for_user(user, pk) -> Program:
    try:
        return programs_for_user(user).get(pk=pk)
    except (Program.DoesNotExist, ValueError, TypeError):
        raise Http404("No such program.") from None


def get_run_for_user(user, pk) -> Run:
    try:
        return runs_for_user(user).get(pk=pk)
    except (Run.DoesNotExist, ValueError, TypeError):
        raise Http404("No such run.") from None
