"""The JavaScript client, the Python client's messages and memory, and the `robot` shell
command: real interpreters, run as the launcher would (each client on its interpreter's own
search path, a clean environment), against a real Robot API server (an agent, its sim robot)
served on the test's event loop."""

import asyncio
import json
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from PIL import Image

from programs.languages import CLIENTS_DIR, LANGUAGES
from robots.host_services import HostServices
from runbox import launcher

sys.path.insert(0, str(CLIENTS_DIR / "python"))
import robot as robot_client  # noqa: E402  (the client programs get on their path)

from tests.robot_api_server import admit

EXAMPLES = Path(__file__).resolve().parents[2] / "programs" / "examples"
TOKEN = "good-token"
EXTENSIONS = {"python": ".py", "javascript": ".js", "shell": ".sh"}


@pytest.fixture
async def agent(agent):
    admit(agent, TOKEN, 7)  # every test here runs as run 7
    return agent


@dataclass
class Finished:
    status: int
    out: str
    err: str


def environment(agent, language: str, home: Path, token=TOKEN, api=None) -> dict:
    extra = {"ROBOT_API": api or agent.server.url, "ROBOT_TOKEN": token}
    return launcher.environment(LANGUAGES[language], home, extra)


async def start(agent, tmp_path, language, source=None, *, file=None, args=(), **env_options):
    """Start a program as the launcher would (without limits and sandbox)."""
    if file is None:
        file = tmp_path / f"program{EXTENSIONS[language]}"
        file.write_text(source)
    return await asyncio.create_subprocess_exec(
        *LANGUAGES[language].command(str(file)), *args,
        env=environment(agent, language, tmp_path, **env_options),
        cwd=tmp_path,
        stdin=asyncio.subprocess.PIPE,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )  # fmt: skip


async def finish(process, stdin: bytes = b"", timeout=60) -> Finished:
    try:
        out, err = await asyncio.wait_for(process.communicate(stdin), timeout)
    except TimeoutError:
        process.kill()
        out, err = await process.communicate()
        pytest.fail(f"still running after {timeout} s: {out.decode()} {err.decode()}")
    return Finished(process.returncode, out.decode(), err.decode())


async def run(agent, tmp_path, language, source=None, stdin=b"", **options) -> Finished:
    return await finish(await start(agent, tmp_path, language, source, **options), stdin)


def lines(text: str) -> list:
    return [json.loads(line) for line in text.splitlines()]


async def publish_until_heard(agent, topic, value, timeout=10.0):
    """Publish from another program until a subscriber gets it (it subscribes on its own)."""
    bot = await asyncio.to_thread(robot_client.Robot, agent.server.url, TOKEN)
    try:
        loop = asyncio.get_running_loop()
        deadline = loop.time() + timeout
        while await asyncio.to_thread(bot.publish, topic, value) < 1:
            assert loop.time() < deadline, f"nobody subscribed to {topic!r}"
            await asyncio.sleep(0.02)
    finally:
        bot.close()


# -- JavaScript ---------------------------------------------------------------------------


async def test_js_drives_and_reads_sensors_and_ends_by_itself(agent, tmp_path):
    # No close(): the connection does not keep Node running once nothing is awaited.
    source = """
        const { Robot } = require('robot');
        (async () => {
          const bot = new Robot();
          console.log(JSON.stringify(await bot.drive(0.2, 0)));
          console.log(JSON.stringify(await bot.drive(0.2)));
          const sensors = await bot.sensors();
          console.log(JSON.stringify([sensors.heading, sensors.range]));
          console.log(JSON.stringify(await bot.sensor('range')));
          console.log(JSON.stringify((await bot.capabilities()).kind));
          console.log(JSON.stringify(await bot.show('speed', 0.2)));
        })();
    """
    result = await run(agent, tmp_path, "javascript", source)
    assert result.status == 0, result.err
    applied, default_angular, readings, range_m, kind, shown = lines(result.out)
    assert applied == default_angular == {"linear": 0.2, "angular": 0}
    assert readings == [0.0, pytest.approx(2.0, abs=0.1)]
    assert 0 < range_m <= 2.0 and kind == "sim" and shown is None
    assert agent.shows["speed"]["value"] == 0.2 and agent.shows["speed"]["run"] == 7
    velocity = (await agent.driver.sensors())["velocity"]
    assert velocity == {"linear": 0.2, "angular": 0.0}  # still driving: nobody stopped it


async def test_js_calls_are_pipelined_and_answered_each_to_its_own(agent, tmp_path):
    source = """
        const { Robot } = require('robot');
        const bot = new Robot();
        const calls = [];
        for (let i = 0; i < 50; i++) {
          calls.push(bot.show('n', i), bot.sensor('heading'), bot.capabilities());
        }
        calls.push(bot.drive(9, 0));  // clamped to the robot's limit
        Promise.all(calls).then((results) => {
          console.log(JSON.stringify(results.slice(0, 3).map((r) => typeof r)));
          console.log(JSON.stringify(results[results.length - 1]));
          return bot.stop();
        }).then(() => bot.close()).then(() => console.log('closed'));
    """
    result = await run(agent, tmp_path, "javascript", source)
    assert result.status == 0, result.err
    assert result.out.splitlines() == [
        '["object","number","object"]',
        '{"linear":0.5,"angular":0}',
        "closed",
    ]
    assert agent.shows["n"]["value"] == 49


async def test_js_rpc_errors_reject_with_an_error_carrying_message_and_code(agent, tmp_path):
    source = """
        const { Robot, RobotError } = require('robot');
        (async () => {
          const bot = new Robot();
          for (const attempt of [() => bot.sensor('gps'), () => bot.call('fly'),
                                 () => bot.drive('fast', 0)]) {
            try {
              await attempt();
              console.log('no error');
            } catch (e) {
              console.log(JSON.stringify([e instanceof RobotError, e instanceof Error,
                                          e.code, e.message]));
            }
          }
          console.log(await bot.sensor('heading'));  // the connection goes on
        })();
    """
    result = await run(agent, tmp_path, "javascript", source)
    assert result.status == 0, result.err
    *errors, heading = result.out.splitlines()
    gps, fly, fast = map(json.loads, errors)
    assert gps[:3] == [True, True, -32000] and "gps" in gps[3]
    assert fly[:3] == [True, True, -32601] and "fly" in fly[3]
    assert fast[:3] == [True, True, -32602]
    assert heading == "0"


@pytest.mark.parametrize(
    "call, code, words",
    [
        ("bot.sensor('gps')", "-32000", "gps"),
        ("bot.call('fly', 1)", "-32601", "no method 'fly'"),
    ],
)
async def test_js_an_unhandled_rpc_error_ends_the_program_with_the_message(
    agent, tmp_path, call, code, words
):
    source = f"""
        const {{ Robot }} = require('robot');
        const bot = new Robot();
        (async () => {{
          await {call};
          console.log('not reached');
        }})();
    """
    result = await run(agent, tmp_path, "javascript", source)
    assert result.status != 0
    assert "not reached" not in result.out
    assert "RobotError" in result.err and words in result.err and code in result.err


async def test_js_a_wrong_token_is_refused(agent, tmp_path):
    source = """
        const { Robot } = require('robot');
        const bot = new Robot();
        bot.sensors().then(() => console.log('not reached'));
    """
    result = await run(agent, tmp_path, "javascript", source, token="someone-elses-guess")
    assert result.status != 0 and "not reached" not in result.out
    assert "invalid token" in result.err


async def test_js_without_a_server_is_a_clear_error(agent, tmp_path):
    source = "const { Robot } = require('robot'); new Robot().sensors();"
    api = f"unix:{tmp_path}/nothing-here.sock"
    result = await run(agent, tmp_path, "javascript", source, api=api)
    assert result.status != 0
    assert "cannot talk to the robot" in result.err and "nothing-here.sock" in result.err


async def test_js_calls_after_close_are_refused(agent, tmp_path):
    source = """
        const { Robot } = require('robot');
        (async () => {
          const bot = new Robot();
          await bot.sensors();
          await bot.close();
          await bot.sensors().catch((e) => console.log(e.message));
        })();
    """
    result = await run(agent, tmp_path, "javascript", source)
    assert result.status == 0, result.err
    assert "closed" in result.out


async def test_js_messages_and_memory(agent, tmp_path):
    source = """
        const { Robot } = require('robot');
        (async () => {
          const listener = new Robot(), talker = new Robot();
          console.log(JSON.stringify(await listener.subscribe('news')));
          const waiting = listener.receive('news', 5);
          console.log(JSON.stringify(await talker.publish('news', { lap: 1, ok: true })));
          console.log(JSON.stringify(await waiting));
          console.log(JSON.stringify(await listener.receive('news', 0.1)));  // timed out
          console.log(JSON.stringify(await talker.publish('nobody-listens', 1)));
          console.log(JSON.stringify(await talker.memory_set('laps', [1, 2, 3])));
          console.log(JSON.stringify(await listener.memory_get('laps')));
          console.log(JSON.stringify(await listener.memory_get('unknown')));
        })();
    """
    result = await run(agent, tmp_path, "javascript", source)
    assert result.status == 0, result.err
    assert lines(result.out) == [None, 1, {"lap": 1, "ok": True}, None, 0, None, [1, 2, 3], None]


# -- Python: messages and memory ----------------------------------------------------------


async def test_python_messages_and_memory(agent, tmp_path):
    source = """
import json
import robot

listener, talker = robot.Robot(), robot.Robot()
out = [listener.subscribe("news")]
out.append(talker.publish("news", "hello"))
out.append(talker.publish("news", {"lap": 2}))
out.append(listener.receive("news", 5))
out.append(listener.receive("news"))  # no timeout: waits, but one is there already
out.append(listener.receive("news", 0.1))  # timed out
out.append(talker.publish("other", 1))
out.append(talker.memory_set("pid", {"kp": 0.5}))
out.append(listener.memory_get("pid"))
out.append(listener.memory_get("unknown"))
print(json.dumps(out))
"""
    result = await run(agent, tmp_path, "python", source)
    assert result.status == 0, result.err
    expected = [None, 1, 1, "hello", {"lap": 2}, None, 0, None, {"kp": 0.5}, None]
    assert json.loads(result.out) == expected


async def test_python_and_javascript_programs_talk(agent, tmp_path):
    (tmp_path / "py").mkdir()
    (tmp_path / "js").mkdir()
    source = """
import robot

bot = robot.Robot()
bot.subscribe("greetings")
print("ready", flush=True)
print("got", bot.receive("greetings", 20))
bot.publish("answers", "hello from Python")
"""
    listener = await start(agent, tmp_path / "py", "python", source)
    assert (await asyncio.wait_for(listener.stdout.readline(), 20)) == b"ready\n"
    source = """
        const { Robot } = require('robot');
        (async () => {
          const bot = new Robot();
          await bot.subscribe('answers');
          console.log(await bot.publish('greetings', 'hello from JavaScript'));
          console.log(await bot.receive('answers', 20));
        })();
    """
    talker = await run(agent, tmp_path / "js", "javascript", source)
    heard = await finish(listener)
    assert talker.status == 0 and heard.status == 0, (talker.err, heard.err)
    assert heard.out == "got hello from JavaScript\n"
    assert talker.out == "1\nhello from Python\n"


async def test_python_a_bad_call_to_a_new_method_raises(agent, tmp_path):
    source = """
import robot

bot = robot.Robot()
bot.receive("never-subscribed", {"not": "a number"})
"""
    result = await run(agent, tmp_path, "python", source)
    assert result.status != 0
    assert "robot.RobotError" in result.err


# -- the shell command --------------------------------------------------------------------


async def test_shell_drives_reads_and_shows(agent, tmp_path):
    source = """
        robot sensors heading
        robot drive 0.2 0
        sleep 0.3
        robot sensors range
        robot sensors velocity
        robot stop
        robot sensors velocity
        robot capabilities > caps.json
        robot show heading 42
        robot show label "a text"
    """
    result = await run(agent, tmp_path, "shell", source)
    assert result.status == 0, result.err
    heading, range_m, moving, stopped = result.out.splitlines()
    assert heading == "0.0" and 1.0 < float(range_m) < 2.0
    assert json.loads(moving) == {"linear": 0.2, "angular": 0.0}
    assert json.loads(stopped) == {"linear": 0.0, "angular": 0.0}
    assert json.loads((tmp_path / "caps.json").read_text())["kind"] == "sim"
    assert agent.shows["heading"]["value"] == 42 and agent.shows["label"]["value"] == "a text"


@pytest.mark.parametrize(
    "command, words",
    [
        ("robot sensors gps", "no sensor 'gps'"),
        ("robot fly", "usage error: robot fly"),
        ("robot drive fast", "not a number: 'fast'"),
        ("robot memory", "usage error"),
    ],
)
async def test_shell_errors_are_a_message_and_exit_status_1(agent, tmp_path, command, words):
    result = await run(agent, tmp_path, "shell", f"{command}\necho status $?\n")
    assert result.out == "status 1\n"
    assert result.err.startswith("robot: ") and words in result.err
    assert result.err.count("\n") == 1  # one line, no traceback


async def test_shell_with_a_wrong_token_or_no_server(agent, tmp_path):
    wrong = await run(agent, tmp_path, "shell", "robot sensors\n", token="guess")
    assert wrong.status == 1 and wrong.err.startswith("robot: invalid token")
    gone = await run(agent, tmp_path, "shell", "robot sensors\n", api=f"unix:{tmp_path}/no.sock")
    assert gone.status == 1 and gone.err.startswith("robot: cannot talk to the robot at unix:")
    assert "Traceback" not in gone.err


async def test_shell_memory(agent, tmp_path):
    source = """
        robot memory set laps 3
        robot memory set who "Ada Lovelace"
        robot memory set pid '{"kp": 0.5}'
        robot memory get laps
        robot memory get who
        robot memory get pid
        robot memory get unknown
        echo "status $?"
    """
    result = await run(agent, tmp_path, "shell", source)
    assert result.status == 0, result.err
    assert result.out.splitlines() == ["3", "Ada Lovelace", '{"kp": 0.5}', "status 0"]
    bot = await asyncio.to_thread(robot_client.Robot, agent.server.url, TOKEN)
    assert await asyncio.to_thread(bot.memory_get, "pid") == {"kp": 0.5}
    bot.close()


async def test_shell_publish_and_receive(agent, tmp_path):
    nobody = await run(agent, tmp_path, "shell", "robot publish news 1\n")
    assert nobody.status == 0 and nobody.out == "0\n", nobody.err
    receiver = await start(agent, tmp_path, "shell", "robot receive news 20\n")
    await publish_until_heard(agent, "news", {"lap": 3})
    result = await finish(receiver)
    assert result.status == 0 and result.out == '{"lap": 3}\n', result.err


async def test_shell_receive_times_out_with_status_1_and_no_output(agent, tmp_path):
    result = await run(agent, tmp_path, "shell", "robot receive quiet 0.2\necho status $?\n")
    assert result.out == "status 1\n" and result.err == ""


async def test_shell_subscribe_prints_each_value_as_it_comes(agent, tmp_path):
    subscriber = await start(agent, tmp_path, "shell", "exec robot subscribe news\n")
    try:
        await publish_until_heard(agent, "news", "first")
        bot = await asyncio.to_thread(robot_client.Robot, agent.server.url, TOKEN)
        for value in (2, [3]):
            assert await asyncio.to_thread(bot.publish, "news", value) == 1
        bot.close()
        got = [await asyncio.wait_for(subscriber.stdout.readline(), 10) for _ in range(3)]
        assert got == [b"first\n", b"2\n", b"[3]\n"]
    finally:
        subscriber.terminate()
        await subscriber.wait()


async def test_shell_publish_reaches_a_javascript_subscriber(agent, tmp_path):
    (tmp_path / "js").mkdir()
    source = """
        const { Robot } = require('robot');
        (async () => {
          const bot = new Robot();
          await bot.subscribe('orders');
          console.log('ready');
          console.log(JSON.stringify(await bot.receive('orders', 20)));
        })();
    """
    listener = await start(agent, tmp_path / "js", "javascript", source)
    assert (await asyncio.wait_for(listener.stdout.readline(), 20)) == b"ready\n"
    sent = await run(agent, tmp_path, "shell", "robot publish orders '{\"go\": true}'\n")
    heard = await finish(listener)
    assert sent.out == "1\n" and heard.status == 0, (sent.err, heard.err)
    assert heard.out == '{"go":true}\n'


async def test_shell_pipe_relays_json_rpc_lines(agent, tmp_path):
    requests = [
        {"jsonrpc": "2.0", "id": 1, "method": "auth", "params": [TOKEN]},
        {"jsonrpc": "2.0", "id": 2, "method": "drive", "params": [0.1, 0]},
        {"jsonrpc": "2.0", "method": "stop"},  # a notification: no answer
        {"jsonrpc": "2.0", "id": 3, "method": "fly", "params": []},
        {"jsonrpc": "2.0", "id": 4, "method": "sensor", "params": ["heading"]},
    ]
    stdin = "".join(json.dumps(r) + "\n" for r in requests).encode() + b"{broken"
    result = await run(agent, tmp_path, "shell", "exec robot pipe\n", stdin=stdin)
    assert result.status == 0, result.err
    auth, drive, fly, heading, broken = lines(result.out)
    assert auth["result"] == {"robot": "sim", "run": 7}
    assert drive["result"] == {"linear": 0.1, "angular": 0.0}
    assert fly["id"] == 3 and fly["error"]["code"] == -32601
    assert heading == {"jsonrpc": "2.0", "id": 4, "result": 0.0}
    assert broken["error"]["code"] == -32700
    assert (await agent.driver.sensors())["velocity"]["linear"] == 0.0


async def test_shell_pipe_waits_for_a_slow_answer_before_it_ends(agent, tmp_path):
    requests = [
        {"jsonrpc": "2.0", "id": 1, "method": "auth", "params": [TOKEN]},
        {"jsonrpc": "2.0", "id": 2, "method": "subscribe", "params": ["t"]},
        {"jsonrpc": "2.0", "id": 3, "method": "receive", "params": ["t", 0.3]},
    ]
    stdin = "".join(json.dumps(r) + "\n" for r in requests).encode()
    result = await run(agent, tmp_path, "shell", "exec robot pipe\n", stdin=stdin)
    assert result.status == 0, result.err
    assert [reply.get("result", reply.get("error")) for reply in lines(result.out)] == [
        {"robot": "sim", "run": 7},
        None,
        None,
    ]


# -- the same example in each language ----------------------------------------------------


@pytest.mark.parametrize("language", ["python", "javascript", "shell"])
async def test_the_wall_turn_example(agent, tmp_path, language):
    start_heading = (await agent.driver.sensors())["heading"]
    file = EXAMPLES / f"wall_turn{EXTENSIONS[language]}"
    result = await finish(await start(agent, tmp_path, language, file=file))
    assert result.status == 0, result.err
    assert re.fullmatch(r"heading: -?\d+\.\d\n", result.out), result.out
    printed = float(result.out.split()[1])
    after = await agent.driver.sensors()
    assert after["velocity"] == {"linear": 0.0, "angular": 0.0}  # stopped
    assert after["odometry"]["distance"] > 1.0 and after["range"] >= 0.4  # drove, not crashed
    assert 60 < (start_heading - after["heading"]) % 360 < 120  # turned left about 86 degrees
    assert printed == round(after["heading"], 1)
    shown = agent.shows["heading"]["value"]  # a number (JavaScript sends 274.0 as 274)
    assert shown == printed and isinstance(shown, int | float) and not isinstance(shown, bool)


# -- the host's services: speech and the camera ----------------------------------------------

HOST_SERVICES = {
    "javascript": """
        const { Robot } = require('robot');
        (async () => {
          const bot = new Robot();
          const said = await bot.say('hello from JavaScript');
          const codes = await bot.scan_barcode();
          const frame = await bot.snapshot();
          console.log(JSON.stringify({
            spoken: typeof said.spoken,
            codes: codes.map((code) => [code.text, code.format, code.position.length]),
            size: [frame.width, frame.height],
          }));
        })();
    """,
    "python": """
import json
import robot

bot = robot.Robot()
said = bot.say("hello from Python")
codes = bot.scan_barcode()
frame = bot.snapshot()
print(json.dumps({
    "spoken": type(said["spoken"]).__name__,
    "codes": [[code["text"], code["format"], len(code["position"])] for code in codes],
    "size": [frame["width"], frame["height"]],
}))
""",
}


@pytest.fixture
async def host_agent(agent):
    agent.api.methods.update(HostServices(agent).methods)  # as RobotApi registers them
    return agent


@pytest.mark.parametrize("language", ["javascript", "python"])
@pytest.mark.django_db(transaction=True)  # the robot's speech and camera settings: from its row
async def test_say_and_scan_barcode(host_agent, tmp_path, language):
    result = await run(host_agent, tmp_path, language, HOST_SERVICES[language])
    assert result.status == 0, result.err
    assert json.loads(result.out) == {
        "spoken": "boolean" if language == "javascript" else "bool",
        "codes": [["kitchen", "QRCode", 4]],  # ahead of the sim robot at the start
        "size": [640, 480],
    }
    label = {"javascript": "JavaScript", "python": "Python"}[language]
    assert host_agent.shows["said"]["value"] == f"hello from {label}"


@pytest.mark.django_db(transaction=True)
async def test_shell_say_scan_snapshot_and_listen(host_agent, tmp_path, settings):
    workdir = settings.RUNS_DIR / "7" / "work"  # run 7's folder: listen() reads files there
    workdir.mkdir(parents=True)
    subprocess.run(["espeak-ng", "-v", "en-us", "-w", str(workdir / "left.wav"), "turn left"])
    source = f"""
        robot say hello from the shell 2> said.txt
        robot scan_barcode
        robot scan_barcode --json > codes.json
        robot snapshot frame.jpg
        robot listen --wav {workdir}/left.wav --words "move,stop,turn left"
        robot listen 5 --wav {workdir}/left.wav --words stop
        echo "status $?"
    """
    result = await run(host_agent, tmp_path, "shell", source)
    assert result.status == 0, result.err
    assert result.out.splitlines() == ["kitchen", "turn left", "status 1"]
    assert host_agent.shows["said"]["value"] == "hello from the shell"
    said = (tmp_path / "said.txt").read_text()
    assert said == "" or said.startswith("robot: not spoken: ")  # no sound here: why, not a fail
    (code,) = lines((tmp_path / "codes.json").read_text())
    assert code["text"] == "kitchen" and code["format"] == "QRCode"
    assert Image.open(tmp_path / "frame.jpg").size == (640, 480)
