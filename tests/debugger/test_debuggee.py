"""The debugger in the box (programs/clients/python/robot_debug.py), run as a run runs it
(`python3 -u -m robot_debug PROGRAM ARGS...`, the client on PYTHONPATH) against a Robot API
peer written from PROTOCOL.md (peer.py): the test answers each pause and decides what
debug_poll returns. Every wait is for an event (a pause, a poll, a line of output, the end)."""

import json
import os
import queue
import subprocess
import sys
import threading
from pathlib import Path

import pytest

from tests.debugger.peer import CLOSE, Peer
from tests.waiting import DEADLINE

ROOT = Path(__file__).resolve().parents[2]
CLIENT = ROOT / "programs" / "clients" / "python"
# The debuggee's interpreter (the box's is python3; ROBOT_DEBUG_PYTHON tries another one).
PYTHON = os.environ.get("ROBOT_DEBUG_PYTHON", sys.executable)
WALL = (ROOT / "programs" / "examples" / "wall.py").read_text()
STATE_KEYS = {"reason", "line", "function", "stack", "locals", "globals", "watches", "exception"}

# Runs until stopped: the range never comes below STOP_AT unless the peer says so.
FOREVER = """import robot

bot = robot.Robot()
count = 0
while True:
    distance = bot.sensors()["range"]
    count += 1
"""

STEPS = """import robot

bot = robot.Robot()


def margin(distance):
    left = distance - 0.5
    return left


distance = bot.sensors()["range"]
room = margin(distance)
print("room", round(room, 2))
"""


def line_of(source: str, text: str) -> int:
    """The (first) line holding `text`."""
    return next(i for i, line in enumerate(source.splitlines(), 1) if text in line)


def point(line, condition=None):
    return {"line": line, "condition": condition}


def named(variables: list, name: str) -> dict:
    return next(v for v in variables if v["name"] == name)


class Debuggee:
    """A program under robot_debug, its output read as it comes."""

    def __init__(self, peer, program: Path, args=(), python=PYTHON):
        env = {
            "PATH": os.environ["PATH"],
            "PYTHONPATH": str(CLIENT),
            "PYTHONDONTWRITEBYTECODE": "1",
            **peer.environment,
        }
        command = [python, "-u", "-m", "robot_debug", str(program), *args]
        self.process = subprocess.Popen(
            command,
            cwd=program.parent,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.PIPE,
            text=True,
        )
        self.out, self.err = queue.Queue(), []
        threading.Thread(target=self._read, daemon=True).start()
        self.stderr_reader = threading.Thread(target=self._read_err, daemon=True)
        self.stderr_reader.start()

    def _read(self):
        for line in self.process.stdout:
            self.out.put(line)
        self.out.put(None)

    def _read_err(self):
        self.err.append(self.process.stderr.read())

    def printed(self, timeout=DEADLINE):
        """The next line it prints (None at its end)."""
        return self.out.get(timeout=timeout)

    def finish(self) -> tuple[int, str, str]:
        status = self.process.wait(timeout=DEADLINE)
        self.stderr_reader.join(DEADLINE)
        lines = []
        while (line := self.printed()) is not None:
            lines.append(line)
        return status, "".join(lines), "".join(self.err)


@pytest.fixture
def debug(tmp_path):
    """debug(source, breakpoints, watches, **peer options) -> (peer, debuggee)."""
    started = []

    def start(source, breakpoints=(), watches=(), args=(), **options):
        program = tmp_path / "program.py"
        program.write_text(source)
        spec = {"breakpoints": list(breakpoints), "watches": list(watches)}
        peer = Peer(spec=spec, **options)
        debuggee = Debuggee(peer, program, args)
        started.append((peer, debuggee))
        return peer, debuggee

    yield start
    for peer, debuggee in started:
        if debuggee.process.poll() is None:
            debuggee.process.kill()
            debuggee.process.wait()
        peer.close()


def plain(program: Path, args=(), env=None) -> subprocess.CompletedProcess:
    """The program run by python3 itself, as a run runs it without the debugger."""
    return subprocess.run(
        [PYTHON, "-u", str(program), *args],
        cwd=program.parent,
        env={"PATH": os.environ["PATH"], "PYTHONPATH": str(CLIENT), **(env or {})},
        capture_output=True,
        text=True,
        timeout=DEADLINE,
    )


def test_a_breakpoint_in_the_wall_example_pauses_with_its_variables(debug):
    show = line_of(WALL, "bot.show(")
    peer, debuggee = debug(WALL, [point(show)], ["distance < STOP_AT"], start=0.8, step=0.1)
    state = peer.paused()
    assert set(state) == STATE_KEYS
    assert (state["reason"], state["line"], state["function"]) == ("breakpoint", show, "<module>")
    assert state["stack"] == [{"function": "<module>", "line": show}]
    assert state["locals"] == []  # at module level its names are the globals
    assert state["exception"] is None
    names = [v["name"] for v in state["globals"]]
    assert named(state["globals"], "distance") == {
        "name": "distance", "type": "float", "value": "0.7", "children": None, "more": 0
    }  # fmt: skip
    assert named(state["globals"], "STOP_AT")["value"] == "0.5"
    assert named(state["globals"], "bot")["type"] == "Robot"
    assert "time" not in names and "robot" not in names  # modules are left out
    assert not any(name.startswith("__") for name in names)
    assert state["watches"] == [
        {"expression": "distance < STOP_AT", "value": {
            "name": "distance < STOP_AT", "type": "bool", "value": "False",
            "children": None, "more": 0}}
    ]  # fmt: skip
    peer.answer("continue", breakpoints=[])
    status, out, err = debuggee.finish()
    assert (status, err) == (0, "")
    assert out == "Stopped 0.30 m before the wall\n"  # the program's output alone
    assert [params[0] for params in peer.called("drive")] == [0.3]


def test_step_over_into_and_out_stay_in_the_program(debug):
    first = line_of(STEPS, 'distance = bot.sensors()["range"]')
    peer, debuggee = debug(STEPS, [point(first)], start=2.0, step=0.5)
    assert (peer.paused()["line"], peer.answer("step_into")) == (first, None)
    # Into a line calling the client library: it steps over robot.py (not the program's).
    state = peer.paused()
    assert (state["reason"], state["line"]) == ("step", first + 1)
    peer.answer("step_into")
    state = peer.paused()
    assert (state["line"], state["function"]) == (line_of(STEPS, "left = distance"), "margin")
    assert state["stack"] == [
        {"function": "<module>", "line": first + 1},
        {"function": "margin", "line": line_of(STEPS, "left = distance")},
    ]
    assert state["locals"] == [
        {"name": "distance", "type": "float", "value": "1.5", "children": None, "more": 0}
    ]
    peer.answer("step_over")
    state = peer.paused()
    assert (state["reason"], state["line"]) == ("step", line_of(STEPS, "return left"))
    assert named(state["locals"], "left")["value"] == "1.0"
    peer.answer("step_out")
    state = peer.paused()
    assert (state["line"], state["function"]) == (line_of(STEPS, 'print("room"'), "<module>")
    assert named(state["globals"], "room")["value"] == "1.0"
    peer.answer("step_over")
    # The program's last line stepped over: it ends, nothing more to pause at.
    assert debuggee.finish() == (0, "room 1.0\n", "")
    assert peer.pauses.empty()


def test_a_conditional_breakpoint_pauses_only_when_true(debug):
    show = line_of(WALL, "bot.show(")
    peer, debuggee = debug(WALL, [point(show, "distance < 1.0")], start=1.3, step=0.1)
    distances = []
    for _ in range(3):
        state = peer.paused()
        distances.append(named(state["globals"], "distance")["value"])
        assert (state["reason"], state["exception"]) == ("breakpoint", None)
        peer.answer("continue")
    assert distances == ["0.9", "0.8", "0.7"]  # 1.2, 1.1 and 1.0 went by
    peer.paused()
    peer.answer("continue", breakpoints=[])
    assert debuggee.finish()[0] == 0


def test_a_condition_that_fails_pauses_saying_why(debug):
    show = line_of(WALL, "bot.show(")
    peer, debuggee = debug(WALL, [point(show, "nowhere < 1")], start=0.6)
    state = peer.paused()
    assert state["reason"] == "breakpoint"
    assert "NameError: name 'nowhere' is not defined" in state["exception"]
    peer.answer("stop")
    assert debuggee.finish() == (0, "", "")


def test_watches_say_true_or_false_and_update_evaluates_new_ones(debug):
    show = line_of(WALL, "bot.show(")
    peer, debuggee = debug(WALL, [point(show)], ["distance < STOP_AT"], start=0.7, step=0.1)
    assert peer.paused()["watches"][0]["value"]["value"] == "False"  # 0.6
    peer.answer("continue")
    assert peer.paused()["watches"][0]["value"]["value"] == "False"  # 0.5
    peer.answer("continue")
    state = peer.paused()
    assert state["watches"][0]["value"]["value"] == "True"  # 0.4
    peer.answer("update", watches=["round(distance * 10)", "[distance, STOP_AT]", "ghost"])
    again = peer.paused()
    assert (again["reason"], again["line"]) == (state["reason"], state["line"])
    first, pair, ghost = again["watches"]
    assert (first["expression"], first["value"]["value"]) == ("round(distance * 10)", "4")
    assert [child["value"] for child in pair["value"]["children"]] == ["0.4", "0.5"]
    assert ghost == {"expression": "ghost", "error": "NameError: name 'ghost' is not defined"}
    peer.answer("continue", breakpoints=[])
    assert debuggee.finish()[0] == 0


def wait_for_line(peer, lines, timeout=DEADLINE):
    """Until debug_poll says the program is at one of `lines`."""
    while peer.lines.get(timeout=timeout) not in lines:
        pass


def test_a_pause_from_poll_stops_a_program_without_breakpoints(debug):
    loop = set(range(line_of(FOREVER, "while True"), line_of(FOREVER, "count += 1") + 1))
    peer, debuggee = debug(FOREVER, step=0)
    wait_for_line(peer, loop)
    peer.change(pause=True)
    state = peer.paused()
    assert state["reason"] == "pause" and state["line"] in loop
    assert named(state["globals"], "count")["type"] == "int"
    peer.answer("continue")  # it runs on, and a second pause request stops it again
    wait_for_line(peer, loop)
    peer.change(pause=True)
    assert peer.paused()["reason"] == "pause"
    peer.answer("stop")
    assert debuggee.finish() == (0, "", "")  # stop: quietly, status 0


def test_breakpoints_added_while_running_pause_the_running_loop(debug):
    count = line_of(FOREVER, "count += 1")
    peer, debuggee = debug(FOREVER, step=0)
    wait_for_line(peer, {count - 1, count})
    peer.change(breakpoints=[point(count, "count >= 3")])
    state = peer.paused()
    assert (state["reason"], state["line"]) == ("breakpoint", count)
    seen = int(named(state["globals"], "count")["value"])
    assert seen >= 3
    peer.answer("continue")
    assert int(named(peer.paused()["globals"], "count")["value"]) == seen + 1
    peer.answer("continue", breakpoints=[])  # removed: it runs on unpaused
    wait_for_line(peer, {count - 1, count})
    peer.change(pause=True)
    assert int(named(peer.paused()["globals"], "count")["value"]) > seen + 1
    peer.answer("stop")
    assert debuggee.finish()[0] == 0


def test_a_blocks_programs_python_says_its_lines_and_pauses_on_a_blocks_line(debug):
    from programs.blocks import to_python_mapped

    code, blocks = to_python_mapped((ROOT / "programs" / "examples" / "wall.json").read_text())
    show = blocks.index("wall-show") + 1  # the first line the block made
    peer, debuggee = debug(code, report_line=0.05, start=1.0, step=0)
    wait_for_line(peer, {show, blocks.index("wall-wait") + 1})  # where it runs, said
    peer.change(breakpoints=[point(show)])
    state = peer.paused()
    assert (state["reason"], state["line"]) == ("breakpoint", show)
    peer.answer("stop")
    assert debuggee.finish() == (0, "", "")


def test_polls_report_the_line_as_often_as_asked(debug):
    peer, debuggee = debug(FOREVER, step=0, report_line=0.05)
    wait_for_line(peer, {line_of(FOREVER, "count += 1") - 1, line_of(FOREVER, "count += 1")})
    peer.change(pause=True)
    peer.paused()
    peer.answer("stop")
    debuggee.finish()
    assert {params[1] for params in peer.called("debug_poll")} == {0.05}


def test_polls_without_line_reports_wait_long(debug):
    peer, debuggee = debug(FOREVER, step=0)
    wait_for_line(peer, {line_of(FOREVER, "count += 1") - 1, line_of(FOREVER, "count += 1")})
    peer.change(pause=True)
    peer.paused()
    peer.answer("stop")
    debuggee.finish()
    assert {params[1] for params in peer.called("debug_poll")} == {5}


CRASH = """def ratio(a, b):
    return a / b


total = 3
print(ratio(total, 0))
"""


def test_an_uncaught_exception_pauses_then_prints_pythons_traceback(debug, tmp_path):
    peer, debuggee = debug(CRASH)
    state = peer.paused()
    assert (state["reason"], state["line"], state["function"]) == ("exception", 2, "ratio")
    assert state["exception"] == "ZeroDivisionError: division by zero"
    assert state["stack"] == [{"function": "<module>", "line": 6}, {"function": "ratio", "line": 2}]
    assert [(v["name"], v["value"]) for v in state["locals"]] == [("a", "3"), ("b", "0")]
    peer.answer("continue")
    status, out, err = debuggee.finish()
    expected = plain(tmp_path / "program.py")
    assert (status, out, err) == (1, "", expected.stderr)
    assert expected.returncode == 1 and "robot_debug" not in err


def test_a_run_ended_during_a_pause_ends_the_program_quietly(debug):
    peer, debuggee = debug(WALL, [point(line_of(WALL, "bot.show("))])
    peer.paused()
    peer.answer(CLOSE)  # the agent closes the run's connections (Stop, the emergency stop)
    assert debuggee.finish() == (0, "", "")


def test_a_crash_whose_pause_the_run_ends_still_says_its_traceback(debug, tmp_path):
    peer, debuggee = debug(CRASH)
    peer.paused()
    peer.answer(CLOSE)
    assert debuggee.finish() == (1, "", plain(tmp_path / "program.py").stderr)


def test_a_syntax_error_is_said_as_python_says_it(debug, tmp_path):
    peer, debuggee = debug("x = (\n")
    expected = plain(tmp_path / "program.py")
    assert debuggee.finish() == (1, "", expected.stderr)
    assert "SyntaxError" in expected.stderr


@pytest.mark.parametrize(
    ("ending", "status", "said"),
    [("sys.exit(3)", 3, ""), ("sys.exit('bye')", 1, "bye\n"), ("raise SystemExit", 0, "")],
)
def test_system_exit_keeps_its_status(debug, ending, status, said):
    peer, debuggee = debug(f"import sys\nprint('before')\n{ending}\n")
    assert debuggee.finish() == (status, "before\n", said)
    assert peer.pauses.empty()


MAIN = """import json, sys, __main__
print(json.dumps({
    "argv": sys.argv, "name": __name__, "file": __file__, "path0": sys.path[0],
    "main": __main__.__dict__ is globals(), "names": sorted(globals()),
    "doc": __doc__, "spec": __spec__, "package": __package__,
}))
"""


def test_the_program_sees_what_plain_python_gives_it(debug, tmp_path):
    args = ["one", "two words"]
    peer, debuggee = debug(MAIN, args=args)
    status, out, err = debuggee.finish()
    expected = plain(tmp_path / "program.py", args)
    assert (status, err) == (0, "")
    assert json.loads(out) == json.loads(expected.stdout)
    assert json.loads(out)["argv"][0].endswith("program.py")


BIG = """big = ["x" * 100 + str(i) for i in range(100_000)]  # 10 MB of text
grid = [[list(range(150)) for _ in range(100)] for _ in range(100)]
wide = {f"key{i}": i for i in range(300)}
long_text = "y" * 1_000_000
done = True
"""


def test_big_values_are_trimmed_to_fit_the_state(debug):
    peer, debuggee = debug(BIG, [point(5)], ["big", "grid"])
    state = peer.paused()
    assert peer.sizes[-1] <= 256 * 1024
    big = named(state["globals"], "big")
    assert len(big["value"]) <= 200 and big["type"] == "list"
    assert len(big["children"]) == 100 and big["more"] == 100_000 - 100
    assert big["children"][3]["name"] == "[3]" and big["children"][3]["value"].endswith("3'")
    wide = named(state["globals"], "wide")
    assert wide["children"][0]["name"] == "['key0']" and wide["more"] == 200
    assert len(named(state["globals"], "long_text")["value"]) <= 200
    grid = named(state["globals"], "grid")
    assert len(grid["children"]) == 100 and grid["more"] == 0
    # Three levels, never more; what did not fit is counted in `more`, not lost silently.
    rows = grid["children"]
    assert all(len(row["children"]) + row["more"] == 100 for row in rows)
    assert all(cell["children"] is None for row in rows for cell in row["children"])
    assert sum(row["more"] for row in rows) > 0
    assert state["watches"][0]["value"]["more"] == 100_000 - 100
    peer.answer("continue")
    assert debuggee.finish() == (0, "", "")


REPRS = """import time


class Raises:
    def __repr__(self):
        raise ValueError("no repr for you")


class Slow:
    def __repr__(self):
        time.sleep(120)
        return "slow"


class Huge:
    def __init__(self):
        self.size = 10_000_000

    def __repr__(self):
        return "z" * self.size


raises, slow, huge = Raises(), Slow(), Huge()
print("made")
"""


def test_values_whose_repr_fails_hangs_or_is_huge_are_shown_safely(debug):
    made = line_of(REPRS, 'print("made")')
    peer, debuggee = debug(REPRS, [point(made)], ["slow", "huge.size"])
    state = peer.paused()
    raises, slow, huge = (named(state["globals"], name) for name in ("raises", "slow", "huge"))
    assert raises["type"] == "Raises" and "ValueError: no repr for you" in raises["value"]
    assert slow["type"] == "Slow" and "too long" in slow["value"]
    assert huge["value"].startswith("zzz") and len(huge["value"]) <= 200
    assert huge["children"] == [
        {"name": ".size", "type": "int", "value": "10000000", "children": None, "more": 0}
    ]
    assert "too long" in state["watches"][0]["value"]["value"]
    assert state["watches"][1]["value"]["value"] == "10000000"
    peer.answer("continue")
    assert debuggee.finish() == (0, "made\n", "")


THREADS = """import threading
import time

ticks = 0


def tick():
    global ticks
    while True:
        ticks += 1
        print("tick", ticks, flush=True)
        time.sleep(0.01)


threading.Thread(target=tick, daemon=True).start()
while ticks < 3:
    time.sleep(0.01)
paused_here = True
"""


def test_the_programs_own_threads_run_on_while_it_is_paused(debug):
    peer, debuggee = debug(THREADS, [point(line_of(THREADS, "paused_here = True"))])
    ticks = int(named(peer.paused()["globals"], "ticks")["value"])
    # Paused, and the program's thread still counts and prints.
    while (line := debuggee.printed()) != f"tick {ticks + 3}\n":
        assert line is not None
    peer.answer("stop")
    assert debuggee.finish()[0] == 0
