"""Watching a run's processes through its own OS account (no Django here).

The kernel enforces most limits (runbox.launcher); this watches what it does not — wall-clock
time and disk written — and remembers how close a run came to the others, so that its log can
say which limit a program ran into when it failed on one.
"""

import asyncio
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

MB = 1024 * 1024
INTERVAL = 0.5
MAX_FILES_COUNTED = 20_000  # a folder with more is "full" whatever their sizes
# What programs print on stderr when the kernel refuses them something, by the limit behind
# it: a run that dies within one sample still gets told which limit it met.
LIMIT_SIGNS = {
    "processes": (b"Resource temporarily unavailable", b"[Errno 11]", b"fork: retry"),
    "open_files": (b"Too many open files",),
    "memory": (b"MemoryError", b"Cannot allocate memory", b"out of memory", b"bad_alloc"),
    "file_size": (b"File too large",),
}


def processes_of(uid: int) -> list[int]:
    """Every process running as `uid`: exactly a run's, since each run has its own account."""
    pids = []
    for entry in os.scandir("/proc"):
        if entry.name.isdigit():
            try:
                if entry.stat().st_uid == uid:
                    pids.append(int(entry.name))
            except FileNotFoundError:
                pass
    return pids


def signal_account(uid: int, sig: int) -> int:
    sent = 0
    for pid in processes_of(uid):
        try:
            os.kill(pid, sig)
            sent += 1
        except ProcessLookupError:
            pass
    return sent


@dataclass
class Usage:
    processes: int = 0
    open_files: int = 0
    memory: int = 0  # bytes of address space, the most any one process had
    disk: int = 0  # bytes in the working directory

    def peak(self, other: "Usage") -> None:
        self.processes = max(self.processes, other.processes)
        self.open_files = max(self.open_files, other.open_files)
        self.memory = max(self.memory, other.memory)
        self.disk = max(self.disk, other.disk)


def measure(uid: int, workdir: Path) -> Usage:
    usage = Usage(disk=disk_used(workdir))
    for pid in processes_of(uid):
        usage.processes += 1
        try:
            usage.open_files = max(usage.open_files, len(os.listdir(f"/proc/{pid}/fd")))
            usage.memory = max(usage.memory, vm_peak(pid))
        except (FileNotFoundError, ProcessLookupError):
            pass
    return usage


def vm_peak(pid: int) -> int:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmPeak:"):
                return int(line.split()[1]) * 1024
    return 0


def disk_used(folder: Path) -> int:
    total, counted = 0, 0
    for root, dirs, files in os.walk(folder):
        for name in files + dirs:
            counted += 1
            if counted > MAX_FILES_COUNTED:
                return 1 << 62
            try:
                total += os.lstat(os.path.join(root, name)).st_blocks * 512
            except FileNotFoundError:
                pass
    return total


class RunWatch:
    """Samples a run twice a second; calls `on_limit(reason)` when it must end."""

    def __init__(self, limits, uid: int, workdir: Path):
        self.limits, self.uid, self.workdir = limits, uid, workdir
        self.peaks = Usage()
        self.signs: set[str] = set()

    def saw_stderr(self, data: bytes) -> None:
        for limit, signs in LIMIT_SIGNS.items():
            if limit not in self.signs and any(sign in data for sign in signs):
                self.signs.add(limit)

    async def run(self, on_limit: Callable[[str], None]) -> None:
        started = time.monotonic()
        while True:
            await asyncio.sleep(INTERVAL)
            now = await asyncio.to_thread(measure, self.uid, self.workdir)
            self.peaks.peak(now)
            wall = self.limits.wall_seconds
            if wall and time.monotonic() - started > wall:
                on_limit(f"wall-clock time limit ({wall} s) reached")
            if now.disk > self.limits.disk_mb * MB:
                on_limit(f"disk limit ({self.limits.disk_mb} MB written) reached")

    def notes(self) -> list[str]:
        """The kernel-enforced limits the run came up against, for its log."""
        limits, peaks, signs, notes = self.limits, self.peaks, self.signs, []
        if peaks.processes >= limits.processes - 1 or "processes" in signs:
            notes.append(f"it reached its process limit ({limits.processes} processes)")
        if peaks.open_files >= limits.open_files - 2 or "open_files" in signs:
            notes.append(f"it reached its open files limit ({limits.open_files})")
        if peaks.memory >= 0.9 * limits.memory_mb * MB or "memory" in signs:
            notes.append(f"it came up to its memory limit ({limits.memory_mb} MB)")
        if "file_size" in signs:
            notes.append(f"it reached its file size limit ({limits.file_size_mb} MB a file)")
        return notes
