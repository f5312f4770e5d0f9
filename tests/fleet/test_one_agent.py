"""One agent process per robot, and one `robotide agent --personal-sims` per fleet, for real
(PostgreSQL, Redis, the robotide command): a second process started for the same robot, or for
the personal sims, finds the first's lock held, says which pid holds it and stands by (or, with
--no-standby, exits 3); the first killed (SIGKILL), the second takes over and serves.

Two that both served took each other's messages and starts (a benchmark's check runs "killed
by SIGKILL" at once). On the code before, the second process serves beside the first and says
no such thing (and knows no --no-standby): these tests fail there."""

import signal

import pytest

from tests.appliance import Appliance, wait_for


@pytest.fixture(scope="module")
def fleet(tmp_path_factory):
    app = Appliance(tmp_path_factory.mktemp("one-agent"), mode="split").start()
    try:
        yield app
    finally:
        print(app.logs()[-6000:])
        app.stop()


def output(app, proc) -> str:
    """What ``proc`` (spawned by the appliance) has printed so far."""
    index = app.processes.index(proc)
    return (app.data_dir / f"agent-{index}.log").read_text()


def said(app, proc, text: str, what: str) -> str:
    """Wait for ``proc`` to print ``text``; its output, or a failure if it ended first."""
    ended = lambda: proc.poll() is not None and text not in output(app, proc)  # noqa: E731
    return wait_for(lambda: text in (out := output(app, proc)) and out, what=what, gone=ended)


def ran(app, program: dict, robot: str, token=None) -> dict:
    run = app.run_program(program["id"], robot=robot, token=token)
    return app.wait_run(run["id"])


def test_a_second_agent_of_a_robot_stands_by_and_takes_over_when_the_first_is_killed(fleet):
    app = fleet
    first = app.agent  # `robotide agent sim`, serving
    second = app._spawn("agent", "sim")
    said(app, second, f"sim is served by pid {first.pid} on ", "the second standing by")
    assert "running" not in output(app, second)
    program = app.create_program("hello", "print('hello from the one agent')\n")
    run = ran(app, program, "sim")
    assert run["state"] == "finished", run
    log = app.api("GET", f"/api/runs/{run['id']}/log").text
    assert log.startswith("hello from the one agent\n[robotide] finished"), log

    first.send_signal(signal.SIGKILL)
    said(app, second, "robotide agent for sim running", "the second taking over")
    assert "sim: took over" in output(app, second)
    run = ran(app, program, "sim")
    assert run["state"] == "finished", run


def test_a_second_personal_sims_process_refuses_or_stands_by(fleet):
    app = fleet
    first = app._spawn("agent", "--personal-sims")
    said(app, first, "robotide agent for personal sims running", "the first serving")

    standby = app._spawn("agent", "--personal-sims")
    said(app, standby, f"personal sims is served by pid {first.pid} on ", "standing by")
    refused = app._spawn("agent", "--personal-sims", "--no-standby")
    assert refused.wait(timeout=60) == 3, output(app, refused)
    assert f"personal sims is served by pid {first.pid} on " in output(app, refused)
    assert "running" not in output(app, refused)

    token = app.new_user("pia")
    sim = app.api("POST", "/api/sims", {}, token=token)
    assert sim.status_code == 201, sim.text
    program = app.create_program("mine", "print('on my sim')\n", token=token)
    run = ran(app, program, sim.json()["name"], token=token)
    assert run["state"] == "finished", run  # one agent for it: not killed by another's start

    first.send_signal(signal.SIGKILL)
    said(app, standby, "robotide agent for personal sims running", "the standby taking over")
    run = ran(app, program, sim.json()["name"], token=token)
    assert run["state"] == "finished", run
    log = app.api("GET", f"/api/runs/{run['id']}/log", token=token).text
    assert log.startswith("on my sim\n[robotide] finished"), log


def test_a_holder_whose_lock_connection_is_cut_stops_and_its_standby_takes_over(fleet):
    """Its lock gone with its connection (PostgreSQL restarted, the network cut), a process
    no longer knows that nobody else serves its robots: it stops, the standby serves."""
    import psycopg

    from tests.appliance import POSTGRES

    app = fleet
    first = app._spawn("agent", "--sim", "1")
    said(app, first, "robotide agent for sim-1 running", "the first serving")
    second = app._spawn("agent", "--sim", "1")
    said(app, second, f"sim-1 is served by pid {first.pid} on ", "the second standing by")
    with psycopg.connect(f"{POSTGRES}/{app.database}", autocommit=True) as conn:
        cut = conn.execute(
            "SELECT pg_terminate_backend(pid) FROM pg_stat_activity"
            " WHERE datname = current_database() AND application_name LIKE %s",
            [f"robotide agent pid {first.pid} on %"],
        ).fetchall()
    assert cut == [(True,)], cut
    assert first.wait(timeout=60) == 3, output(app, first)
    assert "stopped, so that no two processes serve the same robots" in output(app, first)
    said(app, second, "robotide agent for sim-1 running", "the second taking over")
    program = app.create_program("again", "print('sim-1 served')\n")
    run = ran(app, program, "sim-1")
    assert run["state"] == "finished", (run, output(app, second))
