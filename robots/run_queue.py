"""A robot's run queue: on a busy shared robot, a run waits its turn instead of fighting for it.

The robot is busy for someone while its control lease is held by *another* user: their
program, or them driving by hand. A run asked for then, or while others already wait, is
``queued``: its place is ``Run.queue_position``, the pages show "queued — 2nd in line". A
user's own program or hand driving does not make their next run wait (several programs of one
user run at once, a logger beside a driver, as before), nor does a serial bridge client: those
runs start, and drive() is refused naming the holder, as robots.lease and robots.bridges say.
When the lease is free again (a program ended, a person released it, left the page or left the
controls idle, a bridge client left, an emergency stop cleared it), the agent starts the first
in line and gives it the lease at once, so nobody slips in between.

A program that holds the lease while others wait has a turn of ``queue_turn_seconds`` (a robot
setting; ROBOTIDE_QUEUE_TURN_SECONDS, 300 s; 0: no limit), counted from when it took the lease
or from when the first other run began to wait, whichever is later; then it is stopped. A
person driving by hand has no turn limit (they are there, and the lease lets go of a person
idle for 30 s), nor has a bridge client.

The order is in the database: staff and the robot's owner reorder and cancel from the robot's
page or the API, a run's owner (or their teacher) cancels it with the stop action, all without
the agent; the agent is told, and reads the order when it starts the next.

An emergency stop *holds* the runs waiting then and those asked for until it is resumed (their
``reason`` is ``Run.HELD``, so the hold survives the agent's restart). Whatever made someone
press it is likely still there: a resume (staff, the robot's owner or whoever pressed it,
robots.stops) lets the robot move, but a held run stays in line, not started, until its owner
(or staff, or the robot's owner) starts it again, or the one who resumes chooses to start
them all then. A held run does not hold up the others, nor count as waiting. Queued runs
survive an agent that stops or goes silent (they never started: not ``lost``) and are served
when it is back; their owners may cancel them meanwhile.

Fair shares (robots.fair_shares) use the same line: a run beyond its owner's limit of runs
going at once, or its robot's, waits here too, its reason saying which ("waiting: you already
have 2 runs going (your limit is 2)"). It does not hold up the others: runs behind it start
when they may. It starts, without taking the lease, once a share is free and the robot is not
busy for its owner; a run that waited for the robot and finds its owner's share taken waits on
for the share. The agent looks again when a run of its own ends, when another agent says a run
of a waiting run's owner ended there, and every few seconds in case a word was lost.

The agent owns one ``RunQueue`` (its hooks: run.start, the lease changing, a run ending, the
emergency stop, shutdown); the functions below it are for the web tier.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math

from channels.db import database_sync_to_async
from channels.layers import get_channel_layer
from django.conf import settings
from django.core.exceptions import PermissionDenied
from django.http import Http404
from django.utils.translation import gettext as _

from programs.access import get_run_for_user, runs_for_user
from programs.models import Run, in_line
from robots import fair_shares
from robots.bus import RUNS_GROUP, blocking, run_group, send_to_agent, tell_agent_sync
from robots.lease import Holder, LeaseHeld
from robots.models import Robot, robot_group

log = logging.getLogger(__name__)

TICK = 0.25  # seconds between looks at the lease (a person gone idle) and the turn's end
SHARES_LOOK = 3.0  # seconds between looks at runs waiting for a share, if no word came
RETRY_DELAY = 1.0
HELD_REASONS = (Run.HELD, Run.HELD_BEFORE)  # a held run's reason (Run.held)
CHANGED, RESUME = "run.queue_changed", "run.queue_resume"  # RESUME: web tiers of old


def turn_seconds(robot_settings: dict) -> float:
    """A robot's turn length: its ``queue_turn_seconds``, else the default; 0 is no limit."""
    value = robot_settings.get("queue_turn_seconds", settings.QUEUE_TURN_SECONDS)
    try:
        value = float(value)
    except (TypeError, ValueError):
        log.error("queue_turn_seconds %r is not a number: the default is used", value)
        value = float(settings.QUEUE_TURN_SECONDS)
    return value if math.isfinite(value) and value > 0 else 0.0


class RunQueue:
    """The queue as one agent serves it: its decisions in memory, its order in the database."""

    def __init__(self, agent):
        self.agent = agent
        self.waiting = 0  # runs queued on this robot for the robot, as last counted
        self.sharing = 0  # runs queued on this robot for a share (fair_shares), as last counted
        self._look_at_shares = True  # something changed that may free a share
        self._shares_looked = -math.inf  # loop time of the last look
        self._box_cap_said: int | None | bool = False  # what the robot's row says (False: unsaid)
        self._counted = False  # whether the database has been asked since the agent started
        self.held = False  # an emergency stop in force: nothing starts until it is resumed
        # The lease-holding run's turn while others wait: (its run id, loop time it ends).
        self._turn: tuple[int | str, float] | None = None
        self._limit = 0.0
        self._wake = asyncio.Event()
        self._closing = False
        self._task: asyncio.Task | None = None
        self._marking: set[asyncio.Task] = set()  # tasks of the holds and cancels
        self._holding: asyncio.Task | None = None  # the last stop's marking of the held runs
        self.handlers = {CHANGED: self._changed, RESUME: self._resume}

    # -- hooks of the agent -----------------------------------------------------------------

    async def waits(self, message: dict) -> bool:
        """On run.start: True if the run was queued (or no longer waits to start at all),
        False if it starts now."""
        run_id = message["run_id"]
        if message.get("from_queue") or run_id in self.agent.cancelled:
            return False
        if not self._busy_for(message.get("user", "")) and not self.waiting and not self.held:
            # Only this agent queues runs, so once counted its count is an upper bound (the
            # web tier may cancel, never add): only before the first count is the database
            # asked. A start then costs one round trip: its share's (fair_shares.admit).
            if not self._counted:
                await self._count()
            if not self.waiting:
                return await self._waits_for_share(run_id)
        reason = Run.HELD if self.held or self.agent.lease.estopped else ""
        rank = await database_sync_to_async(Run.enqueue)(run_id, reason)
        if rank is None:  # stopped or failed before it was handled: nothing to queue
            return True
        if not reason:
            await self._held_if_stopped(run_id)
        if run_id in self.agent.cancelled:  # its stop came while it was being queued
            self.cancel(run_id)
        log.info("agent %s: run %s queued, %s in line", self.agent.name, run_id, rank)
        self._set_waiting(self.waiting + 1)
        self.agent._run_changed(run_id)
        self.wake()
        return True

    async def _waits_for_share(self, run_id: int) -> bool:
        """The robot is free for it: it starts if its owner's and the robot's shares allow."""
        decision = await database_sync_to_async(fair_shares.admit)(run_id, self.box_cap())
        if decision.outcome is fair_shares.Admission.ADMITTED:
            return False
        if decision.outcome is fair_shares.Admission.QUEUED:
            if run_id in self.agent.cancelled:  # its stop came while it was being queued
                self.cancel(run_id)
            await self._held_if_stopped(run_id)
            log.info(
                "agent %s: run %s %s, %s in line", self.agent.name, run_id, decision.reason,
                decision.rank,
            )  # fmt: skip
            self.sharing += 1
            self.agent._run_changed(run_id)
        return True

    async def _held_if_stopped(self, run_id: int) -> None:
        """A run queued as the emergency stop came (its hold's marking may have looked before
        it was in line) is held like the others."""
        if self.held or self.agent.lease.estopped:
            await database_sync_to_async(_hold_one)(run_id)

    def box_cap(self) -> int | None:
        """Runs the agent's isolation allows at once (runbox.isolation.InForce.runs_at_once,
        where it says; a rootless box without a run-wide cgroup: 1), None: no limit."""
        return getattr(getattr(self.agent, "isolation", None), "runs_at_once", None) or None

    def ended(self, run_id: int) -> None:
        """A run of this agent ended: a share is free; agents holding runs of its owner that
        wait for one look again."""
        self.wake()
        task = asyncio.create_task(self._tell_others(run_id))
        self._marking.add(task)
        task.add_done_callback(self._marking.discard)

    async def _tell_others(self, run_id: int) -> None:
        try:
            robots = await database_sync_to_async(fair_shares.robots_to_look_again)(run_id)
            for name in robots:
                await send_to_agent(name, CHANGED)
        except Exception:  # they look again on their own within SHARES_LOOK
            log.exception(
                "agent %s: could not tell other agents of run %s's end", self.agent.name, run_id
            )

    def cancel(self, run_id: int) -> None:
        """A stop for a run the agent does not run: if it waits in line, it is cancelled."""
        task = asyncio.create_task(self._cancel(run_id))
        self._marking.add(task)
        task.add_done_callback(self._marking.discard)

    async def _cancel(self, run_id: int) -> None:
        try:
            if not await database_sync_to_async(Run.cancel_queued)(run_id):
                return  # not queued (yet, or any more): the agent's own stop handles it
            self.agent.cancelled.discard(run_id)
            self.agent._run_changed(run_id)
            await self._ranks_changed()
            await self._count()
        except Exception:  # it stays in self.agent.cancelled: stopped when its turn comes
            log.exception("agent %s: could not cancel queued run %s", self.agent.name, run_id)

    def wake(self) -> None:
        """Something changed (the lease, the queue, a run ended): look again now."""
        self._look_at_shares = True
        self._wake.set()

    def hold(self) -> None:
        """An emergency stop: runs waiting now (for the robot or a share) are held, and stay
        queued until their owners start them again (the database is asked even if none wait
        as last counted: a count may be behind)."""
        self.held = True
        task = asyncio.create_task(self._mark_held())
        self._marking.add(task)
        task.add_done_callback(self._marking.discard)
        self._holding = task

    async def serve(self) -> None:
        """Until closed: start the next run whenever the robot is free, end turns that ran out."""
        self._task = asyncio.current_task()
        with contextlib.suppress(Exception):
            await self._count()
        while not self._closing:
            self._wake.clear()
            try:
                await self._step()
            except Exception:  # the database away for a moment: look again soon
                log.exception("agent %s: run queue failed", self.agent.name)
                await asyncio.sleep(RETRY_DELAY)
            with contextlib.suppress(TimeoutError):
                await asyncio.wait_for(self._wake.wait(), TICK)

    async def close(self) -> None:
        """Start nothing more (the agent is shutting down); a start under way finishes first,
        so the agent stops its program with the others."""
        self._closing = True
        self.wake()
        if self._task is not None and not self._task.done():
            await asyncio.wait({self._task}, timeout=10)

    # -- messages from the web tier ---------------------------------------------------------

    async def _changed(self, message: dict) -> None:
        await self._count()
        self.wake()

    async def _resume(self, message: dict) -> None:
        await self.resume()

    async def resume(self) -> None:
        """After an emergency stop: the runs not held may start again; the held ones (waiting
        at the press, or asked for since) wait until someone starts them again, which the web
        tier says with a CHANGED."""
        if self._holding is not None:  # a quick resume: the held runs are marked first
            await asyncio.wait({self._holding})
        self.held = False
        await self._count()
        self.wake()

    # -- the work ---------------------------------------------------------------------------

    def _busy_for(self, user: str) -> bool:
        """Another user's program, or another person driving by hand, holds the robot (or
        an emergency stop does: then every run waits, held, until it is resumed)."""
        holder = self.agent.lease.holder
        if self.agent.lease.estopped:
            return True
        if holder is None or holder.kind == "bridge" or holder.user == user:
            return False
        return not self._robot_free()

    def _robot_free(self) -> bool:
        holder = self.agent.lease.holder
        # A person who left the controls alone lets go for the next one (lease.IDLE_SECONDS).
        return holder is None or (holder.kind == "teleop" and self.agent.lease._idle())

    async def _say_box_cap(self) -> None:
        """The robot's row says what the agent's isolation allows at once (for its page and
        the API, which have no agent at hand); written when that changes."""
        cap = self.box_cap()
        await database_sync_to_async(Robot.objects.filter(name=self.agent.name).update)(
            isolation_runs_at_once=cap
        )
        self._box_cap_said = cap

    def _set_waiting(self, count: int) -> None:
        if not (count and self.waiting):
            # Someone begins to wait, or nobody waits any more: a turn is counted from now.
            self._turn = None
        self.waiting = count

    async def _count(self) -> None:
        waiting, sharing = await database_sync_to_async(_queue_state)(self.agent.name)
        self._counted = True
        self._set_waiting(waiting)
        self.sharing = sharing

    async def _step(self) -> None:
        if self.box_cap() != self._box_cap_said:  # the agent started, or was reconfigured
            await self._say_box_cap()
        if self.held or self._closing:
            return
        if (self.waiting and self._robot_free()) or self._shares_due():
            await self._start_next()
            return
        holder = self.agent.lease.holder
        if self.waiting and holder is not None and holder.kind == "run":
            await self._check_turn(holder)

    def _shares_due(self) -> bool:
        """Runs wait for a share, and something changed or a while went by since the last
        look: a look costs the database a query or two, not to be made every tick."""
        if not self.sharing:
            return False
        now = asyncio.get_running_loop().time()
        return self._look_at_shares or now - self._shares_looked >= SHARES_LOOK

    async def _start_next(self) -> None:
        """Start the first in line that may start now, and on while others may: a run that
        waits for the robot once it is free (with the lease), one that waits for a share once
        the robot is not busy for its owner; each only if its shares allow (fair_shares)."""
        self._look_at_shares = False
        self._shares_looked = asyncio.get_running_loop().time()
        refused: set[int] = set()  # owners whose share is taken, as this look found
        while not self._closing:
            line = await database_sync_to_async(_line)(self.agent.name)
            run = self._next_to_try(line, refused)
            if run is None:
                break
            decision = await self._try_start(run)
            if decision is None or decision.robot_full:  # the robot was taken, or is full
                break
            if decision.outcome is fair_shares.Admission.WAITS:
                refused.add(run.owner_id)
        await self._count()

    def _next_to_try(self, line: list[Run], refused: set[int]) -> Run | None:
        for run in line:
            if run.owner_id in refused:
                continue
            if fair_shares.is_share_wait(run.reason):
                if not self._busy_for(run.owner.get_username()):
                    return run
            elif self._robot_free():
                return run
        return None

    async def _try_start(self, run: Run) -> fair_shares.Decision | None:
        """Start ``run`` from the line if its shares allow: the decision (WAITS: a share is
        taken, it waits on), or None if the robot was taken while we looked."""
        agent = self.agent
        try:
            message = run.start_message()  # its owner came with it: no await from here
        except Exception as exc:  # e.g. its language is gone: it must not block the line
            if await database_sync_to_async(Run.unqueue)(run.pk):
                await agent._end_run(run.pk, "failed", None, f"could not start: {exc}")
            return fair_shares.Decision(fair_shares.Admission.GONE)
        # One that waited for the robot takes the lease first, before anything else may run:
        # nobody slips in between. One that waited for a share starts as it would have.
        takes_lease = not fair_shares.is_share_wait(run.reason)
        previous = agent.lease.holder
        if takes_lease:
            try:
                agent.lease.acquire(Holder("run", run.pk, message["user"]))
            except LeaseHeld:  # someone took the robot while we looked
                return None
        decision = await database_sync_to_async(fair_shares.admit)(run.pk, self.box_cap())
        if decision.outcome is not fair_shares.Admission.ADMITTED:
            if takes_lease:
                agent.lease.release(run.pk)
            if decision.changed:
                agent._run_changed(run.pk)  # its page says what it waits for now
            return decision
        if takes_lease:
            agent._lease_changed()
            if previous is not None:  # a person gone idle: their motion ends (it has already)
                await agent.stop_motion_of(previous.key)
        log.info("agent %s: run %s starts from the queue", agent.name, run.pk)
        # As a task the agent knows of: its shutdown waits for it, and stops its program.
        task = asyncio.create_task(agent.start_run({**message, "from_queue": True}))
        agent._starting.add(task)
        task.add_done_callback(agent._starting.discard)
        await asyncio.shield(task)
        if takes_lease and run.pk not in agent.runs and agent.lease.release(run.pk):
            agent._lease_changed()  # it could not start (or ended already): the next may
        await self._ranks_changed()
        return decision

    async def _check_turn(self, holder: Holder) -> None:
        loop = asyncio.get_running_loop()
        if self._turn is None or self._turn[0] != holder.key:
            robot = await database_sync_to_async(Robot.objects.get)(name=self.agent.name)
            self._limit = turn_seconds(robot.settings)
            ends = loop.time() + self._limit if self._limit else math.inf
            self._turn = (holder.key, ends)
        if loop.time() < self._turn[1]:
            return
        await self._count()  # others still waiting? (they may have been cancelled)
        if not self.waiting or self._turn is None:
            return
        self._turn = (holder.key, math.inf)  # once
        why = f"its turn on the shared robot ended ({self._limit:g} s)"
        if self.agent.stop_run(holder.key, why):
            log.info("agent %s: run %s stopped: %s", self.agent.name, holder.key, why)

    async def _mark_held(self) -> None:
        try:
            ids = await database_sync_to_async(_hold)(self.agent.name)
        except Exception:
            log.exception("agent %s: could not mark the queue held", self.agent.name)
            return
        for run_id in ids:
            self.agent.publish(run_group(run_id), {"type": "run.state", "run_id": run_id})
        self._robot_runs_changed()

    async def _ranks_changed(self) -> None:
        """Everyone in line moved up: their pages say so."""
        ids = await database_sync_to_async(_queued_ids)(self.agent.name)
        for run_id in ids:
            self.agent.publish(run_group(run_id), {"type": "run.state", "run_id": run_id})
        self._robot_runs_changed()

    def _robot_runs_changed(self) -> None:
        name = self.agent.name
        self.agent.publish(RUNS_GROUP, {"type": "runs.changed", "run_id": None, "robot": name})
        self.agent.publish(robot_group(name), {"type": "robot.runs", "robot": name})


def _queue_state(robot_name: str) -> tuple[int, int]:
    """Runs waiting for the robot and runs waiting for a share (held runs wait for neither)."""
    queue = Run.objects.filter(robot__name=robot_name, state=Run.State.QUEUED)
    queue = queue.exclude(reason__in=HELD_REASONS)
    sharing = queue.filter(reason__startswith=fair_shares.WAITING).count()
    return queue.count() - sharing, sharing


def _line(robot_name: str) -> list[Run]:
    """The robot's queue as it may start, the next first, with the runs' owners: held runs
    are left out (they start once started again)."""
    robot_id = Robot.objects.filter(name=robot_name).values_list("pk", flat=True).first()
    return list(Run.queue_of(robot_id).exclude(reason__in=HELD_REASONS).select_related("owner"))


def _queued_ids(robot_name: str) -> list[int]:
    return list(
        Run.objects.filter(robot__name=robot_name, state=Run.State.QUEUED).values_list(
            "pk", flat=True
        )
    )


def _hold_one(run_id: int) -> None:
    Run.objects.filter(pk=run_id, state=Run.State.QUEUED).update(reason=Run.HELD)


def _hold(robot_name: str) -> list[int]:
    ids = _queued_ids(robot_name)
    Run.objects.filter(pk__in=ids, state=Run.State.QUEUED).update(reason=Run.HELD)
    return ids


# -- the web tier: who may do what, and doing it --------------------------------------------


def may_manage(user, robot: Robot) -> bool:
    """Reorder, cancel and resume a robot's queue: staff and the robot's owner."""
    return user.is_authenticated and robot.configurable_by(user)


def runs_to_see(user):
    """The runs ``user`` may see (programs.access), and the queued runs of robots they manage
    (staff, the robot's owner): whose and which program waits, to decide the order."""
    from django.db.models import Q

    runs = runs_for_user(user)
    if not user.is_authenticated or user.is_superuser:
        return runs
    mine = Robot.objects.filter(owner=user, checking=False)  # a check sim is not its owner's
    managed = Robot.objects.all() if user.is_staff else mine
    waiting = Q(state=Run.State.QUEUED, robot__in=managed)
    return Run.objects.select_related("robot", "owner").filter(
        Q(pk__in=runs.values("pk")) | waiting
    )


def get_run_to_manage(user, run_id) -> Run:
    """A run ``user`` may see (programs.access), or a queued one of a robot they manage."""
    try:
        return get_run_for_user(user, run_id)
    except Http404:
        run = Run.objects.select_related("robot", "owner").filter(pk=run_id).first()
        if run is not None and run.queued and may_manage(user, run.robot):
            return run
        raise


def queue_rows(user, robot: Robot) -> list[dict]:
    """The robot's queue as ``user`` may see it: every place in line; which program and whose
    for their own runs, their students' (programs.access) and to those who manage the queue."""
    manager = may_manage(user, robot)
    queued = runs_for_user(user).filter(robot=robot, state=Run.State.QUEUED)
    visible = set(queued.values_list("pk", flat=True))
    queue = list(Run.queue_of(robot.pk).select_related("owner"))
    rows = []
    for rank, run in enumerate(queue, 1):
        shown = manager or run.pk in visible
        moves = []
        if manager and rank > 1:
            moves += [
                (_("⇧ first"), 1, _("Move to the front")),
                (_("↑ up"), rank - 1, _("Move up")),
            ]
        if manager and rank < len(queue):
            moves.append((_("↓ down"), rank + 1, _("Move down")))
        rows.append({
            "rank": rank, "place": in_line(rank), "run": run if shown else None,
            "linked": run.pk in visible, "mine": run.owner_id == user.pk,
            "why": _why(run, user) if shown else "", "held": run.held,
            "can_start": run.held and shown and may_start_again(user, run),
            "can_cancel": shown, "can_move": manager, "moves": moves,
        })  # fmt: skip
    return rows


def may_start_again(user, run: Run) -> bool:
    """Who starts a held run again (robots.stops.start_again): its owner, staff and the
    robot's owner."""
    return user.is_authenticated and (run.owner_id == user.pk or may_manage(user, run.robot))


def _why(run: Run, user) -> str:
    """What a run waits for, when not the robot itself: a share (fair_shares)."""
    if not fair_shares.is_share_wait(run.reason):
        return ""
    return fair_shares.reason_shown(run.reason, run.owner_id == user.pk)


def held(robot: Robot) -> int:
    """How many of the robot's queued runs an emergency stop held."""
    return Run.queue_of(robot.pk).filter(reason__in=HELD_REASONS).count()


def cancel(run: Run) -> bool:
    """Cancel a queued run (the stop action on it); False if it no longer waits."""
    if not Run.cancel_queued(run.pk):
        return False
    run.refresh_from_db()
    _changed(run.robot.name, also=[run.pk])
    return True


def move(user, run: Run, rank: int) -> int:
    """Put a queued run at ``rank`` (1-based) of its robot's line: its rank then."""
    if not may_manage(user, run.robot):
        raise PermissionDenied(_("Only staff and the robot's owner reorder its queue."))
    placed = Run.move_in_queue(run.pk, rank)
    if placed is None:
        raise NotQueued(
            _("Run %(id)s is not queued (it is %(state)s).")
            % {"id": run.pk, "state": _state_of(run.pk)}
        )
    _changed(run.robot.name)
    return placed


def unhold(robot: Robot, run_id: int | None = None) -> int:
    """The runs held by an emergency stop (or only ``run_id``) wait as any others now: how
    many. Its agent (it starts them when it may) and the pages hear of it. The caller has
    made sure the stop is not in force (robots.stops.start_again)."""
    runs = Run.queue_of(robot.pk).filter(reason__in=HELD_REASONS)
    if run_id is not None:
        runs = runs.filter(pk=run_id)
    count = runs.update(reason="")
    _changed(robot.name)
    return count


def queue_changed(robot: Robot) -> None:
    """Its queue's runs changed (e.g. resumed, they are held no longer by a stop in force):
    the pages hear of it."""
    _changed(robot.name, tell_agent=False)


class NotQueued(Exception):
    pass


def _state_of(run_id: int) -> str:
    state = Run.objects.filter(pk=run_id).values_list("state", flat=True).first()
    return str(Run.State(state).label) if state else _("gone")


def _changed(robot_name: str, also=(), tell_agent: bool = True) -> None:
    """The queue changed here, in the web tier: its agent and the pages hear of it."""
    if tell_agent:
        with contextlib.suppress(Exception):  # the agent away: it reads the queue when back
            tell_agent_sync(robot_name, CHANGED)
    ids = [*also, *_queued_ids(robot_name)]
    try:
        blocking(_tell_pages)(robot_name, ids)
    except Exception:  # the channel layer away: the pages catch up on their next event
        log.exception("could not tell the pages of robot %s's queue", robot_name)


async def _tell_pages(robot_name: str, run_ids: list[int]) -> None:
    layer = get_channel_layer()
    for run_id in run_ids:
        await layer.group_send(run_group(run_id), {"type": "run.state", "run_id": run_id})
    changed = {"type": "runs.changed", "run_id": None, "robot": robot_name}
    await layer.group_send(RUNS_GROUP, changed)
    await layer.group_send(robot_group(robot_name), {"type": "robot.runs", "robot": robot_name})
