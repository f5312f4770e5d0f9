"""A run's process whose log keeps within its owner's quota and the total (runlogs.quota).

The log grows in grants asked ahead of need, on the database's thread, never on the event
loop. When output comes that the grant does not cover, the program's pipes stop being read
until the answer (the program waits on its writes; nothing is lost or reordered); when no room
is left the run ends, as at the per-run size cap, saying why in its log. Once it ended, its log
counts the bytes it takes, and it is compressed after ``RUN_LOG_COMPRESS_AFTER`` (gzip in a
thread of its own). The agent makes its runs' processes of this class.
"""

import asyncio
import logging
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from channels.db import database_sync_to_async
from django.conf import settings

from programs.models import Run
from runbox.supervisor import RunProcess
from runlogs import files, quota

# A run may write this much before its first grant (beyond a full quota at worst, while it
# asks): its first lines wait for nothing.
FIRST_ALLOWANCE = 64 * 1024
log = logging.getLogger(__name__)

_GZIP = ThreadPoolExecutor(max_workers=1, thread_name_prefix="runlogs-gzip")
_background: set[asyncio.Task] = set()  # held until done (the loop keeps only weak references)


def run_id_of(log_path: Path | None) -> int | None:
    """The run a log path is of (Run.log_path_of), None for a log outside the runs' folder."""
    if log_path is None or Path(log_path).parent.parent != settings.RUNS_DIR:
        return None
    name = Path(log_path).parent.name
    return int(name) if name.isdigit() else None


class QuotaRunProcess(RunProcess):
    def __init__(self, *args, **kwargs):
        super().__init__(*args, **kwargs)
        self._run_id: int | None = None
        self._granted = FIRST_ALLOWANCE
        self._asking: asyncio.Task | None = None
        self._held: list[tuple[bytes, list[bytes], bool]] = []  # output waiting for a grant
        self._refused = ""
        self._finish_when_granted = False
        self._ahead = 0

    async def begin(self, launch=None, gate=None, *, log_path=None, on_output=None) -> None:
        self._run_id = run_id_of(log_path or self.log_path)
        # A grant is asked once it wrote half its first allowance: most runs never ask,
        # and none asks while it starts (the database's thread then claims it).
        self._ahead = min(quota.step(), FIRST_ALLOWANCE) // 2
        await super().begin(launch, gate, log_path=log_path, on_output=on_output)

    # -- output, within its grant ---------------------------------------------------------

    def _append(self, tag: bytes, lines: list[bytes], force: bool = False) -> None:
        if self._run_id is None or self._log is None or self._capped:
            return super()._append(tag, lines, force)
        if self._held:  # behind what waits for a grant, in order
            self._held.append((tag, lines, force))
            return
        size = sum(map(len, lines)) + 3 * len(lines)  # "t " + line + "\n" each
        if force or self._written + size <= self._granted:
            super()._append(tag, lines, force)
            if self._granted - self._written < self._ahead:
                self._ask(0)  # ahead: a steady writer need not wait
            return
        if self._written + size > self.max_log_bytes:  # the per-run cap says so, as ever
            return super()._append(tag, lines, force)
        if self._refused:
            return self._quota_reached()
        self._held.append((tag, lines, force))
        self._hold_reading("quota", True)
        self._ask(size)

    def _ask(self, need: int) -> None:
        if self._asking is not None:
            return
        self._asking = asyncio.ensure_future(
            database_sync_to_async(quota.grant)(
                self._run_id, self._written, need, self.max_log_bytes
            )
        )
        self._asking.add_done_callback(self._answered)

    def _answered(self, asked: asyncio.Task) -> None:
        self._asking = None
        try:
            answer = asked.result()
        except Exception:  # the database failed it: the per-run cap alone holds
            log.exception("run %s: its log's quota could not be read", self._run_id)
            answer = quota.Grant(self.max_log_bytes)
        self._granted, self._refused = answer.limit, answer.refused
        # Asked ahead again only while grants come whole: near a full quota, only when needed.
        step = quota.step()
        self._ahead = step // 2 if answer.limit - self._written >= step // 2 else 0
        held, self._held = self._held, []
        for tag, lines, force in held:
            self._append(tag, lines, force)  # may wait again, for the next grant
        if self._held:
            return
        if self._log is not None and not self._log.closed:
            self._schedule_flush()
        self._hold_reading("quota", False)
        if self._finish_when_granted:
            self._finished()

    def _quota_reached(self) -> None:
        self._capped = True
        reason = f"{self._refused}; further output was discarded"
        self.system_line(reason)
        self.stop(reason, state="failed")

    # -- its end --------------------------------------------------------------------------

    def _finished(self) -> None:
        if self._held:
            self._finish_when_granted = True  # its last lines wait for their grant
            return
        self._finish_when_granted = False
        super()._finished()
        if self._run_id is not None:
            _in_background(settle(self._run_id))
            run_id = self._run_id  # compressed in its time (a timer: nothing waits meanwhile)
            asyncio.get_running_loop().call_later(
                settings.RUN_LOG_COMPRESS_AFTER, lambda: _in_background(compress_ended(run_id))
            )


def _in_background(coroutine) -> None:
    task = asyncio.ensure_future(coroutine)
    _background.add(task)
    task.add_done_callback(_background.discard)


async def settle(run_id: int) -> None:
    """An ended log counts the bytes it takes, no longer what it was granted."""
    try:
        await database_sync_to_async(quota.settle)(run_id)
    except Exception:  # the run has ended: the server's log says what went wrong
        log.exception("run %s: its log's size could not be counted", run_id)


async def compress_ended(run_id: int) -> None:
    """Its log compressed, and any an agent that stopped early left uncompressed."""
    try:
        await compress(run_id)
        for leftover in await database_sync_to_async(quota.due_for_compression)():
            await compress(leftover)
    except Exception:
        log.exception("run %s: its log could not be compressed", run_id)


async def compress(run_id: int) -> bool:
    """gzip in its own thread (a big log takes a while), put in place on the database's."""
    try:
        part = await asyncio.get_running_loop().run_in_executor(
            _GZIP, files.compress_aside, Run.log_path_of(run_id)
        )
    except files.DoesNotCompress:
        await database_sync_to_async(quota.keep_plain)(run_id)
        return False
    if part is None:  # no plain log (compressed already, pruned, never written)
        return False
    return await database_sync_to_async(quota.put_compressed)(run_id, part)
