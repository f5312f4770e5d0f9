"""The websocket consumers: access checks, the log tail, the live lines, the state."""

import asyncio
import contextlib
import gc
import logging
import threading

import pytest
from channels.db import database_sync_to_async
from channels.layers import get_channel_layer
from channels.testing import WebsocketCommunicator
from django.contrib.auth import SESSION_KEY
from django.contrib.auth.models import AnonymousUser, Group, User
from django.contrib.sessions.backends.db import SessionStore
from uvicorn.protocols.utils import ClientDisconnected

from programs import watch_pass
from programs.consumers import ConsoleConsumer, RunConsumer, RunListConsumer
from programs.models import Program, Run
from programs.runlog import tail
from robotide.models import ClassTeacher
from robots.bus import RUNS_GROUP, agent_channel, console_group, run_group
from robots.consumers import RobotConsumer
from robots.models import Robot

pytestmark = pytest.mark.django_db(transaction=True)


@database_sync_to_async
def make_run(log: bytes):
    alice = User.objects.create_user("alice")
    bob = User.objects.create_user("bob")
    robot = Robot.objects.create(name="sim", url="sim://")
    program = Program.objects.create(owner=alice, name="p", language="python")
    run = Run.create_for(program, robot, alice)
    run.log_path.parent.mkdir(parents=True)
    run.log_path.write_bytes(log)
    return alice, bob, run


def teacher_of(student):
    """A teacher (staff) of a class the student is in."""
    group = Group.objects.create(name="class-a")
    student.groups.add(group)
    teacher = User.objects.create_user("teacher", is_staff=True)
    ClassTeacher.objects.create(group=group, user=teacher)
    return teacher


class Communicator(WebsocketCommunicator):
    """A message waited for up to 30 s, not channels' 1 s (which ran out on a busy machine):
    only a message that never comes waits it out."""

    async def receive_from(self, timeout=30):
        return await super().receive_from(timeout)


def communicator(consumer, path, user, **kwargs):
    comm = Communicator(consumer.as_asgi(), path)
    comm.scope["user"] = user
    comm.scope["url_route"] = {"kwargs": kwargs}
    return comm


async def test_the_run_stream_starts_with_the_log_and_skips_what_it_already_sent():
    alice, _, run = await make_run(b"o first\ne oops\no partial line without end")
    comm = communicator(RunConsumer, f"/ws/runs/{run.pk}/", alice, run_id=run.pk)
    connected, _ = await comm.connect()
    assert connected
    tail = await comm.receive_from()
    assert (
        tail
        == '<div id="log-lines"><div class="ln o">first</div><div class="ln e">oops</div></div>'
    )
    assert 'id="run-status"' in await comm.receive_from()
    layer = get_channel_layer()
    lines = [[0, "o", "first"], [8, "e", "oops"], [15, "o", "partial line without end"]]
    await layer.group_send(
        run_group(run.pk), {"type": "run.output", "run_id": run.pk, "lines": lines, "skipped": 0}
    )
    appended = await comm.receive_from()
    assert appended == (
        '<div id="log-lines" hx-swap-oob="beforeend">'
        '<div class="ln o">partial line without end</div></div>'
    )
    await comm.disconnect()


@contextlib.asynccontextmanager
async def database_thread_busy():
    """The one thread that does database work, held by other work until the block ends."""
    busy, release = threading.Event(), threading.Event()

    def database_work():
        busy.set()
        release.wait(30)

    work = asyncio.ensure_future(database_sync_to_async(database_work)())
    try:
        await asyncio.to_thread(busy.wait, 10)
        yield
    finally:
        release.set()
        await work


async def test_a_line_reaches_the_viewer_while_the_database_thread_is_busy():
    # A start's first line comes while its state is written, in the one thread that does
    # database work: handling the line must not wait for that thread.
    alice, _, run = await make_run(b"")
    comm = communicator(RunConsumer, f"/ws/runs/{run.pk}/", alice, run_id=run.pk)
    assert (await comm.connect())[0]
    await comm.receive_from()  # the (empty) tail
    await comm.receive_from()  # the state
    async with database_thread_busy():
        lines = [[0, "o", "first"]]
        await get_channel_layer().group_send(
            run_group(run.pk), {"type": "run.output", "run_id": run.pk, "lines": lines}
        )
        assert "first" in await comm.receive_from(timeout=10)
    await comm.disconnect()


async def test_another_users_run_stream_is_refused():
    _, bob, run = await make_run(b"o secret\n")
    comm = communicator(RunConsumer, f"/ws/runs/{run.pk}/", bob, run_id=run.pk)
    connected, code = await comm.connect()
    assert not connected


async def test_the_run_list_needs_a_signed_in_user():
    comm = communicator(RunListConsumer, "/ws/runs/", AnonymousUser())
    connected, _ = await comm.connect()
    assert not connected


async def test_the_run_list_rerenders_for_its_user_only():
    alice, bob, run = await make_run(b"")
    comm = communicator(RunListConsumer, "/ws/runs/", bob)
    assert (await comm.connect())[0]
    await get_channel_layer().group_send(
        RUNS_GROUP, {"type": "runs.changed", "run_id": run.pk, "robot": "sim"}
    )
    html = await comm.receive_from(timeout=30)
    assert 'id="run-tables"' in html and f"#{run.pk}" not in html
    await comm.disconnect()


async def test_robot_page_shows_svg_only_as_an_image():
    alice, _, _ = await make_run(b"")
    comm = communicator(RobotConsumer, "/ws/robots/sim/", alice, name="sim")
    assert (await comm.connect())[0]
    # First what runs there now: the page may have missed a change since it was rendered.
    running = await comm.receive_from(timeout=30)
    assert 'id="robot-running"' in running and 'p</a> <span class="state starting">' in running
    assert 'id="estop-banner"' in await comm.receive_from(timeout=30)  # no stop in force
    svg = '<svg xmlns="http://www.w3.org/2000/svg"><script>alert(1)</script></svg>'
    event = {
        "type": "robot.telemetry",
        "robot": "sim",
        "sensors": {"heading": 12.5, "position": {"x": 1.0}},
        "units": {"heading": "deg"},
        "shows": {"compass": {"value": svg, "run": 1}, "note": {"value": "<b>hi</b>", "run": 1}},
    }
    await get_channel_layer().group_send("robot-sim", event)
    html = await comm.receive_from(timeout=30)
    assert "<th>heading</th><td>12.5</td>" in html and "position.x" in html
    assert "<script>" not in html and 'src="data:image/svg+xml;base64,' in html
    assert "&lt;b&gt;hi&lt;/b&gt;" in html
    await comm.disconnect()


async def test_a_late_viewer_is_told_exactly_how_many_lines_it_missed():
    log = b"".join(f"o {i}\n".encode() for i in range(10))
    alice, _, run = await make_run(log)
    comm = communicator(RunConsumer, f"/ws/runs/{run.pk}/", alice, run_id=run.pk)
    assert (await comm.connect())[0]
    await comm.receive_from()  # the tail: lines 0-9
    await comm.receive_from()  # the state
    with open(run.log_path, "ab") as f:  # lines 10-14 go by unseen, 15 comes live
        f.write(b"".join(f"o {i}\n".encode() for i in range(10, 16)))
    offsets = [len(log) + sum(len(f"o {j}\n") for j in range(10, i)) for i in range(10, 16)]
    # The agent skipped lines 3-14 since its previous batch (which ended after line 2).
    event = {"type": "run.output", "run_id": run.pk, "lines": [[offsets[-1], "o", "15"]],
             "skipped": 12, "skipped_from": 12}  # fmt: skip
    await get_channel_layer().group_send(run_group(run.pk), event)
    html = await comm.receive_from()
    assert "… 5 line(s) not shown live" in html and '<div class="ln o">15</div>' in html
    await comm.disconnect()


async def test_a_page_rendered_with_the_log_gets_only_what_came_after():
    alice, _, run = await make_run(b"o one\no two\n")
    shown = len(b"o one\no two\n")
    with open(run.log_path, "ab") as f:
        f.write(b"e three\no four\no unfini")
    path = f"/ws/runs/{run.pk}/?from={shown}"
    comm = communicator(RunConsumer, path, alice, run_id=run.pk)
    comm.scope["query_string"] = f"from={shown}".encode()
    assert (await comm.connect())[0]
    assert await comm.receive_from() == (
        '<div id="log-lines" hx-swap-oob="beforeend">'
        '<div class="ln e">three</div><div class="ln o">four</div></div>'
    )
    await comm.disconnect()


# Not an offset of ASCII digits: "²" passes str.isdigit() but not int(), "١" (Arabic-Indic
# one) passes both, a raw byte is not UTF-8; a sign, or more digits than an offset has.
NOT_AN_OFFSET = [b"from=%C2%B2", b"from=%D9%A1", b"from=\xff", b"from=-1", b"from=+5",
                 b"from=99999999999999999999999"]  # fmt: skip


@pytest.mark.parametrize("query", NOT_AN_OFFSET)
async def test_a_bad_offset_gets_the_whole_tail_and_leaves_no_one_in_the_group(query):
    alice, bob, run = await make_run(b"o one\no two\n")
    layer, group = get_channel_layer(), run_group(run.pk)
    comm = communicator(RunConsumer, f"/ws/runs/{run.pk}/", bob, run_id=run.pk)
    comm.scope["query_string"] = query
    assert not (await comm.connect())[0]  # turned away, and out of the run's group again
    assert not layer.groups.get(group)
    comm = communicator(RunConsumer, f"/ws/runs/{run.pk}/", alice, run_id=run.pk)
    comm.scope["query_string"] = query
    assert (await comm.connect())[0]
    assert await comm.receive_from() == (
        '<div id="log-lines"><div class="ln o">one</div><div class="ln o">two</div></div>'
    )
    assert 'id="run-status"' in await comm.receive_from()
    await comm.disconnect()
    assert not layer.groups.get(group)


async def test_the_run_list_keeps_what_staff_see_and_where_stop_returns():
    alice, _, run = await make_run(b"")
    staff = await database_sync_to_async(teacher_of)(alice)
    comm = communicator(RunListConsumer, "/ws/runs/", staff)
    comm.scope["query_string"] = b"robot=sim"
    assert (await comm.connect())[0]
    await get_channel_layer().group_send(
        RUNS_GROUP, {"type": "runs.changed", "run_id": run.pk, "robot": "sim"}
    )
    html = await comm.receive_from(timeout=30)
    assert "<th>User</th>" in html and f"#{run.pk}" in html
    assert 'name="next" value="/runs/?robot=sim"' in html
    await comm.disconnect()


# -- the workbench console -------------------------------------------------------------------


async def test_the_console_follows_the_run_it_is_attached_to_from_its_first_line():
    alice, _, run = await make_run(b"o first\ne oops\n")
    path = f"/ws/programs/{run.program_id}/console/"
    comm = communicator(ConsoleConsumer, path, alice, program_id=run.program_id)
    assert (await comm.connect())[0]
    layer = get_channel_layer()
    attach = {"type": "console.attach", "run_id": run.pk}
    await layer.group_send(console_group(run.program_id, alice.pk), attach)
    console = await comm.receive_from()
    assert f'<div id="console-run" data-run="{run.pk}"' in console
    assert 'id="run-status"' in console
    assert '<div class="ln o">first</div><div class="ln e">oops</div>' in console
    lines = [[15, "o", "live"]]
    await layer.group_send(
        run_group(run.pk), {"type": "run.output", "run_id": run.pk, "lines": lines, "skipped": 0}
    )
    assert "live" in await comm.receive_from()
    await comm.disconnect()


async def test_a_console_is_refused_a_program_its_user_may_not_see():
    alice, bob, run = await make_run(b"o secret\n")
    path = f"/ws/programs/{run.program_id}/console/"
    comm = communicator(ConsoleConsumer, path, bob, program_id=run.program_id)
    assert not (await comm.connect())[0]


async def test_a_console_shows_no_run_its_user_may_not_see():
    # Attaching is by the user's own console group, but a run must still be theirs to see.
    alice, bob, run = await make_run(b"o secret\n")
    other = await database_sync_to_async(Program.objects.create)(
        owner=bob, name="bobs", language="python"
    )
    path = f"/ws/programs/{other.pk}/console/"
    comm = communicator(ConsoleConsumer, path, bob, program_id=other.pk)
    assert (await comm.connect())[0]
    attach = {"type": "console.attach", "run_id": run.pk}
    await get_channel_layer().group_send(console_group(other.pk, bob.pk), attach)
    assert await comm.receive_nothing(timeout=0.3)
    await comm.disconnect()


async def test_a_robot_websocket_stops_driving_once_its_user_may_no_longer(monkeypatch):
    """Access is decided again while the page stays open: a student whose class lost the
    robot kept driving it over the websocket opened before (red team). Once the re-check
    is due, the drive is refused and the connection closes; the agent is told to release
    what it drove."""
    monkeypatch.setattr("robots.consumers.ACCESS_RECHECK_SECONDS", 0.0, raising=False)
    alice, _, run = await make_run(b"")
    group = await database_sync_to_async(Group.objects.create)(name="class-a")
    robot = await database_sync_to_async(Robot.objects.get)(name="sim")
    await database_sync_to_async(robot.groups.add)(group)
    await database_sync_to_async(alice.groups.add)(group)
    layer = get_channel_layer()
    await layer.flush()  # what earlier tests left for an agent of "sim"
    comm = communicator(RobotConsumer, "/ws/robots/sim/", alice, name="sim")
    assert (await comm.connect())[0]
    await comm.receive_from()  # the running programs
    await comm.receive_from()  # the e-stop's banner: none in force
    await comm.send_to(text_data='{"drive": [0.5, 0]}')
    told = await told_agent(layer, "sim")
    assert told["type"] == "robot.teleop" and told["linear"] == 0.5
    await database_sync_to_async(alice.groups.remove)(group)  # the class loses the robot
    await comm.send_to(text_data='{"drive": [0.5, 0]}')
    told = await told_agent(layer, "sim")
    assert told["type"] == "robot.release", told  # not another drive
    assert (await comm.receive_output(2))["type"] == "websocket.close"


async def test_a_run_websocket_closes_once_its_viewer_may_no_longer_see_the_run(monkeypatch):
    """A teacher watching a student's run is no longer the class's teacher: the output after
    the re-check is not sent, and the connection closes (before, it went on streaming)."""
    monkeypatch.setattr("programs.consumers.ACCESS_RECHECK_SECONDS", 0.0, raising=False)
    alice, _, run = await make_run(b"o first\n")
    teacher = await database_sync_to_async(teacher_of)(alice)
    comm = communicator(RunConsumer, f"/ws/runs/{run.pk}/", teacher, run_id=run.pk)
    assert (await comm.connect())[0]
    await comm.receive_from()  # the tail
    await comm.receive_from()  # the state
    await database_sync_to_async(ClassTeacher.objects.filter(user=teacher).delete)()
    event = {"type": "run.output", "run_id": run.pk, "lines": [[8, "o", "secret"]]}
    await get_channel_layer().group_send(run_group(run.pk), event)
    output = await comm.receive_output(2)
    assert output["type"] == "websocket.close", output


class Errors(logging.Handler):
    """The ERROR records of robotide's consumers' logger (caplog has none in async tests)."""

    def __init__(self):
        super().__init__(logging.ERROR)
        self.records: list[logging.LogRecord] = []

    def emit(self, record):
        self.records.append(record)


@pytest.fixture
def consumer_errors():
    handler = Errors()
    logger = logging.getLogger("programs.consumers")
    logger.addHandler(handler)
    yield handler.records
    logger.removeHandler(handler)


def viewer_gone(monkeypatch, consumer):
    """The consumer's sends fail as uvicorn's do once the viewer has closed its socket."""

    async def send_to_closed(self, *args, **kwargs):
        raise ClientDisconnected()

    monkeypatch.setattr(consumer, "send", send_to_closed)


async def test_a_viewer_leaving_as_the_state_comes_is_no_error(monkeypatch, consumer_errors):
    """A run page closed while its state was rendered: the send fails, and that is the viewer
    leaving (before: an ERROR with a traceback in the server's log)."""
    alice, _, run = await make_run(b"o first\n")
    comm = communicator(RunConsumer, f"/ws/runs/{run.pk}/", alice, run_id=run.pk)
    assert (await comm.connect())[0]
    await comm.receive_from()  # the tail
    await comm.receive_from()  # the state
    viewer_gone(monkeypatch, RunConsumer)
    await get_channel_layer().group_send(run_group(run.pk), {"type": "run.state"})
    await asyncio.sleep(0.5)  # the state's trip to the database thread, and its send
    assert [r.getMessage() for r in consumer_errors] == []
    await comm.disconnect()


async def test_a_viewer_leaving_as_the_run_list_refreshes_is_no_error(monkeypatch):
    alice, _, run = await make_run(b"")
    comm = communicator(RunListConsumer, "/ws/runs/", alice)
    assert (await comm.connect())[0]
    monkeypatch.setattr("programs.consumers.LIST_REFRESH_INTERVAL", 0.0)
    viewer_gone(monkeypatch, RunListConsumer)
    await get_channel_layer().group_send(RUNS_GROUP, {"type": "runs.changed", "robot": "sim"})
    loop = asyncio.get_running_loop()
    unhandled = []
    loop.set_exception_handler(lambda _loop, context: unhandled.append(context["message"]))
    try:
        await asyncio.sleep(0.5)
        gc.collect()  # a task that failed unseen says so when it goes
    finally:
        loop.set_exception_handler(None)
    assert unhandled == []
    await comm.disconnect()


@database_sync_to_async
def session_of(user) -> SessionStore:
    """A signed-in browser session of ``user``, as the websocket's cookie names it."""
    session = SessionStore()
    session[SESSION_KEY] = str(user.pk)
    session.create()
    return SessionStore(session_key=session.session_key)


async def with_pass(user, run, session=None):
    """A run websocket opened with a pass given to ``session`` (the user's own by default)."""
    session = session or await session_of(user)
    given = watch_pass.give(run, session.session_key)
    comm = communicator(RunConsumer, f"/ws/runs/{run.pk}/?pass={given}", user, run_id=run.pk)
    comm.scope["session"] = session
    return comm


async def test_a_pass_opens_the_log_while_the_database_thread_is_busy():
    """A start's run page: its websocket sends the log on the pass, without waiting for the
    thread that writes the start's state (before: it waited for three queries)."""
    alice, _, run = await make_run(b"o first\n")
    comm = await with_pass(alice, run)
    async with database_thread_busy():
        connected, _ = await comm.connect(timeout=5)
        assert connected
        assert await comm.receive_from(timeout=30) == (
            '<div id="log-lines"><div class="ln o">first</div></div>'
        )
    assert 'id="run-status"' in await comm.receive_from()  # then its state
    await comm.disconnect()


async def test_another_sessions_pass_opens_nothing():
    alice, bob, run = await make_run(b"o secret\n")
    alices = watch_pass.give(run, (await session_of(alice)).session_key)
    comm = communicator(RunConsumer, f"/ws/runs/{run.pk}/?pass={alices}", bob, run_id=run.pk)
    comm.scope["session"] = await session_of(bob)
    connected, code = await comm.connect()
    assert not connected and code == 4404


async def test_a_pass_stands_only_until_access_is_read_in_full(monkeypatch):
    """A teacher whose class was taken from them after the page was shown: the pass's log
    tail, then the close, as the state is read once their access no longer stands."""
    monkeypatch.setattr("programs.consumers.ACCESS_RECHECK_SECONDS", 0.0)
    alice, _, run = await make_run(b"o first\n")
    teacher = await database_sync_to_async(teacher_of)(alice)
    comm = await with_pass(teacher, run)
    await database_sync_to_async(ClassTeacher.objects.filter(user=teacher).delete)()
    assert (await comm.connect())[0]
    assert "first" in await comm.receive_from()
    assert (await comm.receive_output(2))["type"] == "websocket.close"


async def test_a_pass_reads_a_large_log_off_the_event_loop(monkeypatch):
    """A run's log may be large (its tail counts the lines before it: 64 MB took 30 ms here):
    one larger than LOOP_READ_BYTES is read in a worker thread, not on the loop that serves
    every page and robot."""
    readers = []

    def watched_tail(path):
        readers.append(threading.get_ident())
        return tail(path)

    monkeypatch.setattr("programs.consumers.tail", watched_tail)
    alice, _, run = await make_run(b"o line\n" * 40_000 + b"o first\n")  # 280 KB
    comm = await with_pass(alice, run)
    assert (await comm.connect())[0]
    assert "first" in await comm.receive_from()
    assert readers and threading.get_ident() not in readers
    await comm.disconnect()


async def told_agent(layer, robot: str) -> dict:
    """The next message to the robot's agent but a sim page's pose.watch leases."""
    while True:
        told = await asyncio.wait_for(layer.receive(agent_channel(robot)), 2)
        if not told["type"].startswith("pose."):
            return told
