"""runbox.cgroups on a real cgroup2 hierarchy (the kernel's, not a fake tree of files).

This machine mounts the v1 controllers (memory, pids, cpu...) and beside them the cgroup2
hierarchy at /sys/fs/cgroup/unified, with no resource controller a run needs: what it has is
what every v2 cgroup has (cgroup.procs, cgroup.kill, cgroup.freeze, cgroup.events, cpu.stat),
and that is what these tests hold the v2 code to: the agent's leaf ("no internal
processes"), the run's cgroup, CPU seconds summed over forks from cpu.stat, the kill of a
whole run at once, the rename the kernel refuses on v2 (it found that a box made ahead
cannot take its run's name there), the removal, and detection saying why runs cannot have
v2 here. On a machine with a v2-only tree (Debian 12), the same tests run there, with memory,
pids and cpu as well.
"""

import os
import subprocess
import sys
import time
from pathlib import Path

import pytest

from runbox.cgroups import MB, V2_CONTROLLERS, CgroupError, CgroupSupport, RunCgroup, detect

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="needs root to make cgroups")


def until(condition, timeout: float, step: float = 0.05):
    deadline = time.monotonic() + timeout
    while not (result := condition()):
        if time.monotonic() > deadline:
            return result
        time.sleep(step)
    return result


def cgroup2_mount() -> Path:
    for line in Path("/proc/self/mountinfo").read_text().splitlines():
        fields = line.split()
        if fields[fields.index("-") + 1] == "cgroup2":
            return Path(fields[4])
    raise AssertionError("no cgroup2 hierarchy is mounted: these tests need one")


def own_v2_path() -> str:
    for line in Path("/proc/self/cgroup").read_text().splitlines():
        if line.startswith("0::"):
            return line[3:]
    raise AssertionError("this process is in no cgroup2 cgroup")


@pytest.fixture
def parent():
    """A cgroup of this test's, where the agent would be: one process in it (the agent's)."""
    folder = cgroup2_mount() / own_v2_path().lstrip("/") / f"robotide-v2-test-{os.getpid()}"
    folder.mkdir()
    agent = subprocess.Popen(["sleep", "60"])
    (folder / "cgroup.procs").write_text(str(agent.pid))
    try:
        yield folder, agent
    finally:
        agent.kill()
        agent.wait()
        for sub in sorted(folder.rglob("*"), key=lambda p: len(p.parts), reverse=True):
            if sub.is_dir():
                until(lambda s=sub: _rmdir(s), timeout=2)
        until(lambda: _rmdir(folder), timeout=2)


def _rmdir(path: Path) -> bool:
    try:
        path.rmdir()
        return True
    except FileNotFoundError:
        return True
    except OSError:
        return False


def support_for(folder: Path) -> CgroupSupport:
    """What detect() would give an agent in `folder`, minus its demand for memory."""
    offered = (folder / "cgroup.controllers").read_text().split()
    controllers = [name for name in V2_CONTROLLERS if name in offered]
    if (folder / "cgroup.kill").exists():
        controllers.append("kill")
    return CgroupSupport("v2", tuple(controllers), dict.fromkeys(V2_CONTROLLERS, folder / "runs"))


def cgroup_of(pid: int) -> str:
    return [x for x in Path(f"/proc/{pid}/cgroup").read_text().splitlines() if x[:3] == "0::"][0]


BURNERS = """
import os, time
for _ in range(3):
    if os.fork() == 0:
        while True:
            pass
print("forked", flush=True)
time.sleep(60)
"""


def test_a_run_cgroup_on_the_real_v2_kernel(parent):
    folder, agent = parent
    support = support_for(folder)
    assert "kill" in support.controllers, "kernel without cgroup.kill (before 5.14)"
    cg = RunCgroup.create(
        "run-1", support, memory_bytes=256 * MB, pids=32, cpu_percent=100, cpu_seconds=1
    )
    try:
        # "No internal processes": the agent's process went to its leaf first.
        assert cgroup_of(agent.pid).endswith(f"/{folder.name}/robotide-agent")
        run = folder / "runs" / "run-1"
        assert run.is_dir() and cg.folders() == [run]
        for name, file, value in (("pids", "pids.max", "32"), ("cpu", "cpu.max", "100000 100000")):
            if name in support.controllers:  # a v2-only machine: the kernel holds the limit
                assert (run / file).read_text().strip() == value
        program = subprocess.Popen(
            cg.command([sys.executable, "-c", BURNERS]), stdout=subprocess.PIPE, text=True
        )
        assert program.stdout.readline() == "forked\n"
        assert len(cg.members()) == 4 and program.pid in cg.members()
        assert cgroup_of(program.pid).endswith("/runs/run-1")
        # CPU seconds of the whole run, forks included, as the kernel counts them.
        met = until(lambda: cg.met().get("cpu_seconds"), timeout=20)
        assert met == "CPU time limit (1 s) reached"
        assert cg.usage().cpu_seconds >= 1 and cg.usage().processes >= 4
        with pytest.raises(CgroupError, match="Operation not permitted"):
            cg.rename("run-1-renamed")  # v2 never renames: a box made ahead keeps its name
        assert cg.name == "run-1" and cgroup_of(program.pid).endswith("/runs/run-1")
        assert cg.kill()  # cgroup.kill: the kernel ends every process of the run at once
        assert program.wait(timeout=5) == -9 and cg.procs() == set()
        assert (run / "cgroup.events").read_text().startswith("populated 0")
    finally:
        assert cg.remove()
    assert not run.exists()


def test_detect_on_the_real_v2_tree_says_what_it_finds(parent, tmp_path):
    """detect() reads the real cgroup2 mount: with no memory controller handed down there,
    runs get rlimits and the robot's page says why; where it is, a v2 support."""
    folder, _ = parent
    proc = tmp_path / "proc"
    proc.mkdir()
    # The process detect() looks at is one in `folder`, as an agent there would be.
    relative = folder.relative_to(cgroup2_mount())
    (proc / "cgroup").write_text(f"0::/{relative}\n")
    (proc / "mountinfo").write_text(
        "\n".join(
            line
            for line in Path("/proc/self/mountinfo").read_text().splitlines()
            if line.split()[line.split().index("-") + 1] == "cgroup2"
        )
        + "\n"
    )
    found = detect(str(proc))
    if "memory" in (folder / "cgroup.controllers").read_text().split():
        assert found.describe().startswith("cgroup v2 (memory"), found.describe()
    else:
        assert not found.available
        assert found.why == f"the memory controller is not delegated to {folder} (cgroup v2)"
