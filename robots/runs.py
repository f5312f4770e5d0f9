"""Handing runs to robots: a run is data (programs.models); starting and stopping one is a
message to its robot's agent, or a step of the robot's queue."""

import logging

from channels.db import database_sync_to_async
from channels.exceptions import ChannelFull
from django.core.exceptions import PermissionDenied
from django.db import transaction
from django.utils.translation import gettext as _

from programs import debug_spec
from programs.models import Program, Run
from robots import run_queue
from robots.bus import begin_soon, console_group, hand_over_run, tell_agent_sync, tell_run_changed
from robots.models import Robot

log = logging.getLogger(__name__)


def start_run(
    program: Program, robot: Robot, user, args=(), source: str | None = None,
    debug: dict | None = None,
) -> Run:  # fmt: skip
    """Create the run and hand it to the robot's agent (which owns the process).
    PermissionDenied if `user` may see the robot but not drive it. ``source``: what runs, if
    not the program as saved (an exercise attempt's checked revision). ``debug``: run it under
    the debugger with these breakpoints and watches (programs.debug_spec; ValueError if bad,
    RunRefused if its language has no debugger)."""
    if not robot.drivable_by(user):
        raise PermissionDenied(
            _("Only %(who)s may run programs on %(robot)s.")
            % {"who": robot.get_drive_by_display(), "robot": robot.name}
        )
    if not robot.runs_programs_of(user):  # a personal sim: nobody queues for its owner's
        raise PermissionDenied(
            _("Only its owner runs programs on %(robot)s, a personal sim; make one of your own.")
            % {"robot": robot.name}
        )
    language = program.lang
    if not language.available:
        raise RunRefused(
            _("%(language)s is not available on this robot computer (%(install)s).")
            % {"language": language.label, "install": language.install_hint}
        )
    if debug is not None:
        if (why := debug_spec.check_spec(debug)) is not None:
            raise ValueError(f"debugger: {why}")
        if not language.debuggable:
            raise RunRefused(
                _("%(language)s programs cannot run under the debugger yet.")
                % {"language": language.label}
            )
    run = Run.create_for(program, robot, user, args, source=source, debug=debug)
    message = {
        "run_id": run.pk,
        "language": run.language,
        "source": run.source,
        "filename": program.filename,
        "args": [str(a) for a in args],
        "user": user.get_username(),
        **({"debug": debug} if debug is not None else {}),
    }
    transaction.on_commit(lambda: _hand_to_agent(run, message))
    return run


def _hand_to_agent(run: Run, message: dict) -> None:
    # Not waited for: the response is made while the loop hands the run over and its agent
    # starts it (a start's first line came after the view's wait for the loop, before).
    begin_soon(_hand_over, run, message)


async def _hand_over(run: Run, message: dict) -> None:
    """The run to its agent and its owner's consoles; one that cannot be handed over has
    failed, and its viewers are told."""
    robot = run.robot.name
    try:
        await hand_over_run(robot, message, console_group(run.program_id, run.owner_id))
        return
    except ChannelFull:
        # Nobody has taken the robot's commands for a long while: say so instead of waiting.
        why = f"the agent of robot {robot!r} is not taking commands"
    except Exception as exc:  # the channel layer itself is away (Redis down)
        why = f"the robot's agent cannot be reached ({type(exc).__name__})"
    try:
        await database_sync_to_async(fail_to_start)(run, why)
        await tell_run_changed(run.pk, robot)
    except Exception:
        log.exception("run %s could not start (%s), and could not be marked so", run.pk, why)


def fail_to_start(run: Run, why: str) -> None:
    Run.mark_ended(run.pk, Run.State.FAILED, None, f"could not start: {why}")
    run.refresh_from_db()


def request_stop(run: Run) -> None:
    """Stop a run: a queued one is cancelled here (its agent need not be reachable), an
    active one is stopped by its agent."""
    if run.queued:
        if run_queue.cancel(run):
            return
        run.refresh_from_db()  # it started meanwhile: stop it as any other
    if run.active:
        try:
            tell_agent_sync(run.robot.name, "run.stop", run_id=run.pk)
        except Exception as exc:  # ChannelFull, or the channel layer away
            raise AgentUnreachable(
                _(
                    "the agent of robot %(robot)s cannot be reached to stop it (%(why)s); the"
                    " emergency stop or its agent's restart will stop it"
                )
                % {"robot": repr(run.robot.name), "why": type(exc).__name__}
            ) from exc


class RunRefused(Exception):
    pass


class AgentUnreachable(Exception):
    pass
