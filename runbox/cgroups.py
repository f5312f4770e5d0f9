"""One cgroup per run: limits that hold for the whole run, not for each process (no Django here).

rlimits (prlimit) count every process on its own: four children of 700 MB each pass a 1024 MB
limit, and CPU seconds start again at zero in every fork. A cgroup counts the run as one, and
everything a run starts is born into it. Both cgroup v2 (Debian 12, Raspberry Pi OS) and the
cgroup v1 controllers (memory, pids, cpu, cpuacct, freezer) are supported; which is in force is
read from /proc/self/cgroup and /proc/self/mountinfo.

    support = detect()              # cached; detect.cache_clear() to look again
    support.describe()              # "cgroup v1 (memory+swap, pids, cpu, cpuacct, freezer)",
                                    # or "no cgroups: <why> — per-process rlimits only"
    if support.available:
        cg = RunCgroup.create(f"{agent}-run-{run_id}", support, memory_bytes=1024 * MB,
                              pids=64, cpu_percent=100, cpu_seconds=600)
        argv = cg.command(argv)     # the run's first process joins before it execs anything
        cg.add(pid)                 # or: move a process that has not started the program yet
        cg.rename(f"{agent}-run-{other}")  # a box made ahead, taken by a run
        cg.usage()                  # CgroupUsage: memory now/peak, CPU seconds, processes
        cg.met()                    # {"memory": "memory limit (1024 MB) reached", ...}
        cg.kill()                   # every process of the run, forks included
        cg.remove()                 # never raises; kills what is left first
    sweep(support, prefix=f"{agent}-")  # at agent start: run cgroups a dead agent left behind

The kernel enforces memory (with swap), processes and the CPU share. It does not stop a run at a
total of CPU seconds: the watcher polls `met()` and stops the run when "cpu_seconds" is in it.
On v1 the OOM killer kills one process, not the run: stop the run when "memory" is in `met()`
(v2 kills the whole run itself, memory.oom.group).

Runs' cgroups go below the agent's own cgroup, in <own>/robotide-runs/<name>; an agent makes
them in its robotide's parent instead, <own>/robotide-runs-<instance>/<name>, whose limits hold
for all runs together (runbox.share). On v2 a cgroup that hands controllers to its children may
hold no processes, so the agent's own processes move to <own>/robotide-agent first.
"""

import functools
import os
import re
import shlex
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING

if TYPE_CHECKING:
    from runbox.share import RunsParent

MB = 1024 * 1024
RUNS = "robotide-runs"
AGENT_LEAF = "robotide-agent"
V1_CONTROLLERS = ("memory", "pids", "cpu", "cpuacct", "freezer")
V2_CONTROLLERS = ("memory", "pids", "cpu")
CFS_PERIOD_US = 100_000
REFUSED_CHARGE_MAX = 4 * MB  # a huge page (2 MB) and a batch of pages, with room to spare


class CgroupError(RuntimeError):
    """A run's cgroup could not be made or joined: start the run without it only knowingly."""


@dataclass(frozen=True)
class CgroupSupport:
    version: str | None  # "v2", "v1", or None: per-process rlimits only
    # Of: memory, swap (memory+swap limited), pids, cpu, cpuacct, freezer, kill (cgroup.kill).
    controllers: tuple[str, ...] = ()
    bases: dict[str, Path] = field(default_factory=dict)  # controller -> folder of runs' cgroups
    why: str = ""  # why there are no cgroups
    # The cgroup all runs share (runbox.share.RunsParent), whose folders `bases` are: it
    # makes itself again, limits and all, should it be gone when a run's cgroup is made.
    parent: "RunsParent | None" = None

    @property
    def available(self) -> bool:
        return self.version is not None

    def folders(self) -> list[Path]:
        """The base folders, one per hierarchy (v2: one; v1: one per controller mounted)."""
        return sorted(set(self.bases.values()))

    def describe(self) -> str:
        if not self.available:
            return f"no cgroups: {self.why} — per-process rlimits only"
        shown = []
        for name in self.controllers:
            if name == "memory":
                shown.append("memory+swap" if "swap" in self.controllers else "memory")
            elif name != "swap":
                shown.append(name)
        text = f"cgroup {self.version} ({', '.join(shown)})"
        return f"{text}; {self.parent.describe()}" if self.parent is not None else text


@functools.cache
def detect(proc: str = "/proc/self") -> CgroupSupport:
    """What this process may use; never raises. `proc` is for tests against a fake tree."""
    try:
        member = _memberships(Path(proc, "cgroup").read_text())
        mounts = _cgroup_mounts(Path(proc, "mountinfo").read_text())
    except OSError as e:
        return CgroupSupport(None, why=f"cannot read {e.filename}: {e.strerror}")
    # v1 first: on a hybrid system (this one, older Raspberry Pi OS) the v2 tree has no memory.
    if "memory" in member and any("memory" in opts for kind, _, _, opts in mounts if kind == "v1"):
        return _detect_v1(member, mounts)
    if "" in member and any(kind == "v2" for kind, *_ in mounts):
        return _detect_v2(member[""], mounts)
    return CgroupSupport(None, why="no memory cgroup controller is mounted")


def _memberships(text: str) -> dict[str, str]:
    """/proc/self/cgroup as {controller: path}; the v2 line ("0::/path") under ""."""
    member = {}
    for line in text.splitlines():
        _, controllers, path = line.split(":", 2)
        for name in controllers.split(",") if controllers else [""]:
            member[name] = path
    return member


def _unescape(text: str) -> str:  # mountinfo writes a space as \040
    return re.sub(r"\\([0-7]{3})", lambda m: chr(int(m[1], 8)), text)


def _cgroup_mounts(text: str) -> list[tuple[str, str, Path, set[str]]]:
    """(v1|v2, mount root, mount point, super options) of every cgroup mount."""
    mounts = []
    for line in text.splitlines():
        fields = line.split()
        sep = fields.index("-")
        fstype, options = fields[sep + 1], set(fields[sep + 3].split(","))
        if fstype in ("cgroup", "cgroup2"):
            kind = "v1" if fstype == "cgroup" else "v2"
            mounts.append((kind, _unescape(fields[3]), Path(_unescape(fields[4])), options))
    return mounts


def _folder(path: str, root: str, mountpoint: Path) -> Path | None:
    """Where cgroup `path` is seen under a mount of the hierarchy's `root`, if it is."""
    rel = os.path.relpath(path, root)
    return None if rel.startswith("..") else (mountpoint / rel).resolve()


def _not_writable(folder: Path) -> str:
    if os.geteuid() != 0:
        return f"robotide is not root and cannot write to {folder}"
    return f"{folder} is read-only"


def _detect_v1(member: dict[str, str], mounts) -> CgroupSupport:
    bases = {}
    for name in V1_CONTROLLERS:
        for kind, root, mountpoint, options in mounts:
            own = name in member and kind == "v1" and name in options
            folder = own and _folder(member[name], root, mountpoint)
            if folder and folder.is_dir():
                if os.access(folder, os.W_OK):
                    bases[name] = folder / RUNS
                elif name == "memory":
                    return CgroupSupport(None, why=_not_writable(folder))
                break
    if "memory" not in bases:
        return CgroupSupport(None, why="the memory cgroup (v1) is not mounted where it is seen")
    controllers = list(bases)
    if (bases["memory"].parent / "memory.memsw.limit_in_bytes").exists():
        controllers.insert(1, "swap")
    return CgroupSupport("v1", tuple(controllers), bases)


def _detect_v2(path: str, mounts) -> CgroupSupport:
    # Once the agent has moved into its leaf, its cgroup is that leaf: runs still go beside it.
    if path.rstrip("/").endswith("/" + AGENT_LEAF):
        path = path.rstrip("/").rsplit("/", 1)[0] or "/"
    own = None
    for kind, root, mountpoint, _ in mounts:
        own = own or (kind == "v2" and _folder(path, root, mountpoint))
    if not own or not own.is_dir():
        return CgroupSupport(None, why=f"the cgroup v2 tree does not show this process's {path}")
    try:
        offered = (own / "cgroup.controllers").read_text().split()
    except OSError as e:
        return CgroupSupport(None, why=f"cannot read {e.filename}: {e.strerror}")
    if "memory" not in offered:
        return CgroupSupport(
            None, why=f"the memory controller is not delegated to {own} (cgroup v2)"
        )
    files = (own, own / "cgroup.procs", own / "cgroup.subtree_control")
    if not all(os.access(f, os.W_OK) for f in files):
        why = _not_writable(own)
        if os.geteuid() != 0:
            why += " (run it in a systemd unit with Delegate=yes)"
        return CgroupSupport(None, why=why)
    controllers = [name for name in V2_CONTROLLERS if name in offered]
    # The root cgroup has no memory.* files; there swap accounting is assumed (Debian's kernel).
    if (own / "memory.swap.max").exists() or not (own / "cgroup.type").exists():
        controllers.insert(1, "swap")
    if (own / "cgroup.kill").exists():
        controllers.append("kill")
    return CgroupSupport("v2", tuple(controllers), dict.fromkeys(V2_CONTROLLERS, own / RUNS))


def _write(file: Path, value) -> None:
    # Appending is the same as writing on cgroupfs ("echo +memory >> ..."), and a fake tree
    # in the tests keeps every write.
    with open(file, "a") as f:
        f.write(f"{value}\n")


def _read_int(file: Path, default: int = 0) -> int:
    try:
        return int(file.read_text().split()[0])
    except (OSError, ValueError, IndexError):
        return default


def _words(file: Path) -> list[str]:
    try:
        return file.read_text().split()
    except FileNotFoundError:
        return []


def _keyed(file: Path) -> dict[str, int]:
    """A "key value" file (memory.events, pids.events, cpu.stat, memory.oom_control)."""
    try:
        pairs = (line.split() for line in file.read_text().splitlines())
        return {p[0]: int(p[1]) for p in pairs if len(p) == 2 and p[1].isdigit()}
    except OSError:
        return {}


def prepare_v2(base: Path, controllers: tuple[str, ...]) -> None:
    """Make <own>/robotide-runs hand memory, pids and cpu down to the runs' cgroups."""
    own = base.parent
    enable = [name for name in V2_CONTROLLERS if name in controllers]
    # "No internal processes": the agent leaves its cgroup before it hands controllers down.
    # The root cgroup (no cgroup.type) is exempt and cannot be left.
    procs = _words(own / "cgroup.procs")
    if procs and (own / "cgroup.type").exists():
        leaf = own / AGENT_LEAF
        leaf.mkdir(exist_ok=True)
        for pid in procs:
            try:
                _write(leaf / "cgroup.procs", pid)
            except ProcessLookupError:
                pass  # gone meanwhile
    base.mkdir(exist_ok=True)
    for folder in (own, base):
        on = set(_words(folder / "cgroup.subtree_control"))
        for name in enable:
            if name not in on:
                try:
                    _write(folder / "cgroup.subtree_control", f"+{name}")
                except OSError as e:
                    if name == "memory":
                        raise CgroupError(f"cannot enable memory in {folder}: {e}") from e


@dataclass(frozen=True)
class CgroupUsage:
    memory_bytes: int  # what the memory limit counts now (v1 with memsw: RAM + swap)
    memory_peak_bytes: int | None  # None: the kernel does not keep it (v2 before 5.19)
    cpu_seconds: float | None  # total across the run; None: no cpuacct (v1)
    processes: int  # tasks (threads included) where pids is in force, else processes


class RunCgroup:
    """One run's cgroup, in every hierarchy in force. `create` makes it; the constructor only
    names an existing one (as `sweep` does)."""

    def __init__(
        self,
        name: str,
        support: CgroupSupport,
        *,
        memory_bytes: int | None = None,
        pids: int | None = None,
        cpu_percent: int | None = None,
        cpu_seconds: float | None = None,
    ):
        if not support.available:
            raise CgroupError(support.describe())
        if not name or "/" in name or name.startswith("."):
            raise CgroupError(f"bad cgroup name {name!r}")
        self.name, self.support, self.v2 = name, support, support.version == "v2"
        self.memory_bytes, self.pids = memory_bytes, pids
        self.cpu_percent, self.cpu_seconds = cpu_percent, cpu_seconds
        self.dirs = {c: base / name for c, base in support.bases.items()}  # controller -> dir

    @classmethod
    def create(
        cls,
        name: str,
        support: CgroupSupport,
        *,
        memory_bytes: int | None,
        pids: int | None,
        cpu_percent: int | None = 100,
        cpu_seconds: float | None = None,
    ) -> "RunCgroup":
        """Make the run's cgroup with its limits (None or 0: no limit of that kind).

        memory_bytes: RAM and swap together, for all the run's processes.
        pids: processes and threads at once. cpu_percent: share of one CPU (100 = one core,
        200 = two); a hard cap, so the agent keeps the other core. cpu_seconds: total across
        the run, enforced by the watcher through met(). Raises CgroupError.
        """
        cg = cls(
            name, support, memory_bytes=memory_bytes, pids=pids,
            cpu_percent=cpu_percent, cpu_seconds=cpu_seconds,
        )  # fmt: skip
        if any(d.exists() for d in cg.folders()):
            cg.remove()  # a run's name is never reused: this one is a leftover
        try:
            if support.parent is not None:
                cg._make_in_parent()
            else:
                if cg.v2:
                    prepare_v2(support.bases["memory"], support.controllers)
                for folder in cg.folders():
                    folder.parent.mkdir(exist_ok=True)
                    folder.mkdir()
            cg._limit()
        except (OSError, CgroupError) as e:
            cg.remove()
            raise CgroupError(f"cannot make the run's cgroup {name}: {e}") from e
        return cg

    def _make_in_parent(self) -> None:
        """Its folders in the parent all runs share, never in a parent without its limits:
        made again should the last agent of the robotide have removed it meanwhile."""
        for attempt in range(2):
            self.support.parent.ensure(self.support)
            try:
                for folder in self.folders():
                    folder.mkdir(exist_ok=True)  # a leftover of its name went before
                return
            except FileNotFoundError:
                if attempt:
                    raise

    def _limit(self) -> None:
        d, mem, percent = self.dirs, self.memory_bytes, self.cpu_percent
        if self.v2:
            if mem and "memory" in self.support.controllers:  # detect() asks for it
                _write(d["memory"] / "memory.max", mem)
                # No swap at all: v2 limits swap apart from RAM, so RAM + swap stays <= mem.
                if (d["memory"] / "memory.swap.max").exists():
                    _write(d["memory"] / "memory.swap.max", 0)
            if (d["memory"] / "memory.oom.group").exists():
                _write(d["memory"] / "memory.oom.group", 1)  # an OOM kills the whole run
            if self.pids and "pids" in self.support.controllers:
                _write(d["pids"] / "pids.max", self.pids)
            if percent and "cpu" in self.support.controllers:
                _write(d["cpu"] / "cpu.max", f"{CFS_PERIOD_US * percent // 100} {CFS_PERIOD_US}")
            return
        if mem:
            _write(d["memory"] / "memory.limit_in_bytes", mem)  # first: memsw may not be less
            if "swap" in self.support.controllers:
                _write(d["memory"] / "memory.memsw.limit_in_bytes", mem)
            else:  # swap not counted: 0 keeps the run out of it (limit reclaim then never swaps)
                _write(d["memory"] / "memory.swappiness", 0)
        if self.pids and "pids" in d:
            _write(d["pids"] / "pids.max", self.pids)
        if percent and "cpu" in d:
            period = _read_int(d["cpu"] / "cpu.cfs_period_us", CFS_PERIOD_US)
            _write(d["cpu"] / "cpu.cfs_quota_us", max(1000, period * percent // 100))

    def folders(self) -> list[Path]:
        return sorted(set(self.dirs.values()))

    def rename(self, name: str) -> None:
        """Call it `name` from now on, processes and all (a box made ahead takes its run's
        name). A rename is no move: nothing waits for the kernel. cgroup v1 only: the v2
        kernel refuses (EPERM). Raises CgroupError."""
        if not name or "/" in name or name.startswith("."):
            raise CgroupError(f"bad cgroup name {name!r}")
        done = []
        try:
            for folder in self.folders():
                done.append(folder.rename(folder.with_name(name)))
        except OSError as e:
            for renamed in done:  # all its hierarchies keep one name
                renamed.rename(renamed.with_name(self.name))
            raise CgroupError(f"cannot rename the cgroup {self.name} to {name}: {e}") from e
        self.name = name
        self.dirs = {c: base / name for c, base in self.support.bases.items()}

    def command(self, argv: list[str]) -> list[str]:
        """`argv`, started so that it joins this cgroup before it execs: every process of the
        run, the sandbox included, is counted from its first byte. The shell must run with the
        agent's rights (before setpriv / bwrap), and refuses to go on if it cannot join."""
        files = " ".join(shlex.quote(str(f / "cgroup.procs")) for f in self.folders())
        script = f'for f in {files}; do echo $$ > "$f" || exit 125; done; exec "$@"'
        return ["/bin/sh", "-c", script, "robotide-cgroup", *argv]

    def add(self, pid: int) -> None:
        """Move process `pid` (all its threads) in. Memory it already has stays charged where it
        was (v1 and v2): add a process before it starts the program."""
        for folder in self.folders():
            try:
                _write(folder / "cgroup.procs", pid)
            except OSError as e:
                raise CgroupError(f"cannot move process {pid} into {folder}: {e}") from e

    def procs(self) -> set[int]:
        """Every process in the run's cgroup, in any hierarchy, nested cgroups included."""
        pids = set()
        for folder in self.folders():
            for parent, _, _ in os.walk(folder):
                try:
                    pids.update(map(int, Path(parent, "cgroup.procs").read_text().split()))
                except OSError:
                    pass
        return pids

    def members(self) -> set[int]:
        """The processes that are in the run's cgroup in every hierarchy (fully joined)."""
        sets = []
        for folder in self.folders():
            pids = set()
            for parent, _, _ in os.walk(folder):
                try:
                    pids.update(map(int, Path(parent, "cgroup.procs").read_text().split()))
                except OSError:
                    pass
            sets.append(pids)
        return set.intersection(*sets) if sets else set()

    def usage(self) -> CgroupUsage:
        d = self.dirs
        mem = d["memory"]
        if self.v2:
            current = _read_int(mem / "memory.current")
            peak = _read_int(mem / "memory.peak", -1)
            peak = None if peak < 0 else peak
            cpu = _keyed(mem / "cpu.stat").get("usage_usec", 0) / 1e6  # there without cpu too
        else:
            sw = "memsw." if "swap" in self.support.controllers else ""
            current = _read_int(mem / f"memory.{sw}usage_in_bytes")
            peak = _read_int(mem / f"memory.{sw}max_usage_in_bytes")
            cpu = _read_int(d["cpuacct"] / "cpuacct.usage") / 1e9 if "cpuacct" in d else None
        if "pids" in d and "pids" in self.support.controllers:
            processes = _read_int(d["pids"] / "pids.current")
        else:
            processes = len(self.procs())
        return CgroupUsage(current, peak, cpu, processes)

    def met(self) -> dict[str, str]:
        """The limits the run has met, by the kernel's own counters, each with the sentence
        for the run's log; keys "memory", "processes", "cpu_seconds"."""
        d, met = self.dirs, {}
        mem = d["memory"]
        # Out of memory only: coming to the limit is not (v2's `max` event and v1's failcnt
        # count each time the kernel took page cache back there, as for a program reading a
        # large file, which then goes on as if it had no limit).
        if self.v2:
            events = _keyed(mem / "memory.events")
            kills, hit = events.get("oom_kill", 0), events.get("oom", 0)
        else:
            control = _keyed(mem / "memory.oom_control")
            kills, hit = control.get("oom_kill", 0), control.get("under_oom", 0)
        together = self.support.parent
        if (kills or hit) and together is not None and not self._came_to_own_limit():
            # All runs together did. Only a kill of this run's counts: v1 marks every run
            # under_oom while their parent is, and the kernel may have spared this one.
            if kills:
                met["memory"] = (
                    f"the memory limit of all runs together ({together.memory_bytes // MB} MB)"
                    f" reached: the kernel killed {kills} of this run's processes"
                )
        elif kills or hit:
            limit = f" ({self.memory_bytes // MB} MB)" if self.memory_bytes else ""
            met["memory"] = f"memory limit{limit} reached"
            if kills:
                met["memory"] += f": the kernel killed {kills} of its processes"
        if "pids" in d and _keyed(d["pids"] / "pids.events").get("max", 0):
            met["processes"] = f"process limit ({self.pids} processes) reached"
        if self.cpu_seconds:
            used = self.usage().cpu_seconds
            if used is not None and used >= self.cpu_seconds:
                met["cpu_seconds"] = f"CPU time limit ({self.cpu_seconds:g} s) reached"
        return met

    def _came_to_own_limit(self) -> bool:
        """Whether the run's memory came up to its own limit (else all runs' together did).
        By its peak: the kernel's failcnt stays 0 on some kernels (this machine's), and v2's
        `max` event also counts page cache taken back. A charge refused at the limit may be
        a huge page's: the peak then stops short of it by up to that much."""
        if not self.memory_bytes:
            return True  # not known here: what the run's own limit would say
        peak = self.usage().memory_peak_bytes
        if peak is None:  # v2 before 5.19: no memory.peak
            return _keyed(self.dirs["memory"] / "memory.events").get("oom", 0) > 0
        return peak + REFUSED_CHARGE_MAX >= self.memory_bytes

    def kill(self, timeout: float = 2.0) -> bool:
        """SIGKILL every process of the run, forks made meanwhile included. True: none left."""
        deadline = time.monotonic() + timeout
        if self.v2 and (self.dirs["memory"] / "cgroup.kill").exists():
            try:
                _write(self.dirs["memory"] / "cgroup.kill", 1)  # the kernel does it all at once
            except FileNotFoundError:
                return True
        while pids := self.procs():
            if time.monotonic() > deadline:
                return False
            # Frozen, a fork bomb cannot fork faster than it is killed.
            with self._frozen():
                for pid in self.procs() or pids:
                    try:
                        os.kill(pid, signal.SIGKILL)
                    except ProcessLookupError:
                        pass
            time.sleep(0.01)
        return True

    def _frozen(self):
        if self.v2:
            return _Freeze(self.dirs["memory"] / "cgroup.freeze", "1", "0")
        if "freezer" in self.dirs:
            return _Freeze(self.dirs["freezer"] / "freezer.state", "FROZEN", "THAWED")
        return _Freeze(None, "", "")

    def remove(self, timeout: float = 1.0) -> bool:
        """Kill what is left and remove the cgroup (nested ones too). Never raises; True: gone."""
        try:
            self.kill()
        except OSError:
            pass
        deadline, gone = time.monotonic() + timeout, True
        for folder in self.folders():
            for parent, _, _ in os.walk(folder, topdown=False):
                while True:
                    try:
                        os.rmdir(parent)
                        break
                    except FileNotFoundError:
                        break
                    except OSError:  # EBUSY: its last processes are still exiting
                        if time.monotonic() > deadline:
                            gone = False
                            break
                        time.sleep(0.02)
        return gone


class _Freeze:
    """Freezes a cgroup for the time of a `with` (no-op without a freezer)."""

    def __init__(self, file: Path | None, frozen: str, thawed: str):
        self.file, self.frozen, self.thawed = file, frozen, thawed

    def __enter__(self):
        if self.file is None:
            return
        try:
            _write(self.file, self.frozen)
        except OSError:
            self.file = None
            return
        # Wait briefly for the freeze to take; a task stuck in the kernel may delay it.
        events = self.file.with_name("cgroup.events")
        for _ in range(50):
            if self.file.name == "freezer.state":
                if self.file.read_text().strip() == "FROZEN":
                    return
            elif _keyed(events).get("frozen", 1):
                return
            time.sleep(0.01)

    def __exit__(self, *exc):
        if self.file is not None:
            try:
                _write(self.file, self.thawed)
            except OSError:
                pass


def sweep(support: CgroupSupport, prefix: str = "") -> list[str]:
    """Kill and remove the run cgroups whose name starts with `prefix`, left by a dead agent.

    Agents may share a base (here pids and cpu are at the root): give each agent its own
    prefix for its runs' names, and sweep only that."""
    names = set()
    for base in support.folders():
        try:
            entries = list(os.scandir(base))
        except OSError:
            continue
        names.update(e.name for e in entries if e.is_dir() and e.name.startswith(prefix))
    for name in sorted(names):
        RunCgroup(name, support).remove()
    return sorted(names)
