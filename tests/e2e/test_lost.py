"""A run whose agent died is marked lost when the agent comes back, and its program is gone."""

import pytest

from tests.appliance import Appliance, wait_for

SOURCE = "import os, time\nprint(os.getpid(), flush=True)\nwhile True: time.sleep(1)\n"


@pytest.fixture(params=["embedded", "split"])
def app(request, tmp_path):
    app = Appliance(tmp_path, mode=request.param).start()
    yield app
    app.stop()


def test_runs_of_a_dead_agent_are_lost_and_their_programs_gone(app):
    program = app.create_program("orphan", SOURCE)
    run = app.wait_run(app.run_program(program["id"])["id"], states=("running",))
    pid = int(wait_for(lambda: app.api("GET", f"/api/runs/{run['id']}/log").text.split()[0]))
    # SIGKILL: the agent gets no chance to clean up.
    victim = app.agent if app.mode == "split" else app.server
    victim.kill()
    victim.wait()
    wait_for(lambda: not alive(pid), what="the orphaned program to die")
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


def alive(pid: int) -> bool:
    try:
        with open(f"/proc/{pid}/stat") as f:
            return f.read().split()[2] != "Z"
    except FileNotFoundError:
        return False
