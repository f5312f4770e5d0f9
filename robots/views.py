import threading

from django.contrib import messages
from django.contrib.admin.views.decorators import staff_member_required
from django.contrib.auth.decorators import login_required
from django.core.exceptions import PermissionDenied
from django.http import Http404, HttpRequest, HttpResponse, JsonResponse
from django.shortcuts import get_object_or_404, redirect, render
from django.utils.translation import gettext as _
from django.utils.translation import ngettext
from django.views.decorators.http import require_POST

from programs.access import get_program_for_user, programs_for_user, runs_for_user
from programs.models import Run, in_line
from robotide.redirects import back
from robotide.security import plain_number
from robots import disclosure, fair_shares, gateway_views, run_queue, sims, stops
from robots.availability import no_robot_reason
from robots.bus import AgentUnavailable, ask_agent_sync, reconfigure_sync
from robots.camera import has_camera
from robots.driver_settings import current_values
from robots.forms import ButtonForm, RobotConfigForm
from robots.models import RobotButton, RobotStop, get_robot_for_user, robots_for_user
from robots.readings import seen_by, sensor_rows, show_items, status
from robots.reset import may_reset, setting_row
from robots.runs import RunRefused, start_run

SNAPSHOT_TIMEOUT = 1.0
CAMERA_ASKS = threading.BoundedSemaphore(2)


@login_required
def robot_list(request: HttpRequest) -> HttpResponse:
    robots = list(robots_for_user(request.user))
    for robot in robots:  # its driver alone, but to its owner and staff
        robot.url_shown = disclosure.url_shown(request.user, robot)
    context = {"robots": robots, "no_robot": no_robot_reason(request.user, robots)}
    return render(request, "robots/list.html", context)


@login_required
def robot_detail(request: HttpRequest, name: str) -> HttpResponse:
    robot = get_robot_for_user(request.user, name)
    sims.touch(robot)  # a personal sim watched is in use
    context = {
        "robot": robot,
        "buttons": robot.buttons.all(),
        "can_configure": robot.configurable_by(request.user),
        "url_shown": disclosure.url_shown(request.user, robot),
        "sees_setup": disclosure.sees_setup(request.user, robot),
        # runbox's line (cgroup paths and names) for its owner and staff; a sentence for others.
        "isolation_line": disclosure.isolation_line(request.user, robot),
        # Its settings' values (device paths, hosts...) for its owner and staff only.
        "options": current_values(robot) if disclosure.sees_setup(request.user, robot) else [],
        "start_each_run": setting_row(robot),  # a sim's run setting (robots.reset)
        "running": runs_for_user(request.user).filter(robot=robot, state__in=Run.ACTIVE),
        "programs": programs_for_user(request.user),
        **queue_context(request.user, robot),
        **stop_context(request.user, robot),
        **robot_state_context(robot, request.user),
    }
    # The gateway card once, server-side; it then reloads itself (robots/_gateway.html).
    context["gateway"] = gateway_views.gateway_context(robot, away="agent_error" in context)
    return render(request, "robots/detail.html", context)


def robot_state_context(robot, user) -> dict:
    """The robot's state now, so a page is whole before (or without) its websocket; of the
    values programs show, those ``user`` sees (robots.readings.shows_seen)."""
    context = {"robot": robot}
    try:
        state = ask_agent_sync(robot.name, "robot.state", timeout=SNAPSHOT_TIMEOUT)
    except AgentUnavailable as exc:
        context["agent_error"] = str(exc)
        return context
    return {
        **context,
        **status(state["sensors"], state["units"]),
        "rows": sensor_rows(state["sensors"], state["units"]),
        "camera": has_camera(robot, state),
        # A sim is drawn by the page itself (simview.js); its JPEG only without scripts.
        "sim": state.get("sim"),
        "holder": state["lease"],
        "drive": state["drive"],
        "model": state.get("model"),
        "heard": state.get("heard"),  # what the last listen() heard (robots/_say.html)
        # A Reset (robots/_reset.html) for a robot that can be reset, to whoever may drive it.
        "may_reset": bool(state.get("resettable")) and may_reset(user, robot),
        "shows": show_items(seen_by(user, state["shows"])),
    }


def stop_context(user, robot) -> dict:
    """Its emergency stop in force, if any; who may press and resume it; its recent ones."""
    return {
        **stops.banner_context(user, robot),  # pressed, may_resume, held_runs, who_resumes
        "may_estop": robot.stoppable_by(user),
        "may_drive": robot.drivable_by(user),
        "stops": stops.recent(robot),
    }


def queue_context(user, robot) -> dict:
    """The robot's queue for robots/_running.html: rows as ``user`` may see them."""
    return {
        "robot": robot,
        "queue": run_queue.queue_rows(user, robot),
        "queue_held": run_queue.held(robot),
        "queue_pressed": RobotStop.pressed(robot.pk) is not None,
        "who_resumes": stops.WHO_RESUMES,
        "can_manage_queue": run_queue.may_manage(user, robot),
        "shares": fair_shares.in_force(user, robot),
    }


@login_required
def robot_queue(request: HttpRequest, name: str) -> HttpResponse:
    """The queue's part of the "Running here" card; the robot page reloads it on each change."""
    robot = get_robot_for_user(request.user, name)
    context = {**queue_context(request.user, robot), "queue_only": True}
    return render(request, "robots/_running.html", context)


@login_required
@require_POST
def robot_queue_move(request: HttpRequest, name: str) -> HttpResponse:
    """Staff or the robot's owner put a waiting run at another place in line."""
    robot = get_robot_for_user(request.user, name)
    run = get_object_or_404(Run, pk=_number(request.POST.get("run")), robot=robot)
    try:
        rank = run_queue.move(request.user, run, _number(request.POST.get("to")) or 1)
    except run_queue.NotQueued as exc:
        return _queue_outcome(request, robot, error=str(exc))
    info = _("Run #%(id)s is now %(place)s.") % {"id": run.pk, "place": in_line(rank)}
    return _queue_outcome(request, robot, info=info)


@login_required
@require_POST
def robot_queue_resume(request: HttpRequest, name: str) -> HttpResponse:
    """After an emergency stop was resumed, staff or the robot's owner start every run it
    held, or the one run ``run``; a held run's owner starts theirs (robots.stops.start_again)."""
    robot = get_robot_for_user(request.user, name)
    run = None
    if request.POST.get("run"):
        run = get_object_or_404(Run, pk=_number(request.POST.get("run")), robot=robot)
    try:
        count = stops.start_again(request.user, robot, run)
    except stops.StillPressed as exc:
        if request.htmx:  # said beside the run page's button
            return HttpResponse(str(exc))
        return _queue_outcome(request, robot, error=str(exc))
    info = ngettext(
        "%(count)s held run waits to start again.",
        "%(count)s held runs wait to start again.",
        count,
    ) % {"count": count}
    return _queue_outcome(request, robot, info=info)


def _queue_outcome(request, robot, info: str = "", error: str = "") -> HttpResponse:
    if request.htmx:  # the page hears of the change on its websocket
        return HttpResponse(error, status=409) if error else HttpResponse(status=204)
    if error:
        messages.error(request, error)
    else:
        messages.info(request, info)
    return back(request, "robot-detail", robot.name)


def _number(value) -> int | None:
    try:
        return int(value)
    except (TypeError, ValueError):
        return None


@login_required
def robot_buttons(request: HttpRequest, name: str) -> HttpResponse:
    """The robot's owner or staff set up its manual commands."""
    robot = get_robot_for_user(request.user, name)
    if not robot.configurable_by(request.user):
        raise PermissionDenied(_("Only the robot's owner or staff set up its buttons."))
    button = None
    if "edit" in request.GET:
        number = plain_number(request.GET["edit"])
        if number is None:
            raise Http404
        button = get_object_or_404(RobotButton, robot=robot, pk=number)
    form = ButtonForm(request.POST or None, instance=button, user=request.user, robot=robot)
    if request.method == "POST" and form.is_valid():
        saved = form.save()
        messages.success(request, _("Button %(label)s saved.") % {"label": repr(saved.label)})
        return redirect("robot-buttons", robot.name)
    context = {"robot": robot, "form": form, "buttons": robot.buttons.select_related("program")}
    return render(request, "robots/buttons.html", context)


@login_required
@require_POST
def robot_button_delete(request: HttpRequest, name: str, button_id: int) -> HttpResponse:
    robot = get_robot_for_user(request.user, name)
    if not robot.configurable_by(request.user):
        raise PermissionDenied(_("Only the robot's owner or staff set up its buttons."))
    button = get_object_or_404(RobotButton, robot=robot, pk=button_id)
    button.delete()
    messages.success(request, _("Button %(label)s removed.") % {"label": repr(button.label)})
    return redirect("robot-buttons", robot.name)


@login_required
@require_POST
def robot_button_press(request: HttpRequest, name: str, button_id: int) -> HttpResponse:
    """One click: the button's program runs on the robot, as the person who clicked."""
    robot = get_robot_for_user(request.user, name)
    button = get_object_or_404(RobotButton, robot=robot, pk=button_id)
    try:
        run = start_run(button.program, robot, request.user, button.args)
    except RunRefused as exc:
        outcome = {"error": str(exc)}
    else:
        outcome = {"run": run, "button": button}
    if request.htmx:
        return render(request, "robots/_button_outcome.html", outcome)
    if "error" in outcome:
        messages.error(request, outcome["error"])
    else:
        messages.success(
            request,
            _("%(label)s: run #%(id)s sent to the robot.") % {"label": button.label, "id": run.pk},
        )
    return redirect("robot-detail", robot.name)


@staff_member_required
def robot_settings(request: HttpRequest, name: str) -> HttpResponse:
    """Staff edit the robot's URL and driver options; its agent reopens the robot with them."""
    robot = get_robot_for_user(request.user, name)
    form = RobotConfigForm(request.POST or None, instance=robot)
    if request.method == "POST" and form.is_valid():
        form.save()
        reconfigure_sync(robot.name)
        if form.driver_changed:
            messages.info(request, _("Another driver: its options start from their defaults."))
            return redirect("robot-settings", robot.name)
        messages.success(
            request, _("Settings saved; %(robot)s is reopened with them.") % {"robot": robot.name}
        )
        return redirect("robot-detail", robot.name)
    return render(request, "robots/settings.html", {"robot": robot, "form": form})


@login_required
@require_POST
def robot_estop(request: HttpRequest, name: str) -> HttpResponse:
    robot = get_robot_for_user(request.user, name)
    via = "the workbench" if request.POST.get("via") == "workbench" else "the robot's page"
    try:
        record = stops.press(request.user, robot, via)
    except PermissionDenied as exc:
        if request.htmx:  # the workbench says why on the page
            return HttpResponse(str(exc), status=403)
        raise
    except AgentUnavailable as exc:
        level, text = (
            messages.ERROR,
            _("%(why)s The press is recorded; the robot's own stop is not sure.") % {"why": exc},
        )
    else:
        level, text = (
            messages.WARNING,
            ngettext(
                "Emergency stop: %(robot)s stopped, %(count)s program(s) ended."
                " Nothing moves it until it is resumed.",
                "Emergency stop: %(robot)s stopped, %(count)s program(s) ended."
                " Nothing moves it until it is resumed.",
                len(record.runs),
            )
            % {"robot": robot.name, "count": len(record.runs)},
        )
    if request.htmx:  # the workbench: it stays where it is and says so
        return HttpResponse(text, status=503 if level == messages.ERROR else 200)
    messages.add_message(request, level, text)
    return redirect("robot-detail", robot.name)


@login_required
@require_POST
def robot_resume(request: HttpRequest, name: str) -> HttpResponse:
    robot = get_robot_for_user(request.user, name)
    start_held = request.POST.get("start_held") == "1"
    workbench = request.htmx or request.POST.get("via") == "workbench"
    via = "the workbench" if workbench else "the robot's page"
    count = stops.resume(request.user, robot, via, start_held=start_held)
    if start_held or not count:
        said = ngettext(
            "%(robot)s may move again (%(count)s run(s) waiting).",
            "%(robot)s may move again (%(count)s run(s) waiting).",
            count,
        )
    else:
        said = ngettext(
            "%(robot)s may move again; %(count)s run waits, held, until started again.",
            "%(robot)s may move again; %(count)s runs wait, held, until started again.",
            count,
        )
    said %= {"robot": robot.name, "count": count}
    if request.htmx:  # the workbench's panel: its banner clears on the robot's websocket
        return HttpResponse(said)
    messages.info(request, said)
    return redirect("robot-detail", robot.name)


@login_required
@require_POST
def robot_run(request: HttpRequest, name: str) -> HttpResponse:
    robot = get_robot_for_user(request.user, name)
    program = get_program_for_user(request.user, request.POST.get("program"))
    try:
        run = start_run(program, robot, request.user)
    except (RunRefused, PermissionDenied) as exc:
        messages.error(request, str(exc))
        return redirect("robot-detail", robot.name)
    return redirect("run-detail", run.pk)


@login_required
def robot_world(request: HttpRequest, name: str) -> HttpResponse:
    """A sim's world, its robot and its time scale, for the page that draws it
    (static/robotide/simview.js; robots.sim_view): to whoever may see the robot."""
    robot = get_robot_for_user(request.user, name)
    try:
        answer = ask_agent_sync(robot.name, "robot.world", timeout=SNAPSHOT_TIMEOUT)
    except AgentUnavailable as exc:  # away, or no sim (a real robot has no world)
        return JsonResponse({"error": str(exc)}, status=503)
    answer.pop("type", None)
    response = JsonResponse(answer)
    response["Cache-Control"] = "no-store"
    return response


@login_required
def robot_camera(request: HttpRequest, name: str) -> HttpResponse:
    robot = get_robot_for_user(request.user, name)
    # Each frame holds a web worker while the agent renders it: never all of them.
    if not CAMERA_ASKS.acquire(blocking=False):
        return HttpResponse(_("camera busy; try again"), status=503, content_type="text/plain")
    try:
        jpeg = ask_agent_sync(robot.name, "camera.snapshot", timeout=SNAPSHOT_TIMEOUT)["jpeg"]
    except AgentUnavailable as exc:
        return HttpResponse(str(exc), status=503, content_type="text/plain")
    finally:
        CAMERA_ASKS.release()
    response = HttpResponse(jpeg, content_type="image/jpeg")
    response["Cache-Control"] = "no-store"
    return response
