"""The Robot API as programs call it: the one description of each call, its parameters, what it
returns, and how each language's client in programs/clients/ writes it.

The editor's completion and hover help (programs/api_help.py gives it as JSON to
robotide/static/robotide/api_help.js) and the help page /help/robot-api/ are made from this
module; tests/programs/test_robot_api_spec.py runs every form in every language against the
Robot API server, and checks that every method the server dispatches is described here, so the
description cannot drift from the clients or the server.

A form is the call as a program writes it, each parameter written ``<name>``:

    Python  bot.drive(<linear>, <angular>)       shown  bot.drive(linear, angular)
    Perl    $bot->drive(<linear>, <angular>)     shown  $bot->drive($linear, $angular)
    Tcl     robot::drive <linear> ?<angular>?    shown  robot::drive linear ?angular?
    shell   robot drive <linear> [<angular>]     shown  robot drive LINEAR [ANGULAR]

Tcl's ``?..?`` and the shell's ``[..]`` mark what may be left out, as their own manuals do;
the other languages leave a parameter out from the end. An example is the form with each
parameter's example value written as a literal of the language (`example`).
"""

import json
import re
import shlex
from dataclasses import dataclass, field
from typing import Any

__all__ = ["CALLS", "CLIENTS", "Call", "Client", "Param", "by_language", "call_named"]

PLACEHOLDER = re.compile(r"<(\w+)>")


@dataclass(frozen=True)
class Param:
    name: str
    meaning: str
    unit: str = ""
    default: str | None = None  # what leaving it out means; None: it must be given
    example: Any = None  # what the examples pass
    sent: bool = True  # False: the client uses it itself (the shell's FILE), not the robot


@dataclass(frozen=True)
class Call:
    name: str  # the client method's name, in every language that has it
    rpc: str | None  # the JSON-RPC method it sends; None: the client alone (close)
    group: str
    summary: str  # one line
    doc: str  # a few sentences
    returns: str
    params: tuple[Param, ...] = ()
    forms: dict[str, str] = field(default_factory=dict)  # language -> form
    notes: dict[str, str] = field(default_factory=dict)  # language -> how it differs there
    absent: dict[str, str] = field(default_factory=dict)  # language -> why it has no form

    def param(self, name: str) -> Param:
        return next(p for p in self.params if p.name == name)

    def sent_params(self) -> list[Param]:
        """The parameters in the order the robot gets them."""
        return [p for p in self.params if p.sent]


@dataclass(frozen=True)
class Client:
    language: str  # as programs.languages names it
    label: str
    setup: str  # what a program writes before it can connect
    obj: str  # the robot object in the forms: bot, $bot, or robot (Tcl's namespace, the command)
    accessor: str  # between the object and a call's name
    # JavaScript regular expressions (read by api_help.js): group 1 of `objects` is the name of
    # a connected robot in a program; group 1 of `connects` is the connect call's word
    objects: str
    connects: str
    values: str  # how JSON values look in the language
    errors: str  # what an error the robot reports becomes

    def display(self, form: str) -> str:
        """A form as the help shows it: each parameter in the language's usual style."""
        return PLACEHOLDER.sub(lambda m: self._placeholder(m.group(1)), form)

    def _placeholder(self, name: str) -> str:
        if self.language == "perl":
            return f"${name}"
        if self.language == "shell":
            return name.upper()
        return name

    def example(self, call: "Call") -> str:
        """The form with the example values written in as the language writes them."""
        form = call.forms[self.language]
        if self.language == "tcl":
            form = form.replace("?", "")
        elif self.language == "shell":
            form = form.replace("[", "").replace("]", "")
        return PLACEHOLDER.sub(lambda m: self.literal(call.param(m.group(1)).example), form)

    def literal(self, value) -> str:
        """A value as a literal of the language (the values the examples use)."""
        lang = self.language
        if lang == "shell":
            if isinstance(value, list):
                return shlex.quote(",".join(value))  # --words move,stop
            return shlex.quote(value if isinstance(value, str) else json.dumps(value))
        if lang == "tcl":
            if isinstance(value, list):
                return "{" + " ".join(value) + "}"
            text = "" if value is None else str(value)
            return text if re.fullmatch(r"[\w.+-]+", text) else "{" + text + "}"
        if value is None:
            return {"python": "None", "perl": "undef", "ruby": "nil", "lua": "nil"}.get(
                lang, "null"
            )
        if isinstance(value, bool):
            return {"python": repr(value), "perl": str(int(value))}.get(lang, str(value).lower())
        if isinstance(value, str):
            return repr(value) if lang == "python" else "'" + value.replace("'", "\\'") + "'"
        if isinstance(value, list):
            items = ", ".join(self.literal(item) for item in value)
            return "{" + items + "}" if lang == "lua" else "[" + items + "]"
        return json.dumps(value)


CLIENTS: dict[str, Client] = {
    c.language: c
    for c in [
        Client(
            language="python",
            label="Python",
            setup="import robot",
            obj="bot",
            accessor=".",
            objects=r"([A-Za-z_]\w*)\s*=\s*robot\.Robot\(",
            connects=r"\brobot\.(Robot)\b",
            values="objects are dicts, arrays lists, null None",
            errors="raises robot.RobotError (its .code is the JSON-RPC code)",
        ),
        Client(
            language="perl",
            label="Perl",
            setup="use Robot;",
            obj="$bot",
            accessor="->",
            objects=r"(\$[A-Za-z_]\w*)\s*=\s*Robot->new\b",
            connects=r"\bRobot->(new)\b",
            values="objects are hash references, arrays array references, null undef",
            errors="dies with a Robot::Error ($@->message, $@->code)",
        ),
        Client(
            language="ruby",
            label="Ruby",
            setup="require 'robot'",
            obj="bot",
            accessor=".",
            objects=r"([A-Za-z_]\w*)\s*=\s*Robot\.new\b",
            connects=r"\bRobot\.(new)\b",
            values="objects are Hashes with string keys, arrays Arrays, null nil",
            errors="raises Robot::Error (#message, #code)",
        ),
        Client(
            language="lua",
            label="Lua",
            setup="local Robot = require('robot')",
            obj="bot",
            accessor=":",
            objects=r"([A-Za-z_]\w*)\s*=\s*Robot\.new\(",
            connects=r"\bRobot\.(new)\b",
            values="objects and arrays are tables, null nil (Robot.null inside a table)",
            errors="error() with the message and code (catch it with pcall; bot.last_error)",
        ),
        Client(
            language="javascript",
            label="JavaScript",
            setup="const { Robot } = require('robot');",
            obj="bot",
            accessor=".",
            objects=r"([A-Za-z_$][\w$]*)\s*=\s*new\s+Robot\(",
            connects=r"\bnew\s+(Robot)\b",
            values="every call returns a Promise (await it); objects, arrays and null as JSON",
            errors="the Promise rejects with a RobotError (.message, .code)",
        ),
        Client(
            language="tcl",
            label="Tcl",
            setup="package require robot",
            obj="robot",
            accessor="::",
            objects=r"\b(robot)::",
            connects=r"\brobot::(connect)\b",
            values="objects are dicts, arrays lists, null the empty string; pass [huddle ...]"
            " for true, false, null, lists and objects",
            errors="a Tcl error with -errorcode {ROBOT code}",
        ),
        Client(
            language="shell",
            label="Shell",
            setup="",
            obj="robot",
            accessor=" ",
            objects=r"\b(robot) ",
            connects=r"(?!)",
            values="numbers and texts are printed plain, anything else as JSON; a VALUE is"
            " read as JSON, else as text",
            errors="the message on standard error, exit status 1",
        ),
    ]
}

LANGUAGES = tuple(CLIENTS)

CONNECTION = "Connecting"
MOTION = "Driving"
SENSES = "Sensing"
PAGE = "The robot's page"
TOGETHER = "Programs together"
HOST = "The robot's computer"

CALLS: tuple[Call, ...] = (
    Call(
        name="connect",
        rpc="auth",
        group=CONNECTION,
        summary="Connect to the robot the program runs on.",
        doc="Connects to the Robot API at $ROBOT_API with the run's $ROBOT_TOKEN, which robotide"
        " sets for every run, so a program needs no address. The token is worth nothing once"
        " the run has ended. JavaScript connects on the first call, and so does Tcl's first"
        " command; robot::connect does it at once.",
        returns="the robot object the other calls are made on",
        forms={
            "python": "bot = robot.Robot()",
            "perl": "my $bot = Robot->new",
            "ruby": "bot = Robot.new",
            "lua": "local bot = Robot.new()",
            "javascript": "const bot = new Robot()",
            "tcl": "robot::connect",
        },
        absent={"shell": "each robot command connects by itself"},
    ),
    Call(
        name="drive",
        rpc="drive",
        group=MOTION,
        summary="Drive at a forward speed and a turn rate until told otherwise.",
        doc="Sets the speeds the robot keeps until the next drive() or stop(). Both are"
        " clamped to the robot's limits (capabilities() says them); the result says what was"
        " applied. Refused while someone else controls the robot, and after Stop was pressed.",
        returns="the speeds applied: {linear, angular}",
        params=(
            Param("linear", "forward speed; negative backs up", "m/s", example=0.2),
            Param("angular", "turn rate, counter-clockwise", "rad/s", "0", example=0.5),
        ),
        forms={
            "python": "bot.drive(<linear>, <angular>)",
            "perl": "$bot->drive(<linear>, <angular>)",
            "ruby": "bot.drive(<linear>, <angular>)",
            "lua": "bot:drive(<linear>, <angular>)",
            "javascript": "await bot.drive(<linear>, <angular>)",
            "tcl": "robot::drive <linear> ?<angular>?",
            "shell": "robot drive <linear> [<angular>]",
        },
        notes={"shell": "prints nothing"},
    ),
    Call(
        name="stop",
        rpc="stop",
        group=MOTION,
        summary="Stop the motors.",
        doc="Sends the robot's own stop command. The robot is stopped too when the program"
        " ends, however it ends.",
        returns="nothing (null)",
        forms={
            "python": "bot.stop()",
            "perl": "$bot->stop",
            "ruby": "bot.stop",
            "lua": "bot:stop()",
            "javascript": "await bot.stop()",
            "tcl": "robot::stop",
            "shell": "robot stop",
        },
    ),
    Call(
        name="sensors",
        rpc="sensors",
        group=SENSES,
        summary="All the robot's readings at once.",
        doc="Readings every robot names alike: heading (deg, clockwise from north), range (m to"
        " the nearest obstacle ahead, null when nothing is in reach), position {x, y, theta}"
        " (m, m, rad), velocity {linear, angular} (m/s, rad/s), battery; a robot adds its"
        " own (bumpers, sonar...) and leaves out what it cannot measure.",
        returns="an object: sensor name -> reading",
        forms={
            "python": "bot.sensors()",
            "perl": "$bot->sensors",
            "ruby": "bot.sensors",
            "lua": "bot:sensors()",
            "javascript": "await bot.sensors()",
            "tcl": "robot::sensors",
            "shell": "robot sensors",
        },
        notes={"shell": "prints the readings as JSON"},
    ),
    Call(
        name="sensor",
        rpc="sensor",
        group=SENSES,
        summary="One reading, by its name.",
        doc="The reading sensors() has under that name. A name the robot lacks is an error"
        " that lists the sensors it has.",
        returns="the reading, in the unit capabilities() gives for it",
        params=(Param("name", "the sensor: heading, range, position, ...", example="heading"),),
        forms={
            "python": "bot.sensor(<name>)",
            "perl": "$bot->sensor(<name>)",
            "ruby": "bot.sensor(<name>)",
            "lua": "bot:sensor(<name>)",
            "javascript": "await bot.sensor(<name>)",
            "tcl": "robot::sensor <name>",
            "shell": "robot sensors <name>",
        },
        notes={"shell": "prints a number or a text plain, anything else as JSON"},
    ),
    Call(
        name="capabilities",
        rpc="capabilities",
        group=SENSES,
        summary="What the robot is and can do.",
        doc="The robot's kind, its drive limits {max_linear (m/s), max_angular (rad/s)}, each"
        " sensor sensors() returns with its unit, and its camera if it has one.",
        returns="an object: kind, drive, sensors, camera",
        forms={
            "python": "bot.capabilities()",
            "perl": "$bot->capabilities",
            "ruby": "bot.capabilities",
            "lua": "bot:capabilities()",
            "javascript": "await bot.capabilities()",
            "tcl": "robot::capabilities",
            "shell": "robot capabilities",
        },
        notes={"shell": "prints it as JSON"},
    ),
    Call(
        name="show",
        rpc="show",
        group=PAGE,
        summary="Show a value live on the robot's page, by name.",
        doc="A number, a text, or an SVG drawing (a text starting with <svg). Showing a name"
        " again replaces its value; values stay on the page after the program ends, until the"
        " room is needed. A name has 1 to 64 characters, a value at most 256 KB.",
        returns="nothing (null)",
        params=(
            Param("name", "what the page calls it (1-64 characters)", example="speed"),
            Param("value", "a number, a text or an SVG text", example=0.2),
        ),
        forms={
            "python": "bot.show(<name>, <value>)",
            "perl": "$bot->show(<name>, <value>)",
            "ruby": "bot.show(<name>, <value>)",
            "lua": "bot:show(<name>, <value>)",
            "javascript": "await bot.show(<name>, <value>)",
            "tcl": "robot::show <name> <value>",
            "shell": "robot show <name> <value>",
        },
    ),
    Call(
        name="publish",
        rpc="publish",
        group=TOGETHER,
        summary="Send a value to the programs subscribed to a topic.",
        doc="Any JSON value of at most 64 KB, queued for every connection subscribed to the"
        " topic on this robot. A subscriber that does not keep up loses its oldest values,"
        " never the publisher's call.",
        returns="how many subscribers it was queued for",
        params=(
            Param("topic", "the topic's name (1-64 characters)", example="speed"),
            Param("value", "any JSON value, at most 64 KB", example=0.3),
        ),
        forms={
            "python": "bot.publish(<topic>, <value>)",
            "perl": "$bot->publish(<topic>, <value>)",
            "ruby": "bot.publish(<topic>, <value>)",
            "lua": "bot:publish(<topic>, <value>)",
            "javascript": "await bot.publish(<topic>, <value>)",
            "tcl": "robot::publish <topic> <value>",
            "shell": "robot publish <topic> <value>",
        },
        notes={"shell": "prints how many it reached"},
    ),
    Call(
        name="subscribe",
        rpc="subscribe",
        group=TOGETHER,
        summary="Get the values published on a topic from now on.",
        doc="This connection gets every value published on the topic from now on, to"
        " receive() one at a time. At most 64 topics per connection.",
        returns="nothing (null)",
        params=(Param("topic", "the topic's name", example="speed"),),
        forms={
            "python": "bot.subscribe(<topic>)",
            "perl": "$bot->subscribe(<topic>)",
            "ruby": "bot.subscribe(<topic>)",
            "lua": "bot:subscribe(<topic>)",
            "javascript": "await bot.subscribe(<topic>)",
            "tcl": "robot::subscribe <topic>",
            "shell": "robot subscribe <topic>",
        },
        notes={
            "shell": "prints each value published on TOPIC from now on, one a line, and"
            " never ends by itself"
        },
    ),
    Call(
        name="receive",
        rpc="receive",
        group=TOGETHER,
        summary="The next value published on a subscribed topic.",
        doc="Waits for the next value published on the topic since subscribing, for at most"
        " timeout seconds; without a timeout it waits for ever.",
        returns="the value, or null (None, undef, nil, '') after the timeout",
        params=(
            Param("topic", "a topic subscribed to", example="speed"),
            Param("timeout", "how long to wait at most", "s", "wait for ever", example=0.5),
        ),
        forms={
            "python": "bot.receive(<topic>, <timeout>)",
            "perl": "$bot->receive(<topic>, <timeout>)",
            "ruby": "bot.receive(<topic>, <timeout>)",
            "lua": "bot:receive(<topic>, <timeout>)",
            "javascript": "await bot.receive(<topic>, <timeout>)",
            "tcl": "robot::receive <topic> ?<timeout>?",
            "shell": "robot receive <topic> [<timeout>]",
        },
        notes={
            "shell": "subscribes first, prints the value; after the timeout prints nothing"
            " and exits with status 1"
        },
    ),
    Call(
        name="memory_set",
        rpc="memory_set",
        group=TOGETHER,
        summary="Keep a value under a key in the memory the robot's programs share.",
        doc="Any JSON value of at most 64 KB; every program on this robot can read it with"
        " memory_get(), during this run and later ones.",
        returns="nothing (null)",
        params=(
            Param("key", "the key (1-64 characters)", example="laps"),
            Param("value", "any JSON value, at most 64 KB", example=3),
        ),
        forms={
            "python": "bot.memory_set(<key>, <value>)",
            "perl": "$bot->memory_set(<key>, <value>)",
            "ruby": "bot.memory_set(<key>, <value>)",
            "lua": "bot:memory_set(<key>, <value>)",
            "javascript": "await bot.memory_set(<key>, <value>)",
            "tcl": "robot::memory_set <key> <value>",
            "shell": "robot memory set <key> <value>",
        },
    ),
    Call(
        name="memory_get",
        rpc="memory_get",
        group=TOGETHER,
        summary="The value kept under a key in the shared memory.",
        doc="What memory_set() kept under the key, by this program or another on the robot.",
        returns="the value, or null when nothing is kept under the key",
        params=(Param("key", "the key", example="laps"),),
        forms={
            "python": "bot.memory_get(<key>)",
            "perl": "$bot->memory_get(<key>)",
            "ruby": "bot.memory_get(<key>)",
            "lua": "bot:memory_get(<key>)",
            "javascript": "await bot.memory_get(<key>)",
            "tcl": "robot::memory_get <key>",
            "shell": "robot memory get <key>",
        },
        notes={"shell": "prints the value; nothing when there is none"},
    ),
    Call(
        name="say",
        rpc="say",
        group=HOST,
        summary="Speak a text aloud, and show it on the robot's page.",
        doc="Spoken by espeak-ng on the robot's computer, one utterance at a time per robot;"
        " the call returns once it has been said. The page shows it as 'said' either way."
        " At most 500 characters.",
        returns="{spoken: true, seconds}, or {spoken: false, reason}",
        params=(Param("text", "what to say (at most 500 characters)", example="hello"),),
        forms={
            "python": "bot.say(<text>)",
            "perl": "$bot->say(<text>)",
            "ruby": "bot.say(<text>)",
            "lua": "bot:say(<text>)",
            "javascript": "await bot.say(<text>)",
            "tcl": "robot::say <text>",
            "shell": "robot say <text>",
        },
        notes={"shell": "says all its words; why it was not spoken goes to standard error"},
    ),
    Call(
        name="snapshot",
        rpc="snapshot",
        group=HOST,
        summary="The robot's camera frame now, as a JPEG.",
        doc="From the robot's camera: the device in its camera setting, else the driver's"
        " front camera, else its own. A robot without one answers an error.",
        returns="{jpeg: the JPEG in base64, width, height} (pixels)",
        params=(
            Param(
                "file",
                "where to write the JPEG",
                default="standard output",
                example="frame.jpg",
                sent=False,
            ),
        ),
        forms={
            "python": "bot.snapshot()",
            "perl": "$bot->snapshot",
            "ruby": "bot.snapshot",
            "lua": "bot:snapshot()",
            "javascript": "await bot.snapshot()",
            "tcl": "robot::snapshot",
            "shell": "robot snapshot [<file>]",
        },
        notes={"shell": "writes the JPEG itself to FILE or standard output"},
    ),
    Call(
        name="scan_barcode",
        rpc="scan_barcode",
        group=HOST,
        summary="The barcodes and QR codes the camera sees now.",
        doc="Read in the camera's current frame (the sim robot's walls carry QR landmarks)."
        " Each code's position is its four corners in pixels, clockwise from the top left.",
        returns="a list of {text, format, position}; empty when none is in view",
        forms={
            "python": "bot.scan_barcode()",
            "perl": "$bot->scan_barcode",
            "ruby": "bot.scan_barcode",
            "lua": "bot:scan_barcode()",
            "javascript": "await bot.scan_barcode()",
            "tcl": "robot::scan_barcode",
            "shell": "robot scan_barcode [--json]",
        },
        notes={"shell": "prints each code's text, one a line; --json: each as a JSON object"},
    ),
    Call(
        name="listen",
        rpc="listen",
        group=HOST,
        summary="Recognise speech from the microphone or a WAV file, offline.",
        doc="Listens for some seconds on the robot's microphone, or reads a WAV file in the"
        " program's folder instead. Given words, it listens for those only, which makes short"
        " commands far more reliable. What someone types into the \"Say to the robot\" box on"
        " the robot's page (or beside the editor) is heard too, whichever comes first; the"
        " simulated robot has no microphone, so on it that box is what listen() hears.",
        returns="{text, words}: with words, the text is one of them, or '' when none was heard;"
        " typed: true when it was typed into the box",
        params=(
            Param("seconds", "how long to listen", "s", "5", example=3),
            Param(
                "wav",
                "a WAV file in the program's folder, heard instead of the microphone",
                default="the microphone",
                example="heard.wav",
            ),
            Param(
                "words",
                "the words or short phrases to listen for",
                default="any speech",
                example=["move", "stop"],
            ),
        ),
        forms={
            "python": "bot.listen(<seconds>, <wav>, <words>)",
            "perl": "$bot->listen(<seconds>, <wav>, <words>)",
            "ruby": "bot.listen(<seconds>, wav: <wav>, words: <words>)",
            "lua": "bot:listen(<seconds>, <wav>, <words>)",
            "javascript": "await bot.listen(<seconds>, <wav>, <words>)",
            "tcl": "robot::listen ?<seconds>? ?<wav>? ?<words>?",
            "shell": "robot listen [<seconds>] [--wav <wav>] [--words <words>]",
        },
        notes={
            "python": "wav and words may be given by name: bot.listen(3, words=['go'])",
            "shell": "WORDS are separated by commas; prints the text, and exits with status 1"
            " when nothing was heard",
        },
    ),
    Call(
        name="close",
        rpc=None,
        group=CONNECTION,
        summary="End the connection to the robot.",
        doc="Programs need not call it: the connection ends with the program. Calls after it fail.",
        returns="nothing",
        forms={
            "python": "bot.close()",
            "perl": "$bot->close",
            "ruby": "bot.close",
            "lua": "bot:close()",
            "javascript": "await bot.close()",
            "tcl": "robot::close",
        },
        absent={"shell": "each robot command connects and closes by itself"},
    ),
)


def call_named(name: str) -> Call:
    return next(call for call in CALLS if call.name == name)


def by_language(language: str) -> dict:
    """The description as one language's help: what api_help.js and the help page read.
    KeyError for a language no client is described for."""
    client = CLIENTS[language]
    calls = []
    for call in CALLS:
        form = call.forms.get(language)
        if form is None:
            continue
        calls.append(
            {
                "name": call.name,
                "word": _word(client, call, form),
                "group": call.group,
                "signature": client.display(form),
                "insert": _insert(client, call, form),
                "summary": call.summary,
                "doc": call.doc,
                "note": call.notes.get(language, ""),
                "returns": call.returns,
                "params": [
                    {
                        "name": client.display(f"<{p.name}>"),
                        "unit": p.unit,
                        "meaning": p.meaning,
                        "default": p.default,
                    }
                    for p in call.params
                    if f"<{p.name}>" in form
                ],
                "example": client.example(call),
            }
        )
    return {
        "language": language,
        "label": client.label,
        "setup": client.setup,
        "object": client.obj,
        "accessor": client.accessor,
        "objects": client.objects,
        "connects": client.connects,
        "values": client.values,
        "errors": client.errors,
        "calls": calls,
    }


def _word(client: Client, call: Call, form: str) -> str:
    """What a program writes after the object and accessor to name the call: drive, or the
    shell's `memory get`; for connect, the word its `connects` pattern finds."""
    prefix = client.obj + client.accessor
    at = form.find(prefix)
    if call.rpc == "auth" or at < 0:
        found = re.search(client.connects, form)
        return found.group(1) if found else call.name
    rest = form[at + len(prefix) :]
    return re.match(r"[\w ]*?(?=\s*[(<\[?]|$)", rest).group(0).strip()


def _insert(client: Client, call: Call, form: str) -> str:
    """What completion writes after the object and accessor; `|` marks where the cursor
    goes (inside the parentheses when the call takes parameters)."""
    word = _word(client, call, form)
    if call.rpc == "auth":
        return client.display(form) + "|"
    after = form[form.find(word) + len(word) :]
    takes = PLACEHOLDER.search(after) is not None
    if after.startswith("("):
        return f"{word}(|)" if takes else f"{word}()|"
    return f"{word} |" if takes else f"{word}|"
