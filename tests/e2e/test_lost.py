"""A run whose agent died is marked lost when the agent comes back, and its program is gone."""

import os

import pytest

from runbox.isolation import run_uid
from tests.appliance import Appliance, wait_for

# A program with a child in the background, which a pdeathsig alone would not end.
SOURCE = (
    "import subprocess, time\nsubprocess.Popen(['sleep', '300'])\n"
    "print('started', flush=True)\nwhile True: time.sleep(1)\n"
)


@pytest.fixture(params=["embedded", "split"])
def app(request, tmp_path):
    app = Appliance(tmp_path, mode=request.param).start()
    yield app
    app.stop()


def test_runs_of_a_dead_agent_are_lost_and_their_programs_gone(app):
    program = app.create_program("orphan", SOURCE)
    run = app.wait_run(app.run_program(program["id"])["id"], states=("running",))
    wait_for(lambda: "started" in app.api("GET", f"/api/runs/{run['id']}/log").text)
    pids = processes_of_run(app, run["id"])
    assert len(pids) >= 2
    # SIGKILL: the agent gets no chance to clean up.
    victim = app.agent if app.mode == "split" else app.server
    victim.kill()
    victim.wait()
    wait_for(lambda: not processes_of_run(app, run["id"]), what="the orphaned programs to die")
    if app.mode == "split":
        app.agent = app._spawn("agent", "sim")
    else:
        app.server = app._spawn("up", "--bind", f"127.0.0.1:{app.port}")
    assert app.wait_run(run["id"], states=("lost",))["state"] == "lost"
    # ...and the robot serves again.
    wait_for(lambda: app.api("GET", "/api/robots/sim/sensors").status_code == 200)
    again = app.wait_run(app.run_program(program["id"])["id"], states=("running",))
    app.api("POST", f"/api/runs/{again['id']}/stop")
    assert app.wait_run(again["id"])["state"] == "stopped"


def processes_of_run(app, run_id: int) -> list[int]:
    """Host pids of the processes whose environment names the run and that run as its account
    (seen as root): another appliance's run of the same number (a parallel test) is not it."""
    uid = run_uid(run_id, str(app.data_dir.resolve()))
    found = []
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            environ = open(f"/proc/{entry.name}/environ", "rb").read().split(b"\0")
            state = open(f"/proc/{entry.name}/stat").read().split()[2]
            status = open(f"/proc/{entry.name}/status").read()
            owner = int(status.split("\nUid:", 1)[1].split()[0])  # its real uid
        except OSError:
            continue
        if f"ROBOT_RUN_ID={run_id}".encode() in environ and state != "Z" and owner == uid:
            found.append(int(entry.name))
    return found
