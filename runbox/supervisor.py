"""Runs one program as an OS process and captures its output (no Django here).

Output is written line by line to the run's log file, each line tagged with where it came
from (``o`` stdout, ``e`` stderr, ``s`` robotide itself), and handed in batches to a callback
for the live stream. The log file is the truth: the live batches are a bounded view of it and
may skip lines when a program floods (the batch says how many), the file never does until the
log size cap, which ends the program with a message saying so.

A run's output is read no faster than its ``output_rate`` (bytes a second, after a burst):
past it the pipes are not read for a while, so the program waits in its write and nothing is
lost. Reading, splitting and writing a flood's lines is the server's (or agent's) own work, on
its event loop: unbounded, two floods of one student took a fifth of a core from everyone.
"""

import asyncio
import os
import signal
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from subprocess import DEVNULL, PIPE

from runbox.box import BoxFailed, NotStarted
from runbox.watch import RunWatch

STDOUT, STDERR, SYSTEM = b"o", b"e", b"s"
TAG_OF_FD = {1: STDOUT, 2: STDERR}
MAX_LINE = 64 * 1024  # a longer line without a newline is cut into pieces of this size
# A live batch carries at most this much; the rest is counted as skipped (the log has it all).
LIVE_MAX_BYTES = 128 * 1024
LIVE_MAX_LINES = 1000
OUTPUT_BURST = 2 * 1024 * 1024  # read at once before a run's output rate holds it back

# (offset of the line in the log file, tag "o"|"e"|"s", text)
LiveLine = tuple[int, str, str]
# on_output(lines, skipped, skipped_from): `skipped` lines not sent live lie between offset
# `skipped_from` (where the previous batch ended) and the first of `lines`.
OutputCallback = Callable[[list[LiveLine], int, int], None]

SIGNAL_REASONS = {
    signal.SIGXCPU: "CPU time limit reached",
    signal.SIGXFSZ: "file size limit reached",
}


@dataclass(frozen=True)
class Outcome:
    state: str  # finished | failed | stopped
    exit_code: int | None  # negative: killed by that signal
    reason: str


def format_reason(returncode: int) -> str:
    if returncode >= 0:
        return f"exit status {returncode}"
    sig = signal.Signals(-returncode)
    return SIGNAL_REASONS.get(sig, f"killed by {sig.name}")


class RunProcess:
    """One running program: start(), stop(), wait()."""

    def __init__(
        self,
        argv: list[str],
        *,
        env: dict[str, str],
        cwd: Path,
        log_path: Path | None = None,
        on_output: OutputCallback | None = None,
        max_log_bytes: int = 64 * 1024 * 1024,
        grace: float = 3.0,
        batch_interval: float = 0.1,
        watch: RunWatch | None = None,
        box=None,
        output_rate: int = 0,
        output_burst: int = OUTPUT_BURST,
    ):
        """`box`: the run's box (runbox.box.Box), whose command `argv` is: prepared before
        the run is known, given its program by begin(), signalled as a whole, reporting the
        program's death by signal N as 128 + N. `log_path` and `on_output` may come with
        begin(); what the process says before then waits for the log. `watch`: what it
        samples. `output_rate`: bytes a second its output is read at most, after
        `output_burst` (0: as fast as it comes)."""
        self.argv, self.env, self.cwd, self.log_path = argv, env, cwd, log_path
        self.watch, self.box = watch, box
        self.wrapped = box is not None
        self._watcher: asyncio.Task | None = None
        self.on_output = on_output
        self.max_log_bytes = max_log_bytes
        self.grace = grace
        self.batch_interval = batch_interval
        self.pid: int | None = None
        self.started = False  # the program itself runs (its box let it)
        self.returncode: int | None = None
        self.lines_written = 0
        self._partial = {1: b"", 2: b""}
        self._log = None
        self._early: list[tuple[bytes, list[bytes], bool]] = []  # said before the log opened
        self._written = 0
        self._capped = False
        self._pending: list[tuple[int, bytes]] = []
        self._pending_bytes = 0
        self._skipped = 0
        self._live_end = 0
        self._flush_handle: asyncio.Handle | None = None
        self._last_flush = 0.0
        self._flush_due = 0.0
        self._kill_handle: asyncio.TimerHandle | None = None
        self._stop_reason: str | None = None
        self._stop_state = "stopped"
        self._done: asyncio.Future | None = None
        self._bucket = OutputBucket(output_rate, output_burst) if output_rate > 0 else None
        self._reading_held: set[str] = set()  # why the pipes are not read now (none: read)
        self._refill_handle: asyncio.TimerHandle | None = None

    async def start(self, gate=None, launch=None) -> int:
        """Spawn and begin at once (see both)."""
        await self.spawn(wait_for_cgroup=False)
        await self.begin(launch, gate)
        return self.pid

    async def spawn(self, wait_for_cgroup: bool = True) -> int:
        """The OS process: with a box, the box, prepared and waiting for its run (begin());
        without one, the program itself. A box that cannot be prepared ends the process,
        and the run fails saying why. `wait_for_cgroup` False: a box's processes join its
        cgroup while the program starts (a start that is waited for)."""
        loop = asyncio.get_running_loop()
        self._done = loop.create_future()
        if self.log_path is not None:
            self._open_log()
        try:
            await loop.subprocess_exec(
                lambda: _Protocol(self),
                *self.argv,
                stdin=self.box.stdin() if self.box and self.box.stdin() is not None else DEVNULL,
                stdout=PIPE,
                stderr=PIPE,
                cwd=self.cwd,
                env=self.env,
                start_new_session=True,
                # The server's own umask is 077; a sandbox's mount points must be traversable.
                umask=0o022,
                pass_fds=self.box.pass_fds() if self.box else (),
            )
        except OSError:
            if self._log is not None:
                self._log.close()
            raise
        if self.box is not None:
            try:
                await self.box.prepare(self.pid, wait_for_cgroup)
            except Exception as exc:  # nothing of a program runs: the run fails, saying why
                self._fail(f"could not start: {exc}", f"its box could not be made: {exc}")
        return self.pid

    async def begin(self, launch=None, gate=None, *, log_path=None, on_output=None) -> None:
        """The run begins: its log, then (with a box) its program. `gate`: a coroutine
        function awaited just before the program may run; None lets it run, (state, reason)
        ends it there as NotStarted. `launch`: runbox.box.Launch, what the box runs."""
        self.log_path = log_path or self.log_path
        self.on_output = on_output or self.on_output
        if self._log is None:
            self._open_log()
        if self.box is None:
            self.started = True
        elif not self.running:
            raise BoxFailed("its box ended before the run began")
        elif not self.stop_requested:
            try:
                await self.box.go(launch, gate)
            except NotStarted as refused:  # whoever started it no longer wants it to run
                self._stop_state, self._stop_reason = refused.args
                self._signal_group(signal.SIGKILL)
            except Exception as exc:
                self._fail(f"could not start: {exc}", f"its program could not start: {exc}")
            else:
                self.started = True
        if self.watch is not None and self.running:
            self._watcher = asyncio.get_running_loop().create_task(
                self.watch.run(self._limit_reached)
            )

    def _open_log(self) -> None:
        self.log_path.parent.mkdir(parents=True, exist_ok=True)
        # Buffered writes to a local file; flushed with every live batch so readers see whole lines.
        self._log = open(self.log_path, "ab", buffering=1 << 20)  # noqa: SIM115
        self._written = self._log.tell()
        early, self._early = self._early, []
        for tag, lines, force in early:
            self._append(tag, lines, force)

    def _fail(self, reason: str, line: str) -> None:
        if self.running:
            self.system_line(line)
        self._stop_reason, self._stop_state = reason, "failed"
        self._signal_group(signal.SIGKILL)

    @property
    def stop_requested(self) -> bool:
        return self._stop_reason is not None

    @property
    def running(self) -> bool:
        return self._done is not None and not self._done.done()

    def stop(self, reason: str = "stopped by user", state: str = "stopped") -> None:
        """SIGTERM to the whole process group now, SIGKILL after the grace period."""
        if not self.running or self._stop_reason is not None:
            return
        self._stop_reason, self._stop_state = reason, state
        self.system_line(f"{reason}: sending SIGTERM")
        self._signal_group(signal.SIGTERM)
        self._kill_handle = asyncio.get_running_loop().call_later(self.grace, self._kill_late)

    def kill(self, reason: str, state: str = "stopped") -> None:
        """SIGKILL to every process of the run now, no grace (an emergency stop); it ends
        with `reason` even if a gentler stop was under way."""
        if not self.running:
            return
        if self._kill_handle is not None:
            self._kill_handle.cancel()
        if self._stop_reason is None or self._stop_reason != reason:
            self.system_line(f"{reason}: sending SIGKILL")
        self._stop_reason, self._stop_state = reason, state
        self._signal_group(signal.SIGKILL)

    async def wait(self) -> Outcome:
        await asyncio.shield(self._done)
        return self.outcome()

    def outcome(self) -> Outcome:
        rc = self.returncode
        if self.wrapped and rc is not None and 128 < rc <= 128 + 64:
            rc = -(rc - 128)
        if self._stop_reason is not None:
            return Outcome(self._stop_state, rc, self._stop_reason)
        state = "finished" if rc == 0 else "failed"
        return Outcome(state, rc, format_reason(rc))

    def system_line(self, text: str) -> None:
        self._append(SYSTEM, [f"[robotide] {text}".encode()], force=True)
        self._schedule_flush()

    # -- output ---------------------------------------------------------------------------

    def _feed(self, fd: int, data: bytes) -> None:
        if self._bucket is not None:
            self._meter(len(data))
        if fd == 2 and self.watch is not None:
            self.watch.saw_stderr(data)
        buffer = self._partial[fd] + data
        lines = buffer.split(b"\n")
        if len(buffer) > MAX_LINE:  # only then can a line be too long: worth a look
            lines = [piece for line in lines for piece in _cut(line)] if lines[:-1] else lines
            while len(lines[-1]) > MAX_LINE:
                lines[-1:] = [lines[-1][:MAX_LINE], lines[-1][MAX_LINE:]]
        self._partial[fd] = lines.pop()
        if lines:
            self._append(TAG_OF_FD[fd], lines)
            self._schedule_flush()

    def _meter(self, size: int) -> None:
        wait = self._bucket.take(size, time.monotonic())
        if wait > 0 and self._refill_handle is None:
            self._hold_reading("rate", True)
            loop = asyncio.get_running_loop()
            self._refill_handle = loop.call_later(wait, self._refilled)

    def _refilled(self) -> None:
        self._refill_handle = None
        self._hold_reading("rate", False)

    def _hold_reading(self, why: str, held: bool) -> None:
        """Stop reading the program's pipes for `why` (the output rate, a log quota's grant
        asked) or let go of it; they are read while nothing holds them."""
        (self._reading_held.add if held else self._reading_held.discard)(why)
        transport = getattr(self, "_transport", None)
        for fd in (1, 2):
            pipe = transport.get_pipe_transport(fd) if transport is not None else None
            if pipe is None:
                continue
            if self._reading_held:
                pipe.pause_reading()
            else:
                pipe.resume_reading()

    def _end_of_stream(self, fd: int) -> None:
        if self._partial.get(fd):
            self._append(TAG_OF_FD[fd], [self._partial[fd]])
            self._partial[fd] = b""

    def _append(self, tag: bytes, lines: list[bytes], force: bool = False) -> None:
        if self._log is None:  # a box that has no run yet: at most a few lines of its own
            if len(self._early) < 100:
                self._early.append((tag, lines, force))
            return
        if self._capped and not force:
            return
        prefix = tag + b" "
        chunk = prefix + (b"\n" + prefix).join(lines) + b"\n"
        if not force and self._written + len(chunk) > self.max_log_bytes:
            self._hit_log_cap()
            return
        start = self._written
        self._log.write(chunk)
        self._written += len(chunk)
        self.lines_written += len(lines)
        self._pending.append((start, chunk))
        self._pending_bytes += len(chunk)
        while self._pending_bytes > LIVE_MAX_BYTES and len(self._pending) > 1:
            _, dropped = self._pending.pop(0)
            self._pending_bytes -= len(dropped)
            self._skipped += dropped.count(b"\n")

    def _hit_log_cap(self) -> None:
        self._capped = True
        limit_mb = self.max_log_bytes / (1024 * 1024)
        reason = f"output size limit ({limit_mb:g} MB) reached; further output was discarded"
        self.system_line(reason)
        self.stop(reason, state="failed")

    def _schedule_flush(self) -> None:
        # The first line goes out at once; under a flood, at most one batch per interval.
        if self._flush_handle is not None:
            return
        loop = asyncio.get_running_loop()
        now = time.monotonic()
        self._flush_due = max(now, self._last_flush + self.batch_interval)
        self._flush_handle = loop.call_later(self._flush_due - now, self._flush)

    def _flush(self) -> None:
        self._flush_handle = None
        # From when the batch was due, not when the timer ran (a little late each time): else
        # a program printing once an interval finds each batch due later and later.
        self._last_flush = min(self._flush_due, time.monotonic())
        if self._log is None or self._log.closed:
            return
        self._log.flush()
        pending, skipped, skipped_from = self._pending, self._skipped, self._live_end
        self._pending, self._pending_bytes, self._skipped = [], 0, 0
        if pending:
            self._live_end = pending[-1][0] + len(pending[-1][1])
        lines = list(_live_lines(pending))
        if len(lines) > LIVE_MAX_LINES:
            skipped += len(lines) - LIVE_MAX_LINES
            lines = lines[-LIVE_MAX_LINES:]
        if lines or skipped:
            self.on_output(lines, skipped, skipped_from)

    # -- process --------------------------------------------------------------------------

    def _signal_group(self, sig: int) -> None:
        """To the program's processes: through its box if it has one, else by its group.

        A box signals what runs in it, sparing the sandbox's own first process a SIGTERM (it
        would answer with SIGKILL to all), and reaches a child that left the group.
        """
        if self.box is not None:
            self.box.signal(sig)
            if sig != signal.SIGKILL:
                return
        try:
            os.killpg(self.pid, sig)
        except (ProcessLookupError, PermissionError):
            pass

    def _limit_reached(self, reason: str) -> None:
        self.stop(reason, state="failed")

    def _kill_late(self) -> None:
        if self.running:
            self.system_line(f"did not stop within {self.grace:g} s: sending SIGKILL")
            self._signal_group(signal.SIGKILL)

    def _exited(self) -> None:
        self.returncode = self._transport.get_returncode()
        # Whatever the program left behind in its group ends with it, so its pipes close too.
        self._signal_group(signal.SIGKILL)
        self._unmetered()  # what is left in its pipes is theirs at most: read to the end

    def _unmetered(self) -> None:
        self._bucket = None
        if self._refill_handle is not None:
            self._refill_handle.cancel()
            self._refilled()

    def _finished(self) -> None:
        if self._kill_handle is not None:
            self._kill_handle.cancel()
        for fd in (1, 2):
            self._end_of_stream(fd)
        outcome = self.outcome()
        if self._watcher is not None:
            self._watcher.cancel()
            for note in self.watch.notes(failed=outcome.state == "failed"):
                self._append(SYSTEM, [f"[robotide] {note}".encode()], force=True)
        self._append(SYSTEM, [f"[robotide] {outcome.state}: {outcome.reason}".encode()], force=True)
        if self._flush_handle is not None:
            self._flush_handle.cancel()
        self._flush()
        if self._log is not None:
            self._log.close()
        self._transport.close()
        self._done.set_result(None)


class OutputBucket:
    """A token bucket of bytes: `rate` a second, up to `burst` saved."""

    def __init__(self, rate: int, burst: int):
        self.rate, self.burst = rate, burst
        self.tokens, self.at = float(burst), time.monotonic()

    def take(self, size: int, now: float) -> float:
        """Take `size` bytes' worth; the seconds until the bucket is out of debt (0: none)."""
        self.tokens = min(self.burst, self.tokens + (now - self.at) * self.rate) - size
        self.at = now
        return -self.tokens / self.rate if self.tokens < 0 else 0.0


def _cut(line: bytes) -> list[bytes]:
    return [line[i : i + MAX_LINE] for i in range(0, len(line), MAX_LINE)] or [line]


def _live_lines(pending: list[tuple[int, bytes]]):
    for start, chunk in pending:
        offset = start
        for line in chunk.split(b"\n")[:-1]:
            yield offset, chr(line[0]), line[2:].decode("utf-8", "replace")
            offset += len(line) + 1


class _Protocol(asyncio.SubprocessProtocol):
    def __init__(self, run: RunProcess):
        self.run = run

    def connection_made(self, transport) -> None:
        # Before any other callback: a program that exits at once may be reported as
        # exited before subprocess_exec() has even returned.
        self.run._transport = transport
        self.run.pid = transport.get_pid()

    def pipe_data_received(self, fd: int, data: bytes) -> None:
        self.run._feed(fd, data)

    def pipe_connection_lost(self, fd: int, exc) -> None:
        self.run._end_of_stream(fd)

    def process_exited(self) -> None:
        self.run._exited()

    def connection_lost(self, exc) -> None:
        self.run._finished()
