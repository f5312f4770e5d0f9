"""Two presses of the emergency stop and a resume, raced, never leave the robot free while its
record says it is stopped (issue 28, item 5).

A real agent on the sim robot; its answer to the teacher's press is held back (a slow reply:
the agent has stopped the robot, the teacher's request still waits) while a student presses
and resumes. The student's resume must not clear the teacher's press on its way.
"""

import asyncio

import pytest
from asgiref.sync import sync_to_async
from channels.db import database_sync_to_async
from django.contrib.auth.models import User
from django.core.exceptions import PermissionDenied
from django.db import connections

from robots import stops
from robots.bus import ask_agent, send_to_agent
from robots.models import Robot, RobotStop
from tests.waiting import until

pytestmark = pytest.mark.django_db(transaction=True)
TEACHER, STUDENT = "tina", "sam"


@pytest.fixture
def held_teacher_reply(sim_agent):
    """The agent acts on the teacher's press at once, but its reply waits until the test sets
    ``let_go`` (the agent serves its next messages meanwhile). ``held`` is set once it waits."""
    held, let_go = asyncio.Event(), asyncio.Event()
    reply = sim_agent.reply

    async def later(message, data):
        await let_go.wait()
        await reply(message, data)

    async def slow_for_the_teacher(message, data):
        if message.get("type") == "robot.estop" and message.get("by") == TEACHER:
            asyncio.get_running_loop().create_task(later(message, data))
            held.set()
            return
        await reply(message, data)

    sim_agent.reply = slow_for_the_teacher
    yield held, let_go
    let_go.set()


@pytest.fixture(autouse=True)
def _no_heartbeat_meanwhile(settings):
    # The test's in-memory SQLite fails a write that meets another at once ("table is
    # locked"; a file waits its turn, as robotide's does): the agent's heartbeat stays out.
    settings.AGENT_HEARTBEAT = 3600


class TeachersPress:
    """The teacher's press in a thread of its own, as a web server's worker thread: it waits
    there for the agent's reply while the student's requests go on."""

    def __init__(self, robot, teacher):
        self.connection = None
        self.task = asyncio.ensure_future(sync_to_async(self._press, thread_sensitive=False)(
            teacher, robot))  # fmt: skip

    def _press(self, teacher, robot):
        self.connection = connections["default"]  # this thread's own, not a proxy
        return stops.press(teacher, robot, "the API")

    async def waiting_for_its_reply(self, held: asyncio.Event) -> None:
        """The agent has it, and its request holds no database transaction (the student's
        writes would meet it: see _no_heartbeat_meanwhile)."""
        await asyncio.wait_for(held.wait(), 30)
        await until(self._out_of_transactions, timeout=30)

    def _out_of_transactions(self) -> bool:
        # Committed: autocommit is set back once the commit is done (in_atomic_block before).
        db = self.connection
        return db.connection is None or (db.autocommit and not db.in_atomic_block)


def in_sync_thread(fn):
    """The student's requests: in the thread the agent's database work takes too."""
    return sync_to_async(fn)


@database_sync_to_async
def lab():
    robot = Robot.objects.get(name="sim")
    return robot, User.objects.create_user(TEACHER), User.objects.create_user(STUDENT)


async def robot_stopped_for_its_agent(agent) -> bool:
    """The agent's lease after it handled every message sent before this question (one
    channel, in order): held by an emergency stop?"""
    state = await ask_agent(agent.name, "robot.state")
    return state["lease"] is not None and state["lease"]["kind"] == "estop"


async def student_resumes(robot, student) -> str:
    try:
        await in_sync_thread(stops.resume)(student, robot, "the API")
    except PermissionDenied:
        return "refused"
    return "resumed"


@pytest.mark.parametrize("student_first", [False, True], ids=["teacher-first", "student-first"])
async def test_a_student_cannot_resume_past_a_teachers_press_on_its_way(
    sim_agent, held_teacher_reply, student_first
):
    held, let_go = held_teacher_reply
    robot, teacher, student = await lab()
    if student_first:
        await in_sync_thread(stops.press)(student, robot, "the API")
    teachers_press = TeachersPress(robot, teacher)
    await teachers_press.waiting_for_its_reply(held)  # in flight
    if not student_first:
        await in_sync_thread(stops.press)(student, robot, "the API")
    outcome = await student_resumes(robot, student)
    let_go.set()
    record = await teachers_press.task
    assert record.username == TEACHER
    assert await robot_stopped_for_its_agent(sim_agent), f"the student's resume: {outcome}"
    assert sim_agent.lease.estopped
    pressed = await database_sync_to_async(RobotStop.pressed)(robot.pk)
    assert pressed is not None and pressed.kind == "estop"
    assert outcome == "refused"


async def test_a_press_recorded_before_its_reply_shows_on_the_record_at_once(
    sim_agent, held_teacher_reply
):
    """While the agent's answer is on its way the press is already in force on the record
    (the robot's page says stopped), and the runs it ended are added once the answer comes."""
    held, let_go = held_teacher_reply
    robot, teacher, _student = await lab()
    teachers_press = TeachersPress(robot, teacher)
    await teachers_press.waiting_for_its_reply(held)
    pressed = await database_sync_to_async(RobotStop.pressed)(robot.pk)
    assert pressed is not None and pressed.username == TEACHER
    let_go.set()
    record = await teachers_press.task
    assert record.pk == pressed.pk and record.runs == [] and record.note == ""
    await in_sync_thread(stops.resume)(teacher, robot, "the API")  # hers alone: she may
    assert not await robot_stopped_for_its_agent(sim_agent)


@database_sync_to_async
def recorded(robot, events) -> list[RobotStop]:
    return [
        RobotStop.objects.create(robot=robot, kind=kind, user=user, username=user.username,
                                 via="the API")
        for kind, user in events
    ]  # fmt: skip


async def test_a_resume_reaching_the_agent_after_a_press_recorded_later_is_stale(sim_agent):
    """Redis orders a channel's messages by each sender's clock: a press recorded (and sent)
    after a resume may still reach the agent first. The records' ids decide."""
    robot, teacher, student = await lab()
    _, resumed, pressed = await recorded(
        robot, [("estop", student), ("resume", student), ("estop", teacher)]
    )
    await send_to_agent("sim", "robot.estop", by=TEACHER, record=pressed.pk)  # first
    await send_to_agent("sim", "robot.resume", after=resumed.pk)  # the student's, late
    assert await robot_stopped_for_its_agent(sim_agent)
