"""The Robot API's help (programs/robot_api_spec.py: its calls' summaries, docs, parameters
and notes) in the reader's language, for the help page and the editor's completion and hover
help (programs/api_help.py).

The description stays one plain module, which its tests read with the clients and the server;
its texts are msgids here, translated where shown. tests/test_i18n_complete.py fails when a text
of the description is missing here (written or changed there, not here).
"""

from dataclasses import replace

from django.utils.translation import gettext, gettext_noop

TEXTS = (
    gettext_noop("objects are dicts, arrays lists, null None"),
    gettext_noop("raises robot.RobotError (its .code is the JSON-RPC code)"),
    gettext_noop("objects are hash references, arrays array references, null undef"),
    gettext_noop("dies with a Robot::Error ($@->message, $@->code)"),
    gettext_noop("objects are Hashes with string keys, arrays Arrays, null nil"),
    gettext_noop("raises Robot::Error (#message, #code)"),
    gettext_noop("objects and arrays are tables, null nil (Robot.null inside a table)"),
    gettext_noop("error() with the message and code (catch it with pcall; bot.last_error)"),
    gettext_noop("every call returns a Promise (await it); objects, arrays and null as JSON"),
    gettext_noop("the Promise rejects with a RobotError (.message, .code)"),
    gettext_noop(
        "objects are dicts, arrays lists, null the empty string; pass [huddle ...] for "
        "true, false, null, lists and objects"
    ),
    gettext_noop("a Tcl error with -errorcode {ROBOT code}"),
    gettext_noop(
        "numbers and texts are printed plain, anything else as JSON; a VALUE is read "
        "as JSON, else as text"
    ),
    gettext_noop("the message on standard error, exit status 1"),
    gettext_noop("Connecting"),
    gettext_noop("Connect to the robot the program runs on."),
    gettext_noop(
        "Connects to the Robot API at $ROBOT_API with the run's $ROBOT_TOKEN, which "
        "robotide sets for every run, so a program needs no address. The token is "
        "worth nothing once the run has ended. JavaScript connects on the first call, "
        "and so does Tcl's first command; robot::connect does it at once."
    ),
    gettext_noop("the robot object the other calls are made on"),
    gettext_noop("each robot command connects by itself"),
    gettext_noop("Driving"),
    gettext_noop("Drive at a forward speed and a turn rate until told otherwise."),
    gettext_noop(
        "Sets the speeds the robot keeps until the next drive() or stop(). Both are "
        "clamped to the robot's limits (capabilities() says them); the result says "
        "what was applied. Refused while someone else controls the robot, and after "
        "Stop was pressed."
    ),
    gettext_noop("the speeds applied: {linear, angular}"),
    gettext_noop("forward speed; negative backs up"),
    gettext_noop("turn rate, counter-clockwise"),
    gettext_noop("prints nothing"),
    gettext_noop("Stop the motors."),
    gettext_noop(
        "Sends the robot's own stop command. The robot is stopped too when the program "
        "ends, however it ends."
    ),
    gettext_noop("nothing (null)"),
    gettext_noop("Sensing"),
    gettext_noop("All the robot's readings at once."),
    gettext_noop(
        "Readings every robot names alike: heading (deg, clockwise from north), range "
        "(m to the nearest obstacle ahead, null when nothing is in reach), position "
        "{x, y, theta} (m, m, rad), velocity {linear, angular} (m/s, rad/s), battery; "
        "a robot adds its own (bumpers, sonar...) and leaves out what it cannot "
        "measure."
    ),
    gettext_noop("an object: sensor name -> reading"),
    gettext_noop("prints the readings as JSON"),
    gettext_noop("One reading, by its name."),
    gettext_noop(
        "The reading sensors() has under that name. A name the robot lacks is an error "
        "that lists the sensors it has."
    ),
    gettext_noop("the reading, in the unit capabilities() gives for it"),
    gettext_noop("the sensor: heading, range, position, ..."),
    gettext_noop("prints a number or a text plain, anything else as JSON"),
    gettext_noop("What the robot is and can do."),
    gettext_noop(
        "The robot's kind, its drive limits {max_linear (m/s), max_angular (rad/s)}, "
        "each sensor sensors() returns with its unit, and its camera if it has one."
    ),
    gettext_noop("an object: kind, drive, sensors, camera"),
    gettext_noop("prints it as JSON"),
    gettext_noop("The robot's page"),
    gettext_noop("Show a value live on the robot's page, by name."),
    gettext_noop(
        "A number, a text, or an SVG drawing (a text starting with <svg). Showing a "
        "name again replaces its value; values stay on the page after the program "
        "ends, until the room is needed. A name has 1 to 64 characters, a value at "
        "most 256 KB."
    ),
    gettext_noop("what the page calls it (1-64 characters)"),
    gettext_noop("a number, a text or an SVG text"),
    gettext_noop("Programs together"),
    gettext_noop("Send a value to the programs subscribed to a topic."),
    gettext_noop(
        "Any JSON value of at most 64 KB, queued for every connection subscribed to "
        "the topic on this robot. A subscriber that does not keep up loses its oldest "
        "values, never the publisher's call."
    ),
    gettext_noop("how many subscribers it was queued for"),
    gettext_noop("the topic's name (1-64 characters)"),
    gettext_noop("any JSON value, at most 64 KB"),
    gettext_noop("prints how many it reached"),
    gettext_noop("Get the values published on a topic from now on."),
    gettext_noop(
        "This connection gets every value published on the topic from now on, to "
        "receive() one at a time. At most 64 topics per connection."
    ),
    gettext_noop("the topic's name"),
    gettext_noop(
        "prints each value published on TOPIC from now on, one a line, and never ends by itself"
    ),
    gettext_noop("The next value published on a subscribed topic."),
    gettext_noop(
        "Waits for the next value published on the topic since subscribing, for at "
        "most timeout seconds; without a timeout it waits for ever."
    ),
    gettext_noop("the value, or null (None, undef, nil, '') after the timeout"),
    gettext_noop("a topic subscribed to"),
    gettext_noop("how long to wait at most"),
    gettext_noop("wait for ever"),
    gettext_noop(
        "subscribes first, prints the value; after the timeout prints nothing and "
        "exits with status 1"
    ),
    gettext_noop("Keep a value under a key in the memory the robot's programs share."),
    gettext_noop(
        "Any JSON value of at most 64 KB; every program on this robot can read it with "
        "memory_get(), during this run and later ones."
    ),
    gettext_noop("the key (1-64 characters)"),
    gettext_noop("The value kept under a key in the shared memory."),
    gettext_noop("What memory_set() kept under the key, by this program or another on the robot."),
    gettext_noop("the value, or null when nothing is kept under the key"),
    gettext_noop("the key"),
    gettext_noop("prints the value; nothing when there is none"),
    gettext_noop("The robot's computer"),
    gettext_noop("Speak a text aloud, and show it on the robot's page."),
    gettext_noop(
        "Spoken by espeak-ng on the robot's computer, one utterance at a time per "
        "robot; the call returns once it has been said. The page shows it as 'said' "
        "either way. At most 500 characters."
    ),
    gettext_noop("{spoken: true, seconds}, or {spoken: false, reason}"),
    gettext_noop("what to say (at most 500 characters)"),
    gettext_noop("says all its words; why it was not spoken goes to standard error"),
    gettext_noop("The robot's camera frame now, as a JPEG."),
    gettext_noop(
        "From the robot's camera: the device in its camera setting, else the driver's "
        "front camera, else its own. A robot without one answers an error."
    ),
    gettext_noop("{jpeg: the JPEG in base64, width, height} (pixels)"),
    gettext_noop("where to write the JPEG"),
    gettext_noop("standard output"),
    gettext_noop("writes the JPEG itself to FILE or standard output"),
    gettext_noop("The barcodes and QR codes the camera sees now."),
    gettext_noop(
        "Read in the camera's current frame (the sim robot's walls carry QR "
        "landmarks). Each code's position is its four corners in pixels, clockwise "
        "from the top left."
    ),
    gettext_noop("a list of {text, format, position}; empty when none is in view"),
    gettext_noop("prints each code's text, one a line; --json: each as a JSON object"),
    gettext_noop("Recognise speech from the microphone or a WAV file, offline."),
    gettext_noop(
        "Listens for some seconds on the robot's microphone, or reads a WAV file in "
        "the program's folder instead. Given words, it listens for those only, which "
        'makes short commands far more reliable. What someone types into the "Say to '
        "the robot\" box on the robot's page (or beside the editor) is heard too, "
        "whichever comes first; the simulated robot has no microphone, so on it that "
        "box is what listen() hears."
    ),
    gettext_noop(
        "{text, words}: with words, the text is one of them, or '' when none was "
        "heard; typed: true when it was typed into the box"
    ),
    gettext_noop("how long to listen"),
    gettext_noop("a WAV file in the program's folder, heard instead of the microphone"),
    gettext_noop("the microphone"),
    gettext_noop("the words or short phrases to listen for"),
    gettext_noop("any speech"),
    gettext_noop("wav and words may be given by name: bot.listen(3, words=['go'])"),
    gettext_noop(
        "WORDS are separated by commas; prints the text, and exits with status 1 when "
        "nothing was heard"
    ),
    gettext_noop("End the connection to the robot."),
    gettext_noop(
        "Programs need not call it: the connection ends with the program. Calls after it fail."
    ),
    gettext_noop("nothing"),
    gettext_noop("each robot command connects and closes by itself"),
)


def words(text: str | None) -> str | None:
    """A text of the description in the active language (units and numbers as they are)."""
    return gettext(text) if text else text


def call_shown(call):
    """A Call (robot_api_spec) with its words in the active language."""
    params = tuple(
        replace(p, meaning=words(p.meaning), default=words(p.default)) for p in call.params
    )
    return replace(
        call,
        group=words(call.group),
        summary=words(call.summary),
        doc=words(call.doc),
        returns=words(call.returns),
        params=params,
        notes={language: words(note) for language, note in call.notes.items()},
        absent={language: words(why) for language, why in call.absent.items()},
    )


def client_shown(client):
    """A Client (robot_api_spec) with its words in the active language."""
    return replace(client, values=words(client.values), errors=words(client.errors))


def help_shown(help_: dict) -> dict:
    """robot_api_spec.by_language's help with its words in the active language."""
    for call in help_["calls"]:
        for key in ("group", "summary", "doc", "note", "returns"):
            call[key] = words(call[key])
        for param in call["params"]:
            param["meaning"], param["default"] = words(param["meaning"]), words(param["default"])
    help_["values"], help_["errors"] = words(help_["values"]), words(help_["errors"])
    return help_
