"""runbox.share against the real kernel (cgroup v1 on this machine), with real processes: all
runs together live in one parent cgroup whose memory, processes and CPU weight are limited,
and runs that together want more memory than it has lose a process of theirs to the OOM killer,
never the process that made them (here the test, as the agent would be)."""

import os
import subprocess
import sys
import threading
import time
import zlib
from pathlib import Path

import pytest

from runbox.cgroups import MB, CgroupSupport, RunCgroup, detect, sweep
from runbox.share import Share, release_parent, runs_cgroups

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="needs root to make cgroups")

PAGE = os.sysconf("SC_PAGE_SIZE")
HOLD = """
import sys
data = bytearray({mb} * 1024 * 1024)
for i in range(0, len(data), 4096):  # touched: charged to the cgroup
    data[i] = 1
print("HELD", flush=True)
sys.stdin.read()
"""


def read_int(file: Path) -> int:
    return int(file.read_text().split()[0])


def server_memory() -> int:
    """What the server may use, found here apart from runbox.share: RAM, or its cgroup's limit."""
    total = next(
        int(line.split()[1]) * 1024
        for line in Path("/proc/meminfo").read_text().splitlines()
        if line.startswith("MemTotal:")
    )
    own = detect().bases["memory"].parent
    stat = dict(line.split() for line in (own / "memory.stat").read_text().splitlines())
    return min(total, int(stat["hierarchical_memory_limit"]))


@pytest.fixture
def parent_of():
    """runs_cgroups() for a robotide of this test's own; its runs and parent gone afterwards."""
    made: list[CgroupSupport] = []

    def make(share: Share) -> CgroupSupport:
        detect.cache_clear()
        support = runs_cgroups(share, f"/tmp/test-share-{os.getpid()}-{len(made)}")
        assert support.available, support.describe()
        made.append(support)
        return support

    yield make
    for support in made:
        sweep(support)
        for folder in support.folders():
            rmdir_when_empty(folder)


def rmdir_when_empty(folder: Path) -> None:
    for _ in range(100):  # EBUSY while the last killed processes are still exiting
        try:
            folder.rmdir()
            return
        except FileNotFoundError:
            return
        except OSError:
            time.sleep(0.05)
    raise AssertionError(f"{folder} could not be removed")


def test_the_parent_has_its_limits_and_every_run_is_inside(parent_of):
    support = parent_of(Share(memory_share=0.25, pids=512, cpu_weight=30))
    expected = int(0.25 * server_memory()) // PAGE * PAGE  # the kernel counts whole pages
    memory, pids, cpu = (support.bases[c] for c in ("memory", "pids", "cpu"))
    assert memory.parent == detect().bases["memory"].parent  # beside the server's processes
    assert read_int(memory / "memory.limit_in_bytes") == expected
    assert read_int(memory / "memory.memsw.limit_in_bytes") == expected  # swap no way out
    assert read_int(pids / "pids.max") == 512
    assert read_int(cpu / "cpu.shares") == 307  # 30 of the server's 100, as 1024 is to 100
    said = support.describe()
    assert said.startswith("cgroup v1 (memory+swap, pids, cpu, cpuacct, freezer); "), said
    assert said.endswith(
        f"; all runs together at most {int(0.25 * server_memory()) // MB} MB of memory"
        " and 512 processes, CPU weight 30 (the server's 100)"
    ), said

    run = RunCgroup.create("run-1", support, memory_bytes=256 * MB, pids=64)
    shown = subprocess.run(
        run.command(["cat", "/proc/self/cgroup"]), capture_output=True, text=True, check=True
    ).stdout
    lines = dict(line.split(":", 2)[1:] for line in shown.split())
    for controller in ("memory", "pids", "cpu", "cpuacct", "freezer"):
        assert lines[controller].endswith(f"/{memory.name}/run-1"), shown
        assert run.dirs[controller].parent == support.bases[controller]
    assert run.remove()


def test_a_parent_gone_is_made_again_with_its_limits(parent_of):
    """Whoever removed it meanwhile (an operator tidying up): a run never lands in a parent
    without limits."""
    support = parent_of(Share(memory_share=0.1, pids=300, cpu_weight=20))
    for folder in support.folders():
        folder.rmdir()
    run = RunCgroup.create("run-2", support, memory_bytes=64 * MB, pids=8)
    assert read_int(support.bases["pids"] / "pids.max") == 300
    limit = read_int(support.bases["memory"] / "memory.limit_in_bytes")
    assert limit == int(0.1 * server_memory()) // PAGE * PAGE
    assert run.remove()


def test_the_last_agent_leaves_no_parent_but_one_in_use_stays(parent_of):
    support = parent_of(Share(memory_share=0.1))
    run = RunCgroup.create("run-4", support, memory_bytes=64 * MB, pids=8)
    release_parent(support)  # another agent's run is in it: the kernel refuses
    assert all(folder.is_dir() for folder in support.folders())
    assert run.remove()
    release_parent(support)
    assert not any(folder.exists() for folder in support.folders())


def test_runs_together_stay_within_the_parent_and_lose_a_process_of_theirs(parent_of):
    """Three runs of 300 MB, each well within its own 1024 MB, in a parent of 700 MB: the
    kernel kills a run's process, the runs never hold more than the parent's limit, and the
    process that started them (the test, as the agent) goes on."""
    support = parent_of(Share(memory_share=700 * MB / server_memory()))
    limit = read_int(support.bases["memory"] / "memory.memsw.limit_in_bytes")
    runs = [
        RunCgroup.create(f"run-{n}", support, memory_bytes=1024 * MB, pids=16) for n in range(3)
    ]
    procs = [
        subprocess.Popen(
            run.command([sys.executable, "-c", HOLD.format(mb=300)]),
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )  # fmt: skip
        for run in runs
    ]
    # "HELD", or "" from one the kernel killed on the way (or it kills one that held)
    said = read_lines(procs)
    for proc in procs:
        proc.stdin.close()
    codes = [proc.wait() for proc in procs]
    killed = [n for n, code in enumerate(codes) if code == -9]
    assert 0 < len(killed) < 3, (said, codes)
    assert all(code == 0 and said[n] == "HELD\n" for n, code in enumerate(codes) if n not in killed)
    for n in killed:  # the kernel's own count: it was that run's process it killed
        assert runs[n].met() == {
            "memory": f"the memory limit of all runs together ({limit // MB} MB) reached:"
            " the kernel killed 1 of this run's processes"
        }
    for n in set(range(3)) - set(killed):  # those spared are not told they met a limit
        assert runs[n].met() == {}
    peak = read_int(support.bases["memory"] / "memory.memsw.max_usage_in_bytes")
    assert 600 * MB < peak <= limit, (peak, limit)
    for run in runs:
        assert run.remove()


def test_a_run_at_its_own_limit_inside_the_parent_is_told_its_own(parent_of):
    support = parent_of(Share(memory_share=0.25))
    run = RunCgroup.create("run-own", support, memory_bytes=100 * MB, pids=16)
    greedy = "chunks = []\nwhile True:\n    chunks.append(bytearray(10 * 1024 * 1024))\n"
    assert subprocess.run(run.command([sys.executable, "-c", greedy])).returncode == -9
    assert run.met() == {
        "memory": "memory limit (100 MB) reached: the kernel killed 1 of its processes"
    }
    assert run.remove()


def read_lines(procs: list[subprocess.Popen]) -> list[str]:
    """Each process's first line, read at once from all (one waits for memory another holds)."""
    lines = [""] * len(procs)

    def read(n: int) -> None:
        lines[n] = procs[n].stdout.readline()

    readers = [threading.Thread(target=read, args=(n,)) for n in range(len(procs))]
    for reader in readers:
        reader.start()
    for reader in readers:
        reader.join(120)  # only a kernel that never answers waits this long
    return lines


def test_fake_v2_parent_within_the_servers_own_limit(tmp_path):
    """cgroup v2, on a FAKE tree of plain files (this machine's v2 hierarchy has no memory
    controller): the parent beside the agent's leaf, controllers handed down to it, its limits
    in v2's files, its memory a share of the server's own cgroup's 2 GB (less than the RAM)."""
    from tests.runbox.test_cgroups import fake_v2

    proc = fake_v2(tmp_path)
    own = tmp_path / "cg" / "robotide.service"
    (own / "memory.max").write_text(f"{2048 * MB}\n")
    support = runs_cgroups(Share(0.5, 1000, 25), "/srv/robotide", detect(str(proc)))
    parent = own / f"robotide-runs-{zlib.crc32(b'/srv/robotide'):08x}"
    assert support.folders() == [parent]
    assert (own / "robotide-agent" / "cgroup.procs").read_text() == "111\n222\n"
    for folder in (own, parent):
        assert (folder / "cgroup.subtree_control").read_text() == "+memory\n+pids\n+cpu\n"
    assert (parent / "memory.max").read_text() == f"{1024 * MB}\n"
    assert (parent / "pids.max").read_text() == "1000\n"
    assert (parent / "cpu.weight").read_text() == "25\n"
    assert support.describe() == (
        "cgroup v2 (memory+swap, pids, cpu, kill); all runs together at most 1024 MB of memory"
        " and 1000 processes, CPU weight 25 (the server's 100)"
    )
    run = RunCgroup.create("run-3", support, memory_bytes=256 * MB, pids=64)
    assert run.folders() == [parent / "run-3"]
    assert (parent / "run-3" / "memory.max").read_text() == f"{256 * MB}\n"


def test_settings_out_of_range_are_refused_saying_which():
    for values, said in (
        ({"memory_share": 0}, "memory share"),
        ({"memory_share": 1.5}, "memory share"),
        ({"pids": 0}, "process limit"),
        ({"cpu_weight": 0}, "CPU weight"),
        ({"cpu_weight": 10_001}, "CPU weight"),
    ):
        with pytest.raises(ValueError, match=said):
            Share.from_settings(values)
    assert Share.from_settings({}) == Share(0.6, 4096, 50)
