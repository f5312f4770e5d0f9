"""Fleet mode for real: the compose file's services run by robotide.fleet (as `make fleet`
does), on its own PostgreSQL and Redis with their passwords, with the web tier in 2 worker
processes and 5 robots each added by its own block, each its own agent process.

Programs run on all 5 robots at once; a run's live log is watched through a worker other than
the one that accepted it; an agent is killed (SIGKILL): its robot goes offline, its run is
lost; started again, it serves again, the portal untouched.
"""

import asyncio
import json
import os
import re
import signal
import time

import httpx
import pytest
import websockets
import yaml

from robotide.fleet import Fleet, PrivateServers, secrets
from tests.appliance import ADMIN_PASSWORD, ROOT, Appliance, cookie_header, free_port
from tests.appliance import wait_for as wait

ROBOTS = [f"r{n}" for n in range(1, 6)]
WORKER = "x-robotide-worker"
PRINTS = "import time\nfor i in range(40):\n    print('line', i, flush=True)\n    time.sleep(0.1)\n"
FOREVER = "import time\nprint('started', flush=True)\ntime.sleep(600)\n"


def override(port: int) -> dict:
    """What a lab adds to the compose file: its robots, one block each, and its port."""
    agents = {
        f"agent-{name}": {
            "command": ["robotide", "agent", name, "--url", "sim://"],
            "environment": {"DATABASE_URL": "x", "REDIS_URL": "x", "ROBOTIDE_DATA": "x"},
            "depends_on": {"web": {"condition": "service_healthy"}},
            "healthcheck": {"test": ["CMD", "robotide", "robots", "online", name]},
        }
        for name in ROBOTS
    }
    web = {"ports": [f"{port}:8000"]}
    return {"services": {"web": web, **agents}}


@pytest.fixture(scope="module")
def fleet(fleet_data):
    data = fleet_data
    port = free_port()
    extra = data / "lab.yml"
    extra.write_text(yaml.safe_dump(override(port)))
    passwords = secrets(data / "secrets.env")
    servers = PrivateServers(data, passwords)
    app = Appliance(data, mode="split")
    app.port, app.url = port, f"http://127.0.0.1:{port}"
    variables = {"ROBOTIDE_WEB_WORKERS": "2", "ROBOTIDE_ADMIN_PASSWORD": ADMIN_PASSWORD}
    runner = None
    try:
        servers.start()
        app.env.update(DATABASE_URL=servers.database_url, REDIS_URL=servers.redis_url)
        runner = Fleet(
            [ROOT / "docker-compose.yml", extra], data=data, database=servers.database_url,
            redis=servers.redis_url, host="127.0.0.1", variables={**variables, **passwords},
            only=["web", *(f"agent-{r}" for r in ROBOTS)],
        )  # fmt: skip
        runner.start(timeout=90)
        app.token = app.cli("token", "admin").strip()
        yield app, runner
    finally:
        if runner is not None:
            runner.stop()
        print(app.logs()[-5000:])
        app.stop()
        servers.stop()


def test_a_web_worker_that_dies_is_replaced(fleet):
    app, _ = fleet
    before = workers_seen(app)
    victim = sorted(before)[0]
    os.kill(int(victim.rpartition(":")[2]), signal.SIGKILL)
    wait(lambda: len(seen := workers_seen(app)) == 2 and victim not in seen,
         what="a new worker in place of the dead one")  # fmt: skip


def test_static_files_are_compressed_and_kept_for_good(fleet):
    app, _ = fleet
    page = httpx.get(f"{app.url}/accounts/login/").text
    css = re.search(r'href="(/static/robotide/app\.[0-9a-f]{12}\.css)"', page).group(1)
    response = httpx.get(app.url + css, headers={"Accept-Encoding": "gzip"})
    assert response.status_code == 200 and response.headers["content-encoding"] == "gzip"
    assert "immutable" in response.headers["cache-control"]


def workers_seen(app, times=20) -> set[str]:
    """The workers that answered ``times`` requests, each on a new connection."""
    with httpx.Client(limits=httpx.Limits(max_keepalive_connections=0)) as client:
        return {client.get(f"{app.url}/healthz").headers[WORKER] for _ in range(times)}


def test_two_workers_and_five_agents_serve_the_portal(fleet):
    app, runner = fleet
    # Either worker serves any request; which one accepts is the kernel's choice, and on a
    # loaded machine the same one may win twenty times in a row.
    wait(lambda: len(workers_seen(app)) == 2, timeout=60, what="both workers answering")
    robots = {r["name"]: r for r in app.api("GET", "/api/robots").json()}
    assert all(robots[name]["online"] and robots[name]["last_seen"] for name in ROBOTS)
    pids = {runner.services[f"agent-{name}"].process.pid for name in ROBOTS}
    assert len(pids) == 5


async def watch_log(app, run_id: int, cookies: str, avoid: str) -> tuple[str, str]:
    """The run's live log, through a websocket on a worker other than ``avoid``."""
    for _ in range(50):
        socket = await websockets.connect(
            f"ws://127.0.0.1:{app.port}/ws/runs/{run_id}/",
            additional_headers={"Cookie": cookies, "Origin": app.url},
        )
        worker = socket.response.headers[WORKER]
        if worker != avoid:
            break
        await socket.close()
    else:
        pytest.fail(f"every websocket landed on {avoid}")
    text = ""
    async with socket:
        deadline = time.monotonic() + 30
        while "line 39" not in text and time.monotonic() < deadline:
            text += await asyncio.wait_for(socket.recv(), 30)
    return worker, text


async def test_runs_on_all_five_at_once_logs_through_another_worker(fleet):
    app, _ = fleet
    program = app.create_program("count", PRINTS)
    started = []
    for name in ROBOTS:
        response = app.api("POST", f"/api/programs/{program['id']}/run", {"robot": name})
        assert response.status_code == 201, response.text
        started.append((response.json()["id"], response.headers[WORKER]))
    session = app.session()
    cookies = cookie_header(session)
    run_id, accepted_by = started[0]
    worker, text = await watch_log(app, run_id, cookies, avoid=accepted_by)
    assert worker != accepted_by and "line 39" in text
    for run_id, _ in started:
        run = await asyncio.to_thread(app.wait_run, run_id, timeout=60)
        assert run["state"] == "finished", run
        log = app.api("GET", f"/api/runs/{run_id}/log").text
        assert log.count("line ") == 40
    running = [r["robot"] for r in app.api("GET", "/api/runs?state=finished").json()]
    assert set(ROBOTS) <= set(running)


def test_an_agent_killed_goes_offline_its_run_lost_then_it_serves_again(fleet):
    app, runner = fleet
    program = app.create_program("forever", FOREVER)
    run = app.run_program(program["id"], robot="r3")
    wait(lambda: app.api("GET", f"/api/runs/{run['id']}").json()["state"] == "running",
         what="the run running")  # fmt: skip
    killed_at = time.monotonic()
    runner.kill("agent-r3")  # SIGKILL, as a crash or a pulled power cable

    def robot(name):
        return next(r for r in app.api("GET", "/api/robots").json() if r["name"] == name)

    wait(lambda: not robot("r3")["online"], what="r3 offline")
    offline_after = time.monotonic() - killed_at
    lost = app.wait_run(run["id"], states=("lost",))
    assert "stopped answering" in lost["reason"]
    assert all(robot(name)["online"] for name in ROBOTS if name != "r3")
    runner.restart("agent-r3")
    wait(lambda: robot("r3")["online"], what="r3 online again")
    again = app.run_program(app.create_program("again", "print('back')\n")["id"], robot="r3")
    assert app.wait_run(again["id"])["state"] == "finished"
    assert app.api("GET", f"/api/runs/{again['id']}/log").text.startswith("back\n")
    print(json.dumps({"offline_after_s": round(offline_after, 1)}))


DRIVE_AND_WAIT = "import robot, time\nrobot.Robot().drive(0.1, 0.0)\ntime.sleep(600)\n"


def test_three_users_queue_for_one_robot(fleet):
    app, _ = fleet
    tokens = {name: app.new_user(name) for name in ("alice", "bob", "carol")}

    def run_as(user, source):
        program = app.create_program(f"{user}'s", source, token=tokens[user])
        return app.run_program(program["id"], robot="r1", token=tokens[user])

    def run(run_id, user):
        return app.api("GET", f"/api/runs/{run_id}", token=tokens[user]).json()

    alice = run_as("alice", DRIVE_AND_WAIT)
    wait(lambda: run(alice["id"], "alice")["state"] == "running", what="alice's run")
    time.sleep(1.0)  # her drive() takes the robot's lease
    bob = run_as("bob", "print('bob drove')\n")
    wait(lambda: run(bob["id"], "bob")["queue_position"] == 1, what="bob first in line")
    carol = run_as("carol", "print('carol drove')\n")
    wait(lambda: run(carol["id"], "carol")["queue_position"] == 2, what="carol second")
    app.api("POST", f"/api/runs/{alice['id']}/stop", token=tokens["alice"])
    assert app.wait_run(bob["id"])["state"] == "finished"
    assert app.wait_run(carol["id"])["state"] == "finished"
    assert run(alice["id"], "alice")["state"] == "stopped"
