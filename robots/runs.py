"""Handing runs to robots: a run is data (programs.models); starting and stopping one is a
message to its robot's agent, or a step of the robot's queue."""

from channels.exceptions import ChannelFull
from django.core.exceptions import PermissionDenied
from django.db import transaction
from django.utils.translation import gettext as _

from programs.models import Program, Run
from robots import run_queue
from robots.bus import console_group, hand_over_run_sync, tell_agent_sync
from robots.models import Robot


def start_run(program: Program, robot: Robot, user, args=()) -> Run:
    """Create the run and hand it to the robot's agent (which owns the process).
    PermissionDenied if `user` may see the robot but not drive it."""
    if not robot.drivable_by(user):
        raise PermissionDenied(
            _("Only %(who)s may run programs on %(robot)s.")
            % {"who": robot.get_drive_by_display(), "robot": robot.name}
        )
    language = program.lang
    if not language.available:
        raise RunRefused(
            _("%(language)s is not available on this robot computer (%(install)s).")
            % {"language": language.label, "install": language.install_hint}
        )
    run = Run.create_for(program, robot, user, args)
    message = {
        "run_id": run.pk,
        "language": run.language,
        "source": run.source,
        "filename": program.filename,
        "args": [str(a) for a in args],
        "user": user.get_username(),
    }
    transaction.on_commit(lambda: _hand_to_agent(run, message))
    return run


def _hand_to_agent(run: Run, message: dict) -> None:
    try:
        hand_over_run_sync(run.robot.name, message, console_group(run.program_id, run.owner_id))
    except ChannelFull:
        # Nobody has taken the robot's commands for a long while: say so instead of waiting.
        fail_to_start(run, f"the agent of robot {run.robot.name!r} is not taking commands")
    except Exception as exc:  # the channel layer itself is away (Redis down)
        fail_to_start(run, f"the robot's agent cannot be reached ({type(exc).__name__})")


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
