"""The Lua and Tcl Robot API clients, run by their real interpreters as programs against a
real agent's Robot API server and sim robot."""

import asyncio
import json
import os
from pathlib import Path

import pytest

from programs.languages import CLIENTS_DIR
from robots.host_services import HostServices
from tests.robot_api_server import admit, check_wall_turn

EXAMPLES = CLIENTS_DIR.parent / "examples"

# language -> (interpreter, file extension)
LANGUAGES = {"lua": ("lua5.4", "lua"), "tcl": ("tclsh", "tcl"), "python": ("python3", "py")}

each_language = pytest.mark.parametrize("language", ["lua", "tcl"])


async def start(agent, language, program: Path, token="good-token", api=None, tcp=None):
    """`api`/`tcp` override ROBOT_API/ROBOT_API_TCP; "" leaves the variable out."""
    env = {
        "PATH": os.environ["PATH"],
        "LANG": "C.UTF-8",
        "ROBOT_API": f"unix:{agent.server.unix_path}" if api is None else api,
        "ROBOT_API_TCP": agent.api_address if tcp is None else tcp,
        "ROBOT_TOKEN": token,
        "LUA_PATH": f"{CLIENTS_DIR}/lua/?.lua;;",
        "TCLLIBPATH": str(CLIENTS_DIR / "tcl"),
        "PYTHONPATH": str(CLIENTS_DIR / "python"),
    }
    env = {name: value for name, value in env.items() if value}
    return await asyncio.create_subprocess_exec(
        LANGUAGES[language][0],
        str(program),
        env=env,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )


async def finish(process, timeout=30) -> tuple[int, str, str]:
    try:
        out, err = await asyncio.wait_for(process.communicate(), timeout)
    finally:
        if process.returncode is None:
            process.kill()
            await process.wait()
    return process.returncode, out.decode(), err.decode()


async def run(agent, language, source: str, tmp_path, name="program", **options):
    program = tmp_path / f"{name}.{LANGUAGES[language][1]}"
    program.write_text(source)
    return await finish(await start(agent, language, program, **options))


def fields(out: str) -> dict[str, str]:
    """Tcl programs print `name value` lines."""
    return dict(line.split(" ", 1) for line in out.splitlines())


# ---------------------------------------------------------------------------------------------
# drive, sensors and the rest of the robot

ROUND_TRIP = {
    "lua": """\
local socket = require('socket')
local Robot = require('robot')
local bot = Robot.new()
local out = { applied = bot:drive(0.2, 0) }
socket.sleep(0.2)
local sensors = bot:sensors()
out.heading = sensors.heading
out.y = sensors.position.y
out.bumper = sensors.bumper and 'pressed' or 'free'
out.range = bot:sensor('range')
out.kind = bot:capabilities().kind
out.clamped = bot:drive(5)
out.stop = tostring(bot:stop())
out.show = tostring(bot:show('speed', 0.25))
out.label = tostring(bot:show('label', '0.5'))  -- a text stays a text
print(Robot.json.encode(out))
""",
    "tcl": """\
package require robot
set applied [robot::drive 0.2 0]
after 200
set sensors [robot::sensors]
puts "applied [dict get $applied linear] [dict get $applied angular]"
puts "heading [dict get $sensors heading]"
puts "y [dict get $sensors position y]"
puts "bumper [expr {[dict get $sensors bumper] ? "pressed" : "free"}]"
puts "range [robot::sensor range]"
puts "kind [dict get [robot::capabilities] kind]"
set clamped [robot::drive 5]
puts "clamped [dict get $clamped linear] [dict get $clamped angular]"
puts "stop <[robot::stop]>"
puts "show <[robot::show speed 0.25]>"
puts "label <[robot::show label [huddle string 0.5]]>"
""",
}


@each_language
async def test_drive_and_sensors_round_trip(agent, language, tmp_path):
    admit(agent)
    source = ROUND_TRIP[language]
    if language == "tcl":
        source = "package require huddle\n" + source
    status, out, err = await run(agent, language, source, tmp_path)
    assert status == 0 and err == "", err
    if language == "lua":
        result = json.loads(out)
        assert result["applied"] == {"linear": 0.2, "angular": 0.0}
        assert result["clamped"] == {"linear": 0.5, "angular": 0.0}
        assert result["stop"] == result["show"] == result["label"] == "nil"
    else:
        result = fields(out)
        assert result["applied"] == "0.2 0.0" and result["clamped"] == "0.5 0.0"
        assert result["stop"] == result["show"] == result["label"] == "<>"
        result = {k: float(v) if k in ("heading", "y", "range") else v for k, v in result.items()}
    assert result["heading"] == 0.0 and result["y"] > 0.0 and result["bumper"] == "free"
    assert 0.0 < result["range"] < 2.0
    assert result["kind"] == "sim"
    assert agent.shows["speed"]["value"] == 0.25 and agent.shows["speed"]["run"] == 7
    assert agent.shows["label"]["value"] == "0.5"
    assert (await agent.driver.sensors())["velocity"] == {"linear": 0.0, "angular": 0.0}


# ---------------------------------------------------------------------------------------------
# errors

CAUGHT_THEN_UNCAUGHT = {
    "lua": """\
local Robot = require('robot')
local bot = Robot.new()
local ok, message = pcall(function() %(call)s end)
print(tostring(ok), bot.last_error.code, message)
%(call)s
print('not reached')
""",
    "tcl": """\
package require robot
if {[catch {%(call)s} message options]} {
    puts "[dict get $options -errorcode] $message"
}
%(call)s
puts "not reached"
""",
}

CALLS = {
    "unknown sensor": ({"lua": "bot:sensor('gps')", "tcl": "robot::sensor gps"}, -32000),
    "unknown method": ({"lua": "bot:call('fly', 1)", "tcl": "robot::call fly 1"}, -32601),
    "bad params": ({"lua": "bot:drive('fast')", "tcl": "robot::drive fast"}, -32602),
}


@each_language
@pytest.mark.parametrize("case", sorted(CALLS))
async def test_an_rpc_error_is_the_languages_error(agent, language, case, tmp_path):
    admit(agent)
    calls, code = CALLS[case]
    source = CAUGHT_THEN_UNCAUGHT[language] % {"call": calls[language]}
    status, out, err = await run(agent, language, source, tmp_path)
    word = {-32000: "gps", -32601: "fly", -32602: "linear"}[code]
    # caught: the code and the robot's message
    (caught,) = out.splitlines()
    if language == "lua":
        ok, caught_code, message = caught.split("\t")
        assert ok == "false" and int(caught_code) == code
        where, message = message.split(": ", 1)
        assert where.endswith("/program.lua:3")  # the program's line that called
        assert message.startswith(f"robot error {code}: ")
    else:
        tag, caught_code, message = caught.split(" ", 2)
        assert tag == "ROBOT" and int(caught_code) == code
    assert word in message
    # uncaught: the message on stderr, with where it happened, and a failed exit
    assert status != 0 and "not reached" not in out
    assert message in err
    if language == "lua":
        assert f"program.lua:5: {message}" in err
    else:
        assert 'file "' in err and "program.tcl" in err and "line 5)" in err


HEADING = {
    "lua": "print(require('robot').new():sensors().heading)\n",
    "tcl": "package require robot\nputs [dict get [robot::sensors] heading]\n",
}


@each_language
async def test_a_wrong_token_fails_clearly(agent, language, tmp_path):
    admit(agent)
    status, out, err = await run(agent, language, HEADING[language], tmp_path, token="a-guess")
    assert status != 0 and out == ""
    assert "invalid token" in err


@each_language
async def test_no_robot_api_in_the_environment_fails_clearly(agent, language, tmp_path):
    status, out, err = await run(agent, language, HEADING[language], tmp_path, token="", api="")
    variable = {"lua": "ROBOT_API", "tcl": "ROBOT_API_TCP"}[language]
    assert status != 0 and f"{variable} and ROBOT_TOKEN are not set" in err


async def test_lua_works_over_loopback_tcp_too(agent, tmp_path):
    admit(agent)
    status, out, err = await run(agent, "lua", HEADING["lua"], tmp_path, api=agent.api_address)
    assert status == 0, err
    assert float(out) == 0.0


async def test_tcl_without_tcp_goes_through_the_unix_socket(agent, tmp_path):
    """Tcl has no Unix sockets: with no TCP address (network "none") `robot pipe` relays."""
    admit(agent)
    status, out, err = await run(agent, "tcl", HEADING["tcl"], tmp_path, tcp="")
    assert status == 0, err
    assert float(out) == 0.0
    # ROBOT_API as host:port will do
    status, out, err = await run(
        agent, "tcl", HEADING["tcl"], tmp_path, tcp="", api=agent.api_address
    )
    assert status == 0, err
    assert float(out) == 0.0


# ---------------------------------------------------------------------------------------------
# JSON both ways: text with escapes and non-ASCII, nesting, null

TEXT = 'h\u00e9llo \U0001f600 \u2028 "quoted" \\ back/slash\nline\ttab\x01'

FROM_PYTHON = {
    "text": '\u00fcn\u00ef \u2028 \U0001f600 \u0000 "q" \\',
    "list": [None, 1, None],
    "deep": [[[]], {}],
    "n": -1.5e-7,
    "big": 2**53 + 1,
    "t": True,
    "f": False,
    "word": "null",
}

JSON_EDGES_LUA = r"""
local Robot = require('robot')
local json = Robot.json
local bot = Robot.new()
bot:show('greeting', 'h\u{e9}llo \u{1F600} \u{2028} "quoted" \\ back/slash\nline\ttab\1')
bot:show('big', 12345678901)
bot:show('small', -0.000123)
bot:show('float', 2.0)
bot:memory_set('nested', {
  a = { b = { c = { 1, 2.5, 'x', true, false, Robot.null, {} } } },
  empty = Robot.array({}),
  ['\u{43a}\u{43b}\u{44e}\u{447}'] = '\u{437}\u{43d}\u{430}\u{447}\u{435}\u{43d}\u{438}\u{435}',
})
bot:memory_set('nothing', nil)
print(json.encode(bot:memory_get('nested')))
print(tostring(bot:memory_get('nothing')), tostring(bot:memory_get('never set')))
local p = bot:memory_get('from python')
print(json.encode(p))
print(p.list[1] == Robot.null, #p.list, math.type(p.big), math.type(p.n), p.word)
print(bot:call('memory_get', 'from python').text == p.text)
"""

JSON_EDGES_TCL = r"""
package require robot
package require huddle
robot::show greeting "h\u00e9llo \ud83d\ude00 \u2028 \"quoted\" \\ back/slash\nline\ttab\x01"
robot::show big 12345678901
robot::show small -0.000123
robot::show float 2.0
robot::show code 007
robot::memory_set nested [huddle create \
    a [huddle create b [huddle create c [huddle list \
        [huddle number 1] [huddle number 2.5] x [huddle true] [huddle false] [huddle null] \
        [huddle create]]]] \
    empty [huddle list] \
    "\u043a\u043b\u044e\u0447" "\u0437\u043d\u0430\u0447\u0435\u043d\u0438\u0435"]
robot::memory_set nothing [huddle null]
robot::memory_set word null
set nested [robot::memory_get nested]
puts "c [dict get $nested a b c]"
puts "key [dict get $nested \u043a\u043b\u044e\u0447]"
puts "nothing <[robot::memory_get nothing]> <[robot::memory_get {never set}]>"
puts "word <[robot::memory_get word]>"
set p [robot::memory_get {from python}]
puts "text [string equal [dict get $p text] "\u00fcn\u00ef \u2028 \ud83d\ude00 \u0000 \"q\" \\"]"
puts "list [dict get $p list]"
puts "big [dict get $p big]"
puts "n [dict get $p n]"
puts "pword <[dict get $p word]>"
puts "call [string equal [robot::call memory_get {from python}] $p]"
"""


async def test_lua_json_edge_cases(agent, tmp_path):
    admit(agent)
    agent.api.memory["from python"] = FROM_PYTHON
    status, out, err = await run(agent, "lua", JSON_EDGES_LUA, tmp_path)
    assert status == 0 and err == "", err
    nested, nothing, from_python, checks, same = out.split("\n")[:-1]  # (U+2028 is no line end)
    assert agent.shows["greeting"]["value"] == TEXT
    assert agent.shows["big"]["value"] == 12345678901
    assert agent.shows["small"]["value"] == -0.000123
    assert type(agent.shows["float"]["value"]) is float  # 2.0 stays a float
    expected = {
        "a": {"b": {"c": [1, 2.5, "x", True, False, None, {}]}},
        "empty": [],
        "\u043a\u043b\u044e\u0447": "\u0437\u043d\u0430\u0447\u0435\u043d\u0438\u0435",
    }
    assert agent.api.memory["nested"] == expected
    assert json.loads(nested) == expected
    assert "nothing" in agent.api.memory and agent.api.memory["nothing"] is None
    assert nothing == "nil\tnil"  # null is nil
    assert json.loads(from_python) == FROM_PYTHON
    assert checks == "true\t3\tinteger\tfloat\tnull"
    assert same == "true"


async def test_tcl_json_edge_cases(agent, tmp_path):
    admit(agent)
    agent.api.memory["from python"] = FROM_PYTHON
    status, out, err = await run(agent, "tcl", JSON_EDGES_TCL, tmp_path)
    assert status == 0 and err == "", err
    result = fields(out)
    assert agent.shows["greeting"]["value"] == TEXT
    assert agent.shows["big"]["value"] == 12345678901
    assert agent.shows["small"]["value"] == -0.000123
    assert type(agent.shows["float"]["value"]) is float
    assert agent.shows["code"]["value"] == "007"  # not a JSON number: a text
    assert agent.api.memory["nested"] == {
        "a": {"b": {"c": [1, 2.5, "x", True, False, None, {}]}},
        "empty": [],
        "\u043a\u043b\u044e\u0447": "\u0437\u043d\u0430\u0447\u0435\u043d\u0438\u0435",
    }
    assert "nothing" in agent.api.memory and agent.api.memory["nothing"] is None
    assert agent.api.memory["word"] == "null"  # a text, not null
    assert result["c"] == "1 2.5 x true false null {}"
    assert result["key"] == "\u0437\u043d\u0430\u0447\u0435\u043d\u0438\u0435"
    assert result["nothing"] == "<> <>"  # a null result is the empty string
    assert result["word"] == "<null>"
    assert result["text"] == "1"
    assert result["list"] == "null 1 null"
    assert int(result["big"]) == 2**53 + 1 and float(result["n"]) == -1.5e-7
    assert result["pword"] == "<null>"
    assert result["call"] == "1"


# ---------------------------------------------------------------------------------------------
# programs that cooperate: messages and the shared memory

SUBSCRIBER = {
    "lua": """\
local Robot = require('robot')
local bot = Robot.new()
print(tostring(bot:subscribe('chat')))
io.stdout:flush()
local out = { value = bot:receive('chat') }  -- no timeout: waits for ever
out.none = tostring(bot:receive('chat', 0.1))  -- nothing more: nil after the timeout
out.memory = bot:memory_get('shared')
out.missing = tostring(bot:memory_get('nothing'))
print(Robot.json.encode(out))
local ok, message = pcall(bot.receive, bot, 'elsewhere', 0)
print(message)
""",
    "tcl": """\
package require robot
puts "<[robot::subscribe chat]>"
flush stdout
set value [robot::receive chat]  ;# no timeout: waits for ever
puts "value [dict get $value text] [dict get $value n]"
puts "none <[robot::receive chat 0.1]>"
puts "memory [dict get [robot::memory_get shared] list]"
puts "missing <[robot::memory_get nothing]>"
catch {robot::receive elsewhere 0} message
puts "refused $message"
""",
    "python": """\
import json
import robot

bot = robot.Robot()
bot.subscribe("chat")
print("None", flush=True)
out = {"value": bot.receive("chat", 20)}
out["none"] = bot.receive("chat", 0.1)
out["memory"] = bot.memory_get("shared")
out["missing"] = bot.memory_get("nothing")
print(json.dumps(out))
try:
    bot.receive("elsewhere", 0)
except robot.RobotError as exc:
    print(exc)
""",
}

PUBLISHER = {
    "lua": """\
local Robot = require('robot')
local bot = Robot.new()
bot:memory_set('shared', { list = { 1, 2.5, 'x', true, Robot.null } })
print(bot:publish('chat', { text = 'hello', n = 3 }))
print(bot:publish('nobody-listens', 1))
""",
    "tcl": """\
package require robot
package require huddle
robot::memory_set shared [huddle create list [huddle list \\
    [huddle number 1] [huddle number 2.5] x [huddle true] [huddle null]]]
puts [robot::publish chat [huddle create text hello n [huddle number 3]]]
puts [robot::publish nobody-listens 1]
""",
    "python": """\
import robot

bot = robot.Robot()
bot.memory_set("shared", {"list": [1, 2.5, "x", True, None]})
print(bot.publish("chat", {"text": "hello", "n": 3}))
print(bot.publish("nobody-listens", 1))
""",
}

READY = {"lua": b"nil\n", "tcl": b"<>\n", "python": b"None\n"}


@pytest.mark.parametrize(
    "language, other",
    [("lua", "tcl"), ("tcl", "lua"), ("lua", "python"), ("python", "lua"), ("tcl", "python")],
)
async def test_programs_exchange_messages_and_share_memory(agent, language, other, tmp_path):
    """`language` subscribes; `other` publishes and writes the shared memory."""
    admit(agent, "subscriber-token", 7)
    admit(agent, "publisher-token", 8)
    subscriber_file = tmp_path / f"subscriber.{LANGUAGES[language][1]}"
    subscriber_file.write_text(SUBSCRIBER[language])
    subscriber = await start(agent, language, subscriber_file, token="subscriber-token")
    try:
        ready = await asyncio.wait_for(subscriber.stdout.readline(), 30)
        assert ready == READY[language], (await subscriber.stderr.read()).decode()
        status, out, err = await run(
            agent, other, PUBLISHER[other], tmp_path, name="publisher", token="publisher-token"
        )
        assert status == 0, err
        assert out.split() == ["1", "0"]  # reached one subscriber, then none
        status, out, err = await finish(subscriber)
    finally:
        if subscriber.returncode is None:
            subscriber.kill()
            await subscriber.wait()
    assert status == 0, err
    if language == "tcl":
        assert fields(out) == {
            "value": "hello 3",
            "none": "<>",
            "memory": "1 2.5 x true null",
            "missing": "<>",
            "refused": "subscribe to 'elsewhere' before receiving from it",
        }
        return
    received, refused = out.splitlines()
    nothing = "nil" if language == "lua" else None
    assert json.loads(received) == {
        "value": {"text": "hello", "n": 3},
        "none": nothing,
        "memory": {"list": [1, 2.5, "x", True, None]},
        "missing": nothing,
    }
    assert "subscribe to 'elsewhere' before receiving" in refused


# ---------------------------------------------------------------------------------------------
# the example every language has


@each_language
async def test_the_wall_turn_example(agent, language):
    """Forward to the wall, stop, turn, print the heading and show it: on the sim robot."""
    admit(agent)
    program = EXAMPLES / f"wall_turn.{LANGUAGES[language][1]}"
    status, out, err = await finish(await start(agent, language, program), timeout=60)
    await check_wall_turn(agent, status, out, err)


# ---------------------------------------------------------------------------------------------
# the host's services: speech and the camera


@pytest.fixture
async def host_agent(agent):
    agent.api.methods.update(HostServices(agent).methods)  # as RobotApi registers them
    admit(agent)
    return agent


HOST_SERVICES = {
    "lua": """\
local Robot = require('robot')
local bot = Robot.new()
local said = bot:say('hello from Lua')
print(type(said.spoken))
local codes = bot:scan_barcode()
print(#codes, codes[1].text, codes[1].format, #codes[1].position)
local frame = bot:snapshot()
print(frame.width, frame.height, #frame.jpeg > 1000)
""",
    "tcl": """\
package require robot
set said [robot::say "hello from Tcl"]
puts [expr {[dict get $said spoken] in {true false}}]
set codes [robot::scan_barcode]
set code [lindex $codes 0]
set corners [llength [dict get $code position]]
puts "[llength $codes] [dict get $code text] [dict get $code format] $corners"
set frame [robot::snapshot]
set large [expr {[string length [dict get $frame jpeg]] > 1000}]
puts "[dict get $frame width] [dict get $frame height] $large"
""",
}


@each_language
@pytest.mark.django_db(transaction=True)  # the robot's speech and camera settings: from its row
async def test_say_and_scan_barcode(host_agent, language, tmp_path):
    status, out, err = await run(host_agent, language, HOST_SERVICES[language], tmp_path)
    assert status == 0, err
    spoken, codes, frame = out.splitlines()
    assert spoken in ("boolean", "1")
    assert codes.split() == ["1", "kitchen", "QRCode", "4"]  # ahead of the sim robot at start
    assert frame.split()[:2] == ["640", "480"] and frame.split()[2] in ("true", "1")
    expected = "hello from Lua" if language == "lua" else "hello from Tcl"
    assert host_agent.shows["said"]["value"] == expected
