"""A run's page (templates/runs/detail.html): its output so far, each error line that points
into the program a link to that line of the program as it ran (listed on the page, so the link
works without scripts and for a program edited since), and the robot beside the output while
the run goes on (the workbench's robot panel)."""

from django.http import Http404
from django.urls import reverse

from programs.runlog import places_in, read_for_page, render_lines
from robots.models import get_robot_for_user
from robots.views import robot_state_context


def run_page_context(request, run) -> dict:
    lines, skipped, offset = read_for_page(run)
    # Blocks run as Python made of them: their errors' lines are that Python's (the workbench
    # finds the block), not lines of what the user edits: none listed or linked.
    source = [] if run.language == "blocks" else run.source.splitlines()
    return {
        "run": run,
        "log_html": render_lines(lines, places_in(run), link=line_link(len(source))),
        "skipped": skipped,
        "offset": offset,
        "source_lines": source,
        **robot_view(request, run),
    }


def line_link(count: int):
    """The link of an error line to line N of the listing: ``#line-N``; none for a line the
    listing does not have (an old run's, saved without its source)."""
    return lambda line: f"#line-{line}" if 1 <= line <= count else None


def robot_view(request, run) -> dict:
    """Whether the page shows the robot (camera or the sim's drawing, readings, shown values):
    while the run is not over, to a viewer who may see the robot (not a teacher's student's
    run on another class's robot). The panel itself is fetched once the page is shown
    (robot_panel_context): the run's page never waits for the robot's agent."""
    robot = _robot_seen(request, run)
    return {} if robot is None else {"robot_view": True, "robot": robot}


def robot_panel_context(request, run) -> dict | None:
    """The run page's robot panel (programs/_panel.html), asked of the robot's agent; None
    once the run is over or for a viewer who may not see the robot."""
    robot = _robot_seen(request, run)
    if robot is None:
        return None
    # say_next: the panel's "Say to the robot" form comes back to the run's page without scripts.
    say_next = reverse("run-detail", args=[run.pk])
    return {"say_next": say_next, **robot_state_context(robot, request.user)}


def _robot_seen(request, run):
    if not run.ongoing:
        return None
    try:
        return get_robot_for_user(request.user, run.robot.name)
    except Http404:
        return None
