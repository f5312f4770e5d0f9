"""Watching a run's processes through its box (no Django here).

The kernel enforces most limits (the run's cgroup, its folder's size, rlimits); this watches
what it does not — wall-clock time, CPU seconds across the whole run, a run its cgroup's
memory limit has struck — and remembers how close a run came to the others, so that its log
can say which limit a program ran into when it failed on one.
"""

import asyncio
import os
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

MB = 1024 * 1024
INTERVAL = 0.5
# What programs print on stderr when the kernel refuses them something, by the limit behind
# it: a run that dies within one sample still gets told which limit it met.
LIMIT_SIGNS = {
    "processes": (b"Resource temporarily unavailable", b"[Errno 11]", b"fork: retry"),
    "open_files": (b"Too many open files",),
    "memory": (b"MemoryError", b"Cannot allocate memory", b"out of memory", b"bad_alloc"),
    "file_size": (b"File too large",),
    "disk": (b"No space left on device", b"ENOSPC"),
}


def processes_of(uid: int) -> list[int]:
    """Every process running as `uid` (as root, a run's own account)."""
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
    memory: int = 0  # bytes: the run's cgroup's count, else the most one process reserved
    disk: int = 0  # bytes in the run's folder (its tmpfs)

    def peak(self, other: "Usage") -> None:
        self.processes = max(self.processes, other.processes)
        self.open_files = max(self.open_files, other.open_files)
        self.memory = max(self.memory, other.memory)
        self.disk = max(self.disk, other.disk)


def measure(box) -> Usage:
    usage = Usage(disk=disk_used(box.folder))
    for pid in box.processes():
        usage.processes += 1
        try:
            usage.open_files = max(usage.open_files, len(os.listdir(f"/proc/{pid}/fd")))
            usage.memory = max(usage.memory, vm_peak(pid))
        except (FileNotFoundError, ProcessLookupError):
            pass
    if box.cgroup is not None:  # the run as one: what the memory limit counts
        counted = box.cgroup.usage()
        usage.memory = max(counted.memory_peak_bytes or 0, counted.memory_bytes)
    return usage


def vm_peak(pid: int) -> int:
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            if line.startswith("VmPeak:"):
                return int(line.split()[1]) * 1024
    return 0


def disk_used(folder: Path | None) -> int:
    """Bytes in the run's folder, a tmpfs of its own: the kernel's count, unlinked files too."""
    if folder is None:
        return 0
    try:
        stats = os.statvfs(folder)
    except OSError:  # the run has just ended
        return 0
    return (stats.f_blocks - stats.f_bfree) * stats.f_frsize


class RunWatch:
    """Samples a run twice a second; calls `on_limit(reason)` when it must end."""

    def __init__(self, limits, box):
        self.limits, self.box = limits, box
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
            now = await asyncio.to_thread(measure, self.box)
            self.peaks.peak(now)
            wall = self.limits.wall_seconds
            if wall and time.monotonic() - started > wall:
                on_limit(f"wall-clock time limit ({wall} s) reached")
            for reason in await asyncio.to_thread(self.cgroup_limits_met):
                on_limit(reason)

    def cgroup_limits_met(self) -> list[str]:
        """What the run's cgroup says ends it: CPU seconds across the run (the kernel only
        counts them), memory (on cgroup v1 the OOM killer ends one process, not the run)."""
        if self.box.cgroup is None:
            return []
        self.box.gather()  # a process that slipped out of its first move
        met = self.box.cgroup.met()
        if "processes" in met:
            self.signs.add("processes")
        return [met[key] for key in ("cpu_seconds", "memory") if key in met]

    def notes(self, failed: bool = True) -> list[str]:
        """The kernel-enforced limits the run came up against, for its log: its cgroup's own
        count where it has one, else — for a run that failed — what the samples and its error
        messages suggest. A run that ended well or was stopped by someone met none of those
        guesses: without a cgroup the memory sample is address space reserved (VmPeak), and
        Node.js reserves most of its limit without using it."""
        limits, peaks, signs = self.limits, self.peaks, self.signs
        met = self.box.cgroup.met() if self.box is not None and self.box.cgroup else {}
        notes = [met[key] for key in ("memory", "processes") if key in met]
        if not failed:
            return notes
        if "processes" not in met and (
            peaks.processes >= limits.processes - 1 or "processes" in signs
        ):
            notes.append(f"it reached its process limit ({limits.processes} processes)")
        if peaks.open_files >= limits.open_files - 2 or "open_files" in signs:
            notes.append(f"it reached its open files limit ({limits.open_files})")
        if "memory" not in met and (
            peaks.memory >= 0.9 * limits.memory_mb * MB or "memory" in signs
        ):
            notes.append(f"it came up to its memory limit ({limits.memory_mb} MB)")
        if peaks.disk >= 0.95 * limits.disk_mb * MB or "disk" in signs:
            notes.append(f"it filled its folder ({limits.disk_mb} MB)")
        if "file_size" in signs:
            notes.append(f"it reached its file size limit ({limits.file_size_mb} MB a file)")
        return notes
