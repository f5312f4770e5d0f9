"""runbox.cgroups against the real kernel (cgroup v1 on this machine), with real processes.

Each limit test is one that per-process rlimits would fail: four children of 450 MB each under
1024 MB, CPU seconds spread over forks, forks as root (RLIMIT_NPROC does not bind root).
The cgroup v2 code paths that this machine cannot run are checked at the end against a FAKE
cgroup2 tree in a temporary folder (plain files, no kernel behind them).
"""

import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import pytest

from runbox.cgroups import MB, CgroupError, CgroupSupport, RunCgroup, detect, sweep

PREFIX = f"test-{os.getpid()}-"
SYSTEM_PYTHON = "/usr/bin/python3"  # readable by the unprivileged user of the non-root tests
REPO = Path(__file__).resolve().parents[2]

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="needs root to make cgroups")


def until(condition, timeout: float, step: float = 0.05):
    deadline = time.monotonic() + timeout
    while not (result := condition()):
        if time.monotonic() > deadline:
            return result
        time.sleep(step)
    return result


@pytest.fixture
def support() -> CgroupSupport:
    detect.cache_clear()
    found = detect()
    assert found.available, found.describe()
    return found


@pytest.fixture
def make(support):
    """RunCgroup.create with this test's names; removes them and their bases afterwards."""
    made: list[RunCgroup] = []

    def create(**limits) -> RunCgroup:
        limits.setdefault("memory_bytes", 256 * MB)
        limits.setdefault("pids", 64)
        cg = RunCgroup.create(f"{PREFIX}{len(made)}", support, **limits)
        made.append(cg)
        return cg

    yield create
    for cg in made:
        assert cg.remove(), f"{cg.name} left behind"
    for base in support.folders():
        try:
            base.rmdir()  # only if empty: another user's runs may be there
        except OSError:
            pass


def start(cg: RunCgroup, code: str) -> subprocess.Popen:
    return subprocess.Popen(
        cg.command([sys.executable, "-c", code]), stdout=subprocess.PIPE, text=True
    )


def test_detects_v1_below_own_cgroup_here(support):
    own = dict(line.split(":", 2)[1:] for line in Path("/proc/self/cgroup").read_text().split())
    assert support.version == "v1"
    assert support.describe() == "cgroup v1 (memory+swap, pids, cpu, cpuacct, freezer)"
    memory_base = support.bases["memory"]
    assert memory_base.name == "robotide-runs"
    assert str(memory_base.parent).endswith(own["memory"].rstrip("/"))
    assert (memory_base.parent / "memory.limit_in_bytes").exists()


def test_not_root_says_why_and_does_not_raise():
    code = "from runbox.cgroups import detect; print(detect().describe())"
    out = subprocess.run(
        ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups", SYSTEM_PYTHON, "-c", code],
        cwd=REPO, capture_output=True, text=True, timeout=10,
    )  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert out.stdout.startswith("no cgroups: robotide is not root and cannot write to /sys/fs/")
    assert out.stdout.rstrip().endswith("— per-process rlimits only")


def test_memory_limit_holds_for_the_whole_run(make):
    cg = make(memory_bytes=1024 * MB)
    # The attack that passed prlimit --as: four children of 450 MB each (every page touched).
    p = start(cg, """
import os, time
for _ in range(4):
    if os.fork() == 0:
        data = b"x" * (450 << 20)
        time.sleep(30)
        os._exit(0)
time.sleep(30)
""")  # fmt: skip
    try:
        met = until(lambda: "killed" in cg.met().get("memory", ""), timeout=20)
        assert met, f"no OOM kill; usage {cg.usage()}"
        usage = cg.usage()
        assert usage.memory_peak_bytes <= 1024 * MB
        assert cg.met()["memory"].startswith("memory limit (1024 MB) reached: the kernel killed")
    finally:
        assert cg.kill()
        p.wait(timeout=5)


def test_reading_files_past_the_limit_is_not_meeting_it(make, tmp_path):
    """A program that reads more data than its memory limit (a map, a recorded flight) fills
    the page cache, which the kernel takes back at the limit: the run was never short of
    memory, and must not be ended as if it had been (v2 counts each such reclaim as a `max`
    event; older kernels' v1 in memory.failcnt)."""
    data = tmp_path / "recording.bin"
    with open(data, "wb") as f:
        for _ in range(192):
            f.write(os.urandom(1 << 20))
        f.flush()
        os.fsync(f.fileno())
        os.posix_fadvise(f.fileno(), 0, 0, os.POSIX_FADV_DONTNEED)  # the run reads it in
    cg = make(memory_bytes=64 * MB)
    p = start(cg, f"""
with open({str(data)!r}, "rb") as f:
    while f.read(1 << 20):
        pass
print("read it all")
""")  # fmt: skip
    out, _ = p.communicate(timeout=60)
    assert p.returncode == 0 and out == "read it all\n", (p.returncode, out)
    assert cg.usage().memory_peak_bytes > 48 * MB  # the cache did come up to the limit
    assert "memory" not in cg.met(), cg.met()


def test_cpu_seconds_add_up_across_forks(make):
    cg = make(cpu_percent=None, cpu_seconds=1.5)
    # Three burners of 0.8 s each: none alone reaches 1.5 s (an rlimit never fires), the run does.
    p = start(cg, """
import os, time
for _ in range(3):
    if os.fork() == 0:
        while time.process_time() < 0.8:
            pass
        os.write(1, f"{time.process_time()}\\n".encode())  # one write: lines do not mix
        os._exit(0)
for _ in range(3):
    os.wait()
""")  # fmt: skip
    out, _ = p.communicate(timeout=15)
    each = [float(line) for line in out.split()]
    assert len(each) == 3 and max(each) < 1.5
    used = cg.usage().cpu_seconds
    assert used >= sum(each) > 2.3
    assert cg.met()["cpu_seconds"] == "CPU time limit (1.5 s) reached"


def test_cpu_percent_caps_the_run(make):
    cg = make(cpu_percent=50)
    # Three burners for 1.5 s of wall time would get ~3 CPU seconds from two cores uncapped.
    p = start(cg, """
import os, time
end = time.monotonic() + 1.5
for _ in range(3):
    if os.fork() == 0:
        while time.monotonic() < end:
            pass
        os._exit(0)
for _ in range(3):
    os.wait()
""")  # fmt: skip
    p.wait(timeout=15)
    assert 0.3 < cg.usage().cpu_seconds < 1.0
    assert "cpu_seconds" not in cg.met()  # no total given


def test_pids_limit_stops_forks(make):
    cg = make(pids=8)
    p = start(cg, """
import os, time
made = failed = 0
for _ in range(20):
    try:
        if os.fork() == 0:
            time.sleep(30)
            os._exit(0)
        made += 1
    except BlockingIOError:
        failed += 1
print(made, failed, flush=True)
""")  # fmt: skip
    made, failed = map(int, p.stdout.readline().split())  # the orphans keep stdout open
    p.wait(timeout=5)
    assert made == 7 and failed == 13  # the first process counts as one of the eight
    assert cg.met()["processes"] == "process limit (8 processes) reached"
    assert len(cg.procs()) == 7  # orphans, outliving the program's first process
    assert cg.kill()


def test_kill_leaves_nothing(make):
    cg = make(pids=200)
    # Sleepers, a double-forked daemon in its own session, and a child that forks without end.
    p = start(cg, """
import os, time
def child(body):
    if os.fork() == 0:
        body()
        os._exit(0)
def daemon():
    os.setsid()
    child(lambda: time.sleep(60))
def spawner():
    while True:
        try:
            child(lambda: time.sleep(0.2))
        except BlockingIOError:
            time.sleep(0.01)
for body in [lambda: time.sleep(60)] * 5 + [daemon, spawner]:
    child(body)
time.sleep(60)
""")  # fmt: skip
    assert until(lambda: len(cg.procs()) >= 9, timeout=10)
    seen = cg.procs()
    assert cg.kill()
    assert cg.procs() == set()
    assert p.wait(timeout=5) == -9
    # The orphans were children of init: wait until it has reaped them.
    assert until(lambda: not any(os.path.exists(f"/proc/{pid}") for pid in seen), timeout=5)


def test_add_moves_a_process_in_every_hierarchy(make, support):
    cg = make()
    sleeper = subprocess.Popen(["sleep", "30"])
    try:
        cg.add(sleeper.pid)
        assert sleeper.pid in cg.procs()
        lines = Path(f"/proc/{sleeper.pid}/cgroup").read_text().splitlines()
        inside = {
            c
            for line in lines
            if line.endswith("/" + cg.name)
            for c in line.split(":")[1].split(",")
        }
        assert inside == set(support.bases)
    finally:
        sleeper.kill()
        sleeper.wait()


def test_rename_takes_the_processes_and_limits_along(make, support):
    """A box made ahead takes its run's name: its processes stay, its limits too."""
    cg = make(pids=7)
    sleeper = subprocess.Popen(["sleep", "30"])
    try:
        cg.add(sleeper.pid)
        old = cg.folders()
        cg.rename(f"{PREFIX}renamed")
        assert not any(folder.exists() for folder in old)
        lines = Path(f"/proc/{sleeper.pid}/cgroup").read_text().splitlines()
        inside = {
            c for line in lines if line.endswith(f"/{PREFIX}renamed")
            for c in line.split(":")[1].split(",")
        }  # fmt: skip
        assert inside == set(support.bases) and sleeper.pid in cg.members()
        assert (cg.dirs["pids"] / "pids.max").read_text().strip() == "7"
        other = make()
        with pytest.raises(CgroupError):
            cg.rename(other.name)  # taken: it keeps its name everywhere
        assert cg.name == f"{PREFIX}renamed" and all(f.exists() for f in cg.folders())
    finally:
        sleeper.kill()
        sleeper.wait()


def test_remove_kills_and_cleans_up(make):
    cg = make()
    p = start(cg, "import time; time.sleep(30)")
    assert until(lambda: cg.procs(), timeout=5)
    assert cg.remove()
    assert p.wait(timeout=5) == -9
    assert not any(folder.exists() for folder in cg.folders())
    assert cg.remove()  # again: nothing to do, no error


def test_sweep_removes_only_the_prefix(make, support):
    stale, other = make(), make()
    stale_name = stale.name
    p = start(stale, "import time; time.sleep(30)")
    assert until(lambda: stale.procs(), timeout=5)
    # As a new agent would after a crash: by name only, nothing remembered of the runs.
    assert sweep(support, prefix=stale_name) == [stale_name]
    assert p.wait(timeout=5) == -9
    assert not any(folder.exists() for folder in stale.folders())
    assert all(folder.exists() for folder in other.folders())


# ---- FAKE cgroup2 tree: plain files laid out like /sys/fs/cgroup; no kernel behind them. ----
# These check only which files the v2 code reads and writes (detection, placement, the "no
# internal processes" move, subtree_control, limit values, met/usage parsing, cgroup.kill).


def fake_v2(root: Path, own: str = "/robotide.service", procs: str = "111\n222\n") -> Path:
    """A proc dir (cgroup, mountinfo) and a cgroup2 mount at root/cg; returns the proc dir."""
    proc, mount = root / "proc", root / "cg"
    proc.mkdir()
    (proc / "cgroup").write_text(f"0::{own}\n")
    (proc / "mountinfo").write_text(
        "22 1 0:21 / / rw - ext4 /dev/vda rw\n"
        f"31 22 0:27 / {mount} rw,nosuid - cgroup2 cgroup2 rw,nsdelegate\n"
    )
    service = mount / "robotide.service"
    service.mkdir(parents=True)
    files = {
        "cgroup.controllers": "cpuset cpu io memory pids\n",
        "cgroup.subtree_control": "",
        "cgroup.procs": procs,
        "cgroup.type": "domain\n",
        "memory.swap.max": "max\n",
        "cgroup.kill": "",
    }
    for name, text in files.items():
        (service / name).write_text(text)
    return proc


def test_fake_v2_detect_and_create(tmp_path):
    proc = fake_v2(tmp_path)
    own = tmp_path / "cg" / "robotide.service"
    support = detect(str(proc))
    assert support.describe() == "cgroup v2 (memory+swap, pids, cpu, kill)"
    assert support.folders() == [own / "robotide-runs"]

    cg = RunCgroup.create(
        "run-7", support, memory_bytes=1024 * MB, pids=64, cpu_percent=100, cpu_seconds=600
    )
    # The agent's processes went into a leaf before controllers were handed down.
    assert (own / "robotide-agent" / "cgroup.procs").read_text() == "111\n222\n"
    assert (own / "cgroup.subtree_control").read_text() == "+memory\n+pids\n+cpu\n"
    runs = own / "robotide-runs"
    assert (runs / "cgroup.subtree_control").read_text() == "+memory\n+pids\n+cpu\n"
    run = runs / "run-7"
    assert (run / "memory.max").read_text() == f"{1024 * MB}\n"
    assert (run / "pids.max").read_text() == "64\n"
    assert (run / "cpu.max").read_text() == "100000 100000\n"
    argv = cg.command(["prog", "an arg"])
    assert argv[0] == "/bin/sh" and argv[-2:] == ["prog", "an arg"]
    assert f"for f in {run / 'cgroup.procs'}; do" in argv[2]  # one hierarchy on v2

    # What the kernel would have written, then what the run's log is told.
    (run / "memory.events").write_text("low 0\nhigh 0\nmax 9\noom 1\noom_kill 2\n")
    (run / "pids.events").write_text("max 3\n")
    (run / "cpu.stat").write_text("usage_usec 601000000\nuser_usec 1\n")
    (run / "memory.current").write_text("1000\n")
    (run / "memory.peak").write_text("2000\n")
    (run / "pids.current").write_text("5\n")
    assert cg.met() == {
        "memory": "memory limit (1024 MB) reached: the kernel killed 2 of its processes",
        "processes": "process limit (64 processes) reached",
        "cpu_seconds": "CPU time limit (600 s) reached",
    }
    usage = cg.usage()
    assert (usage.memory_bytes, usage.memory_peak_bytes) == (1000, 2000)
    assert (usage.cpu_seconds, usage.processes) == (601.0, 5)
    (run / "cgroup.kill").write_text("")
    assert cg.kill()
    assert (run / "cgroup.kill").read_text() == "1\n"


def test_fake_v2_reclaim_at_the_limit_is_not_meeting_it(tmp_path):
    """cgroup v2's memory.events counts `max` each time usage came to memory.max and the
    kernel reclaimed (page cache a program read, say); only `oom` and `oom_kill` say the run
    was short of memory (Documentation/admin-guide/cgroup-v2.rst)."""
    support = detect(str(fake_v2(tmp_path)))
    cg = RunCgroup.create("run-8", support, memory_bytes=64 * MB, pids=64)
    events = tmp_path / "cg" / "robotide.service" / "robotide-runs" / "run-8" / "memory.events"
    events.write_text("low 0\nhigh 0\nmax 4711\noom 0\noom_kill 0\noom_group_kill 0\n")
    (events.parent / "pids.events").write_text("max 0\n")
    assert cg.met() == {}
    events.write_text("low 0\nhigh 0\nmax 4712\noom 1\noom_kill 0\noom_group_kill 0\n")
    assert cg.met() == {"memory": "memory limit (64 MB) reached"}


def fake_v1(root: Path, memsw: bool) -> Path:
    """A proc dir and cgroup v1 memory, pids and cpu hierarchies at root/cg, with or without
    swap accounting (memory.memsw.*: a kernel booted without swapaccount=1)."""
    proc = root / "proc"
    proc.mkdir()
    (proc / "cgroup").write_text("6:memory:/robotide.service\n5:pids:/robotide.service\n")
    lines = ["22 1 0:21 / / rw - ext4 /dev/vda rw"]
    for n, name in enumerate(("memory", "pids")):
        own = root / "cg" / name / "robotide.service"
        own.mkdir(parents=True)
        (own / "memory.limit_in_bytes").write_text("9223372036854771712\n")
        if memsw:
            (own / "memory.memsw.limit_in_bytes").write_text("9223372036854771712\n")
        lines.append(f"{30 + n} 22 0:{27 + n} / {root / 'cg' / name} rw - cgroup cgroup rw,{name}")
    (proc / "mountinfo").write_text("\n".join(lines) + "\n")
    return proc


@pytest.mark.parametrize("memsw", [True, False])
def test_fake_v1_swap_is_inside_the_limit_with_or_without_accounting(tmp_path, memsw):
    """Memory with swap: where v1 counts swap (memsw) RAM + swap is limited; where it does not,
    the run's memory.swappiness is 0, which keeps limit reclaim from ever swapping
    (Documentation/admin-guide/cgroup-v1/memory.rst), so the run meets its limit in RAM."""
    support = detect(str(fake_v1(tmp_path, memsw)))
    assert support.describe().startswith(
        "cgroup v1 (memory+swap, pids" if memsw else "cgroup v1 (memory, pids"
    ), support.describe()
    RunCgroup.create("run-9", support, memory_bytes=64 * MB, pids=16)
    run = tmp_path / "cg" / "memory" / "robotide.service" / "robotide-runs" / "run-9"
    assert (run / "memory.limit_in_bytes").read_text() == f"{64 * MB}\n"
    if memsw:
        assert (run / "memory.memsw.limit_in_bytes").read_text() == f"{64 * MB}\n"
        assert not (run / "memory.swappiness").exists()
    else:
        assert (run / "memory.swappiness").read_text() == "0\n"


def test_fake_v2_agent_already_in_its_leaf(tmp_path):
    # After the move above, a re-detect sees the agent in robotide-agent: runs stay beside it.
    proc = fake_v2(tmp_path, own="/robotide.service/robotide-agent", procs="")
    support = detect(str(proc))
    assert support.folders() == [tmp_path / "cg" / "robotide.service" / "robotide-runs"]


def test_fake_v2_not_root_needs_a_delegated_cgroup():
    # Run as an unprivileged user: a cgroup it owns (Delegate=yes) serves, a root one does not.
    root = Path(tempfile.mkdtemp(prefix="fake-cgroup2-"))
    try:
        root.chmod(0o755)
        proc = fake_v2(root)
        code = f"from runbox.cgroups import detect; print(detect({str(proc)!r}).describe())"
        argv = ["setpriv", "--reuid=65534", "--regid=65534", "--clear-groups"]
        as_nobody = [*argv, SYSTEM_PYTHON, "-c", code]
        refused = subprocess.run(as_nobody, cwd=REPO, capture_output=True, text=True, timeout=10)
        assert refused.stdout.startswith("no cgroups: robotide is not root and cannot write to")
        assert "Delegate=yes" in refused.stdout
        for path in [
            root / "cg" / "robotide.service",
            *(root / "cg" / "robotide.service").iterdir(),
        ]:
            os.chown(path, 65534, 65534)
        delegated = subprocess.run(as_nobody, cwd=REPO, capture_output=True, text=True, timeout=10)
        assert delegated.stdout.strip() == "cgroup v2 (memory+swap, pids, cpu, kill)", delegated
    finally:
        shutil.rmtree(root)


def test_fake_v2_memory_not_delegated(tmp_path):
    proc = fake_v2(tmp_path)
    (tmp_path / "cg" / "robotide.service" / "cgroup.controllers").write_text("cpu pids\n")
    assert (
        detect(str(proc))
        .describe()
        .startswith("no cgroups: the memory controller is not delegated to")
    )
