"""A teacher's classes without the admin site: /classroom/ (their classes, a new one), a class
(/classroom/<id>/: students, adding them in bulk, the join code, its robots and worlds), the
printable sheet of new accounts' one-time passwords, a student's page, and sign-up with a join
code (/accounts/join/).

Classes are auth Groups: those made here, by the API, by an admin, or by LDAP/OpenID Connect
sign-ins (robotide.models.DirectoryAccount) all show; only classes made here or by the API have
a Classroom row (a join code), which one made elsewhere gets when its join code is turned on.
Every class, student and object is fetched through the access helpers (classroom.access,
programs.access, robots.models, worlds.access).
"""

import base64
import functools
import hashlib
import hmac
import json
import math
import secrets
from datetime import datetime, time, timedelta

from django.conf import settings
from django.contrib import messages
from django.contrib.auth import login
from django.contrib.auth.decorators import login_required
from django.contrib.auth.models import Group
from django.core.exceptions import PermissionDenied
from django.db import IntegrityError, transaction
from django.db.models import Count, IntegerField, Max, OuterRef, Q, Subquery
from django.db.models.functions import Coalesce
from django.http import Http404, HttpRequest, HttpResponse
from django.shortcuts import redirect, render
from django.urls import reverse
from django.utils import timezone
from django.utils.translation import gettext as _
from django.utils.translation import ngettext
from django.views.decorators.cache import never_cache
from django.views.decorators.debug import sensitive_post_parameters
from django.views.decorators.http import require_POST

from classroom.access import classes_for_teacher, exercises_for_user, get_class_for_teacher
from classroom.access import is_teacher as teaches_a_class
from classroom.accounts import AccountsError, create_class, create_students, free_join_code
from classroom.forms_classes import (
    AddStudentsForm,
    JoinForm,
    JoinSignedInForm,
    NewClassForm,
    StudentFilterForm,
)
from classroom.models import Classroom, OneTimePassword, Work
from programs.access import programs_for_user, runs_for_user
from programs.models import Program, Run
from robotide import names
from robotide.models import ClassTeacher
from robotide.security import locked_for, record_failure
from robots.models import Robot, robots_for_user
from worlds.access import OWN, get_world_for_user, worlds_for_user
from worlds.models import WorldShare
from worlds.shares import ShareError, add_share, remove_share

LATELY = timedelta(days=7)  # "programs changed lately" on a class's page
RUNS_SHOWN = 50
SHEET_KEY = "classroom_sheet"  # the session's (encrypted) sheet
SHEET_COOKIE = "classroom_sheet_key"  # its key, in the teacher's browser only
SHEET_SECONDS = 3600  # a sheet not looked at within the hour is gone
JOIN_THROTTLE_PREFIX = "join\0"  # join codes' failures: counted as sign-ins', per typed username


def teacher_required(view):
    """Signed in, and teaches a class (or is staff): others get 403."""

    @functools.wraps(view)
    @login_required
    def wrapped(request, *args, **kwargs):
        if not teaches_a_class(request.user):
            raise PermissionDenied(_("Only a class's teachers and staff see the classroom."))
        return view(request, *args, **kwargs)

    return wrapped


# -- The classes -----------------------------------------------------------------------------


@teacher_required
def class_list(request: HttpRequest) -> HttpResponse:
    form = NewClassForm()
    if request.method == "POST":
        form = NewClassForm(request.POST)
        if form.is_valid():
            try:
                group = create_class(form.cleaned_data["name"], request.user)
            except AccountsError as exc:
                form.add_error("name", str(exc))
            else:
                messages.success(
                    request,
                    _("Made the class %(name)s: add its students.") % {"name": group.name},
                )
                return redirect("class-detail", group.pk)
    classes = (
        classes_for_teacher(request.user)
        .annotate(students=Count("user", distinct=True))
        .select_related("classroom")
        .prefetch_related("teachers__user")
    )
    taught = set(ClassTeacher.objects.filter(user=request.user).values_list("group", flat=True))
    context = {
        "form": form,
        "mine": [group for group in classes if group.pk in taught],
        # Staff see every class: those they do not teach apart; a group that grants
        # permissions is an admin's role, never a class (as DirectoryAccount.sync_classes).
        "others": [g for g in classes.filter(permissions__isnull=True) if g.pk not in taught],
    }
    return render(request, "classroom/class_list.html", context, status=400 if form.errors else 200)


def _example_names() -> set[str]:
    from programs.signals import EXAMPLES, example_name

    return {example_name(f, code) for f in EXAMPLES for code, _label in settings.LANGUAGES}


def _students(group: Group) -> list:
    """The class's students with what their row on the class's page shows: programs changed
    lately (an example with its first revision only was not changed), runs, sims."""

    def count(model, **filters):
        rows = model.objects.filter(owner=OuterRef("pk"), **filters).order_by()
        counted = rows.values("owner").annotate(n=Count("pk")).values("n")
        return Coalesce(Subquery(counted, output_field=IntegerField()), 0)

    students = list(
        group.user_set.annotate(
            run_count=count(Run),
            sim_count=count(Robot, personal=True, reaped__isnull=True, checking=False),
            one_time=Count("one_time_password"),
        ).order_by("first_name", "last_name", "username")
    )
    examples = _example_names()
    changed: dict[int, int] = {}
    recent = (
        Program.objects.filter(owner__in=group.user_set.all(), updated__gte=timezone.now() - LATELY)
        .annotate(revision_count=Count("revisions"))
        .values_list("owner", "name", "origin", "revision_count")
    )
    for owner, name, origin, revision_count in recent:
        if name in examples and not origin and revision_count <= 1:
            continue
        changed[owner] = changed.get(owner, 0) + 1
    for student in students:
        student.changed = changed.get(student.pk, 0)
    return students


@teacher_required
def class_detail(request: HttpRequest, group_id: int) -> HttpResponse:
    group = get_class_for_teacher(request.user, group_id)
    return _render_class(request, group, AddStudentsForm())


def _render_class(request, group: Group, add_form: AddStudentsForm, status: int = 200):
    user = request.user
    classroom = Classroom.objects.filter(group=group).first()
    robots = group.robots.filter(personal=False).order_by("name")
    givable = [
        robot
        for robot in robots_for_user(user)
        .filter(personal=False, checking=False)
        .exclude(groups=group)
        .prefetch_related("groups")
        .order_by("name")
        if _may_give(user, robot)
    ]
    shares = WorldShare.objects.filter(group=group).select_related("world", "world__owner")
    shared_ids = {share.world_id for share in shares}
    context = {
        "group": group,
        "classroom": classroom,
        "teachers": [t.user for t in group.teachers.select_related("user").order_by("user")],
        "students": _students(group),
        "add_form": add_form,
        "robots": robots,
        "givable": givable,
        "world_shares": shares,
        "shareable": worlds_for_user(user, OWN)
        .exclude(pk__in=shared_ids)
        .defer("document")
        .order_by("name"),
        "join_url": request.build_absolute_uri(reverse("join")),
        "exercises": exercises_for_user(user).filter(group=group).order_by("due", "title"),
        "directory": group.user_set.filter(
            Q(directory_account__isnull=False) | Q(provider_account__isnull=False)
        ).exists(),
    }
    return render(request, "classroom/class_detail.html", context, status=status)


# -- Students in bulk, and their sheet -------------------------------------------------------


@never_cache
@teacher_required
@require_POST
def class_add_students(request: HttpRequest, group_id: int) -> HttpResponse:
    group = get_class_for_teacher(request.user, group_id)
    form = AddStudentsForm(request.POST, request.FILES)
    if form.is_valid():
        try:
            made = create_students(group, form.cleaned_data["entries"], request.user)
        except AccountsError as exc:
            entries = form.cleaned_data["entries"]
            where = ""
            if exc.index is not None and exc.index < len(entries):
                entry = entries[exc.index]
                where = _("line %(line)s (%(name)s): ") % {
                    "line": exc.index + 1,
                    "name": entry.username or entry.name,
                }
            form.add_error(None, _("Nobody was added: %(why)s") % {"why": where + str(exc)})
        else:
            new = [account for account in made if account.created]
            joined = len(made) - len(new)
            if joined:
                messages.info(
                    request,
                    ngettext(
                        "%(count)s existing account is in the class (no new password).",
                        "%(count)s existing accounts are in the class (no new passwords).",
                        joined,
                    )
                    % {"count": joined},
                )
            if not new:
                return redirect("class-detail", group.pk)
            messages.success(
                request,
                ngettext(
                    "Made %(count)s account: print its sheet now, its password is shown once.",
                    "Made %(count)s accounts: print their sheet now, the passwords are shown once.",
                    len(new),
                )
                % {"count": len(new)},
            )
            rows = [{"username": a.username, "name": a.full_name, "password": a.password}
                    for a in new]  # fmt: skip
            response = redirect("class-sheet", group.pk)
            _keep_sheet(request, response, group, rows)
            return response
    return _render_class(request, group, form, status=400)


@never_cache
@teacher_required
@require_POST
def student_new_password(request: HttpRequest, group_id: int, user_id: int) -> HttpResponse:
    """A student who lost their sheet, or forgot their password: a new one-time password
    (their old password stops working), on a sheet of its own."""
    from classroom.accounts import new_password

    group = get_class_for_teacher(request.user, group_id)
    student = _get_student(group, user_id)
    if not _local_student(student):
        messages.error(
            request,
            _(
                "%(username)s signs in through the school's directory or provider, or is a"
                " teacher's or staff account: its password is not changed here."
            )
            % {"username": student.username},
        )
        return redirect("class-detail", group.pk)
    password = new_password()
    with transaction.atomic():
        student.set_password(password)
        student.save(update_fields=["password"])
        OneTimePassword.objects.update_or_create(user=student, defaults={
            "issued_by": request.user, "created": timezone.now()})  # fmt: skip
    row = {"username": student.username, "name": student.get_full_name(), "password": password}
    response = redirect("class-sheet", group.pk)
    _keep_sheet(request, response, group, [row])
    return response


def _local_student(user) -> bool:
    if user.is_staff or user.is_superuser or ClassTeacher.objects.filter(user=user).exists():
        return False
    return not (hasattr(user, "directory_account") or hasattr(user, "provider_account"))


@teacher_required
@require_POST
def student_remove(request: HttpRequest, group_id: int, user_id: int) -> HttpResponse:
    """Out of the class (the account and its programs stay)."""
    group = get_class_for_teacher(request.user, group_id)
    student = _get_student(group, user_id)
    student.groups.remove(group)
    messages.success(
        request,
        _("%(username)s is no longer in %(name)s.")
        % {"username": student.username, "name": group.name},
    )
    return redirect("class-detail", group.pk)


# The sheet's passwords are kept for the one page that shows them, never in clear where the
# server stores anything: the session (a database row) holds them encrypted, the key is a
# cookie of the teacher's browser. One look takes both away.


def _keystream(key: bytes, length: int) -> bytes:
    blocks = math.ceil(length / 32)
    stream = b"".join(
        hmac.digest(key, counter.to_bytes(8, "big"), hashlib.sha256) for counter in range(blocks)
    )
    return stream[:length]


def _xor(data: bytes, key: bytes) -> bytes:
    return bytes(a ^ b for a, b in zip(data, _keystream(key, len(data)), strict=True))


def _keep_sheet(request, response, group: Group, rows: list[dict]) -> None:
    key = secrets.token_bytes(32)  # a fresh key for each sheet: a keystream used once
    data = json.dumps({"group": group.pk, "made": timezone.now().isoformat(), "rows": rows})
    sealed = _xor(data.encode(), key)
    request.session[SHEET_KEY] = base64.b64encode(sealed).decode()
    response.set_cookie(
        SHEET_COOKIE,
        base64.urlsafe_b64encode(key).decode(),
        max_age=SHEET_SECONDS,
        path=reverse("class-sheet", args=[group.pk]),
        secure=request.is_secure(),
        httponly=True,
        samesite="Strict",
    )


def _take_sheet(request, group: Group) -> dict | None:
    sealed, key = request.session.get(SHEET_KEY), request.COOKIES.get(SHEET_COOKIE)
    if not sealed or not key:
        return None
    try:
        data = json.loads(_xor(base64.b64decode(sealed), base64.urlsafe_b64decode(key)))
    except ValueError:
        return None
    if data.get("group") != group.pk:
        return None  # another class's: left for its own page
    del request.session[SHEET_KEY]
    made = datetime.fromisoformat(data["made"])
    if timezone.now() - made > timedelta(seconds=SHEET_SECONDS):
        return None
    return data


@never_cache
@teacher_required
def class_sheet(request: HttpRequest, group_id: int) -> HttpResponse:
    """The new accounts' one-time passwords, to print and cut out: shown once."""
    group = get_class_for_teacher(request.user, group_id)
    sheet = _take_sheet(request, group)
    context = {
        "group": group,
        "rows": sheet["rows"] if sheet else [],
        "sign_in": request.build_absolute_uri(reverse("login")),
    }
    response = render(request, "classroom/class_sheet.html", context, status=200 if sheet else 410)
    if sheet:
        response.delete_cookie(
            SHEET_COOKIE, path=reverse("class-sheet", args=[group.pk]), samesite="Strict"
        )
    return response


# -- Join code, robots, worlds ---------------------------------------------------------------


@teacher_required
@require_POST
def class_join_code(request: HttpRequest, group_id: int) -> HttpResponse:
    """Turn the class's join code on (a class made elsewhere gets its Classroom row now), off,
    or make a new one (the old stops working)."""
    group = get_class_for_teacher(request.user, group_id)
    action = request.POST.get("action")
    if action not in ("on", "off", "new"):
        raise Http404(_("No such action."))
    with transaction.atomic():
        classroom, _created = Classroom.objects.select_for_update().get_or_create(
            group=group, defaults={"created_by": request.user}
        )
        for _attempt in range(5):
            classroom.join_code = None if action == "off" else free_join_code()
            try:
                with transaction.atomic():
                    classroom.save(update_fields=["join_code"])
                break
            except IntegrityError:  # another class took the same code meanwhile
                continue
    if action == "off":
        messages.success(request, _("Joining by code is off."))
    else:
        messages.success(request, _("The join code is %(code)s.") % {"code": classroom.join_code})
    return redirect(reverse("class-detail", args=[group.pk]) + "#join")


def _may_give(user, robot: Robot) -> bool:
    """Who looks after a robot (its owner, staff) gives it to a class; a teacher also gives
    one of their classes' robots to their other classes. A robot of no class is everyone's:
    only who looks after it makes it a class's."""
    if robot.configurable_by(user):
        return True
    return robot.groups.filter(teachers__user=user).exists()


@teacher_required
@require_POST
def class_robots(request: HttpRequest, group_id: int) -> HttpResponse:
    group = get_class_for_teacher(request.user, group_id)
    name, action = request.POST.get("robot", ""), request.POST.get("action")
    robot = None
    if not names.problem(name):  # none is named so, and PostgreSQL cannot look for NUL
        robot = robots_for_user(request.user).filter(name=name, personal=False).first()
    back = redirect(reverse("class-detail", args=[group.pk]) + "#robots")
    if robot is None or action not in ("give", "take"):
        messages.error(request, _("No robot named %(name)s.") % {"name": repr(name)})
        return back
    if action == "give":
        if not _may_give(request.user, robot):
            messages.error(
                request,
                _(
                    "%(robot)s is not yours to give: its owner or staff give it to a class,"
                    " or a teacher of one of its classes."
                )
                % {"robot": robot.name},
            )
            return back
        robot.groups.add(group)
        messages.success(
            request,
            _("%(robot)s is %(name)s's: its students may use it.")
            % {"robot": robot.name, "name": group.name},
        )
        return back
    others = robot.groups.exclude(pk=group.pk)
    if not others.exists() and not robot.configurable_by(request.user):
        messages.error(
            request,
            _(
                "%(robot)s has no other class: without one it would be everyone's. Its owner"
                " or staff may do that."
            )
            % {"robot": robot.name},
        )
        return back
    robot.groups.remove(group)
    if others.exists():
        messages.success(
            request,
            _("%(robot)s is no longer %(name)s's.") % {"robot": robot.name, "name": group.name},
        )
    else:
        messages.warning(
            request,
            _("%(robot)s is no longer %(name)s's: it has no class now, so everyone may use it.")
            % {"robot": robot.name, "name": group.name},
        )
    return back


@teacher_required
@require_POST
def class_worlds(request: HttpRequest, group_id: int) -> HttpResponse:
    """Share one of the teacher's worlds with the class, or take the share back."""
    group = get_class_for_teacher(request.user, group_id)
    back = redirect(reverse("class-detail", args=[group.pk]) + "#worlds")
    world = get_world_for_user(request.user, request.POST.get("world"), OWN)
    if request.POST.get("action") == "unshare":
        share = WorldShare.objects.filter(world=world, group=group).first()
        if share is not None:
            remove_share(world, share)
        messages.success(
            request,
            _("%(world)s is no longer shared with %(name)s.")
            % {"world": world.title or world.name, "name": group.name},
        )
        return back
    try:
        add_share(world, request.user, group=group.name)
    except ShareError as exc:
        messages.error(request, _("Not shared: %(why)s.") % {"why": exc})
    else:
        messages.success(
            request,
            _("%(world)s is shared with %(name)s: its students see it and may put their sims"
              " in it.") % {"world": world.title or world.name, "name": group.name},
        )  # fmt: skip
    return back


# -- A student -------------------------------------------------------------------------------


def _get_student(group: Group, user_id):
    student = group.user_set.filter(pk=user_id).first()
    if student is None:
        raise Http404(_("No such student in this class."))
    return student


def untouched_examples(programs) -> set[int]:
    """Of ``programs``, the examples their owner got with the account and never touched (as
    programs.signals decides it: one revision, the example's text, never run, shared,
    drafted, copied or given a button)."""
    from programs.models import Draft, Revision, Share
    from programs.signals import EXAMPLES, example_name, example_source
    from robots.models import RobotButton

    names = {
        example_name(filename, code): (filename, code)
        for filename in EXAMPLES
        for code, _label in settings.LANGUAGES
    }  # every example's name in every language: (file, language)
    candidates = {p.pk: p for p in programs if p.name in names and not p.origin}
    if not candidates:
        return set()
    ids = list(candidates)
    touched = set(Run.objects.filter(program__in=ids).values_list("program", flat=True))
    touched |= set(Share.objects.filter(program__in=ids).values_list("program", flat=True))
    touched |= set(Draft.objects.filter(program__in=ids).values_list("program", flat=True))
    touched |= set(RobotButton.objects.filter(program__in=ids).values_list("program", flat=True))
    revisions: dict[int, list[str]] = {}
    for program_id, source in Revision.objects.filter(program__in=ids).values_list(
        "program", "source"
    ):
        revisions.setdefault(program_id, []).append(source)
    untouched = set()
    for pk, program in candidates.items():
        if pk in touched:
            continue
        source = example_source(*names[program.name])
        if program.source == source and revisions.get(pk) == [source]:
            untouched.add(pk)
    return untouched


@teacher_required
def student_detail(request: HttpRequest, group_id: int, user_id: int) -> HttpResponse:
    """A student's programs (filtered), runs and sims: what the teacher may open of them."""
    group = get_class_for_teacher(request.user, group_id)
    student = _get_student(group, user_id)
    viewer = request.user
    exercises = exercises_for_user(viewer).filter(group=group).order_by("due", "title")
    form = StudentFilterForm(request.GET or None, exercises=exercises)
    since = exercise = None
    examples = False
    if form.is_valid():
        since, exercise = form.cleaned_data["since"], form.cleaned_data["exercise"]
        examples = form.cleaned_data["examples"]
    programs = programs_for_user(viewer).filter(owner=student).order_by("-updated", "name")
    runs = runs_for_user(viewer).filter(owner=student).order_by("-created", "-pk")
    if since is not None:
        start = timezone.make_aware(datetime.combine(since, time.min))
        programs = programs.filter(updated__gte=start)
        runs = runs.filter(created__gte=start)
    if exercise is not None:
        works = Work.objects.filter(exercise_id=exercise, student=student).values("program")
        programs = programs.filter(pk__in=works)
        runs = runs.filter(program__in=works)
    programs = list(programs.annotate(run_count=Count("runs"), last_run=Max("runs__created")))
    hidden = set() if examples or exercise is not None else untouched_examples(programs)
    work_of = dict(
        Work.objects.filter(student=student, program__in=[p.pk for p in programs]).values_list(
            "program", "exercise__title"
        )
    )
    for program in programs:
        program.exercise_title = work_of.get(program.pk, "")
    sims = (
        robots_for_user(viewer)
        .filter(personal=True, owner=student, checking=False)
        .order_by("name")
    )
    context = {
        "group": group,
        "student": student,
        "form": form,
        "programs": [p for p in programs if p.pk not in hidden],
        "hidden_examples": len(hidden),
        "runs": runs[:RUNS_SHOWN],
        "sims": sims,
        "one_time": OneTimePassword.objects.filter(user=student).exists(),
        "local": _local_student(student),
        "filtered": bool(since or exercise),
        # Staff who do not teach the class see only what is theirs to open (shared with them).
        "partial": not viewer.is_superuser
        and not ClassTeacher.objects.filter(group=group, user=viewer).exists(),
    }
    return render(request, "classroom/class_student.html", context)


# -- Sign-up with a join code ----------------------------------------------------------------


def _wait_words(seconds: int) -> str:
    if seconds < 60:
        wait = ngettext("%(count)d second", "%(count)d seconds", seconds) % {"count": seconds}
    else:
        minutes = math.ceil(seconds / 60)
        wait = ngettext("%(count)d minute", "%(count)d minutes", minutes) % {"count": minutes}
    return _("Too many wrong join codes; try again in %(wait)s.") % {"wait": wait}


def _classroom_for_code(request, form, code: str, who: str) -> Classroom | None:
    """The class whose join code ``code`` is; None with the form's error else. Wrong codes
    count as failed sign-ins do (robotide.security), per (typed username, address) and per
    address: while locked, no code is even looked at."""
    key = JOIN_THROTTLE_PREFIX + who
    if wait := locked_for(request, key):
        form.add_error("code", _wait_words(wait))
        return None
    found = (
        Classroom.objects.select_related("group").filter(join_code=code).first() if code else None
    )
    if found is None:
        record_failure(request, key)
        form.add_error(
            "code",
            _("No class has this join code. Check it with your teacher (it may have been"
              " turned off or changed)."),
        )  # fmt: skip
    return found


@never_cache
@sensitive_post_parameters("password1", "password2")
def join(request: HttpRequest) -> HttpResponse:
    """A new account in the class whose join code is typed, signed in at once; someone signed
    in joins the class with their account."""
    signed_in = request.user.is_authenticated
    form_class = JoinSignedInForm if signed_in else JoinForm
    form = form_class(request.POST or None)
    if request.method == "POST" and form.is_valid():
        who = request.user.username if signed_in else form.cleaned_data["username"]
        classroom = _classroom_for_code(request, form, form.cleaned_data["code"], who)
        if classroom is not None:
            group = classroom.group
            if signed_in:
                user = request.user
                if user.is_staff or user.is_superuser or user.teaching.exists():
                    form.add_error(
                        "code",
                        _("A teacher's or staff account cannot join a class as a student."),
                    )
                else:
                    request.user.groups.add(group)
                    messages.success(request, _("You are in %(name)s.") % {"name": group.name})
                    return redirect("home")
            else:
                try:
                    with transaction.atomic():
                        user = form.save()
                        user.groups.add(group)
                except IntegrityError:
                    form.add_error("username", _("This username was taken meanwhile."))
                else:
                    login(request, user, backend=settings.AUTHENTICATION_BACKENDS[0])
                    messages.success(
                        request,
                        _("Welcome, %(name)s: you are in %(class)s.")
                        % {"name": user.get_full_name() or user.username, "class": group.name},
                    )
                    return redirect("home")
    status = 400 if request.method == "POST" else 200
    return render(request, "registration/join.html", {"form": form}, status=status)
