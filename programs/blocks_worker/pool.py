"""The worker processes (see the package's docstring), as the server or an agent keeps them."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import threading
from pathlib import Path

from django.conf import settings
from django.utils import translation
from django.utils.translation import gettext as _

from programs.blocks import BlocksError, failing
from runbox import SYSTEM_PATH
from runbox.isolation import tool
from runbox.oom import first_to_go

# The folder holding the `programs` package: the worker's working folder, whence `-m` finds it.
SOURCE_ROOT = Path(__file__).resolve().parents[2]
# CPU seconds a worker may use in all: past them it is replaced (its cap per program is set
# by the worker itself, see __main__).
LIFETIME_CPU_SECONDS = 3600
NICENESS = 10  # below the server's and agents' priority: they answer first


class BlocksBusy(BlocksError):
    """Every worker stayed busy for as long as a caller waits for one."""


def to_python(source: str) -> str:
    """The Python of a blocks program, made and compiled in a worker; BlocksError if it
    cannot be (the message names the block), or if the worker ran out of time or memory."""
    return _pool().make(source)


def to_python_mapped(source: str) -> tuple[str, list[str | None]]:
    """The Python and its source map (programs.blocks.to_python_mapped), made in a worker."""
    return _pool().make_mapped(source)


def to_runnable_python(source: str) -> str:
    """What a run writes and runs, as programs.blocks.to_runnable_python, made in a worker."""
    try:
        return to_python(source)
    except BlocksError as exc:
        return failing(str(exc))


def worker_command(memory: int, seconds: int) -> list[str]:
    """A worker, its address space and lifetime CPU set by util-linux's prlimit, its priority
    by coreutils' nice and its oom_score_adj by choom (the OOM killer's first choice, with the
    runs, not the server's -500 it would inherit): nothing runs between fork and exec in the
    threaded server."""
    worker = [
        tool("prlimit"), f"--as={memory}", f"--cpu={LIFETIME_CPU_SECONDS}", "--core=0", "--",
        tool("nice"), "-n", str(NICENESS),
        sys.executable, "-E", "-s", "-m", "programs.blocks_worker", str(seconds),
    ]  # fmt: skip
    return first_to_go(worker, tool("choom"))


class Worker:
    """One worker process, asked one program at a time."""

    def __init__(self, memory: int, seconds: int) -> None:
        self.process = subprocess.Popen(
            worker_command(memory, seconds),
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, bufsize=0,
            cwd=SOURCE_ROOT, env={"PATH": SYSTEM_PATH, "LC_ALL": "C.UTF-8"},
        )  # fmt: skip
        self.killed = False
        self.ended_before_asked = False

    @property
    def alive(self) -> bool:
        return self.process.poll() is None

    def ask(self, request: dict, seconds: float) -> dict | None:
        """Its answer, or None if it ended first or took longer than `seconds`, killed then
        (`killed` says which)."""
        watchdog = threading.Timer(seconds, self.kill)
        watchdog.start()
        try:
            try:
                self.process.stdin.write(json.dumps(request).encode() + b"\n")
            except BrokenPipeError:  # it had ended before (found dead between two polls)
                self.ended_before_asked = not self.killed  # not the watchdog's doing
                return None
            line = self._answer_line()
        except OSError:
            return None
        finally:
            watchdog.cancel()
        return json.loads(line) if line.endswith(b"\n") else None

    def _answer_line(self) -> bytes:
        chunks = []
        while chunk := os.read(self.process.stdout.fileno(), 1 << 16):
            chunks.append(chunk)
            if chunk.endswith(b"\n"):  # JSON escapes newlines: this is the answer's end
                break
        return b"".join(chunks)

    def kill(self) -> None:
        self.killed = True
        self.process.kill()

    def close(self) -> None:
        """Gone for good: killed if still running, and its pipes closed."""
        if self.alive:
            self.process.kill()
        self.process.wait()
        self.process.stdin.close()
        self.process.stdout.close()


class Pool:
    """At most `size` workers, each asked by one caller at a time; started when first needed
    and replaced when one ends."""

    def __init__(self, size: int, memory: int, seconds: int) -> None:
        self.memory, self.seconds = memory, seconds
        self.free = threading.BoundedSemaphore(size)
        self.lock = threading.Lock()
        self.idle: list[Worker] = []
        self.pid = os.getpid()

    def make(self, source: str) -> str:
        return self.make_mapped(source)[0]

    def make_mapped(self, source: str) -> tuple[str, list[str | None]]:
        request = {"source": source, "language": translation.get_language() or "en"}
        # A caller waits its turn behind a few programs at most, each held to `seconds`.
        if not self.free.acquire(timeout=3 * self.seconds):
            raise BlocksBusy(
                _("Making Python of blocks is busy for everyone just now: try again shortly.")
            )
        try:
            worker = self._take()
            answer = worker.ask(request, self.seconds)
            if answer is None and worker.ended_before_asked:  # not this program's doing
                worker.close()
                worker = Worker(self.memory, self.seconds)
                answer = worker.ask(request, self.seconds)
            if answer is None or answer["retire"]:
                worker.close()
            else:
                self._give_back(worker)
        finally:
            self.free.release()
        if answer is None and worker.killed:
            raise BlocksError(
                _("Making Python of these blocks took longer than %(seconds)s s.")
                % {"seconds": self.seconds}
            )
        if answer is None or answer.get("out_of_memory"):
            raise BlocksError(
                _("Making Python of these blocks took more memory or time than it may.")
            )
        if "error" in answer:
            raise BlocksError(answer["error"])
        return answer["python"], answer["blocks"]

    def _take(self) -> Worker:
        with self.lock:
            while self.idle:
                worker = self.idle.pop()
                if worker.alive:
                    return worker
                worker.close()
        return Worker(self.memory, self.seconds)

    def _give_back(self, worker: Worker) -> None:
        with self.lock:
            self.idle.append(worker)

    def close(self) -> None:
        with self.lock:
            workers, self.idle = self.idle, []
        for worker in workers:
            worker.close()


_the_pool: Pool | None = None
_the_pool_lock = threading.Lock()


def _pool() -> Pool:
    """This process's pool (a forked child makes its own: the workers' pipes are its
    parent's)."""
    global _the_pool
    with _the_pool_lock:
        if _the_pool is None or _the_pool.pid != os.getpid():
            _the_pool = Pool(
                settings.BLOCKS_WORKERS,
                settings.BLOCKS_WORKER_MEMORY_MB * 1024 * 1024,
                settings.BLOCKS_WORKER_SECONDS,
            )
        return _the_pool
