"""A run's process whose log keeps within its owner's quota and the total (runlogs.quota).

The log grows in grants asked off the event loop, ahead of need. When output comes that the
grant does not cover, the program's pipes stop being read until the answer (the program waits
on its writes; nothing is lost or reordered); when no room is left it ends, as at the per-run
size cap, saying why in its log. Once it ended, its log counts the bytes it takes and is
compressed after ``RUN_LOG_COMPRESS_AFTER``. The agent makes its runs' processes of this class.
"""

import asyncio
import logging
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

from django.conf import settings
from django.db import close_old_connections, connections

from runbox.supervisor import RunProcess
from runlogs import quota

# Before the first grant's answer a run may write this much (its first lines wait for nothing).
FIRST_ALLOWANCE = 64 * 1024
log = logging.getLogger(__name__)

# Grants in one thread, compression in another: a grant never waits behind a big log's gzip.
_GRANTS = ThreadPoolExecutor(max_workers=1, thread_name_prefix="runlogs-grant")
_STORAGE = ThreadPoolExecutor(max_workers=1, thread_name_prefix="runlogs-compress")


def _in_database_thread(job, *args):
    close_old_connections()
    try:
        return job(*args)
    finally:
        connections.close_all()


def _stored(job, run_id: int) -> None:
    """A storage job's failure is the server's log's to say: the run has ended."""
    try:
        _in_database_thread(job, run_id)
    except Exception:
        log.exception("run %s: its log could not be stored (%s)", run_id, job.__name__)


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
        self._asking: asyncio.Future | None = None
        self._held: list[tuple[bytes, list[bytes], bool]] = []  # output waiting for a grant
        self._refused = ""
        self._finish_when_granted = False

    async def begin(self, launch=None, gate=None, *, log_path=None, on_output=None) -> None:
        self._run_id = run_id_of(log_path or self.log_path)
        if self._run_id is not None:
            self._ask(0)  # its first grant, asked before it says anything
        await super().begin(launch, gate, log_path=log_path, on_output=on_output)

    # -- output, within its grant ---------------------------------------------------------

    def _append(self, tag: bytes, lines: list[bytes], force: bool = False) -> None:
        if self._run_id is None or self._log is None or self._capped:
            return super()._append(tag, lines, force)
        if self._held:  # behind what waits for a grant, in order
            self._held.append((tag, lines, force))
            return
        size = sum(len(line) + 3 for line in lines)  # "t " + line + "\n"
        if force or self._written + size <= self._granted:
            super()._append(tag, lines, force)
            if self._written > self._granted - quota.step() // 2:
                self._ask(0)  # ahead: a steady writer need not wait
            return
        if self._written + size > self.max_log_bytes:  # the per-run cap says so, as ever
            return super()._append(tag, lines, force)
        if self._refused:
            return self._quota_reached()
        self._held.append((tag, lines, force))
        self._pause_reading(True)
        self._ask(size)

    def _ask(self, need: int) -> None:
        if self._asking is not None:
            return
        loop = asyncio.get_running_loop()
        self._asking = loop.run_in_executor(
            _GRANTS, _in_database_thread, quota.grant,
            self._run_id, self._written, need, self.max_log_bytes,
        )  # fmt: skip
        self._asking.add_done_callback(self._answered)

    def _answered(self, asked: asyncio.Future) -> None:
        self._asking = None
        try:
            answer = asked.result()
        except Exception:  # the database failed it: the per-run cap alone holds
            log.exception("run %s: its log's quota could not be read", self._run_id)
            answer = quota.Grant(self.max_log_bytes)
        self._granted, self._refused = answer.limit, answer.refused
        held, self._held = self._held, []
        for tag, lines, force in held:
            self._append(tag, lines, force)  # may wait again, for the next grant
        if self._held:
            return
        if self._log is not None and not self._log.closed:
            self._schedule_flush()
        self._pause_reading(False)
        if self._finish_when_granted:
            self._finished()

    def _quota_reached(self) -> None:
        self._capped = True
        reason = f"{self._refused}; further output was discarded"
        self.system_line(reason)
        self.stop(reason, state="failed")

    def _pause_reading(self, pause: bool) -> None:
        transport = getattr(self, "_transport", None)
        for fd in (1, 2):
            pipe = transport.get_pipe_transport(fd) if transport is not None else None
            if pipe is not None:
                pipe.resume_reading() if not pause else pipe.pause_reading()

    # -- its end --------------------------------------------------------------------------

    def _finished(self) -> None:
        if self._held:
            self._finish_when_granted = True  # its last lines wait for their grant
            return
        self._finish_when_granted = False
        super()._finished()
        if self._run_id is not None:
            self._store_when_ended(self._run_id)

    def _store_when_ended(self, run_id: int) -> None:
        loop = asyncio.get_running_loop()
        loop.run_in_executor(_STORAGE, _stored, quota.settle, run_id)
        loop.call_later(
            settings.RUN_LOG_COMPRESS_AFTER,
            lambda: loop.run_in_executor(_STORAGE, _stored, compress_ended, run_id),
        )


def compress_ended(run_id: int) -> None:
    """This log, and any an agent that stopped early left uncompressed."""
    quota.compress(run_id)
    quota.compress_due()
