"""Run a Python program under the debugger of the workbench (standard library only: bdb).

    python3 -u -m robot_debug PROGRAM ARGS...

PROGRAM runs as `python3 PROGRAM ARGS...` would run it (__main__, sys.argv, sys.path[0],
__file__), while the debugger talks to the robot's agent over the Robot API on connections of
its own (programs/clients/PROTOCOL.md, "The debugger"): `debug_start` says the breakpoints and
watches; at a pause `debug_paused(state)` waits for the page's command; a daemon thread calls
`debug_poll` for breakpoints and watches changed while the program runs, and pause requests.

What this debugger does where the protocol leaves a choice:
- Only the main thread is debugged; the program's own threads run on, paused or not.
- A line with no code never pauses. A breakpoint whose condition fails pauses (reason
  "breakpoint") with the error in the state's "exception". A condition is evaluated at each
  pass without a time limit (it is the user's own expression); watches and reprs get 0.5 s
  each, 3 s in all per pause ("takes too long" after that).
- Reason "entry" is never said (the program starts running; a pause asked before its first
  line says "pause").
- An uncaught exception pauses once (reason "exception", at the innermost line of the
  program where it went through) before Python's traceback is printed; then exit status 1.
- `stop` ends the program at once (no `finally`, no atexit), exit status 0.
- A pause request reaches a program blocked in a call (a sleep, a robot call) when the call
  returns. `pause` while paused is `update`; an unknown command is `continue`.
- The debugger writes nothing on stdout; it says on stderr only why it could not go on.

Cost: the trace function is set on the main thread only; calls into other files return at
once, and lines are traced only in code objects holding a breakpoint (or while stepping).
"""

import bdb
import builtins
import io
import itertools
import json
import os
import reprlib
import signal
import sys
import threading
import time
import traceback
import types

import robot

STATE_BYTES = 240 * 1024  # the protocol's cap is 256 KB of JSON: room for the request
REPR_CHARS = 200
MAX_CHILDREN = 100
LEVELS = 3  # a variable, its children, theirs
REPR_SECONDS = 0.5  # one value's repr (a program's __repr__ may hang)
VALUES_SECONDS = 3.0  # all the reprs of one pause
POLL_SECONDS = 5.0  # debug_poll's wait when no line reports are asked for
STOP_STATUS = 0
USAGE_STATUS = 2

_encode = json.JSONEncoder(separators=(",", ":")).encode
_HIDDEN = (types.ModuleType, types.FunctionType, types.BuiltinFunctionType, type, types.MethodType)
_CONTAINERS = (list, tuple, dict, set, frozenset)
_PLAIN = (float, complex, bool, type(None), range, type(...))  # their repr is short and safe


class _Slow(BaseException):
    """A repr or an expression ran past its time (raised by the alarm)."""


class _Clock:
    """Bounds the time of a program's code run for a pause (reprs, watches, conditions):
    SIGALRM in the main thread, the program's own alarm put back after."""

    def __init__(self, total):
        self.left = total

    def run(self, function, *args):
        if self.left <= 0:
            raise _Slow
        if threading.current_thread() is not threading.main_thread():
            return function(*args)
        seconds = min(REPR_SECONDS, self.left)
        handler = signal.signal(signal.SIGALRM, _alarm)
        delay, interval = signal.setitimer(signal.ITIMER_REAL, seconds)
        try:
            return function(*args)
        finally:
            rest, _ = signal.setitimer(signal.ITIMER_REAL, 0)
            signal.signal(signal.SIGALRM, handler)
            self.left -= seconds - rest
            if delay:  # the program's alarm, less the time spent here
                signal.setitimer(signal.ITIMER_REAL, max(delay - (seconds - rest), 0.001), interval)


def _alarm(signum, frame):
    raise _Slow


class _ShortRepr(reprlib.Repr):
    """reprlib that never walks a whole container (a dict is not sorted) and caps a text."""

    def __init__(self, clock):
        super().__init__()
        self.clock = clock
        self.maxlevel = 3
        self.maxstring = self.maxother = self.maxlong = REPR_CHARS
        self.maxlist = self.maxtuple = self.maxset = self.maxfrozenset = 30
        self.maxdeque = self.maxarray = 30
        self.maxdict = 20

    def repr1(self, x, level):
        kind = type(x)
        if kind in _PLAIN:
            return builtins.repr(x)
        for base in _CONTAINERS:  # a subclass that keeps its base's repr
            if kind is not base and issubclass(kind, base) and kind.__repr__ is base.__repr__:
                return kind.__name__ + "(" + getattr(self, "repr_" + base.__name__)(x, level) + ")"
        return super().repr1(x, level)

    def repr_dict(self, x, level):
        if not x:
            return "{}"
        if level <= 0:
            return "{...}"
        items = [
            self.repr1(key, level - 1) + ": " + self.repr1(value, level - 1)
            for key, value in itertools.islice(dict.items(x), self.maxdict)
        ]
        return "{" + ", ".join(items) + (", ..." if len(x) > self.maxdict else "") + "}"

    def _repr_iterable(self, x, level, left, right, maxiter, trail=""):
        if issubclass(type(x), (set, frozenset)):
            x = list(itertools.islice(x, maxiter + 1))  # not sorted, as reprlib would
        return super()._repr_iterable(x, level, left, right, maxiter, trail)

    def repr_bytes(self, x, level):
        return builtins.repr(x[:REPR_CHARS]) + ("..." if len(x) > REPR_CHARS else "")

    def repr_int(self, x, level):
        if x.bit_length() > 600:
            return f"<int of {x.bit_length()} bits>"
        return super().repr_int(x, level)

    def repr_instance(self, x, level):
        try:
            text = self.clock.run(builtins.repr, x)
        except _Slow:
            return f"<{type(x).__name__} object: its repr takes too long>"
        except Exception as error:
            return f"<{type(x).__name__} object: repr failed: {_said(error)}>"
        if not isinstance(text, str):
            return f"<{type(x).__name__} object>"
        return text if len(text) <= REPR_CHARS else text[: REPR_CHARS - 3] + "..."


def _said(error, limit=500):
    """'ZeroDivisionError: division by zero', as Python's traceback ends."""
    try:
        text = traceback.format_exception_only(type(error), error)[-1].strip()
    except Exception:
        text = type(error).__name__
    return text if len(text) <= limit else text[: limit - 3] + "..."


class _Values:
    """The variables of a pause, within STATE_BYTES: top-level names first, then their
    children level by level while room remains (`more` counts what did not fit)."""

    def __init__(self, budget):
        self.budget = budget
        self.clock = _Clock(VALUES_SECONDS)
        self.reprs = _ShortRepr(self.clock)
        self.unfolded = []  # (node, value, level) waiting for their children

    def variable(self, name, value, level=1):
        node = {"name": name, "type": _type_name(value), "value": self.text(value)}
        node["children"], node["more"] = None, 0
        self.budget -= len(_encode(node)) + 1
        if level < LEVELS and _has_children(value):
            self.unfolded.append((node, value, level))
        return node

    def text(self, value):
        try:
            text = self.reprs.repr(value)
        except _Slow:
            text = "<its repr takes too long>"
        except Exception as error:
            text = f"<repr failed: {_said(error)}>"
        return text if len(text) <= REPR_CHARS else text[: REPR_CHARS - 3] + "..."

    def listing(self, names_values):
        """Top-level variables while they fit; a last '...' entry counts the rest."""
        nodes, pairs = [], list(names_values)
        for index, (name, value) in enumerate(pairs):
            if self.budget < 1024:
                rest = len(pairs) - index
                nodes.append({"name": "...", "type": "", "value": f"{rest} more not shown",
                              "children": None, "more": rest})  # fmt: skip
                break
            nodes.append(self.variable(name, value))
        return nodes

    def unfold(self):
        """Children breadth first, so that every variable gets its first level."""
        while self.unfolded:
            node, value, level = self.unfolded.pop(0)
            try:
                total, items = _children(value)
            except Exception:
                continue
            children = []
            for name, child in items:
                if self.budget < 512:
                    break
                try:
                    children.append(self.variable(name, child, level + 1))
                except _Slow:
                    break
            self.budget -= 2
            node["children"], node["more"] = children, max(total - len(children), 0)


def _type_name(value):
    try:
        return str(type(value).__name__)
    except Exception:
        return "?"


def _has_children(value):
    kind = type(value)
    if issubclass(kind, _CONTAINERS):
        return True
    if issubclass(kind, _HIDDEN):
        return False
    try:
        return isinstance(object.__getattribute__(value, "__dict__"), dict)
    except Exception:
        return False


def _children(value):
    """(how many, an iterator of (name, value)) of a container or an object's attributes."""
    kind = type(value)
    if issubclass(kind, dict):
        items = itertools.islice(dict.items(value), MAX_CHILDREN)
        return len(value), ((f"[{_key_name(key)}]", item) for key, item in items)
    if issubclass(kind, (list, tuple)):
        items = itertools.islice(list.__iter__(value) if issubclass(kind, list) else
                                 tuple.__iter__(value), MAX_CHILDREN)  # fmt: skip
        return len(value), ((f"[{i}]", v) for i, v in enumerate(items))
    if issubclass(kind, (set, frozenset)):
        items = itertools.islice(value, MAX_CHILDREN)
        return len(value), ((f"[{i}]", v) for i, v in enumerate(items))
    attributes = object.__getattribute__(value, "__dict__")
    items = list(itertools.islice(dict.items(attributes), MAX_CHILDREN))
    return len(attributes), ((f".{name}", item) for name, item in items)


def _key_name(key):
    if type(key) in (str, int, float, bool, type(None)):
        text = repr(key) if type(key) is not int or key.bit_length() < 200 else "<int>"
    else:
        text = f"<{_type_name(key)}>"
    return text if len(text) <= 60 else text[:57] + "..."


class _Point:
    """A breakpoint: its line and its condition, compiled once."""

    def __init__(self, line, condition):
        self.line = line
        self.condition = condition or None
        self.code, self.error = None, None
        if self.condition:
            try:
                self.code = compile(self.condition, "<condition>", "eval")
            except SyntaxError as error:
                self.error = _said(error)

    def test(self, frame):
        """(pause?, the error in the condition or None)."""
        if self.condition is None:
            return True, None
        if self.error:
            return True, self.said(self.error)
        # Not under the alarm (_Clock): it would cost more than the condition, at each pass.
        try:
            return bool(eval(self.code, frame.f_globals, frame.f_locals)), None
        except Exception as error:
            return True, self.said(_said(error))

    def said(self, error):
        return f"{error} (in the condition `{self.condition}` of line {self.line})"


def _code_lines(code):
    """{id(code object): (code object, the lines it holds itself)} for a module's code."""
    found, waiting = {}, [code]
    while waiting:
        code = waiting.pop(0)
        found[id(code)] = (code, {line for _, _, line in code.co_lines() if line is not None})
        waiting.extend(const for const in code.co_consts if isinstance(const, types.CodeType))
    return found


class Debugger(bdb.Bdb):
    """bdb, told to trace lines only in the program's own code objects that hold a breakpoint
    (or while stepping, or when a pause is asked), and to say its pauses over the Robot API."""

    def __init__(self, filename, code, channel):
        super().__init__()
        self.program = filename  # the program's code's co_filename
        self.codes = _code_lines(code)
        self.channel = channel  # the main thread's connection
        self.main = threading.main_thread().ident
        self.lock = threading.Lock()
        self.points, self.traced = {}, frozenset()  # {line: (_Point, id(code))}, ids
        self.watches = []
        self.pause_requested = False
        self.running = threading.Event()
        self.running.set()
        self.reset()

    # -- what the agent says ------------------------------------------------------------

    def apply(self, reply):
        """New breakpoints and watches (from debug_paused or debug_poll: any thread)."""
        if not isinstance(reply, dict):
            return
        with self.lock:
            if isinstance(reply.get("watches"), list):
                self.watches = [w for w in reply["watches"] if isinstance(w, str)]
            if isinstance(reply.get("breakpoints"), list):
                self.set_points(reply["breakpoints"])
        if reply.get("pause"):
            self.request_pause()

    def set_points(self, breakpoints):
        points = {}
        for point in breakpoints:
            if isinstance(point, dict) and type(point.get("line")) is int:
                points[point["line"]] = _Point(point["line"], point.get("condition"))
        # A line holds a breakpoint in the outermost code object holding it (not also in a
        # comprehension or lambda written on it).
        owners = {}
        for key, (_, lines) in self.codes.items():
            for line in lines & points.keys():
                owners.setdefault(line, key)
        self.points = {line: (points[line], key) for line, key in owners.items()}
        self.traced = frozenset(owners.values())
        self.trace_main_frames(lambda frame: id(frame.f_code) in self.traced)

    def request_pause(self):
        self.pause_requested = True
        self.trace_main_frames(lambda frame: True)

    def trace_main_frames(self, which):
        """Line tracing on in the main thread's running program frames `which` picks (a
        frame entered before its code held a breakpoint is not traced otherwise)."""
        frame = sys._current_frames().get(self.main)
        while frame is not None:
            if frame.f_code.co_filename == self.program and frame.f_trace is None and which(frame):
                frame.f_trace = self.trace_dispatch
            frame = frame.f_back

    def current_line(self):
        """The innermost line of the program the main thread is at, or None."""
        frame = sys._current_frames().get(self.main)
        while frame is not None:
            if frame.f_code.co_filename == self.program:
                return frame.f_lineno
            frame = frame.f_back
        return None

    # -- tracing ---------------------------------------------------------------------

    def global_trace(self):
        """The function for sys.settrace: a call into another file costs one comparison."""
        program, dispatch_call = self.program, self.dispatch_call

        def trace(frame, event, arg):
            if frame.f_code.co_filename == program:
                return dispatch_call(frame, arg)
            return None

        return trace

    def trace_dispatch(self, frame, event, arg):
        if event == "line":
            return self.dispatch_line(frame)
        if event == "return":
            return self.dispatch_return(frame, arg)
        return self.trace_dispatch

    def dispatch_call(self, frame, arg):
        if self.quitting:
            return None
        if self.stopframe is None or self.pause_requested or id(frame.f_code) in self.traced:
            return self.trace_dispatch
        return None

    def dispatch_line(self, frame):
        reason, error = None, None
        if self.pause_requested:
            reason = "pause"
        elif self.stop_here(frame):
            reason = "step"
        else:
            point, owner = self.points.get(frame.f_lineno, (None, None))
            if owner == id(frame.f_code):
                hit, error = point.test(frame)
                reason = "breakpoint" if hit else None
        if reason is not None:
            self.interact(frame, reason, error)
        elif self.stoplineno == -1 and id(frame.f_code) not in self.traced:
            frame.f_trace = None  # continuing, no breakpoint here: no more line events
            # ...unless debug_poll's thread asked for them meanwhile (it sets `traced` or
            # `pause_requested` before it looks at the frames' f_trace).
            if id(frame.f_code) not in self.traced and not self.pause_requested:
                return None
            frame.f_trace = self.trace_dispatch
        return self.trace_dispatch

    def dispatch_return(self, frame, arg):
        # Stepping out of the frame being stepped (or stepped out of): stop at the next line
        # of the program, wherever (its caller may be the client library's or a C call).
        if (frame is self.stopframe and self.stoplineno != -1) or frame is self.returnframe:
            self._set_stopinfo(None, None)
        return self.trace_dispatch

    def set_return(self, frame):
        # bdb's would not stop after a generator's frame: this stops where it yields.
        self._set_stopinfo(frame.f_back, frame)

    def set_continue(self):
        # bdb's would drop the trace function when it has no breakpoints of its own: this
        # one's come later, from debug_poll.
        self._set_stopinfo(self.botframe, None, -1)

    # -- a pause -----------------------------------------------------------------------

    def interact(self, frame, reason, error=None):
        """Say the pause, obey the commands, until one lets the program go on."""
        self.running.clear()
        self.pause_requested = False
        self.trace_callers(frame)
        try:
            while True:
                try:
                    reply = self.say_paused(self.state(frame, reason, error))
                except _Lost as lost:
                    lost.end()
                self.apply(reply)
                command = reply.get("command") if isinstance(reply, dict) else None
                if command not in ("update", "pause"):
                    break
        finally:
            self.running.set()
        if command == "stop":
            _end(STOP_STATUS)
        elif command == "step_over":
            self.set_next(frame)
        elif command == "step_into":
            self.set_step()
        elif command == "step_out":
            self.set_return(frame)
        else:
            self.set_continue()

    def trace_callers(self, frame):
        """The frames a step may go back to must be traced."""
        while frame is not None:
            if frame.f_code.co_filename == self.program and frame.f_trace is None:
                frame.f_trace = self.trace_dispatch
            frame = frame.f_back

    def say_paused(self, state):
        """The command (and changes) the agent answers a pause with; _Lost if it cannot."""
        try:
            try:
                return self.channel.call("debug_paused", state)
            except robot.RobotError as refused:
                if refused.code != -32602:
                    raise
            state.update(locals=[], globals=[], watches=[], exception="the state is too large")
            return self.channel.call("debug_paused", state)
        except (robot.RobotError, OSError, ValueError) as error:
            raise _Lost(error) from None

    def state(self, frame, reason, error=None, stack=None, line=None):
        values = _Values(STATE_BYTES - 4096)
        with self.lock:
            watches = list(self.watches)
        watched = [self.watch(values, frame, expression) for expression in watches]
        module = frame.f_locals is frame.f_globals
        local_items = [] if module else list(frame.f_locals.items())
        global_items = [
            (name, value)
            for name, value in list(frame.f_globals.items())
            if not (name.startswith("__") and name.endswith("__"))
            and not isinstance(value, _HIDDEN)
        ]
        state = {
            "reason": reason,
            "line": line or frame.f_lineno,
            "function": frame.f_code.co_name,
            "stack": stack or self.stack_of(frame),
            "locals": values.listing(local_items),
            "globals": values.listing(global_items),
            "watches": watched,
            "exception": error,
        }
        values.unfold()
        return state

    def watch(self, values, frame, expression):
        try:
            code = compile(expression, "<watch>", "eval")
            value = values.clock.run(eval, code, frame.f_globals, frame.f_locals)
        except _Slow:
            return {"expression": expression, "error": "it takes too long"}
        except BaseException as error:  # noqa: B036  (a watch may say sys.exit())
            return {"expression": expression, "error": _said(error)}
        return {"expression": expression, "value": values.variable(expression, value)}

    def stack_of(self, frame):
        stack = []
        while frame is not None:
            if frame.f_code.co_filename == self.program:
                stack.append({"function": frame.f_code.co_name, "line": frame.f_lineno})
            frame = frame.f_back
        return stack[::-1]

    # -- running the program -------------------------------------------------------------

    def run_program(self, code, namespace):
        """Run the program's code in `namespace`; an uncaught exception pauses once."""
        self.botframe = sys._getframe()
        self.set_continue()
        sys.settrace(self.global_trace())
        try:
            exec(code, namespace)
        except SystemExit:
            raise
        except BaseException as error:
            sys.settrace(None)
            self.after_crash(error)
            return 1
        finally:
            sys.settrace(None)
        return 0

    def after_crash(self, error):
        """Pause where the exception left the program, then print its traceback."""
        entries = [
            (tb.tb_frame, tb.tb_lineno)
            for tb in _walk_tb(error.__traceback__)
            if tb.tb_frame.f_code.co_filename == self.program
        ]
        if entries:
            frame, line = entries[-1]
            stack = [{"function": f.f_code.co_name, "line": n} for f, n in entries]
            self.interact_after(self.state(frame, "exception", _said(error), stack, line))
        error.__traceback__ = _program_tb(error.__traceback__, self.program)
        sys.excepthook(type(error), error, error.__traceback__)

    def interact_after(self, state):
        self.running.clear()
        try:
            reply = self.say_paused(state)
        except _Lost:
            return  # the run has ended: the traceback is still the program's last word
        finally:
            self.running.set()
        if isinstance(reply, dict) and reply.get("command") == "stop":
            _end(STOP_STATUS)


def _walk_tb(tb):
    while tb is not None:
        yield tb
        tb = tb.tb_next


def _program_tb(tb, program):
    """The traceback from the program's first frame on (the debugger's own left out)."""
    for entry in _walk_tb(tb):
        if entry.tb_frame.f_code.co_filename == program:
            return entry
    return tb


def _end(status):
    """End the program at once, its output written."""
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except Exception:
            pass
    os._exit(status)


class _Lost(Exception):
    """The agent did not answer a pause: the run has ended (its connections closed), or the
    agent refused the debugger."""

    def end(self):
        error = self.args[0]
        if not (isinstance(error, robot.RobotError) and error.code is None):
            print(f"robot_debug: the agent refused the debugger: {error}", file=sys.stderr)
        _end(STOP_STATUS)


def poll(debugger, channel, report_line):
    """The daemon thread's loop: changes and pause requests while the program runs."""
    timeout = min(max(float(report_line), 0.05), 5.0) if report_line else POLL_SECONDS
    while True:
        debugger.running.wait()
        try:
            reply = channel.call("debug_poll", debugger.current_line(), timeout)
        except robot.RobotError as error:
            if error.code is None:
                return  # the run has ended (its connections closed)
            time.sleep(1.0)  # refused: ask again, not in a busy loop
            continue
        except (OSError, ValueError):
            return
        if reply:
            # The agent answers a poll only while the program runs, so a reply that finds
            # it paused was said after the pause's answer, which the main thread has not
            # read yet: it comes after that answer.
            debugger.running.wait()
            debugger.apply(reply)


def main_namespace(filename):
    """__main__'s namespace as Python gives a program it runs (like pdb's _runscript)."""
    from importlib.machinery import SourceFileLoader

    import __main__

    __main__.__dict__.clear()
    __main__.__dict__.update(
        __name__="__main__",
        __doc__=None,
        __package__=None,
        __loader__=SourceFileLoader("__main__", filename),
        __spec__=None,
        __annotations__={},
        __builtins__=builtins,
        __file__=filename,
        __cached__=None,
    )
    return __main__.__dict__


def main(argv=None):
    argv = sys.argv[1:] if argv is None else argv
    if not argv:
        print("usage: python3 -m robot_debug PROGRAM [ARGS...]", file=sys.stderr)
        sys.exit(USAGE_STATUS)
    filename = os.path.abspath(argv[0])
    try:
        with io.open_code(filename) as source:
            code = compile(source.read(), filename, "exec")
    except OSError as error:  # said as python3 says it
        said = f"can't open file {filename!r}: [Errno {error.errno}] {error.strerror}"
        print(f"{sys.executable}: {said}", file=sys.stderr)
        sys.exit(USAGE_STATUS)
    except SyntaxError as error:
        error.__traceback__ = None  # the debugger's own frames are not the program's
        sys.excepthook(type(error), error, None)
        sys.exit(1)
    try:
        channel, poller = robot.Robot(), robot.Robot()
        spec = channel.call("debug_start")
        spec = spec if isinstance(spec, dict) else {}
    except (robot.RobotError, OSError) as error:
        print(f"robot_debug: cannot start the debugger: {error}", file=sys.stderr)
        sys.exit(USAGE_STATUS)
    debugger = Debugger(filename, code, channel)
    debugger.apply({"breakpoints": spec.get("breakpoints", []), "watches": spec.get("watches", [])})
    threading.Thread(
        target=poll,
        args=(debugger, poller, spec.get("report_line")),
        name="robot_debug",
        daemon=True,
    ).start()
    sys.argv[:] = argv
    sys.path[0] = os.path.dirname(os.path.realpath(filename))
    status = debugger.run_program(code, main_namespace(filename))
    sys.exit(status)


if __name__ == "__main__":
    import robot_debug  # the debugger's own module: __main__ becomes the program's

    robot_debug.main()
