"""All runs together: one parent cgroup per robotide, holding a share of the machine (no Django).

A run's own cgroup bounds that run; eight runs of 800 MB each still add up to more than the
machine can spare, and then the kernel's OOM killer picks among everything, the server
included. Every run's cgroup therefore lives in one parent, beside the server's own processes,
whose limits leave the web tier and the agents room:

    memory   a share (ROBOTIDE_RUNS_MEMORY_SHARE, 0.6) of the machine's RAM or of the cgroup the
             server lives in, whichever is smaller (RAM and swap together on v1 with memsw)
    pids     processes and threads of all runs at once
    weight   CPU weight against the server's (v2 cpu.weight, the server's 100; v1 cpu.shares,
             the server's tasks 1024 each): busy runs yield to a busy server

At the parent's memory limit the kernel kills a process of a run (runs' processes are the OOM
killer's first choice anyway: runbox.oom), never the server, which is not in it. One parent a
robotide (its data folder): the agents of one robotide on one machine share it, in fleet mode
too, and another robotide's have their own.

    support = runs_cgroups(Share(0.6, 4096, 50), instance=str(DATA_DIR))  # detect() + parent
    support.bases                  # the parent's folders: RunCgroup.create makes runs there
    support.describe()             # "cgroup v1 (...); all runs together at most 14463 MB of ..."
"""

import zlib
from dataclasses import dataclass
from pathlib import Path

from runbox.cgroups import (
    MB,
    RUNS,
    CgroupError,
    CgroupSupport,
    _keyed,
    _read_int,
    _write,
    detect,
    prepare_v2,
)

SERVER_WEIGHT = 100  # cgroup v2's default cpu.weight: what the server's processes have
V1_SHARES_PER_WEIGHT = 1024 / SERVER_WEIGHT  # v1's default cpu.shares is 1024
UNLIMITED = 1 << 62  # more than any limit a kernel reports as a number


@dataclass(frozen=True)
class Share:
    """What all runs together may have (the settings' RUNS_SHARE)."""

    memory_share: float = 0.6  # of the machine's RAM, or of the server's cgroup if smaller
    pids: int = 4096
    cpu_weight: int = 50  # 1..10000; the server's is 100

    @classmethod
    def from_settings(cls, values: dict) -> "Share":
        """Raises ValueError naming the setting that is out of range."""
        share = cls(float(values.get("memory_share", cls.memory_share)),
                    int(values.get("pids", cls.pids)),
                    int(values.get("cpu_weight", cls.cpu_weight)))  # fmt: skip
        if not 0 < share.memory_share <= 1:
            raise ValueError(f"the runs' memory share must be in (0, 1], not {share.memory_share}")
        if share.pids < 1:
            raise ValueError(f"the runs' process limit must be at least 1, not {share.pids}")
        if not 1 <= share.cpu_weight <= 10_000:
            raise ValueError(f"the runs' CPU weight must be in 1..10000, not {share.cpu_weight}")
        return share


@dataclass(frozen=True)
class RunsParent:
    """The parent cgroup of one robotide's runs, named `name` in every hierarchy."""

    name: str
    memory_bytes: int
    pids: int
    cpu_weight: int

    def describe(self) -> str:
        return (
            f"all runs together at most {self.memory_bytes // MB} MB of memory and"
            f" {self.pids} processes, CPU weight {self.cpu_weight} (the server's {SERVER_WEIGHT})"
        )

    def ensure(self, support: CgroupSupport) -> None:
        """Made with its limits, unless all its folders are there already."""
        if not all(folder.is_dir() for folder in support.folders()):
            self.make(support)

    def make(self, support: CgroupSupport) -> None:
        """Its folders (`support.bases`), made if missing, and its limits written. Raises
        OSError or CgroupError."""
        if support.version == "v2":
            prepare_v2(support.bases["memory"], support.controllers)
        for folder in support.folders():
            folder.mkdir(exist_ok=True)
        (self._limit_v2 if support.version == "v2" else self._limit_v1)(support)

    def _limit_v2(self, support: CgroupSupport) -> None:
        memory = support.bases["memory"]
        _write(memory / "memory.max", self.memory_bytes)
        if "pids" in support.controllers:
            _write(memory / "pids.max", self.pids)
        if "cpu" in support.controllers:
            _write(memory / "cpu.weight", self.cpu_weight)

    def _limit_v1(self, support: CgroupSupport) -> None:
        memory = support.bases["memory"]
        if _read_int(memory / "memory.use_hierarchy", 1) != 1:  # only old kernels allow 0
            raise CgroupError(f"{memory} does not count its children (memory.use_hierarchy 0)")
        limits = [("memory.limit_in_bytes", self.memory_bytes)]
        if "swap" in support.controllers:  # RAM + swap: never more than RAM alone allows
            limits.append(("memory.memsw.limit_in_bytes", self.memory_bytes))
        try:
            for file, value in limits:
                _write(memory / file, value)
        except OSError:  # raised above the old memsw limit: that one must go first
            for file, value in reversed(limits):
                _write(memory / file, value)
        if "pids" in support.bases:
            _write(support.bases["pids"] / "pids.max", self.pids)
        if "cpu" in support.bases:
            shares = max(2, round(self.cpu_weight * V1_SHARES_PER_WEIGHT))
            _write(support.bases["cpu"] / "cpu.shares", shares)


def runs_cgroups(
    share: Share, instance: str, support: CgroupSupport | None = None
) -> CgroupSupport:
    """The cgroups runs get: those of `support` (detect()'s by default) inside this robotide's
    parent, made now with its limits. Without cgroups, `support` itself; a parent that cannot
    be made is no cgroups at all, saying why (runs are then bounded per process, one at a
    time, and say so), never runs without the parent's limits."""
    support = support or detect()
    if not support.available:
        return support
    name = f"{RUNS}-{zlib.crc32(instance.encode()):08x}"
    memory = int(share.memory_share * machine_memory(support))
    parent = RunsParent(name, memory, share.pids, share.cpu_weight)
    bases = {controller: base.with_name(name) for controller, base in support.bases.items()}
    within = CgroupSupport(support.version, support.controllers, bases, parent=parent)
    try:
        parent.make(within)
    except (OSError, CgroupError) as exc:
        return CgroupSupport(None, why=f"the runs' parent cgroup {name} could not be made: {exc}")
    return within


def release_parent(support: CgroupSupport) -> None:
    """The parent removed if no run and no box is left in it (an agent's last act): else the
    kernel refuses, and it stays for the agents still serving."""
    if support.parent is None:
        return
    for folder in support.folders():
        try:
            folder.rmdir()
        except OSError:
            pass


def machine_memory(support: CgroupSupport, meminfo: str = "/proc/meminfo") -> int:
    """Bytes the server's processes may use: the machine's RAM, or less where the cgroup it
    lives in (or one above) is limited."""
    total = UNLIMITED
    for line in Path(meminfo).read_text().splitlines():
        if line.startswith("MemTotal:"):
            total = int(line.split()[1]) * 1024
    own = support.bases["memory"].parent  # the runs' folders sit beside the server
    return min(total, _own_limit_v2(own) if support.version == "v2" else _own_limit_v1(own))


def _own_limit_v1(own: Path) -> int:
    # The kernel's own answer for the whole chain of ancestors.
    stat = _keyed(own / "memory.stat")
    return min(stat.get("hierarchical_memory_limit", UNLIMITED), UNLIMITED)


def _own_limit_v2(own: Path) -> int:
    limit = UNLIMITED
    for folder in (own, *own.parents):
        if not (folder / "cgroup.controllers").exists():
            break  # above the cgroup2 mount
        try:
            text = (folder / "memory.max").read_text().strip()
        except OSError:
            continue  # the root cgroup has none
        if text != "max":
            limit = min(limit, int(text))
    return limit
