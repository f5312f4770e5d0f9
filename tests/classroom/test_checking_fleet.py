"""Checking in fleet mode: the web server (PostgreSQL, Redis) makes the attempt through the
API; the check sims' agents run in `robotide agent --personal-sims`, another process, which
marks each run ended and so judges it there (classroom.receivers on programs' run_ended: the
web server marks no finished run ended). The attempt is DONE as the API shows it, its hidden
variant's run sealed from its student, and the check sims are gone after.

On the code before this issue there is no check endpoint (404): the test fails there."""

import math

import pytest

from tests.appliance import Appliance, wait_for

NORTH = math.pi / 2
PASSES = """\
import time
import robot
bot = robot.Robot()
bot.drive(0.3, 0.0)
while bot.sensors()["range"] > 0.5:
    time.sleep(0.02)
bot.stop()
print("stopped before the wall", flush=True)
"""


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    app = Appliance(tmp_path_factory.mktemp("fleet-checks"), mode="split").start()
    try:
        app._spawn("agent", "--personal-sims")
        yield app
    finally:
        app.stop()


def test_a_check_is_judged_in_the_agent_process_that_ends_its_runs(fleet):
    tess = fleet.new_user("tess", staff=True)
    made = fleet.api("POST", "/api/classes", {"name": "7a", "students": ["ana"]}, token=tess)
    assert made.status_code == 201, made.text
    ana = fleet.cli("token", "ana").strip()
    exercise = {
        "title": "Reach the kitchen", "text": "", "world": "boxes", "class": made.json()["id"],
        "languages": [], "speed": 2, "time_limit_s": 30,
        "variants": [{"x": -0.5, "y": 0.0, "theta": NORTH, "hidden": False},
                     {"x": -0.6, "y": -0.6, "theta": NORTH, "hidden": True}],
        "checks": [{"kind": "reach_zone", "zone": "kitchen", "points": 2},
                   {"kind": "no_contact"}],
    }  # fmt: skip
    exercise = fleet.api("POST", "/api/exercises", exercise, token=tess)
    assert exercise.status_code == 201, exercise.text
    program = fleet.create_program("kitchen", PASSES, token=ana)
    path = f"/api/exercises/{exercise.json()['id']}/check"
    asked = fleet.api("POST", path, {"program": program["id"]}, token=ana)
    assert asked.status_code == 202, asked.text
    attempt_path = f"/api/attempts/{asked.json()['id']}"

    def judged():
        attempt = fleet.api("GET", attempt_path, token=ana).json()
        return attempt if attempt["state"] in ("done", "error") else None

    attempt = wait_for(judged, timeout=300, what="the attempt judged")
    assert attempt["state"] == "done" and attempt["passed"], attempt
    assert attempt["score"] == 3.0 and len(attempt["results"]) == 4, attempt
    hidden = [row for row in attempt["results"] if row["variant"] == 1]
    assert all(row["why"].startswith("hidden variant 2: ") for row in hidden), hidden

    # Its runs: the visible one hers to read, the hidden one sealed (her teacher reads it).
    runs = fleet.api("GET", "/api/runs?limit=1000", token=tess).json()
    checked = sorted((run for run in runs if run["owner"] == "ana"), key=lambda r: r["id"])
    assert len(checked) == 2 and all(run["state"] == "finished" for run in checked), checked
    visible, sealed = checked
    assert fleet.api("GET", f"/api/runs/{visible['id']}", token=ana).status_code == 200
    assert fleet.api("GET", f"/api/runs/{sealed['id']}", token=ana).status_code == 404
    assert fleet.api("GET", f"/api/runs/{sealed['id']}", token=tess).status_code == 200
    # The check sims are gone: removed by their agents (their rows kept for their runs).
    count = (
        "from robots.models import Robot;"
        "print(Robot.objects.filter(checking=True, reaped__isnull=True).count(),"
        " Robot.objects.filter(checking=True).count())"
    )
    # (the shell's last line: it may say what it imported first)
    wait_for(lambda: fleet.cli("manage", "shell", "-c", count).split()[-2:] == ["0", "2"],
             what="the check sims removed", interval=0.5)  # fmt: skip
