"""Run log quotas: what a user's logs and everybody's take, how far a running log may grow,
and the oldest ended logs pruned to make room. Only logs are ever deleted: the runs stay, saying
when and why their log went.

A running log grows in grants (``grant``): its row's ``log_bytes`` holds what it may grow to,
so two runs never count on the same free bytes; an ended log's holds the bytes it takes on disk
(``settle``, then ``compress``). Every change to what counts is made holding one lock file, so
agents in several processes of this machine take turns.
"""

import fcntl
import os
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from datetime import timedelta

from django.conf import settings
from django.db.models import Q, Sum
from django.utils import timezone

from programs.models import Run
from runlogs import files
from runlogs.notes import megabytes

MB = 1024 * 1024
TOTAL_AT_MOST = 4096 * MB
STEP_MIN, STEP_MAX = 64 * 1024, 4 * MB  # a running log is granted this much more at a time
PRUNED_AT_ONCE = 1000  # the oldest logs looked at for one grant (the next goes on)


@dataclass(frozen=True)
class Grant:
    limit: int  # the run's log may grow to this many bytes
    refused: str = ""  # why it may not grow as far as it asked (then it grows no further)


def per_user() -> int:
    """The setting; 0: none of its own, the total alone."""
    return settings.RUN_LOG_QUOTA_PER_USER or total()


def total() -> int:
    """The setting, else 4 GB or a quarter of the disk the runs are on, whichever is less."""
    if settings.RUN_LOG_QUOTA_TOTAL:
        return settings.RUN_LOG_QUOTA_TOTAL
    settings.RUNS_DIR.mkdir(parents=True, exist_ok=True)
    disk = os.statvfs(settings.RUNS_DIR)
    return min(TOTAL_AT_MOST, disk.f_blocks * disk.f_frsize // 4)


def step() -> int:
    return max(STEP_MIN, min(STEP_MAX, per_user() // 32))


@contextmanager
def quota_lock() -> Iterator[None]:
    """One holder at a time, across the processes of this machine (an open file's lock)."""
    settings.RUNS_DIR.mkdir(parents=True, exist_ok=True)
    with open(settings.RUNS_DIR / ".log-quota.lock", "ab") as lock:
        fcntl.flock(lock, fcntl.LOCK_EX)
        yield  # unlocked as the file closes


def counted() -> "Q":
    return Q(log_pruned_at__isnull=True, log_bytes__gt=0)


def prunable() -> "Q":
    """Ended runs' logs: a running run's never goes."""
    return counted() & ~Q(state__in=Run.ONGOING)


def user_reason(quota: int) -> str:
    return f"run log quota reached ({quota / MB:g} MB for a user's logs, the oldest pruned first)"


def total_reason(quota: int) -> str:
    return f"run log quota reached ({quota / MB:g} MB for all users' logs, the oldest pruned first)"


def grant(run_id: int, written: int, need: int, cap: int) -> Grant:
    """How far run ``run_id``'s log, ``written`` bytes long, may grow: by a step, or at least
    by ``need``, within ``cap``; its owner's oldest ended logs pruned to make room, then
    anybody's for the total. Refused (``refused`` says why) if ``need`` does not fit."""
    with quota_lock():
        owner = Run.objects.filter(pk=run_id).values_list("owner_id", flat=True).first()
        if owner is None:  # no such run (deleted meanwhile): its cap alone bounds it
            return Grant(cap)
        want = min(cap, written + max(need, step()))
        others = counted() & ~Q(pk=run_id)
        mine = Q(owner_id=owner)
        limit, why = want, ""
        for quota, scope, reason in (
            (per_user(), mine, user_reason(per_user())),
            (total(), Q(), total_reason(total())),
        ):
            room = _make_room(
                quota, others & scope, prunable() & scope & ~Q(pk=run_id), limit, reason
            )
            if room < limit:
                limit, why = room, reason
        limit = max(limit, written)  # what is written stays counted until it is settled
        Run.objects.filter(pk=run_id).update(log_bytes=limit)
        return Grant(limit, why if limit < written + need else "")


def _make_room(quota: int, counted_q: Q, prunable_q: Q, want: int, reason: str) -> int:
    """Room for a log of ``want`` bytes beside what ``counted_q`` takes within ``quota``, the
    oldest logs of ``prunable_q`` pruned until it fits (or none is left): the bytes that log
    may have now."""
    used = Run.objects.filter(counted_q).aggregate(used=Sum("log_bytes"))["used"] or 0
    if used + want > quota:
        oldest = Run.objects.filter(prunable_q).order_by("ended", "pk")
        for run_id, size in oldest.values_list("pk", "log_bytes")[:PRUNED_AT_ONCE]:
            if used + want <= quota:
                break
            if prune(run_id, reason):
                used -= size
    return max(0, min(want, quota - used))


def prune(run_id: int, reason: str) -> bool:
    """Run ``run_id``'s log deleted, the run saying when and why. Marked first, then removed:
    a reader that finds no file finds the run saying so. The caller holds the lock."""
    marked = Run.objects.filter(pk=run_id, log_pruned_at__isnull=True).update(
        log_pruned_at=timezone.now(), log_pruned_reason=reason[:200], log_bytes=0
    )
    files.remove(Run.log_path_of(run_id))
    return bool(marked)


def settle(run_id: int) -> None:
    """An ended log counts the bytes it takes, not what it was granted."""
    with quota_lock():
        size = files.disk_bytes(Run.log_path_of(run_id))
        Run.objects.filter(pk=run_id, log_pruned_at__isnull=True).update(log_bytes=size)


def put_compressed(run_id: int, part) -> bool:
    """Run ``run_id``'s log made gzip aside (runlogs.files.compress_aside) put in place,
    holding the lock, unless it was pruned meanwhile: whether it was."""
    path = Run.log_path_of(run_id)
    with quota_lock():
        if not Run.objects.filter(pk=run_id, log_pruned_at__isnull=True).exists():
            files.remove(path)  # the part too: pruned while it was made
            return False
        size = files.put_in_place(path, part)
        Run.objects.filter(pk=run_id).update(log_storage="gzip", log_bytes=size)
    return True


def keep_plain(run_id: int) -> None:
    """Run ``run_id``'s ended log stays as written (it does not compress): not tried again."""
    Run.objects.filter(pk=run_id, log_storage="").update(log_storage="plain")


def due_for_compression(limit: int = 50) -> list[int]:
    """Ended runs whose logs are not compressed yet and whose time has come (a leftover of an
    agent that stopped before it compressed its own among them)."""
    due = timezone.now() - timedelta(seconds=settings.RUN_LOG_COMPRESS_AFTER)
    runs = Run.objects.filter(prunable(), log_storage="", ended__lte=due).order_by("ended")
    return list(runs.values_list("pk", flat=True)[:limit])


@dataclass(frozen=True)
class Usage:
    used: int
    quota: int

    @property
    def used_text(self) -> str:
        return megabytes(self.used)

    @property
    def quota_text(self) -> str:
        return megabytes(self.quota)

    @property
    def percent(self) -> int:
        return min(100, round(100 * self.used / self.quota)) if self.quota else 100


def usage_of(user) -> Usage:
    """What ``user``'s run logs take on disk now (a running log: as far as it got)."""
    runs = Run.objects.filter(counted(), owner=user)
    ended = runs.exclude(state__in=Run.ONGOING).aggregate(used=Sum("log_bytes"))["used"] or 0
    running = runs.filter(state__in=Run.ONGOING).values_list("pk", "log_bytes")
    growing = sum(min(size, files.disk_bytes(Run.log_path_of(pk))) for pk, size in running)
    return Usage(ended + growing, per_user())
