"""On the sim robot, listen() hears what is typed into the robot page's "Say to the robot" box
(or sent to POST /api/robots/{name}/hear): the paper's voice example runs there. Whoever may
drive the robot may speak to it. Before, the example exited 1 on the sim ("listen() hears the
microphone through sounddevice ... or arecord ..., and neither is installed")."""

import asyncio
import json
import sys

import pytest
from django.contrib.auth.models import Group, User
from django.test import Client

from programs.languages import CLIENTS_DIR
from robotide.models import ClassTeacher
from robots import host_services, messages
from robots.models import Robot
from robots.typed_speech import KEEP_SECONDS, MAX_WAITING, Phrase, Refused, TypedSpeech, heard
from tests.appliance import wait_for
from tests.robot_api_server import admit
from tests.robots.test_run_queue import api
from tests.waiting import until

sys.path.insert(0, str(CLIENTS_DIR / "python"))
import robot as robot_client  # noqa: E402  (the client programs get on their path)

VOICE_MOVE = (CLIENTS_DIR.parent / "examples" / "voice_move.py").read_text()
COMMANDS = ("move", "left", "right", "stop")


# -- the example, run for real on the appliance's sim robot ----------------------------------


def say_to_a_listener(app, text: str) -> dict:
    """`text` said once a program's listen() waits for it (queue false: refused, 409, while
    none does; so it is heard once, by a program that is listening)."""

    def said():
        response = app.api("POST", "/api/robots/sim/hear", {"text": text, "queue": False})
        assert response.status_code in (200, 409), response.text
        return response.json() if response.status_code == 200 else None

    return wait_for(said, what=f"a listen() hearing {text!r}")


def test_the_voice_example_hears_move_typed_to_the_sim_and_moves(any_appliance):
    """Embedded, and split (the agent a process of its own, over Redis and PostgreSQL)."""
    appliance = any_appliance
    program = appliance.create_program("voice", VOICE_MOVE)
    start = appliance.api("GET", "/api/robots/sim/sensors").json()["position"]
    run = appliance.run_program(program["id"])
    assert say_to_a_listener(appliance, "Move!") == {
        "robot": "sim", "text": "Move!", "listening": True,
    }  # fmt: skip

    def moved():
        now = appliance.api("GET", "/api/robots/sim/sensors").json()["position"]
        return abs(now["x"] - start["x"]) + abs(now["y"] - start["y"]) > 0.1

    wait_for(moved, what="the sim robot moving")
    say_to_a_listener(appliance, "stop")
    ended = appliance.wait_run(run["id"])
    log = appliance.api("GET", f"/api/runs/{run['id']}/log").text
    assert ended["state"] == "finished", log
    assert "heard: move" in log and "heard: stop" in log


# -- who may speak to it ---------------------------------------------------------------------


@pytest.fixture
def lab():
    """olga owns the class's robot, which only its owner and staff drive; sam is a student in
    the class (he sees it), tina teaches it."""
    users = {n: User.objects.create_user(n) for n in ("olga", "tina", "sam", "eve")}
    group = Group.objects.create(name="class-a")
    users["sam"].groups.add(group)
    ClassTeacher.objects.create(group=group, user=users["tina"])
    robot = Robot.objects.create(name="arm", url="sim://", owner=users["olga"], drive_by="owner")
    robot.groups.add(group)
    return users, robot


@pytest.mark.django_db
def test_a_student_who_may_not_drive_the_robot_may_not_speak_to_it(lab):
    users, _robot = lab
    status, body = api(users["sam"])("POST", "/api/robots/arm/hear", {"text": "move"})
    assert status == 403, body
    assert body["detail"] == "Only its owner and staff may speak to arm."
    status, body = api(users["eve"])("POST", "/api/robots/arm/hear", {"text": "move"})
    assert status == 404, body  # not in the class: no such robot, for her
    client = Client()
    client.force_login(users["sam"])
    assert client.post("/robots/arm/say", {"say": "move"}).status_code == 403
    for url in ("/robots/arm/", "/robots/arm/say"):  # the box, and the box on its own page
        page = client.get(url).content.decode()
        assert 'name="say"' in page and "Only its owner and staff may speak to it" in page


@pytest.mark.django_db
def test_the_box_speaks_portuguese(lab):
    users, _robot = lab
    client = Client(headers={"accept-language": "pt-br"})
    client.force_login(users["olga"])
    page = client.get("/robots/arm/say").content.decode()
    assert "Diga ao robô" in page and "Nada ouvido ainda." in page
    said = client.post("/robots/arm/say", {"say": "  "}, follow=True).content.decode()
    assert "Digite o que o robô deve ouvir." in said


@pytest.mark.django_db
def test_the_api_checks_what_is_said(lab):
    users, _robot = lab
    call = api(users["olga"])
    for body in ({"text": ""}, {"text": "x" * 201}, {}, {"text": 7}, ["move"]):
        status, answer = call("POST", "/api/robots/arm/hear", body)
        assert status == 422, (body, answer)


def test_the_agent_takes_robot_hear_messages_of_the_right_shape():
    good = {"type": "robot.hear", "text": "move", "user": "sam", "queue": False}
    assert messages.check(good) is None
    assert messages.check({**good, "text": 7}) is not None
    assert messages.check({**good, "text": "x" * 5000}) is not None
    assert messages.check({**good, "queue": "no"}) is not None


# -- listen() through a real agent's Robot API socket, in this process ------------------------

TOKEN, RUN = "good-token", 7


@pytest.fixture
async def bot(agent):
    agent.api.methods.update(agent.api.host.methods)
    admit(agent, TOKEN, RUN)
    client = await asyncio.to_thread(robot_client.Robot, agent.server.url, TOKEN)
    yield client
    client.close()


async def hear_message(agent, text, queue=True) -> dict:
    """A robot.hear as the web tier sends it; the agent's reply."""
    replies = []

    async def reply(message, data):
        replies.append(data)

    agent.reply = reply
    await agent.api.host.hear_typed({"type": "robot.hear", "text": text, "user": "sam",
                                     "queue": queue})  # fmt: skip
    return replies[0]


async def test_a_phrase_typed_while_listen_waits_is_what_it_hears(agent, bot):
    host = agent.api.host
    listening = asyncio.ensure_future(
        asyncio.to_thread(bot.call, "listen", 30, None, list(COMMANDS))
    )
    await until(lambda: host.typed.listening)
    assert await hear_message(agent, "please MOVE now", queue=False) == {"listening": True}
    assert await listening == {"text": "move", "words": ["move"], "typed": True}
    assert host.last_heard["text"] == "move" and host.last_heard["typed_by"] == "sam"


async def test_a_phrase_typed_before_waits_for_the_next_listen(agent, bot):
    assert await hear_message(agent, "turn left") == {"listening": False}
    heard_now = await asyncio.to_thread(bot.call, "listen", 1, None, ["left", "turn left"])
    assert heard_now == {"text": "turn left", "words": ["turn", "left"], "typed": True}
    # Nothing typed: the sim hears nothing, and says so without error.
    assert await asyncio.to_thread(bot.call, "listen", 0.1) == {"text": "", "words": []}


async def test_nobody_floods_the_robot_with_phrases(agent):
    for number in range(MAX_WAITING):
        assert await hear_message(agent, f"phrase {number}") == {"listening": False}
    refused = await hear_message(agent, "one more")
    assert refused["refused"] == "full"
    assert (await hear_message(agent, "now?", queue=False))["refused"] == "nobody"
    assert (await hear_message(agent, "   "))["refused"] == "empty"


def test_phrases_nobody_listened_to_are_forgotten_after_a_while():
    now = [0.0]
    typed = TypedSpeech(clock=lambda: now[0])
    typed.say("move", "sam")
    now[0] = KEEP_SECONDS + 1
    assert typed.take() is None
    for number in range(MAX_WAITING):
        typed.say(f"go {number}", "sam")
    with pytest.raises(Refused):
        typed.say("again", "sam")


@pytest.mark.parametrize(
    ("typed", "words", "text"),
    [
        ("Move!", COMMANDS, "move"),
        ("turn  LEFT, please", ("left", "turn left"), "turn left"),
        ("go left then right", COMMANDS, "left"),
        ("mova", COMMANDS, ""),
        ("Hello, robot.", (), "hello robot"),
    ],
)
def test_typed_phrases_are_heard_as_a_recogniser_hears_words(typed, words, text):
    assert heard(Phrase(typed, "sam", 0.0), words)["text"] == text


@pytest.mark.django_db(transaction=True)  # the robot's speech setting is read at each call
async def test_on_a_robot_with_a_microphone_a_phrase_typed_wins_over_the_recording(
    agent, bot, monkeypatch
):
    """The box works on a real robot too: the recording is given up for what was typed."""
    agent.driver.hearing = "microphone"
    recording = asyncio.Event()

    async def hear(phrases, recording_fd=None, record=None):
        recording.set()
        await asyncio.Event().wait()  # a recording that takes its time

    monkeypatch.setattr(host_services, "hear", hear)
    listening = asyncio.ensure_future(asyncio.to_thread(bot.call, "listen", 5, None, ["stop"]))
    await recording.wait()
    assert await hear_message(agent, "stop", queue=False) == {"listening": True}
    assert await listening == {"text": "stop", "words": ["stop"], "typed": True}


async def test_the_robot_page_hears_what_was_heard(agent, bot):
    published = []
    agent.publish = lambda group, message: published.append(message)
    await hear_message(agent, "right")
    await asyncio.to_thread(bot.call, "listen", 1, None, list(COMMANDS))
    last = [m for m in published if m["type"] == "robot.hearing"][-1]
    assert last["last"]["text"] == "right" and last["last"]["typed_by"] == "sam"
    assert json.dumps(last)  # goes on the channel layer as it is
