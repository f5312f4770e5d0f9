"""Programs that attack: none may harm the server, another run or the robot's owner.

Each runs on a real appliance through the API like a student's program, its outcome is
asserted from its log and state, and the server is checked to keep serving meanwhile.
"""

import html
import json
import time

import pytest

from robots.isolation_words import isolation_shown
from runbox import cgroups
from tests.appliance import Appliance, wait_for

LIMITS = {"wall_seconds": 4, "log_size_mb": 1, "processes": 32, "memory_mb": 200,
          "open_files": 64, "disk_mb": 8, "cpu_seconds": 3}  # fmt: skip


@pytest.fixture(scope="module")
def app(tmp_path_factory):
    # Not under /tmp/pytest-of-root (0700): without a sandbox, run accounts walk the real path.
    app = Appliance(tmp_path_factory.mktemp("attacks")).start()
    # "spin": a CPU limit well inside its wall clock, so a loaded machine still reaches it.
    spin = {**LIMITS, "wall_seconds": 60, "cpu_seconds": 2}
    for name, network, limits in [("jail", "none", LIMITS), ("lab", "loopback", LIMITS),
                                  ("spin", "none", spin)]:  # fmt: skip
        body = {"name": name, "url": "sim://", "settings": {"limits": limits, "network": network}}
        assert app.api("POST", "/api/robots", body).status_code == 201
        wait_for(lambda n=name: app.api("GET", f"/api/robots/{n}/sensors").status_code == 200)
    app.bystander = app.new_user("bystander")
    yield app
    app.stop()


def attack(app, source, robot="jail", language="python", timeout=30):
    """Run `source` as a user's program; check the server serves others meanwhile."""
    name = f"attack {time.monotonic_ns()}"
    program = app.create_program(name, source, language=language)
    run_id = app.run_program(program["id"], robot=robot)["id"]
    assert_serving(app)
    run = app.wait_run(run_id, timeout=timeout)
    assert_serving(app)
    log = app.api("GET", f"/api/runs/{run_id}/log").text
    return run, log


def assert_serving(app):
    started = time.monotonic()
    response = app.api("GET", "/api/programs", token=app.bystander)
    assert response.status_code == 200 and time.monotonic() - started < 5


def test_the_robot_page_and_admin_say_which_isolation_is_in_force(app):
    """The box, the network and the cgroup version with its controllers (this machine
    mounts v1), in the API, on the robot's page and in the admin's list of robots."""
    cgroup = cgroups.detect().describe()
    assert cgroup.startswith("cgroup v1 (memory"), cgroup
    robots = {r["name"]: r for r in app.api("GET", "/api/robots").json()}
    isolation = robots["jail"]["isolation"]
    assert "sandbox (bubblewrap)" in isolation and "network none" in isolation, isolation
    assert cgroup in isolation, isolation
    client = app.session()  # staff: the whole line, in words (robots.isolation_words)
    shown = isolation_shown(isolation)
    assert "in a sandbox (bubblewrap)" in shown and "cgroup v1 (memory+swap" in shown, shown
    assert shown in html.unescape(client.get("/robots/jail/").text)
    assert isolation in html.unescape(client.get("/admin/robots/robot/").text)  # as recorded


def test_it_cannot_read_the_database_or_the_secret_key(app):
    data = app.data_dir
    source = f"""
import os
print("uid", os.getuid())
for path in [{str(data / "robotide.sqlite3")!r}, {str(data / "secret_key")!r}]:
    try:
        print("READ", path, open(path, "rb").read(16))
    except OSError as e:
        print("DENIED", path, type(e).__name__)
"""
    run, log = attack(app, source)
    assert run["state"] == "finished", log
    assert log.count("DENIED") == 2 and "READ" not in log
    assert (data / "secret_key").read_text().strip() not in log
    assert "uid 0" not in log


def test_it_cannot_see_other_runs_or_the_data_folder(app):
    first, _ = attack(app, "print('a run with files')\nopen('notes.txt', 'w').write('private')\n")
    runs = app.data_dir / "runs"
    source = f"""
import os
for path in [{str(runs)!r}, {str(runs / str(first["id"]) / "work")!r}, {str(app.data_dir)!r}]:
    try:
        print("LISTED", path, os.listdir(path))
    except OSError as e:
        print("DENIED", path, type(e).__name__)
try:
    print("READ", open({str(runs / str(first["id"]) / "work" / "notes.txt")!r}).read())
except OSError as e:
    print("DENIED notes", type(e).__name__)
"""
    run, log = attack(app, source)
    assert log.count("DENIED") == 4, log
    assert "private" not in log


def test_it_cannot_write_outside_its_folder(app):
    source = f"""
import os
for path in ["/usr/evil", "/etc/evil", {str(app.data_dir / "evil")!r}, "/root/evil"]:
    try:
        open(path, "w").write("x")
        print("WROTE", path)
    except OSError as e:
        print("DENIED", path, type(e).__name__)
open("mine.txt", "w").write("ok")
open("/tmp/scratch", "w").write("private tmp")
print("own folder and /tmp ok")
"""
    run, log = attack(app, source)
    assert "WROTE" not in log and log.count("DENIED") == 4, log
    assert "own folder and /tmp ok" in log
    assert not (app.data_dir / "evil").exists()


def test_a_fork_bomb_is_contained(app):
    source = (
        "import os\nwhile True:\n    try:\n        os.fork()\n    except OSError:\n        pass\n"
    )
    run, log = attack(app, source)
    assert run["state"] == "failed"
    assert "process limit (32 processes)" in log or "wall-clock" in log, log


def test_allocating_without_end_hits_the_memory_limit(app):
    source = "chunks = []\nwhile True:\n    chunks.append(bytearray(10 * 1024 * 1024))\n"
    run, log = attack(app, source)
    assert run["state"] == "failed" and "memory limit (200 MB)" in log, log


def test_printing_without_end_hits_the_output_limit(app):
    run, log = attack(app, "while True:\n    print('flood ' * 20)\n")
    assert run["state"] == "failed" and "output size limit (1 MB) reached" in log


def test_sleeping_forever_hits_the_wall_clock_limit(app):
    run, log = attack(app, "import time\ntime.sleep(10**6)\n")
    assert run["state"] == "failed" and "wall-clock time limit (4 s) reached" in log


def test_spinning_hits_the_cpu_limit(app):
    run, log = attack(app, "while True:\n    pass\n", robot="spin", timeout=90)
    assert run["state"] == "failed" and "CPU time limit reached" in log


def test_opening_thousands_of_files_hits_the_limit(app):
    source = (
        "files = []\ntry:\n    while True:\n        files.append(open('/dev/null'))\n"
        "except OSError as e:\n    print('stopped at', len(files), e)\n    raise\n"
    )
    run, log = attack(app, source)
    assert run["state"] == "failed" and "Too many open files" in log
    assert "open files limit (64)" in log


def test_filling_the_disk_hits_the_disk_limit(app):
    source = (
        "import time\nwith open('big', 'wb') as f:\n    while True:\n"
        "        f.write(b'x' * 1024 * 1024)\n        f.flush()\n        time.sleep(0.05)\n"
    )
    run, log = attack(app, source)
    assert run["state"] == "failed" and "No space left on device" in log, log
    assert "it filled its folder (8 MB)" in log


def test_without_network_it_cannot_connect_anywhere(app):
    source = f"""
import socket
for host, port in [("127.0.0.1", {app.port}), ("::1", {app.port})]:
    try:
        socket.create_connection((host, port), timeout=2)
        print("CONNECTED", host)
    except OSError as e:
        print("REFUSED", host, type(e).__name__)
import robot
print("robot api", robot.Robot().sensors()["range"])
"""
    run, log = attack(app, source)
    assert log.count("REFUSED") == 2 and "CONNECTED" not in log
    assert "robot api 2.0" in log or "robot api" in log  # the Robot API still works


def test_one_run_cannot_reach_another(app):
    victim = app.create_program("victim", "import os, time\nprint('pid', os.getpid(), flush=True)\n"
                                          "time.sleep(60)\n")  # fmt: skip
    victim_run = app.run_program(victim["id"], robot="jail")["id"]
    wait_for(lambda: "pid" in app.api("GET", f"/api/runs/{victim_run}/log").text)
    source = """
import os, signal
mine = os.getpid()
others = [p for p in os.listdir('/proc') if p.isdigit() and int(p) not in (1, mine)]
print('OTHERS', others)
for pid in range(2, 4000):
    if pid == mine:
        continue
    try:
        os.kill(pid, signal.SIGKILL)
        print('KILLED', pid)
    except OSError:
        pass
"""
    run, log = attack(app, source)
    assert "KILLED" not in log
    assert app.api("GET", f"/api/runs/{victim_run}").json()["state"] == "running"
    app.api("POST", f"/api/runs/{victim_run}/stop")
    assert app.wait_run(victim_run)["state"] == "stopped"


def test_a_token_is_worthless_after_its_run(app):
    run, log = attack(app, "import os\nprint(os.environ['ROBOT_TOKEN'])\n")
    old_token = log.split()[0]
    source = f"""
import json, os, socket
s = socket.socket(socket.AF_UNIX)
s.connect(os.environ["ROBOT_API"][len("unix:"):])
auth = {{"jsonrpc": "2.0", "id": 1, "method": "auth", "params": [{old_token!r}]}}
s.sendall(json.dumps(auth).encode() + b"\\n")
print("REPLY", s.makefile().readline())
"""
    run, log = attack(app, source)
    reply = json.loads(log.split("REPLY ", 1)[1].splitlines()[0])
    assert reply["error"]["code"] == -32001, log


def test_a_run_holds_only_so_many_robot_api_connections(app):
    """Each connection costs the agent (the web server too, embedded) a file descriptor, and a
    run may hold thousands: from four processes, 25 each on the Unix socket the robot's runs
    share and on the TCP port in its namespace, the agent serves 64 a side and closes the rest;
    a second run still gets its own 64, and the server serves on."""
    source = """
import json, os, socket, sys
def serve_count(make):
    served, held = 0, []
    for _ in range(25):
        s = make()
        held.append(s)
        s.settimeout(2)
        try:  # one the agent closed at once: a broken pipe or an empty read
            s.sendall(b'{"jsonrpc": "2.0", "id": 1, "method": "sensors"}\\n')
            served += bool(s.recv(100))
        except OSError:
            pass
    return served, held
def over_unix():
    s = socket.socket(socket.AF_UNIX)
    s.connect(os.environ["ROBOT_API"][len("unix:"):])
    return s
def over_tcp():
    host, port = os.environ["ROBOT_API_TCP"].split(":")
    return socket.create_connection((host, int(port)))
counts_r, counts_w = os.pipe()
release_r, release_w = os.pipe()
children = []
for _ in range(4):
    pid = os.fork()
    if pid == 0:
        counts = [serve_count(over_unix), serve_count(over_tcp)]
        os.write(counts_w, f"{counts[0][0]} {counts[1][0]}\\n".encode())
        os.read(release_r, 1)  # hold them until all have counted
        os._exit(0)
    children.append(pid)
got = b""
while got.count(b"\\n") < 4:
    got += os.read(counts_r, 100)
lines = got.decode().split()
print("SERVED", [sum(int(n) for n in lines[i::2]) for i in (0, 1)])
os.write(release_w, b"x" * 4)
for pid in children:
    os.waitpid(pid, 0)
"""
    first = app.create_program("holder", source)
    first_run = app.run_program(first["id"], robot="lab")["id"]
    second = app.create_program("second holder", source)
    second_run = app.run_program(second["id"], robot="lab")["id"]
    for run_id in (first_run, second_run):
        run = app.wait_run(run_id, timeout=60)
        log = app.api("GET", f"/api/runs/{run_id}/log").text
        assert run["state"] == "finished", log
        assert "SERVED [64, 64]" in log, log
    assert_serving(app)


def test_markup_in_output_and_shown_values_stays_text(app):
    source = (
        "import robot\nprint('<script>alert(1)</script><b>bold</b>')\n"
        "robot.Robot().show('x', '<img src=x onerror=alert(1)>')\n"
    )
    run, _ = attack(app, source)
    client = app.session()
    page = client.get(f"/runs/{run['id']}/").text
    assert "<script>alert(1)</script>" not in page and "&lt;script&gt;alert(1)" in page
    assert "<b>bold</b>" not in page


def test_a_robot_cannot_ask_for_runs_without_a_box(app):
    body = {"name": "bare", "url": "sim://", "settings": {"isolation": "account"}}
    refused = app.api("POST", "/api/robots", body)
    assert refused.status_code == 422 and "every run is boxed" in refused.text


@pytest.fixture(scope="module")
def heavy(app):
    """A robot with the default memory (1024 MB) and a short CPU budget for the whole run."""
    limits = {"memory_mb": 1024, "cpu_seconds": 3, "wall_seconds": 60, "processes": 32}
    body = {"name": "heavy", "url": "sim://", "settings": {"limits": limits, "network": "none"}}
    assert app.api("POST", "/api/robots", body).status_code == 201
    wait_for(lambda: app.api("GET", "/api/robots/heavy/sensors").status_code == 200)
    return "heavy"


def test_memory_is_limited_for_the_whole_run(app, heavy):
    """Four children of 450 MB each: under a per-process limit each would pass."""
    source = """
import os, time
for _ in range(4):
    if os.fork() == 0:
        block = bytearray(450 * 2**20)
        for i in range(0, len(block), 4096):
            block[i] = 1
        time.sleep(30)
        os._exit(0)
print("children started", flush=True)
for _ in range(4):
    os.wait()
print("ALL CHILDREN LIVED")
"""
    run, log = attack(app, source, robot=heavy, timeout=60)
    assert run["state"] == "failed" and "ALL CHILDREN LIVED" not in log, log
    assert "memory limit (1024 MB) reached" in log, log


def test_cpu_seconds_are_counted_for_the_whole_run(app, heavy):
    """Four forked burners of 1.5 s each: none meets 3 s alone, the run does."""
    source = """
import os, time
for _ in range(4):
    if os.fork() == 0:
        end = time.process_time() + 1.5
        while time.process_time() < end:
            pass
        time.sleep(30)
        os._exit(0)
for _ in range(4):
    os.wait()
print("ALL BURNERS DONE")
"""
    run, log = attack(app, source, robot=heavy, timeout=60)
    assert run["state"] == "failed" and "ALL BURNERS DONE" not in log, log
    assert "CPU time limit (3 s) reached" in log, log


def test_what_it_forks_at_once_is_in_its_cgroup_too(app, heavy):
    """The run joins its cgroup while it starts: what it forks before that is gathered."""
    source = """
import os, time
children = []
for _ in range(8):
    pid = os.fork()
    if pid == 0:
        time.sleep(1.5)
        memory = [line for line in open("/proc/self/cgroup") if ":memory:" in line]
        os.write(1, f"CG {memory[0].strip() if memory else 'none'}\\n".encode())  # one write
        os._exit(0)
    children.append(pid)
for pid in children:
    os.waitpid(pid, 0)
"""
    run, log = attack(app, source, robot=heavy)
    lines = [line for line in log.splitlines() if line.startswith("CG ")]
    # Its name: the run's; on cgroup v2 (no renames) a box made ahead keeps its own.
    name = f"-heavy.run-{run['id']}" if cgroups.detect().version == "v1" else "-heavy."
    assert len(lines) == 8 and len(set(lines)) == 1 and name in lines[0], log


def test_it_cannot_make_a_user_namespace_of_its_own(app):
    """From there it would be root of a namespace: mounts, network set-up, kernel surface."""
    source = (
        "import subprocess\ndone = subprocess.run(['unshare', '-Ur', 'id'], capture_output=True)\n"
        "print('ALLOWED' if done.returncode == 0 else 'refused', done.stdout, done.stderr)\n"
    )
    run, log = attack(app, source, robot="lab")
    assert "refused" in log and "ALLOWED" not in log, log


def test_tcl_reaches_the_robot_api_without_network(app):
    """Tcl has no Unix sockets, and network "none" leaves no TCP: its client relays."""
    source = 'package require robot\nputs "heading [dict get [robot::sensors] heading]"\n'
    run, log = attack(app, source, language="tcl")
    assert run["state"] == "finished" and "heading" in log, log
