"""The Perl and Ruby Robot API clients, run by their real interpreters as programs against a
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

# language -> (interpreter, file extension, the variable that finds the client, its folder)
LANGUAGES = {
    "perl": ("perl", "pl", "PERL5LIB", CLIENTS_DIR / "perl"),
    "ruby": ("ruby", "rb", "RUBYLIB", CLIENTS_DIR / "ruby"),
    "python": ("python3", "py", "PYTHONPATH", CLIENTS_DIR / "python"),  # a partner to talk to
}

each_language = pytest.mark.parametrize("language", ["perl", "ruby"])


async def start(agent, language, program: Path, token="good-token", address=None):
    interpreter, _, variable, folder = LANGUAGES[language]
    env = {
        "PATH": os.environ["PATH"],
        "LANG": "C.UTF-8",
        "ROBOT_API": address or f"unix:{agent.server.unix_path}",
        "ROBOT_TOKEN": token,
        variable: str(folder),
    }
    return await asyncio.create_subprocess_exec(
        interpreter,
        str(program),
        env=env,
        stdout=asyncio.subprocess.PIPE,
        stderr=asyncio.subprocess.PIPE,
    )


async def finish(process, timeout=30) -> tuple[int, str, str]:
    out, err = await asyncio.wait_for(process.communicate(), timeout)
    return process.returncode, out.decode(), err.decode()


async def run(agent, language, source: str, tmp_path, name="program", **options):
    program = tmp_path / f"{name}.{LANGUAGES[language][1]}"
    program.write_text(source)
    return await finish(await start(agent, language, program, **options))


# A Perl string that only looks like a number must still go out as a JSON number.
ROUND_TRIP = {
    "perl": """\
use strict; use warnings;
use JSON::PP;
use Robot;
my $bot = Robot->new;
my ($speed) = '--speed=0.2' =~ /=(.+)/;   # text, as read from @ARGV or a file
my %out = (applied => $bot->drive($speed, '0'));
select undef, undef, undef, 0.2;
my $sensors = $bot->sensors;
$out{heading} = $sensors->{heading};
$out{y} = $sensors->{position}{y};
$out{bumper} = $sensors->{bumper} ? 'pressed' : 'free';
$out{range} = $bot->sensor('range');
$out{kind} = $bot->capabilities->{kind};
$out{clamped} = $bot->drive(5);
$out{stop} = $bot->stop;
$out{show} = $bot->show('speed', 0.25);
print JSON::PP->new->canonical->encode(\\%out), "\\n";
""",
    "ruby": """\
require 'json'
require 'robot'
bot = Robot.new
out = { applied: bot.drive(0.2, 0) }
sleep 0.2
sensors = bot.sensors
out[:heading] = sensors['heading']
out[:y] = sensors['position']['y']
out[:bumper] = sensors['bumper'] ? 'pressed' : 'free'
out[:range] = bot.sensor('range')
out[:kind] = bot.capabilities['kind']
out[:clamped] = bot.drive(5)
out[:stop] = bot.stop
out[:show] = bot.show('speed', 0.25)
puts JSON.generate(out)
""",
}


@each_language
async def test_drive_and_sensors_round_trip(agent, language, tmp_path):
    admit(agent)
    status, out, err = await run(agent, language, ROUND_TRIP[language], tmp_path)
    assert status == 0 and err == "", err  # not even a warning
    result = json.loads(out)
    assert result["applied"] == {"linear": 0.2, "angular": 0.0}
    assert result["heading"] == 0.0 and result["y"] > 0.0 and result["bumper"] == "free"
    assert 0.0 < result["range"] < 2.0
    assert result["kind"] == "sim"
    assert result["clamped"] == {"linear": 0.5, "angular": 0.0}
    assert result["stop"] is None and result["show"] is None
    assert agent.shows["speed"]["value"] == 0.25 and agent.shows["speed"]["run"] == 7
    assert (await agent.driver.sensors())["velocity"] == {"linear": 0.0, "angular": 0.0}


CAUGHT_THEN_UNCAUGHT = {
    "perl": """\
use strict; use warnings;
use Robot;
my $bot = Robot->new;
eval { %(call)s };
print ref($@), "\\n", $@->code, "\\n", $@->message, "\\n";
%(call)s;
print "not reached\\n";
""",
    "ruby": """\
require 'robot'
bot = Robot.new
begin
  %(call)s
rescue Robot::Error => e
  puts e.class, e.code, e.message
end
%(call)s
puts 'not reached'
""",
}

CALLS = {
    "unknown sensor": ({"perl": "$bot->sensor('gps')", "ruby": "bot.sensor('gps')"}, -32000),
    "unknown method": ({"perl": "$bot->call('fly', 1)", "ruby": "bot.call('fly', 1)"}, -32601),
}


@each_language
@pytest.mark.parametrize("case", sorted(CALLS))
async def test_an_rpc_error_is_the_languages_error(agent, language, case, tmp_path):
    admit(agent)
    calls, code = CALLS[case]
    source = CAUGHT_THEN_UNCAUGHT[language] % {"call": calls[language]}
    status, out, err = await run(agent, language, source, tmp_path)
    kind, caught_code, message = out.splitlines()
    assert kind == "Robot::Error" and int(caught_code) == code
    word = "gps" if code == -32000 else "fly"
    assert word in message
    # uncaught: the message on stderr, with where it happened, and a failed exit
    assert status != 0 and "not reached" not in out
    assert message in err and "program." + LANGUAGES[language][1] in err
    if language == "perl":
        assert err.startswith(f"robot: {message} at ") and "line 6." in err
    else:
        assert "program.rb:8" in err and "(Robot::Error)" in err


HEADING = {
    "perl": "use Robot; print Robot->new->sensors->{heading}, qq(\\n);\n",
    "ruby": "require 'robot'; puts Robot.new.sensors['heading']\n",
}


@each_language
async def test_a_wrong_token_fails_clearly(agent, language, tmp_path):
    admit(agent)
    status, out, err = await run(agent, language, HEADING[language], tmp_path, token="a-guess")
    assert status != 0 and out == ""
    assert "invalid token" in err


@each_language
async def test_no_robot_api_in_the_environment_fails_clearly(agent, language, tmp_path):
    status, out, err = await run(agent, language, HEADING[language], tmp_path, token="")
    assert status != 0 and "ROBOT_API and ROBOT_TOKEN are not set" in err


@each_language
async def test_loopback_tcp_works_too(agent, language, tmp_path):
    admit(agent)
    assert not agent.api_address.startswith("unix:")
    status, out, err = await run(
        agent, language, HEADING[language], tmp_path, address=agent.api_address
    )
    assert status == 0, err
    assert float(out) == 0.0


SUBSCRIBER = {
    "perl": """\
use strict; use warnings;
use JSON::PP;
use Robot;
$| = 1;
my $bot = Robot->new;
$bot->subscribe('chat');
print "ready\\n";
my %out = (value => $bot->receive('chat', 20));
$out{none} = $bot->receive('chat', 0.1);   # nothing more: undef after the timeout
$out{memory} = $bot->memory_get('shared');
$out{missing} = $bot->memory_get('nothing');
print JSON::PP->new->canonical->encode(\\%out), "\\n";
eval { $bot->receive('elsewhere', 0) };
print $@->message, "\\n";
""",
    "ruby": """\
require 'json'
require 'robot'
$stdout.sync = true
bot = Robot.new
bot.subscribe('chat')
puts 'ready'
out = { value: bot.receive('chat', 20) }
out[:none] = bot.receive('chat', 0.1) # nothing more: nil after the timeout
out[:memory] = bot.memory_get('shared')
out[:missing] = bot.memory_get('nothing')
puts JSON.generate(out)
begin
  bot.receive('elsewhere', 0)
rescue Robot::Error => e
  puts e.message
end
""",
    "python": """\
import json
import robot

bot = robot.Robot()
bot.subscribe("chat")
print("ready", flush=True)
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
    "perl": """\
use strict; use warnings;
use JSON::PP;
use Robot;
my $bot = Robot->new;
$bot->memory_set('shared', { list => [1, 2.5, 'x', JSON::PP::true, undef] });
print $bot->publish('chat', { text => 'hello', n => 3 }), "\\n";
print $bot->publish('nobody-listens', 1), "\\n";
""",
    "ruby": """\
require 'robot'
bot = Robot.new
bot.memory_set('shared', { 'list' => [1, 2.5, 'x', true, nil] })
puts bot.publish('chat', { 'text' => 'hello', 'n' => 3 })
puts bot.publish('nobody-listens', 1)
""",
    "python": """\
import robot

bot = robot.Robot()
bot.memory_set("shared", {"list": [1, 2.5, "x", True, None]})
print(bot.publish("chat", {"text": "hello", "n": 3}))
print(bot.publish("nobody-listens", 1))
""",
}


@pytest.mark.parametrize(
    "language, other", [("perl", "ruby"), ("ruby", "perl"), ("perl", "python"), ("python", "perl")]
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
        assert ready == b"ready\n", (await subscriber.stderr.read()).decode()
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
    received, refused = out.splitlines()
    assert json.loads(received) == {
        "value": {"text": "hello", "n": 3},
        "none": None,
        "memory": {"list": [1, 2.5, "x", True, None]},
        "missing": None,
    }
    assert "subscribe to 'elsewhere' before receiving" in refused


@each_language
async def test_the_wall_turn_example(agent, language):
    """Forward to the wall, stop, turn, print the heading and show it: on the sim robot."""
    admit(agent)
    program = EXAMPLES / f"wall_turn.{LANGUAGES[language][1]}"
    status, out, err = await finish(await start(agent, language, program), timeout=60)
    await check_wall_turn(agent, status, out, err)


# -- the host's services: speech and the camera ----------------------------------------------

HOST_SERVICES = {
    "perl": """\
use strict; use warnings;
use JSON::PP;
use Robot;
my $bot = Robot->new;
my $said = $bot->say('hello from Perl');
my $codes = $bot->scan_barcode;
my $frame = $bot->snapshot;
print JSON::PP->new->canonical->encode({
    spoken => JSON::PP::is_bool($said->{spoken}) ? 'boolean' : 'other',
    codes => [map { [$_->{text}, $_->{format}, scalar @{$_->{position}}] } @$codes],
    size => [$frame->{width}, $frame->{height}],
}), "\\n";
""",
    "ruby": """\
require 'json'
require 'robot'
bot = Robot.new
said = bot.say('hello from Ruby')
codes = bot.scan_barcode
frame = bot.snapshot
puts JSON.generate({
  spoken: [true, false].include?(said['spoken']) ? 'boolean' : 'other',
  codes: codes.map { |code| [code['text'], code['format'], code['position'].length] },
  size: [frame['width'], frame['height']],
})
""",
}


@each_language
@pytest.mark.django_db(transaction=True)  # the robot's speech and camera settings: from its row
async def test_say_and_scan_barcode(agent, language, tmp_path):
    agent.api.methods.update(HostServices(agent).methods)  # as RobotApi registers them
    admit(agent)
    status, out, err = await run(agent, language, HOST_SERVICES[language], tmp_path)
    assert status == 0 and err == "", err
    assert json.loads(out) == {
        "spoken": "boolean",
        "codes": [["kitchen", "QRCode", 4]],  # ahead of the sim robot at the start
        "size": [640, 480],
    }
    expected = "hello from Perl" if language == "perl" else "hello from Ruby"
    assert agent.shows["said"]["value"] == expected
