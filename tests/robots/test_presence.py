"""A robot is online while its agent's heartbeat lands; the runs of one gone silent are lost."""

from datetime import timedelta

import pytest
from django.contrib.auth.models import User
from django.utils import timezone

from programs.models import Program, Run
from robotide.models import ApiToken
from robots.models import Robot
from robots.presence import sweep_lost, sweep_unclaimed

pytestmark = pytest.mark.django_db


@pytest.fixture
def lab():
    alice = User.objects.create_user("alice")
    program = Program.objects.create(owner=alice, name="p", language="python")
    now = timezone.now()
    alive = Robot.objects.create(name="alive", url="sim://", last_seen=now)
    silent = Robot.objects.create(
        name="silent", url="sim://", last_seen=now - timedelta(seconds=60)
    )
    never = Robot.objects.create(name="never", url="sim://")
    return alice, program, alive, silent, never


def run_on(program, robot, state, age=30, pid=None):
    run = Run.create_for(program, robot, program.owner)
    created = timezone.now() - timedelta(seconds=age)
    Run.objects.filter(pk=run.pk).update(state=state, created=created, pid=pid)
    return run


def test_runs_of_a_silent_agent_are_lost_and_the_others_are_not(lab):
    alice, program, alive, silent, never = lab
    running_alive = run_on(program, alive, Run.State.RUNNING, pid=10)
    running_silent = run_on(program, silent, Run.State.RUNNING, pid=11)
    claimed_never = run_on(program, never, Run.State.STARTING, pid=0)  # taken (Run.claim)
    just_asked = run_on(program, silent, Run.State.STARTING, age=0)  # may still be handed over
    finished = run_on(program, silent, Run.State.FINISHED)
    lost = sweep_lost()
    assert sorted(lost) == sorted([(running_silent.pk, "silent"), (claimed_never.pk, "never")])
    running_silent.refresh_from_db()
    assert running_silent.state == "lost" and "stopped answering" in running_silent.reason
    for run, state in [(running_alive, "running"), (just_asked, "starting"),
                       (finished, "finished")]:  # fmt: skip
        run.refresh_from_db()
        assert run.state == state
    assert sweep_lost() == []  # once


def test_a_run_no_agent_took_yet_waits_for_it_and_is_not_lost(lab):
    """Asked of a robot just added, whose agent is still starting (never seen yet), or of one
    whose agent is away: nothing of it ran, so it is not lost; it waits to be taken (the
    agent's start takes it, sweep_unclaimed fails it if nobody does)."""
    alice, program, alive, silent, never = lab
    untaken = [run_on(program, robot, Run.State.STARTING) for robot in (never, silent)]
    assert sweep_lost() == []
    for run in untaken:
        run.refresh_from_db()
        assert (run.state, run.pid) == ("starting", None)


def test_the_api_says_which_robots_are_online(client, lab):
    alice, *_ = lab
    _, token = ApiToken.issue(alice)
    robots = client.get("/api/robots", HTTP_AUTHORIZATION=f"Bearer {token}").json()
    online = {r["name"]: (r["online"], r["last_seen"] is not None) for r in robots}
    assert online == {"alive": (True, True), "silent": (False, True), "never": (False, False)}


def test_the_pages_say_online_offline_and_when_last_seen(client, lab):
    alice, *_ = lab
    client.force_login(alice)
    listing = client.get("/robots/").content.decode()
    assert (
        listing.count('class="badge online"') == 1 and listing.count('class="badge offline"') == 2
    )
    assert "never seen" in listing
    page = client.get("/robots/silent/").content.decode()
    assert "The robot's agent is offline: last seen 1\xa0minute ago" in page


def test_a_run_no_agent_took_is_failed_after_the_start_timeout(lab, settings):
    settings.AGENT_START_TIMEOUT = 30
    alice, program, alive, *_ = lab
    waiting = run_on(program, alive, Run.State.STARTING, age=0)
    taken = run_on(program, alive, Run.State.STARTING, age=0)
    seen = {}
    assert sweep_unclaimed(seen, now=100.0) == []  # noted, not failed: it may be on its way
    Run.objects.filter(pk=taken.pk).update(pid=0)  # the agent took this one
    assert sweep_unclaimed(seen, now=129.0) == []
    assert sweep_unclaimed(seen, now=131.0) == [(waiting.pk, "alive")]
    waiting.refresh_from_db()
    assert waiting.state == "failed" and "did not take it" in waiting.reason
    assert seen == {}


def test_the_agents_health_check_says_whether_its_robots_are_online(lab, capsys):
    import socket

    from robotide.cli import build_parser, cmd_online

    def online(*argv):
        return cmd_online(build_parser().parse_args(["robots", "online", *argv]), [])

    assert online("alive") == 0
    assert online("alive", "silent") == 1 and "silent: offline" in capsys.readouterr().out
    assert online("--here") == 1  # no agent on this host has beaten yet
    Robot.objects.filter(name="alive").update(agent_host=socket.gethostname())
    assert online("--here") == 0
    Robot.objects.filter(name="silent").update(agent_host=socket.gethostname())
    assert online("--here") == 1
