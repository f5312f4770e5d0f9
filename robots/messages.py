"""What the robot agent accepts from the channel layer, checked at the door.

In fleet mode the agent's channel lives in Redis, which anything that reaches Redis can write
to; so every message is checked before the agent acts on it (``RobotAgent.dispatch``): its
``type`` must be one the agent knows, it may carry only the fields that type has, each of the
right type and size. ``check(message)`` returns None for a good message and the reason for a
bad one. A bad message is refused as a whole, never acted on in part.

The fields here are what the web tier sends (robots.bus, robots.runs, robots.consumers,
robots.api, robots.views, robots.gateway_api, robots.bridges_api, robots.run_queue, the camera
consumer); a new field there needs its line here.
"""

import logging
import math
import re
import time
from collections.abc import Callable

from programs import debug_spec

log = logging.getLogger(__name__)

MAX_NAME = 256  # a user name, a language
MAX_CHANNEL = 99  # Channels' own limit on a channel's name (less than 100)
MAX_FILENAME = 128  # Program.filename: a slug of at most 100 characters and an extension
MAX_SOURCE = 4 * 1024 * 1024  # characters; programs are limited to 512 KB where they are saved
MAX_ARGS = 1024
MAX_ARG = 128 * 1024  # characters: Linux's own limit on one argument (MAX_ARG_STRLEN)
MAX_ARGS_TOTAL = 1024 * 1024  # characters, all arguments together
MAX_SAY = 1000  # characters of a phrase typed for listen() (robots.typed_speech says less)

# What Program.filename can be: slugify(name) (ASCII letters, digits, "_" and "-", starting with
# a letter or digit) and the language's extension (".py", ".sh", ...).
_FILENAME = re.compile(r"[A-Za-z0-9][A-Za-z0-9_.-]*")
# A channel name as Channels' layers accept it (BaseChannelLayer.channel_name_regex, ASCII only):
# anything else would make the layer raise when the agent answers or writes to it.
_CHANNEL = re.compile(r"[a-zA-Z0-9_.-]+(![a-zA-Z0-9_.-]*)?", re.ASCII)


def check_filename(name) -> str | None:
    """None if ``name`` is a plain file name a run's program may be written to: no folder
    ("/"), no "..", no NUL, not hidden, not an option ("-..."), at most MAX_FILENAME
    characters; else why not."""
    if not isinstance(name, str):
        return "filename must be a text"
    if not 0 < len(name) <= MAX_FILENAME:
        return f"filename must be 1 to {MAX_FILENAME} characters"
    if ".." in name or not _FILENAME.fullmatch(name):
        return (
            f"filename {name[:40]!r} is not a plain file name (letters, digits, '_', '-' and"
            " '.', starting with a letter or digit, no '..')"
        )
    return None


# -- field checkers: value -> None if good, else why not ------------------------------------


def _text(limit: int = MAX_NAME) -> Callable:
    def check(value):
        if not isinstance(value, str):
            return "must be a text"
        if len(value) > limit:
            return f"must be at most {limit} characters"
        return None

    return check


def _name(value):
    if not isinstance(value, str) or not 0 < len(value) <= MAX_NAME:
        return f"must be a text of 1 to {MAX_NAME} characters"
    return None


def _channel(value):
    if not isinstance(value, str) or len(value) > MAX_CHANNEL or not _CHANNEL.fullmatch(value):
        return f"must be a channel name (letters, digits, '-', '_', '.', at most {MAX_CHANNEL})"
    return None


def _run_id(value):
    if type(value) is not int or not 0 < value < 2**63:
        return "must be a positive whole number"
    return None


def _speed(value):
    if type(value) not in (int, float) or not math.isfinite(value):
        return "must be a finite number"
    return None


def _bool(value):
    return None if type(value) is bool else "must be true or false"


def _pose(value):
    if not isinstance(value, list | tuple) or len(value) != 3 or any(_speed(v) for v in value):
        return "must be [x, y, theta], three finite numbers"
    return None


def _args(value):
    if not isinstance(value, list | tuple) or len(value) > MAX_ARGS:
        return f"must be a list of at most {MAX_ARGS} texts"
    total = 0
    for arg in value:
        if not isinstance(arg, str) or len(arg) > MAX_ARG:
            return f"must be a list of texts of at most {MAX_ARG} characters"
        total += len(arg)
    if total > MAX_ARGS_TOTAL:
        return f"must be at most {MAX_ARGS_TOTAL} characters in all"
    return None


def _filename(value):
    why = check_filename(value)
    return None if why is None else why.removeprefix("filename ")


REQUIRED, OPTIONAL = True, False
_REPLY = {"reply_to": (_channel, OPTIONAL)}  # ask_agent's reply channel: any message may have one

# type -> {field: (checker, required)}; "type" itself is checked by the lookup.
SCHEMAS: dict[str, dict[str, tuple[Callable, bool]]] = {
    "run.start": {
        "run_id": (_run_id, REQUIRED),
        "language": (_name, REQUIRED),
        "source": (_text(MAX_SOURCE), REQUIRED),
        "filename": (_filename, REQUIRED),
        "args": (_args, OPTIONAL),
        "user": (_text(), OPTIONAL),
        "debug": (debug_spec.check_spec, OPTIONAL),  # a run under the debugger
    },
    "run.stop": {"run_id": (_run_id, REQUIRED)},
    # robots.debugger: a debugger command from the run's page (programs.debug_spec)
    "run.debug": {
        "run_id": (_run_id, REQUIRED),
        "command": (debug_spec.check_command, REQUIRED),
        "breakpoints": (debug_spec.check_breakpoints, OPTIONAL),
        "watches": (debug_spec.check_watches, OPTIONAL),
    },
    "robot.estop": {"by": (_text(), OPTIONAL), "record": (_run_id, OPTIONAL)},
    "robot.resume": {"after": (_run_id, OPTIONAL)},
    "robot.sensors": {},
    "robot.state": {},
    "robot.teleop": {
        "owner": (_channel, REQUIRED),
        "user": (_text(), OPTIONAL),
        "linear": (_speed, REQUIRED),
        "angular": (_speed, REQUIRED),
    },
    "robot.teleop_stop": {"owner": (_channel, REQUIRED)},
    "robot.release": {"owner": (_channel, REQUIRED)},
    "robot.take_control": {"owner": (_channel, REQUIRED), "user": (_text(), REQUIRED)},
    "robot.reconfigure": {},
    # robots.start_pose (StartPose.handlers): a sim put back at its start, or at a pose
    "robot.reset": {
        "pose": (_pose, OPTIONAL),
        "by": (_text(), OPTIONAL),
        "override": (_bool, OPTIONAL),
    },
    # robots.sim_view (PoseStream.handlers): a sim's world, for pages that draw it
    "robot.world": {},
    "pose.watch": {"viewer": (_channel, REQUIRED)},
    "pose.unwatch": {"viewer": (_channel, REQUIRED)},
    # robots.host_services (HostServices.handlers): a phrase typed for listen()
    "robot.hear": {
        "text": (_text(MAX_SAY), REQUIRED),
        "user": (_text(), OPTIONAL),
        "queue": (_bool, OPTIONAL),
    },
    # robots.camera (CameraHub.handlers)
    "camera.watch": {"viewer": (_channel, REQUIRED)},
    "camera.unwatch": {"viewer": (_channel, REQUIRED)},
    "camera.info": {},
    "camera.snapshot": {},
    # robots.gateway (Gateway.handlers)
    "gateway.stats": {},
    "gateway.reload": {},
    "gateway.record": {"on": (_bool, REQUIRED)},
    # robots.bridges (Bridges.handlers)
    "bridges.stats": {},
    "bridges.reload": {},
    # robots.run_queue (RunQueue.handlers: CHANGED, RESUME)
    "run.queue_changed": {},
    "run.queue_resume": {},
}
for _fields in SCHEMAS.values():
    _fields.update(_REPLY)


def check(message) -> str | None:
    """None if the agent may act on ``message``; else the reason it is refused."""
    if not isinstance(message, dict):
        return "a message must be an object"
    kind = message.get("type")
    fields = SCHEMAS.get(kind) if isinstance(kind, str) else None
    if fields is None:
        return f"unknown message type {str(kind)[:60]!r}"
    for name, value in message.items():
        if name == "type":
            continue
        spec = fields.get(name)
        if spec is None:
            return f"{kind}: unknown field {str(name)[:60]!r}"
        why = spec[0](value)
        if why is not None:
            return f"{kind}: {name} {why}"
    for name, (_, required) in fields.items():
        if required and name not in message:
            return f"{kind}: {name} is missing"
    return None


def reply_channel(message) -> str | None:
    """Where a refusal may be told: the message's reply_to, if it is a proper channel name."""
    if isinstance(message, dict):
        reply_to = message.get("reply_to")
        if _channel(reply_to) is None:
            return reply_to
    return None


class _RateLimit:
    """At most ``burst`` log lines per ``period`` seconds; the rest are counted and said in
    the next line that goes out, so a flood of bad messages cannot flood the log."""

    def __init__(self, burst: int = 10, period: float = 60.0):
        self.burst, self.period = burst, period
        self.window_start, self.sent, self.suppressed = 0.0, 0, 0

    def allow(self) -> tuple[bool, int]:
        """(whether to log now, how many were suppressed before this one)."""
        now = time.monotonic()
        if now - self.window_start >= self.period:
            self.window_start, self.sent = now, 0
        if self.sent >= self.burst:
            self.suppressed += 1
            return False, 0
        self.sent += 1
        suppressed, self.suppressed = self.suppressed, 0
        return True, suppressed


_refusals = _RateLimit()


def log_refused(agent_name: str, why: str) -> None:
    """One log line for a refused message (rate-limited)."""
    allowed, suppressed = _refusals.allow()
    if allowed:
        more = f" ({suppressed} more refused, not logged)" if suppressed else ""
        log.warning("agent %s: message refused: %s%s", agent_name, why, more)
