"""Boxes made ahead of their runs (runbox.ahead), as root: real bubblewrap boxes and cgroups.

What the agent relies on: a run takes the box made for its settings, whose processes are all
in a cgroup carrying the run's name from the program's first statement; a box made for other
settings, or one that ended while it waited, is never used and leaves nothing behind.
"""

import asyncio
import os
import signal
from pathlib import Path

import pytest

from runbox import SYSTEM_PATH, cgroups, launcher, seccomp
from runbox.ahead import Ahead
from runbox.box import Launch, make_box
from runbox.isolation import Policy
from runbox.supervisor import RunProcess

REPO = Path(__file__).resolve().parents[2]
PREFIX = f"test-ahead-{os.getpid()}-"
SOURCE = b"print(open('/proc/self/cgroup').read(), flush=True)\n"

pytestmark = pytest.mark.skipif(os.geteuid() != 0, reason="bubblewrap boxes as root")


@pytest.fixture
def boxes(tmp_path):
    """An Ahead that makes boxes for network `key` ("none" or "loopback"), and what it made."""
    support = cgroups.detect()
    assert support.available, support.describe()
    limits = launcher.Limits()
    made: list[RunProcess] = []

    def make(name: str, key: str) -> RunProcess:
        in_force = Policy(network=key).resolve(REPO / "programs" / "clients")
        cgroup = cgroups.RunCgroup.create(name, support, memory_bytes=256 << 20, pids=64)
        box = make_box(
            in_force, socket_dir=tmp_path, disk_mb=16, cgroup=cgroup,
            seccomp_fd=seccomp.open_filter_fd(), rlimits=limits.rlimits(address_space=False),
        )  # fmt: skip
        process = RunProcess(box.command(), env={"PATH": SYSTEM_PATH}, cwd=tmp_path, box=box)
        made.append(process)
        return process

    ahead = Ahead(make, PREFIX, delay=0)
    yield ahead, made
    cgroups.sweep(support, PREFIX)


def launch(uid: int) -> Launch:
    argv = ["setpriv", f"--reuid={uid}", f"--regid={uid}", "--clear-groups", "--"]
    return Launch("main.py", SOURCE, [*argv, "/usr/bin/python3", "/home/robot/main.py"], {})


async def run(process: RunProcess, log: Path) -> str:
    await process.begin(launch(1_999_000_001), log_path=log, on_output=lambda *_: None)
    outcome = await process.wait()
    await process.box.close()
    assert outcome.state == "finished", log.read_text()
    return log.read_text()


async def settled(ahead: Ahead) -> None:
    while ahead._making is not None and not ahead._making.done():
        await asyncio.sleep(0.01)


async def test_a_run_takes_the_box_made_for_it(boxes, tmp_path):
    ahead, made = boxes
    try:
        ahead.soon("none")
        await settled(ahead)
        ready = ahead.ready
        assert ready is not None and ready.box.cgroup.name == f"{PREFIX}box-1"
        taken = await ahead.take("none", "run-1")
        assert taken is ready and taken.box.cgroup.name == f"{PREFIX}run-1"
        log = await run(taken, tmp_path / "1.log")
        # Born in the run's cgroup, under its name, in every hierarchy in force.
        memory = [line for line in log.splitlines() if ":memory:" in line]
        assert memory and memory[0].endswith(f"/{PREFIX}run-1"), log
        await settled(ahead)
        assert ahead.ready is not None and ahead.ready is not taken  # the next one, made
    finally:
        await ahead.close()
    assert all(not p.running for p in made)


async def test_a_box_for_other_settings_is_not_used_and_goes(boxes, tmp_path):
    ahead, made = boxes
    try:
        ahead.soon("none")
        await settled(ahead)
        old = ahead.ready
        old_pid = old.box.init_pid
        taken = await ahead.take("loopback", "run-2")
        assert taken is not old and not old.running
        assert not Path(f"/proc/{old_pid}").exists()
        assert not any(folder.exists() for folder in old.box.cgroup.folders())
        await run(taken, tmp_path / "2.log")
    finally:
        await ahead.close()


async def test_a_box_that_ended_while_it_waited_is_made_again(boxes, tmp_path):
    ahead, made = boxes
    try:
        ahead.soon("none")
        await settled(ahead)
        dead = ahead.ready
        os.kill(dead.box.init_pid, signal.SIGKILL)  # an operator, the OOM killer...
        await asyncio.wait_for(dead.wait(), 5)
        taken = await ahead.take("none", "run-3")
        # Made now, at the start: its processes join the cgroup while the program starts.
        assert taken is not dead and taken.box.cgroup.name == f"{PREFIX}run-3"
        await run(taken, tmp_path / "3.log")
    finally:
        await ahead.close()
