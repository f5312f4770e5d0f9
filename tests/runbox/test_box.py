"""The run box, as root (bubblewrap) and as an ordinary user (unshare + runbox/inbox.py).

Each case runs a program through tests/runbox/boxrun.py, the way the agent does, with the
system's python3: as root, and as the account `nobody` for the rootless box (a copy of the
code where that account can read it).
"""

import json
import os
import shutil
import subprocess
import tempfile
from pathlib import Path

import pytest

from tests.net_probes import DNS_ANSWERED, DNS_PROBE

ROOT = Path(__file__).resolve().parents[2]
NOBODY = 65534


@pytest.fixture(scope="module")
def readable_copy():
    """runbox/ and boxrun.py where an ordinary account may read them: a folder of its own in
    /tmp (pytest's folder is 0700, and any pytest started meanwhile makes it so again)."""
    folder = Path(tempfile.mkdtemp(prefix="robotide-boxcode-"))
    folder.chmod(0o755)
    shutil.copytree(
        ROOT / "runbox", folder / "runbox", ignore=shutil.ignore_patterns("__pycache__")
    )
    (folder / "tests" / "runbox").mkdir(parents=True)
    shutil.copy(ROOT / "tests" / "runbox" / "boxrun.py", folder / "tests" / "runbox")
    for path in folder.rglob("*"):
        path.chmod(path.stat().st_mode | 0o005)
    yield folder
    shutil.rmtree(folder)


def box_run(mode: str, code: Path, source: str, **spec) -> dict:
    script = str(code / "tests" / "runbox" / "boxrun.py")
    argv = ["/usr/bin/python3", script, json.dumps({"source": source, **spec})]
    if mode == "rootless":
        argv = ["setpriv", f"--reuid={NOBODY}", f"--regid={NOBODY}", "--clear-groups", *argv]
    done = subprocess.run(argv, capture_output=True, text=True, timeout=120, cwd="/")
    assert done.returncode == 0, done.stderr
    result = json.loads(done.stdout)
    assert result["rootless"] == (mode == "rootless")
    return result


MODES = ["root", "rootless"]
if os.geteuid() != 0:
    MODES = ["rootless"]


@pytest.mark.parametrize("mode", MODES)
def test_the_run_sees_its_own_folder_and_services_only(mode, readable_copy):
    source = """
import os, socket
print("uid", os.getuid(), "cwd", os.getcwd(), "files", os.listdir("."))
print("root", sorted(os.listdir("/")))
s = socket.create_connection(("127.0.0.1", 7010)); s.sendall(b"echo\\n"); print("api", s.recv(10))
for port in (5432, 6379):
    try:
        socket.create_connection(("127.0.0.1", port), timeout=1); print("REACHED", port)
    except OSError as e:
        print("refused", port)
print("tcp", len(open("/proc/net/tcp").read().splitlines()) - 1)
for path in ["/root", "/var", "/work", "CODE"]:
    print("visible" if os.path.exists(path) else "hidden", path)
"""
    result = box_run(mode, readable_copy, source.replace("CODE", str(readable_copy)))
    log = result["log"]
    assert result["state"] == "finished", log
    assert "cwd /home/robot files ['main.py']" in log
    assert "api b'echo\\n'" in log and "REACHED" not in log
    assert "refused 5432" in log and "refused 6379" in log
    assert int(log.split("o tcp ")[1].split()[0]) <= 3  # the echo's listener and connection
    assert "visible" not in log, log
    uid = int(log.split("o uid ")[1].split()[0])
    assert uid == 1000 if mode == "rootless" else uid >= 1_000_000_000


@pytest.mark.parametrize("mode", MODES)
def test_unlinked_files_count_against_the_folder(mode, readable_copy):
    """24 files of 60 MB, each unlinked and held open: the folder's tmpfs says no."""
    source = """
import os
held, written = [], 0
try:
    for i in range(24):
        f = open(f"big{i}", "wb"); os.unlink(f"big{i}"); held.append(f)
        for _ in range(60):
            f.write(b"x" * 2**20); f.flush(); written += 1
except OSError as e:
    print("REFUSED after", written, "MB:", e.strerror)
print("done", written)
"""
    result = box_run(mode, readable_copy, source, limits={"disk_mb": 64, "memory_mb": 1024})
    log = result["log"]
    assert "REFUSED after" in log and "No space left on device" in log, log
    assert int(log.split("REFUSED after ")[1].split()[0]) <= 64


@pytest.mark.parametrize("mode", MODES)
def test_stop_ends_every_process_of_the_run(mode, readable_copy):
    """A program that ignores SIGTERM and leaves a grandchild in a session of its own."""
    source = """
import os, signal, subprocess, time
signal.signal(signal.SIGTERM, signal.SIG_IGN)
subprocess.Popen(["sh", "-c", "trap '' TERM; sleep 300"], start_new_session=True)
print("started", flush=True)
time.sleep(300)
"""
    result = box_run(mode, readable_copy, source, stop_after=1.0, grace=0.5)
    assert result["state"] == "stopped", result
    assert "did not stop within 0.5 s: sending SIGKILL" in result["log"]
    assert result["left"] == [] and result["seconds"] < 10


@pytest.mark.parametrize("mode", MODES)
def test_a_stop_reaches_a_daemon_the_run_left_behind(mode, readable_copy):
    """Grandchildren in a session of their own, one whose parent waits for it and one whose
    parent is gone (adopted by the box's first process): the stop's SIGTERM finds both
    (Box.processes walks down the children from the box's first process)."""
    source = """
import os, signal, time
def daemon(name, parent_stays):
    if os.fork() == 0:
        os.setsid()
        if os.fork() == 0:
            def ended(*_):
                print(name, "got TERM", flush=True)
                os._exit(0)
            signal.signal(signal.SIGTERM, ended)
            print(name, "ready", flush=True)
            time.sleep(300)
        if parent_stays:
            signal.signal(signal.SIGTERM, signal.SIG_IGN)
            os.wait()
        os._exit(0)
daemon("orphan", False)
daemon("grandchild", True)
# The program outlives the SIGTERM (until the grace's SIGKILL): a program that ends ends its
# leftovers with SIGKILL at once, which on a busy machine came before they could say "got TERM"
signal.signal(signal.SIGTERM, signal.SIG_IGN)
time.sleep(300)
"""
    result = box_run(mode, readable_copy, source, stop_on="grandchild ready", grace=5.0)
    assert result["state"] == "stopped", result
    assert "orphan got TERM" in result["log"], result["log"]
    assert "grandchild got TERM" in result["log"], result["log"]
    assert result["left"] == []


@pytest.mark.parametrize("mode", MODES)
def test_the_run_cannot_make_namespaces_or_mount(mode, readable_copy):
    source = """
import subprocess
for argv in (["unshare", "-Ur", "true"], ["unshare", "-n", "true"],
             ["mount", "-t", "tmpfs", "x", "/tmp"]):
    done = subprocess.run(argv, capture_output=True)
    print("ALLOWED" if done.returncode == 0 else "refused", argv[:2])
"""
    result = box_run(mode, readable_copy, source)
    assert result["log"].count("refused") == 3 and "ALLOWED" not in result["log"], result


@pytest.mark.parametrize("mode", MODES)
def test_a_gate_that_says_no_keeps_the_program_from_running(mode, readable_copy):
    """The agent claims the run while its box is made: a run stopped or lost meanwhile never
    runs a line of its program."""
    source = "print('RAN', flush=True)\nopen('/home/robot/ran', 'w').close()\n"
    result = box_run(mode, readable_copy, source, refuse="stopped by user before it started")
    assert result["state"] == "stopped" and result["started"] is False, result
    assert result["reason"] == "stopped by user before it started"
    assert "RAN" not in result["log"] and result["left"] == []
    ran = box_run(mode, readable_copy, source)
    assert ran["state"] == "finished" and "RAN" in ran["log"] and ran["started"] is True


NASTY = ["$(touch /home/robot/pwned)", "`id`", "it's", 'say "hi"', "two\nlines", "a;b|c&", "*"]


@pytest.mark.parametrize("mode", MODES)
def test_a_box_made_ahead_runs_the_run_given_later_word_for_word(mode, readable_copy):
    """The box waits, made, for its run: the program, its arguments and its environment come
    then, and reach the program as they are (nothing of them is read as shell)."""
    source = """
import os, sys
print("ARGS", repr(sys.argv[1:]))
print("ENV", sorted(os.environ))
print("FILES", sorted(os.listdir(".")), "PID", os.getpid())
"""
    result = box_run(mode, readable_copy, source, ahead=0.5, args=NASTY)
    log = result["log"]
    assert result["state"] == "finished", log
    assert f"ARGS {NASTY!r}" in log, log
    assert "ENV ['HOME', 'LANG', 'LC_ALL', 'PATH', 'TERM', 'TMPDIR']" in log, log
    assert "FILES ['main.py'] PID 2" in log, log  # pid 1 is the box's first process


@pytest.mark.parametrize("mode", MODES)
def test_a_box_whose_run_never_comes_ends_with_nothing_left(mode, readable_copy):
    """A box made ahead and then given up (the robot's settings changed): stopped before its
    program, it leaves no process behind."""
    result = box_run(mode, readable_copy, "print('RAN')", ahead=0.3, refuse="settings changed")
    assert result["started"] is False and "RAN" not in result["log"] and result["left"] == []


@pytest.mark.parametrize("mode", MODES)
def test_the_run_cannot_change_the_robot_api_sockets_folder(mode, readable_copy):
    """The folder is the robot's, shared by all its runs: a run that could write there would
    fill the host's disk outside its own, or put its listener where the next run's program
    connects and take that run's token."""
    source = """
import os, socket
attempts = [
    ("write", lambda: open("/run/robot/junk", "wb").write(b"x" * 4096)),
    ("unlink", lambda: os.unlink("/run/robot/api.sock")),
    ("bind", lambda: socket.socket(socket.AF_UNIX).bind("/run/robot/mine.sock")),
    ("chmod", lambda: os.chmod("/run/robot", 0o777)),
]
for name, attempt in attempts:
    try:
        attempt()
        print("DID", name)
    except OSError as e:
        print("refused", name, e.strerror)
s = socket.socket(socket.AF_UNIX); s.connect("/run/robot/api.sock"); print("connected")
"""
    result = box_run(mode, readable_copy, source)
    log = result["log"]
    assert result["state"] == "finished", log
    assert "DID" not in log and log.count("refused") == 4, log
    assert "connected" in log
    assert result["api_folder"] == {"files": ["api.sock"], "mode": "0o711", "reaches": True}


@pytest.mark.parametrize("mode", MODES)
def test_the_program_inherits_no_descriptor_of_the_box(mode, readable_copy):
    """Nothing of the box's making (its control socket to the agent, the seccomp filter's
    file) reaches the program: only its standard input, output and error."""
    source = """
import os
print("fds", sorted(int(fd) for fd in os.listdir("/proc/self/fd")))
"""
    result = box_run(mode, readable_copy, source)
    assert result["state"] == "finished", result["log"]
    assert "fds [0, 1, 2, 3]" in result["log"], result["log"]  # 3: the listing's own


@pytest.mark.parametrize("mode", MODES)
def test_the_run_has_a_shared_memory_folder_of_its_own(mode, readable_copy):
    """POSIX shared memory and semaphores (multiprocessing's locks and queues) live in
    /dev/shm: the run's own, writable, sized as its /tmp."""
    source = """
import multiprocessing, os
lock = multiprocessing.Lock()
with lock:
    print("lock ok", oct(os.stat("/dev/shm").st_mode & 0o7777))
"""
    result = box_run(mode, readable_copy, source)
    assert result["state"] == "finished", result["log"]
    assert "lock ok 0o1777" in result["log"]


FULL_PROBE = (
    DNS_PROBE
    + r"""
routes = [line.split() for line in open("/proc/net/route").read().splitlines()[1:]]
print("DEFAULT", [r[0] for r in routes if r[1] == "00000000" and r[7] == "00000000"])
print("REFUSED", sorted(r[1] for r in routes if int(r[3], 16) & 0x0200))
for host in ("10.0.2.2", "127.0.0.1"):
    try:
        socket.create_connection((host, 5432), timeout=2).close()
        print("REACHED", host)
    except OSError as e:
        print("refused", host, type(e).__name__)
"""
)


@pytest.mark.parametrize("mode", MODES)
def test_a_full_run_has_the_internet_through_its_nat_and_nothing_of_the_host(
    mode, readable_copy, tun_as_debian_has_it
):
    """Network `full`, as root and rootless: names are looked up through the NAT's DNS
    forwarder, the way out is the run's own tap device, the private ranges are refused, and
    the host's loopback is reached neither behind the NAT's gateway nor on 127.0.0.1."""
    control = subprocess.run(["pg_isready", "-h", "127.0.0.1"], capture_output=True)
    assert control.returncode == 0, "PostgreSQL must answer the host for the control"
    result = box_run(mode, readable_copy, FULL_PROBE, network="full")
    log = result["log"]
    assert result["state"] == "finished", log
    assert "SERVERS ['10.0.2.3']" in log and DNS_ANSWERED in log, log
    assert "DEFAULT ['tap0']" in log, log
    assert "'0000000A'" in log.split("REFUSED", 1)[1].splitlines()[0], log  # 10.0.0.0/8
    assert "REACHED" not in log and log.count("refused") == 2, log
