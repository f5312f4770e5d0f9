"""Fair shares in fleet mode: PostgreSQL, Redis, a web server and one agent process per robot.
A student whose limit is one run asks a run of two robots at the same instant, five times: each
time exactly one starts and the other waits saying why (two agents deciding at once in their
own processes); when the first is stopped, the other robot's agent starts the waiting one."""

import threading

import pytest

from tests.appliance import Appliance, wait_for

ROBOTS = ("fair-1", "fair-2")
SLEEPS = "import time\nprint('going', flush=True)\ntime.sleep(120)\n"
WHY = "waiting: you already have 1 run going (your limit is 1)"


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    app = Appliance(
        tmp_path_factory.mktemp("fair-fleet"), mode="split",
        extra_env={"ROBOTIDE_RUNS_PER_USER": "1"},
    ).start()  # fmt: skip
    try:
        for name in ROBOTS:
            response = app.api("POST", "/api/robots", {"name": name, "url": "sim://"})
            assert response.status_code == 201, response.text
            app._spawn("agent", name)  # a process each, as on a robot computer each
        for name in ROBOTS:
            wait_for(lambda name=name: app.api("GET", f"/api/robots/{name}").json()["online"],
                     timeout=60, what=f"{name}'s agent")  # fmt: skip
        yield app
    finally:
        app.stop()


def both_at_once(app, token: str, program_id: int) -> list[int]:
    """A run asked of each robot, the requests let go together."""
    gate, ids = threading.Barrier(len(ROBOTS)), {}

    def ask(robot):
        gate.wait(10)
        ids[robot] = app.run_program(program_id, robot=robot, token=token)["id"]

    threads = [threading.Thread(target=ask, args=(robot,)) for robot in ROBOTS]
    for thread in threads:
        thread.start()
    for thread in threads:
        thread.join(30)
    return [ids[robot] for robot in ROBOTS]


def test_two_agents_never_start_a_students_second_run_at_once(fleet):
    app = fleet
    token = app.new_user("pat")
    program = app.create_program("sleeps", SLEEPS, token=token)
    for _ in range(5):
        runs = both_at_once(app, token, program["id"])

        def settled(runs=runs):
            found = [app.api("GET", f"/api/runs/{r}", token=token).json() for r in runs]
            return found if all(r["state"] in ("running", "queued") for r in found) else None

        found = wait_for(settled, timeout=30, what="both runs decided")
        assert sorted(r["state"] for r in found) == ["queued", "running"], found
        going = next(r for r in found if r["state"] == "running")
        waiting = next(r for r in found if r["state"] == "queued")
        assert waiting["reason"] == WHY, waiting
        assert app.api("POST", f"/api/runs/{going['id']}/stop", token=token).status_code == 200
        app.wait_run(going["id"])
        started = app.wait_run(waiting["id"], states=("running",), timeout=30)
        assert started["reason"] == "", started
        assert app.api("POST", f"/api/runs/{waiting['id']}/stop", token=token).status_code == 200
        app.wait_run(waiting["id"])
    robot = app.api("GET", f"/api/robots/{ROBOTS[0]}", token=token).json()
    assert robot["runs_per_user"] == 1 and robot["your_runs_going"] == 0, robot
