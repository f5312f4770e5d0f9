"""The supervisor and the launcher, with real processes (no Django)."""

import asyncio
import os
import signal
import sys
import time
from pathlib import Path

import pytest

from programs.languages import LANGUAGES
from programs.runlog import tail
from runbox import launcher
from runbox.supervisor import RunProcess
from tests.waiting import DEADLINE, until

PYTHON = LANGUAGES["python"]
SHELL = LANGUAGES["shell"]


class Collector:
    def __init__(self):
        self.lines, self.skipped, self.batches, self.gaps = [], 0, 0, []

    def __call__(self, lines, skipped, skipped_from):
        self.gaps.append((skipped_from, lines[0][0] if lines else None, skipped))
        self.lines.extend(lines)
        self.skipped += skipped
        self.batches += 1


async def run(tmp_path: Path, source: str, language=PYTHON, limits=None, **kwargs):
    program = tmp_path / f"program{language.extension}"
    program.write_text(source)
    collector = Collector()
    process = RunProcess(
        launcher.command(language, program, limits or launcher.Limits()),
        env=launcher.environment(language, tmp_path, {"ROBOT_RUN_ID": "1"}),
        cwd=tmp_path,
        log_path=tmp_path / "output.log",
        on_output=collector,
        **kwargs,
    )
    await process.start()
    return process, collector


def log_lines(tmp_path):
    lines, earlier, _ = tail(tmp_path / "output.log", limit=10**9)
    assert earlier == 0
    return lines


async def test_it_captures_stdout_and_stderr_apart(tmp_path):
    process, collector = await run(
        tmp_path, "import sys\nprint('out 1')\nprint('err 1', file=sys.stderr)\nprint('out 2')\n"
    )
    outcome = await process.wait()
    assert (outcome.state, outcome.exit_code, outcome.reason) == ("finished", 0, "exit status 0")
    lines = log_lines(tmp_path)
    assert ("o", "out 1") in lines and ("o", "out 2") in lines and ("e", "err 1") in lines
    assert lines[-1] == ("s", "[robotide] finished: exit status 0")
    assert [(tag, text) for _, tag, text in collector.lines] == lines


async def test_live_lines_carry_their_offset_in_the_log(tmp_path):
    process, collector = await run(tmp_path, "for i in range(50): print(i)\n")
    await process.wait()
    data = (tmp_path / "output.log").read_bytes()
    for offset, tag, text in collector.lines:
        assert data[offset:].startswith(f"{tag} {text}\n".encode())


async def test_a_failing_program_is_failed_with_its_exit_status(tmp_path):
    process, _ = await run(tmp_path, "raise SystemExit(3)\n")
    outcome = await process.wait()
    assert (outcome.state, outcome.exit_code, outcome.reason) == ("failed", 3, "exit status 3")


async def test_a_line_without_newline_at_the_end_is_kept(tmp_path):
    process, _ = await run(tmp_path, "printf 'no newline'", language=SHELL)
    await process.wait()
    assert ("o", "no newline") in log_lines(tmp_path)


async def test_stop_terminates_the_whole_process_group(tmp_path):
    source = 'sleep 1000 &\nchild=$!\necho "child $child"\nwait\n'
    process, collector = await run(tmp_path, source, language=SHELL)
    await wait_until(lambda: any("child" in t for _, _, t in collector.lines))
    child = int(next(t for _, _, t in collector.lines if t.startswith("child")).split()[1])
    process.stop()
    outcome = await asyncio.wait_for(process.wait(), 10)
    assert outcome.state == "stopped"
    # The group was signalled; the child's own exit can trail its shell's on a busy machine
    # (its pipe closes before it is gone from the process table), so wait for it to go.
    await wait_until(lambda: not pid_alive(child))


async def test_a_program_that_ignores_sigterm_is_killed_after_the_grace_period(tmp_path):
    source = (
        "import signal, time\nsignal.signal(signal.SIGTERM, signal.SIG_IGN)\n"
        "print('ready', flush=True)\nwhile True: time.sleep(1)\n"
    )
    process, collector = await run(tmp_path, source, grace=0.5)
    await wait_until(lambda: collector.lines)
    process.stop()
    outcome = await asyncio.wait_for(process.wait(), 10)
    assert outcome.state == "stopped" and outcome.exit_code == -signal.SIGKILL
    assert any("sending SIGKILL" in text for _, text in log_lines(tmp_path))


async def test_children_left_behind_end_with_the_program(tmp_path):
    source = 'sleep 1000 &\necho "child $!"\n'
    process, collector = await run(tmp_path, source, language=SHELL)
    outcome = await asyncio.wait_for(process.wait(), 10)
    assert outcome.state == "finished"
    child = int(next(t for _, _, t in collector.lines if t.startswith("child")).split()[1])
    await wait_until(lambda: not pid_alive(child))


async def test_a_flood_is_stored_whole_and_streamed_in_bounded_batches(tmp_path):
    n = 300_000
    process, collector = await run(tmp_path, f"for i in range({n}): print(i)\n")
    outcome = await asyncio.wait_for(process.wait(), 60)
    assert outcome.state == "finished"
    lines = log_lines(tmp_path)
    numbers = [text for tag, text in lines if tag == "o"]
    assert numbers == [str(i) for i in range(n)]  # none lost, none reordered
    assert len(collector.lines) + collector.skipped == n + 1  # + the closing line
    data = (tmp_path / "output.log").read_bytes()
    for skipped_from, first, skipped in collector.gaps:  # each gap is where the batch says
        assert data[skipped_from:first].count(b"\n") == skipped
    assert collector.batches < 500  # batched, not one message per line


async def test_a_flood_is_read_no_faster_than_its_output_rate(tmp_path):
    """Past its burst, a flood's output is left in the pipe: the program waits in its write
    (the server spends nothing on it meanwhile), and what it wrote is all kept."""
    burst, block = 256 * 1024, 64 * 1024
    flood = f"import sys\nfor _ in range(128): sys.stdout.write('x' * {block - 1} + '\\n')\n"
    flood += "open('done', 'w').close()\n"
    process, _ = await run(tmp_path, flood, output_rate=1024, output_burst=burst)
    log = tmp_path / "output.log"

    def blocked_in_its_write() -> bool:
        assert process.running, "the flood ended: nothing held it back"
        return "pipe_write" in Path(f"/proc/{process.pid}/wchan").read_text()

    await until(lambda: log.exists() and log.stat().st_size >= burst and blocked_in_its_write())
    await asyncio.sleep(0)
    assert log.stat().st_size <= burst + 2 * block  # the burst, and what one read took with it
    assert not (tmp_path / "done").exists()
    process.kill("stopped by the test")
    outcome = await asyncio.wait_for(process.wait(), DEADLINE)
    assert outcome.state == "stopped"
    assert all(text == "x" * (block - 1) for tag, text in log_lines(tmp_path) if tag == "o")


async def test_output_within_its_rate_is_read_as_it_comes(tmp_path):
    """A rate held back nothing within its burst: a program's lines all come, in order."""
    process, collector = await run(
        tmp_path, "for i in range(1000): print(i)\n", output_rate=1024, output_burst=64 * 1024
    )
    outcome = await asyncio.wait_for(process.wait(), DEADLINE)
    assert outcome.state == "finished"
    numbers = [text for tag, text in log_lines(tmp_path) if tag == "o"]
    assert numbers == [str(i) for i in range(1000)]


async def test_the_log_size_cap_ends_the_program_and_says_so(tmp_path):
    process, _ = await run(tmp_path, "while True: print('x' * 100)\n", max_log_bytes=200_000)
    outcome = await asyncio.wait_for(process.wait(), 20)
    assert outcome.state == "failed"
    assert "output size limit" in outcome.reason
    assert (tmp_path / "output.log").stat().st_size < 200_000 + 1000
    assert any("output size limit" in text for tag, text in log_lines(tmp_path) if tag == "s")


async def test_a_very_long_line_is_cut_into_pieces(tmp_path):
    process, _ = await run(tmp_path, "print('y' * 200000)\n")
    await process.wait()
    pieces = [text for tag, text in log_lines(tmp_path) if tag == "o"]
    assert "".join(pieces) == "y" * 200000 and max(map(len, pieces)) <= 64 * 1024


async def test_the_environment_is_clean(tmp_path, monkeypatch):
    monkeypatch.setenv("SECRET_KEY", "server-secret")
    monkeypatch.setenv("DATABASE_URL", "postgres://secret")
    process, collector = await run(
        tmp_path, "import os, json\nprint(json.dumps(dict(os.environ)))\n"
    )
    await process.wait()
    import json

    env = json.loads(collector.lines[0][2])
    assert "SECRET_KEY" not in env and "DATABASE_URL" not in env
    assert env["HOME"] == str(tmp_path) and env["ROBOT_RUN_ID"] == "1"
    assert str(launcher.SYSTEM_PATH) in env["PATH"]
    assert env["PYTHONPATH"].endswith("clients/python")
    assert ".venv" not in env["PATH"]


# -- limits ----------------------------------------------------------------------------------


async def test_cpu_time_limit_ends_a_busy_program(tmp_path):
    process, _ = await run(tmp_path, "while True: pass\n", limits=launcher.Limits(cpu_seconds=1))
    outcome = await asyncio.wait_for(process.wait(), 20)
    assert outcome.state == "failed"
    assert outcome.reason == "CPU time limit reached"


async def test_memory_limit_stops_an_allocation(tmp_path):
    source = (
        "try:\n    x = bytearray(400 * 1024 * 1024)\nexcept MemoryError:\n    print('denied')\n"
    )
    process, collector = await run(tmp_path, source, limits=launcher.Limits(memory_mb=200))
    await process.wait()
    assert [t for _, _, t in collector.lines][0] == "denied"


async def test_open_files_limit(tmp_path):
    source = (
        "import resource\nfiles = []\ntry:\n    while True: files.append(open('/dev/null'))\n"
        "except OSError as e:\n    print('limit', len(files))\n"
    )
    process, collector = await run(tmp_path, source, limits=launcher.Limits(open_files=40))
    await process.wait()
    opened = int(collector.lines[0][2].split()[1])
    assert 30 <= opened < 40


async def test_file_size_limit(tmp_path):
    source = "with open('big', 'wb') as f:\n    f.write(b'x' * (3 * 1024 * 1024))\n"
    process, _ = await run(tmp_path, source, limits=launcher.Limits(file_size_mb=1))
    outcome = await process.wait()
    # Python ignores SIGXFSZ, so the write fails with EFBIG instead of the signal ending it.
    assert outcome.state == "failed"
    assert (tmp_path / "big").stat().st_size <= 1024 * 1024
    assert any("File too large" in text for tag, text in log_lines(tmp_path) if tag == "e")


async def test_file_size_limit_signal_is_reported(tmp_path):
    source = "head -c 3000000 /dev/zero > big\n"
    process, _ = await run(tmp_path, source, language=SHELL, limits=launcher.Limits(file_size_mb=1))
    outcome = await process.wait()
    assert outcome.state == "failed"
    assert (tmp_path / "big").stat().st_size <= 1024 * 1024


async def test_process_limit_is_applied(tmp_path):
    # RLIMIT_NPROC is not enforced for root; the limit itself must be in place for the program.
    source = "import resource\nprint(resource.getrlimit(resource.RLIMIT_NPROC))\n"
    process, collector = await run(tmp_path, source, limits=launcher.Limits(processes=17))
    await process.wait()
    assert collector.lines[0][2] == "(17, 17)"


async def test_a_program_is_killed_when_its_agent_dies(tmp_path):
    """setpriv --pdeathsig: no program outlives the process that launched it."""
    program = tmp_path / "forever.py"
    # It says when it runs: killed before setpriv set its death signal, it would be orphaned.
    program.write_text("import time\nprint('ready', flush=True)\nwhile True: time.sleep(1)\n")
    argv = launcher.command(PYTHON, program, launcher.Limits())
    code = (
        "import subprocess, sys, time\n"
        f"p = subprocess.Popen({argv!r}, start_new_session=True)\n"
        "print(p.pid, flush=True)\ntime.sleep(60)\n"
    )
    parent = await asyncio.create_subprocess_exec(
        sys.executable, "-c", code, stdout=asyncio.subprocess.PIPE
    )
    # The program shares its parent's stdout: its "ready" may come before the parent's pid.
    lines = [await parent.stdout.readline(), await parent.stdout.readline()]
    assert b"ready\n" in lines, lines  # the program shares its stdout
    child = int(next(line for line in lines if line.strip().isdigit()))
    assert pid_alive(child)
    parent.kill()
    await parent.wait()
    await wait_until(lambda: not pid_alive(child))


def test_limits_from_robot_settings_ignore_unknown_keys():
    limits = launcher.Limits.from_settings({"cpu_seconds": "5", "log_size_mb": 3, "other": 1})
    assert limits.cpu_seconds == 5 and limits.memory_mb == launcher.Limits().memory_mb


def pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    # A zombie has ended; it only waits for its parent to collect it.
    try:
        return Path(f"/proc/{pid}/stat").read_text().split()[2] != "Z"
    except FileNotFoundError:
        return False


async def wait_until(predicate, timeout=10.0):
    deadline = time.monotonic() + timeout
    while not predicate():
        if time.monotonic() > deadline:
            pytest.fail("timed out")
        await asyncio.sleep(0.02)


async def test_programs_that_end_at_once_are_always_seen_to_end(tmp_path):
    """A program may exit before subprocess_exec() returns; its end must still be noticed."""
    for i in range(40):
        workdir = tmp_path / str(i)
        workdir.mkdir()
        process, _ = await run(workdir, "true\n", language=SHELL)
        outcome = await asyncio.wait_for(process.wait(), 10)
        assert outcome.state == "finished"
