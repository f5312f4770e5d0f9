"""End to end on a real appliance, embedded and split (Redis + PostgreSQL + separate agent)."""

import re
import time

from websockets.sync.client import connect

from tests.appliance import cookie_header, wait_for

FOREVER = (
    "import time\ni = 0\nwhile True:\n    print('tick', i)\n    i += 1\n    time.sleep(0.05)\n"
)


def open_ws(app, path, client=None):
    client = client or app.session()
    headers = {"Cookie": cookie_header(client), "Origin": app.url}
    return connect(f"ws://127.0.0.1:{app.port}{path}", additional_headers=headers, open_timeout=10)


def read_until(ws, predicate, timeout=15):
    received = []
    deadline = time.monotonic() + timeout
    while time.monotonic() < deadline:
        try:
            received.append(ws.recv(timeout=max(0.01, deadline - time.monotonic())))
        except TimeoutError:
            break
        if predicate("".join(received)):
            return "".join(received)
    raise AssertionError(f"not seen in time; received: {''.join(received)[-2000:]}")


def test_a_program_drives_and_reads_sensors_through_the_robot_api(any_appliance):
    app = any_appliance
    source = (
        "import robot\nbot = robot.Robot()\nprint(bot.drive(0.2, 0.0))\n"
        "print(bot.sensors()['heading'])\nprint(sorted(bot.capabilities()['sensors']))\n"
    )
    program = app.create_program("api-check", source)
    run = app.wait_run(app.run_program(program["id"])["id"])
    assert (run["state"], run["exit_code"], run["reason"]) == ("finished", 0, "exit status 0")
    assert run["started"] and run["ended"] and run["robot"] == "sim"
    log = app.api("GET", f"/api/runs/{run['id']}/log").text
    assert "{'linear': 0.2, 'angular': 0.0}" in log
    assert "heading" in log and "range" in log
    # The program drove and ended: its motion ended with it.
    sensors = wait_for(
        lambda: (
            (s := app.api("GET", "/api/robots/sim/sensors").json())["velocity"]["linear"] == 0 and s
        ),
        what="the robot to stop",
    )
    assert sensors["velocity"] == {"linear": 0.0, "angular": 0.0}


def test_shell_programs_use_the_robot_command(any_appliance):
    app = any_appliance
    source = 'echo "heading $(robot sensors heading)"\nrobot sensors gps || echo "status $?"\n'
    program = app.create_program("shell-check", source, language="shell")
    run = app.wait_run(app.run_program(program["id"])["id"])
    assert run["state"] == "finished"
    log = app.api("GET", f"/api/runs/{run['id']}/log").text
    assert re.search(r"heading \d+(\.\d+)?", log)
    assert "robot: " in log and "gps" in log and "status 1" in log


def test_live_output_from_the_first_line_then_stop(any_appliance):
    app = any_appliance
    program = app.create_program("forever", FOREVER)
    run = app.run_program(program["id"])
    with open_ws(app, f"/ws/runs/{run['id']}/") as ws:
        seen = read_until(ws, lambda text: "tick 5" in text)
        assert "tick 0" in seen  # from the first line, whenever we joined
        assert 'class="ln o"' in seen
        assert app.api("GET", f"/api/runs/{run['id']}").json()["state"] == "running"
        stop = app.api("POST", f"/api/runs/{run['id']}/stop")
        assert stop.status_code == 200
        read_until(ws, lambda text: 'data-state="stopped"' in text)
    ended = app.wait_run(run["id"])
    assert ended["state"] == "stopped" and ended["reason"] == "stopped by user"
    log = app.api("GET", f"/api/runs/{run['id']}/log?stream=stdout").text.splitlines()
    assert log[:3] == ["tick 0", "tick 1", "tick 2"]
    assert all(line.startswith("tick") for line in log)


def test_several_programs_at_once_and_the_list_of_running_ones(any_appliance):
    app = any_appliance
    program = app.create_program("forever-2", FOREVER)
    runs = [app.run_program(program["id"])["id"] for _ in range(3)]
    for run_id in runs:
        app.wait_run(run_id, states=("running",))
    running = {r["id"] for r in app.api("GET", "/api/runs?state=running").json()}
    assert set(runs) <= running
    with open_ws(app, "/ws/runs/") as ws:
        app.api("POST", f"/api/runs/{runs[0]}/stop")
        html = read_until(ws, lambda text: 'id="run-tables"' in text)
        assert f"#{runs[1]}" in html
    for run_id in runs[1:]:
        app.api("POST", f"/api/runs/{run_id}/stop")
    for run_id in runs:
        assert app.wait_run(run_id)["state"] == "stopped"


def test_stderr_is_told_apart(any_appliance):
    app = any_appliance
    source = "import sys\nprint('to out')\nprint('to err', file=sys.stderr)\nsys.exit(4)\n"
    program = app.create_program("stderr", source)
    run = app.wait_run(app.run_program(program["id"])["id"])
    assert (run["state"], run["exit_code"]) == ("failed", 4)
    assert app.api("GET", f"/api/runs/{run['id']}/log?stream=stderr").text == "to err\n"
    with open_ws(app, f"/ws/runs/{run['id']}/") as ws:
        html = read_until(ws, lambda text: "to err" in text and "to out" in text)
    assert '<div class="ln e">to err</div>' in html and '<div class="ln o">to out</div>' in html


def test_a_flooding_program_loses_no_line(any_appliance):
    app = any_appliance
    n = 200_000
    program = app.create_program("flood", f"for i in range({n}):\n    print(i)\n")
    run = app.wait_run(app.run_program(program["id"])["id"], timeout=60)
    assert run["state"] == "finished"
    lines = app.api("GET", f"/api/runs/{run['id']}/log?stream=stdout").text.splitlines()
    assert lines == [str(i) for i in range(n)]


def test_emergency_stop_stops_programs_and_motors(any_appliance):
    app = any_appliance
    source = (
        "import robot, time\nbot = robot.Robot()\nbot.drive(0.1, 0.3)\nwhile True: time.sleep(1)\n"
    )
    program = app.create_program("estop", source)
    run = app.run_program(program["id"])
    wait_for(
        lambda: app.api("GET", "/api/robots/sim/sensors").json()["velocity"]["angular"] > 0,
        what="the robot to move",
    )
    reply = app.api("POST", "/api/robots/sim/estop")
    assert reply.status_code == 200 and reply.json()["stopped_runs"] >= 1
    ended = app.wait_run(run["id"])
    assert ended["state"] == "stopped" and ended["reason"] == "emergency stop"
    assert app.api("GET", "/api/robots/sim/sensors").json()["velocity"]["angular"] == 0
    app.resume()


def test_bad_requests_get_clear_json_errors(any_appliance):
    app = any_appliance
    program = app.create_program("bad-input", "print(1)\n")
    unknown_robot = app.api("POST", f"/api/programs/{program['id']}/run", {"robot": "nope"})
    assert unknown_robot.status_code == 404 and "nope" in unknown_robot.json()["detail"]
    bad_language = app.api("POST", "/api/programs", {"name": "x", "language": "cobol"})
    assert bad_language.status_code == 422 and "cobol" in bad_language.text
    assert app.api("GET", "/api/runs/999999").status_code == 404
    assert app.api("GET", "/api/runs", token="rt_wrong").status_code == 401
    duplicate = app.api("POST", "/api/programs", {"name": "bad-input", "language": "python"})
    assert duplicate.status_code == 409
    assert app.api("GET", "/api/runs?state=sleeping").status_code == 422
    malformed = app.api("POST", f"/api/programs/{program['id']}/run", {"robot": 5})
    assert malformed.status_code == 422


def test_another_users_programs_and_runs_are_out_of_reach(any_appliance):
    app = any_appliance
    program = app.create_program("private", "print('mine')\n")
    run = app.wait_run(app.run_program(program["id"])["id"])
    bob = app.new_user(f"bob{int(time.time() * 1000) % 100000}")
    for method, path in [
        ("GET", f"/api/programs/{program['id']}"),
        ("PUT", f"/api/programs/{program['id']}"),
        ("DELETE", f"/api/programs/{program['id']}"),
        ("POST", f"/api/programs/{program['id']}/run"),
        ("GET", f"/api/runs/{run['id']}"),
        ("GET", f"/api/runs/{run['id']}/log"),
        ("POST", f"/api/runs/{run['id']}/stop"),
    ]:
        body = {"robot": "sim"} if path.endswith("/run") else ({} if method == "PUT" else None)
        assert app.api(method, path, body, token=bob).status_code == 404, (method, path)
    assert all(r["id"] != run["id"] for r in app.api("GET", "/api/runs", token=bob).json())
    names = {p["name"] for p in app.api("GET", "/api/programs", token=bob).json()}
    assert "private" not in names and "Compass" in names  # bob has his own examples


def test_the_examples_run(any_appliance):
    app = any_appliance
    programs = {p["name"]: p for p in app.api("GET", "/api/programs").json()}
    assert {"Compass", "Drive a square", "Stop before the wall", "Hello from the shell"} <= set(
        programs
    )
    run = app.wait_run(app.run_program(programs["Stop before the wall"]["id"])["id"])
    assert run["state"] == "finished", app.api("GET", f"/api/runs/{run['id']}/log").text
    log = app.api("GET", f"/api/runs/{run['id']}/log").text
    distance = float(re.search(r"Stopped (\d\.\d+) m before the wall", log).group(1))
    assert 0.3 < distance <= 0.5


def test_staff_add_a_robot_and_its_agent_starts(any_appliance):
    app = any_appliance
    name = f"sim{app.mode}"
    body = {"name": name, "url": "sim://?arena=square", "settings": {"max_linear": 0.1}}
    response = app.api("POST", "/api/robots", body)
    assert response.status_code == 201, response.text
    if app.mode == "split":  # fleet mode: the robot computer runs its own agent
        app._spawn("agent", name)
    sensors = wait_for(lambda: (r := app.api("GET", f"/api/robots/{name}/sensors")).status_code
                       == 200 and r.json(), what="the new robot's agent")  # fmt: skip
    assert sensors["heading"] == 0.0
    program = app.create_program(
        f"slow on {name}", "import robot\nprint(robot.Robot().drive(1, 0))\n"
    )
    run = app.wait_run(app.run_program(program["id"], robot=name)["id"])
    log = app.api("GET", f"/api/runs/{run['id']}/log").text
    assert "{'linear': 0.1, 'angular': 0.0}" in log  # the robot's own speed limit
    assert app.api("POST", "/api/robots", body).status_code == 409


def test_a_run_asked_of_a_robot_just_added_waits_for_its_agent(any_appliance):
    """Added, then run at once, before its agent is up: the run waits (starting) and runs,
    never `lost` (which is for runs whose process died with their agent). Ten times.
    (tests/e2e/test_add_and_run.py: with robots slow to answer, and each run started once.)"""
    app = any_appliance
    program = app.create_program("first run", "print('first')\n")
    for i in range(10):
        name = f"fresh{app.mode}{i}"
        assert app.api("POST", "/api/robots", {"name": name, "url": "sim://"}).status_code == 201
        run = app.run_program(program["id"], robot=name)
        assert run["state"] in ("starting", "running", "finished"), run
        agent = None
        if app.mode == "split":  # fleet mode: the robot computer starts its agent after
            agent = app._spawn("agent", name)
        # However long a loaded machine takes to start the agent: the timeout only says
        # when a run that never ends has failed.
        ended = app.wait_run(run["id"], timeout=120)
        assert ended["state"] == "finished", (i, ended)
        if agent is not None:  # done: it must not load the machine for the tests after
            agent.terminate()
            agent.wait(timeout=30)


def test_sensors_of_an_unknown_robot(any_appliance):
    response = any_appliance.api("GET", "/api/robots/ghost/sensors")
    assert response.status_code == 404 and "ghost" in response.json()["detail"]


def test_a_program_may_call_the_robot_api_the_moment_it_starts(any_appliance):
    app = any_appliance
    program = app.create_program("eager", "import robot\nrobot.Robot().sensors()\n")
    runs = [app.run_program(program["id"])["id"] for _ in range(12)]
    states = [app.wait_run(run_id)["state"] for run_id in runs]
    assert states == ["finished"] * len(runs)


def test_a_robot_that_is_away_is_reported_not_waited_for(any_appliance):
    app = any_appliance
    name = f"away{app.mode}"
    body = {"name": name, "url": "pioneer+tcp://127.0.0.1:1"}  # nothing listens there
    assert app.api("POST", "/api/robots", body).status_code == 201
    if app.mode == "split":
        app._spawn("agent", name)
    response = wait_for(
        lambda: (
            (r := app.api("GET", f"/api/robots/{name}/sensors")).status_code == 503
            and "cannot" in r.json()["detail"]
            and r
        ),
        what="the agent to report its robot away",
    )
    assert name in response.json()["detail"]


def test_a_run_stopped_as_it_starts_never_runs_a_line(any_appliance):
    """Its stop may come while its box is made: then its program must not run at all, nor
    be left running until the stop's grace period ends it."""
    app = any_appliance
    program = app.create_program("stopped at once", "print('RAN', flush=True)\n" + FOREVER)
    for _ in range(5):
        run_id = app.run_program(program["id"])["id"]
        app.api("POST", f"/api/runs/{run_id}/stop")
        run = app.wait_run(run_id)
        log = app.api("GET", f"/api/runs/{run_id}/log").text
        assert run["state"] == "stopped", (run, log)
        if run["reason"] == "stopped by user before it started":
            assert "RAN" not in log and "tick" not in log, log
        else:  # it had started: the SIGTERM ended it at once, no grace needed
            assert "did not stop within" not in log, log
