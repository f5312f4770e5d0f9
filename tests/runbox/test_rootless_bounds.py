"""A rootless run, without a cgroup it may write, is bounded as the robot page says.

The box is started as the account `nobody` (as tests/runbox/test_box.py does), so no cgroup
bounds the run as a whole. The description the agent stores for the robot page and the API
(InForce.describe) must then say exactly what holds: each process's memory, the number of
processes, one run at a time, and that there is no run-wide memory limit. Each claim is tried
by a real program in the real box.
"""

import os

import pytest

from tests.runbox.test_box import box_run, readable_copy  # noqa: F401 (a fixture)

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="becomes `nobody`: run as root")

# Four children touch SIZE MB each at once and hold it until all have answered; their parent
# then adds up what they hold (VmRSS) and tries to start FORKS processes.
PROGRAM = """
import os
MB = 1024 * 1024

def child(size, report, go):
    try:
        data = bytearray(size * MB)
        for i in range(0, len(data), 4096):
            data[i] = 1
        os.write(report, b"HELD\\n")
    except MemoryError:
        os.write(report, b"REFUSED\\n")
    os.read(go, 1)
    os._exit(0)

def hold(size):
    report_r, report_w = os.pipe()
    go_r, go_w = os.pipe()
    pids = []
    for _ in range(4):
        pid = os.fork()
        if pid == 0:
            os.close(go_w)  # its parent's close is its go: no child may hold it open
            child(size, report_w, go_r)
        pids.append(pid)
    answers = b""
    while answers.count(b"\\n") < 4:
        answers += os.read(report_r, 64)
    held = 0
    for pid in pids:
        for line in open(f"/proc/{pid}/status"):
            if line.startswith("VmRSS:"):
                held += int(line.split()[1]) * 1024
    print(size, "MB:", sorted(answers.decode().split()), "together", held // MB, "MB", flush=True)
    os.close(go_w)
    for pid in pids:
        os.waitpid(pid, 0)

def forks(most):
    go_r, go_w = os.pipe()
    pids = []
    for _ in range(most):
        try:
            pid = os.fork()
        except BlockingIOError:
            break
        if pid == 0:
            os.close(go_w)
            os.read(go_r, 1)
            os._exit(0)
        pids.append(pid)
    print("FORKED", len(pids), flush=True)
    os.close(go_w)
    for pid in pids:
        os.waitpid(pid, 0)

hold(450)
hold(300)
forks(100)
"""


def test_a_rootless_run_with_four_450_mb_children_is_bounded_as_the_page_says(readable_copy):  # noqa: F811
    limits = {"memory_mb": 400, "processes": 32}
    result = box_run("rootless", readable_copy, PROGRAM, limits=limits, network="none")
    assert result["state"] == "finished", result["log"]
    said = result["isolation"]
    assert said.startswith(
        "rootless box (user namespaces), own user namespace, seccomp, network none;"
        " no cgroups: robotide is not root and cannot write to "
    ), said
    assert said.endswith(
        " — per-process rlimits only: each process at most 400 MB, at most 32 processes,"
        " one run at a time; no run-wide memory limit: no delegated cgroup"
    ), said
    assert result["runs_at_once"] == 1  # what the robot's queue reads
    log = result["log"]
    # Each process at most 400 MB: every child that wants 450 MB is refused.
    assert "o 450 MB: ['REFUSED', 'REFUSED', 'REFUSED', 'REFUSED']" in log, log
    # No run-wide memory limit, as said: four of 300 MB hold more than 400 MB together.
    held = next(line for line in log.splitlines() if line.startswith("o 300 MB:"))
    assert "['HELD', 'HELD', 'HELD', 'HELD'] together" in held, log
    assert int(held.split("together")[1].split()[0]) > 4 * 290, held
    # At most 32 processes: the run's own included, its 100 forks stop short.
    forked = int(next(line for line in log.splitlines() if "FORKED" in line).split()[-1])
    assert 0 < forked < 32, log


@pytest.mark.parametrize("mode", ["root", "rootless"])
def test_a_runs_processes_are_the_oom_killers_first_choice(mode, readable_copy):  # noqa: F811
    source = "print('ADJ', open('/proc/self/oom_score_adj').read())"
    result = box_run(mode, readable_copy, source, network="none")
    assert result["state"] == "finished", result["log"]
    assert "o ADJ 1000" in result["log"], result["log"]


# Address space reserved and never touched, as Node.js's heap reservations are; then a loop.
RESERVES = """
import mmap, time
reserved = mmap.mmap(-1, 700 * 1024 * 1024)
print("READY", flush=True)
while True:
    time.sleep(0.05)
"""


@pytest.mark.parametrize("mode", ["root", "rootless"])
def test_a_run_its_user_stops_is_not_said_to_have_met_its_memory_limit(mode, readable_copy):  # noqa: F811
    limits = {"memory_mb": 768}  # the run reserves 700 MB of it: over 0.9 of the limit
    result = box_run(
        mode, readable_copy, RESERVES, limits=limits, network="none",
        stop_on="READY", stop_on_peak_mb=700,
    )  # fmt: skip
    assert result["state"] == "stopped", result["log"]
    assert "memory limit" not in result["log"], result["log"]
