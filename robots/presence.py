"""Which robots are online, in fleet mode: an agent's heartbeat (Robot.last_seen) says so.

The web tier watches: runs held by an agent that has gone silent are marked ``lost`` within
AGENT_OFFLINE_AFTER seconds (nothing supervises them any more), and the pages hear of it. A run
no agent has taken yet (its robot just added, its agent still starting) is not lost: it waits,
and is failed if no agent takes it within AGENT_START_TIMEOUT. Every web worker may watch; the
update is conditional, so each run is marked once. An agent that comes back serves again as
soon as its first heartbeat lands.

Runs waiting in a robot's queue (``queued``, robots.run_queue) are not lost with a silent
agent: they never started, so nothing of theirs went unsupervised. They stay in line and the
agent serves them when it is back; their owners may cancel them meanwhile (that needs no agent).
"""

from __future__ import annotations

import asyncio
import logging
from datetime import timedelta

from channels.db import database_sync_to_async
from django.conf import settings
from django.db.models import Q
from django.utils import timezone

from programs.models import Run
from robots.bus import tell_run_changed

log = logging.getLogger(__name__)


def silent_since() -> timezone.datetime:
    return timezone.now() - timedelta(seconds=settings.AGENT_OFFLINE_AFTER)


# A run an agent holds: claimed by it (Run.claim sets its pid). One asked of a robot whose agent
# is still starting, or has not taken it yet, is not: nothing of it ran, so nothing went
# unsupervised; it waits for the agent, and sweep_unclaimed fails it if none takes it.
HELD = Q(state=Run.State.RUNNING) | Q(state=Run.State.STARTING, pid__isnull=False)


def sweep_lost() -> list[tuple[int, str]]:
    """Mark lost the runs held by agents that went silent: (run id, robot name) of each."""
    cutoff = silent_since()
    silent = Q(robot__last_seen__lt=cutoff) | Q(robot__last_seen__isnull=True)
    # Not those waiting in the robot's queue, nor those no agent has taken yet.
    candidates = Run.objects.filter(silent, HELD, created__lt=cutoff)
    lost = []
    for run_id, robot_name in candidates.values_list("pk", "robot__name"):
        updated = Run.objects.filter(HELD, pk=run_id).update(
            state=Run.State.LOST,
            reason=f"the agent of robot {robot_name!r} stopped answering",
            ended=timezone.now(),
        )
        if updated:
            lost.append((run_id, robot_name))
    Run.tell_ended([run_id for run_id, _ in lost])
    return lost


def sweep_unclaimed(seen: dict[int, float], now: float) -> list[tuple[int, str]]:
    """Fail the runs an online agent has not taken for AGENT_START_TIMEOUT: their run.start
    was lost (the channel layer delivers to whoever listens: an agent restarting missed it).

    ``seen``: run id -> when a sweep first found it waiting to be taken (kept by the caller),
    so a run that just left its robot's queue, and is being taken, is not failed by mistake.
    """
    waiting = dict(
        Run.objects.filter(state=Run.State.STARTING, pid__isnull=True).values_list(
            "pk", "robot__name"
        )
    )
    for run_id in list(seen):
        if run_id not in waiting:
            del seen[run_id]
    failed = []
    for run_id, robot_name in waiting.items():
        first = seen.setdefault(run_id, now)
        if now - first < settings.AGENT_START_TIMEOUT:
            continue
        why = f"could not start: the agent of robot {robot_name!r} did not take it; run it again"
        updated = Run.objects.filter(pk=run_id, state=Run.State.STARTING, pid__isnull=True).update(
            state=Run.State.FAILED, reason=why, ended=timezone.now()
        )
        if updated:
            failed.append((run_id, robot_name))
        del seen[run_id]
    Run.tell_ended([run_id for run_id, _ in failed])
    return failed


async def watch() -> None:
    """Until cancelled: sweep every heartbeat period, and tell the pages of runs lost."""
    unclaimed: dict[int, float] = {}
    while True:
        try:
            ended = await database_sync_to_async(sweep_lost)()
            for run_id, robot in ended:
                log.warning("run %s lost: the agent of robot %s stopped answering", run_id, robot)
            loop_time = asyncio.get_running_loop().time()
            failed = await database_sync_to_async(sweep_unclaimed)(unclaimed, loop_time)
            for run_id, robot in failed:
                log.warning("run %s failed: the agent of robot %s did not take it", run_id, robot)
            for run_id, robot in ended + failed:
                await tell_run_changed(run_id, robot)
        except Exception:  # the database or Redis away for a moment: try again next time
            log.exception("presence watch failed")
        await asyncio.sleep(settings.AGENT_HEARTBEAT)
