"""Error lines to program lines: real interpreters' output, and each format's lines as text."""

import shutil
import subprocess
from dataclasses import dataclass, field
from pathlib import Path

import pytest

from programs.error_lines import FORMATS, RUNS_AS, ErrorPlace, error_place, last_error_place
from programs.languages import LANGUAGES
from runbox import SYSTEM_PATH
from tests.conftest import in_ci

NAME = "line-follower"  # a program's file is its slugified name and the language's extension


def program_file(language: str, folder: str = "/x") -> str:
    return f"{folder}/{NAME}{LANGUAGES[language].extension}"


def test_every_language_has_a_format():
    for name, language in LANGUAGES.items():
        assert name in FORMATS and FORMATS[name] is not None, name
        # a compiled language (blocks) runs another file: its errors name that one
        if getattr(language, "compiler", None) is not None:
            assert RUNS_AS[name] == language.compiled_extension, name


def test_blocks_lines_are_those_of_the_python_they_run():
    """The line of the Python made of the blocks (the workbench maps it to a block)."""
    text = '  File "/x/line-follower.py", line 12, in <module>'
    assert error_place("blocks", text, "line-follower.json") == ErrorPlace(12, None, "")
    assert last_error_place("blocks", [text], "line-follower.json") == ErrorPlace(12, None, "")
    assert error_place("blocks", text.replace("follower", "other"), "line-follower.json") is None


def test_an_unknown_language_is_an_error():
    with pytest.raises(ValueError, match="cobol"):
        error_place("cobol", "x", "x.cob")


# -- real interpreters ----------------------------------------------------------------------


@dataclass(frozen=True)
class Broken:
    """A broken program, the line its interpreter's output must lead to, and its libraries."""

    language: str
    what: str
    line: int | None
    source: list[str]
    libraries: dict[str, str] = field(default_factory=dict)
    interpreter: str = ""  # a command; "" for the registry's choice

    def __str__(self) -> str:
        return f"{self.interpreter or self.language}-{self.what}"


def lines(*text: str) -> str:
    return "".join(f"{line}\n" for line in text)


PY_LIB = lines("def boom():", "    raise ValueError('lib failed')")
# confess, as Carp reports for the Robot API client: the caller's lines follow the library's
PL_LIB = lines(
    "package Helper;", "use Carp;", "sub boom { confess 'lib failed' }",
    "sub plain { die 'lib failed' }", "1;",
)  # fmt: skip
RB_LIB = lines("module Helper", "  def self.boom", "    raise ArgumentError, 'x'", "  end", "end")
LUA_LIB = lines("local M = {}", "function M.boom()", "  error('lib failed')", "end", "return M")
JS_LIB = lines("exports.boom = function () {", "  throw new TypeError('lib failed');", "};")
TCL_LIB = lines("proc boom {} {", "    error {lib failed}", "}")
SH_LIB = lines("boom() {", "  a=1", "  no_such_command_in_lib", "}")
PL_USE_HELPER = ["use strict;", "use FindBin;", "use lib $FindBin::Bin;", "use Helper;"]


def shell(sh: str) -> list[Broken]:
    return [
        Broken(
            "shell", "raised", 4,
            ["x=1", "y=2", "z=3", "no_such_command", "x=5", "x=6"], {}, sh,
        ),
        Broken("shell", "syntax", 3, ["x=1", "y=2", "if then", "x=4"], {}, sh),
        Broken(
            "shell", "in-function", 3,
            ["turn() {", "  a=1", "  no_such_command", "}", "", "", "turn"], {}, sh,
        ),
    ]  # fmt: skip


BROKEN = [
    Broken(
        "python", "raised", 4,
        ["x = 1", "y = 2", "z = 3", "raise RuntimeError('boom')", "x = 5", "x = 6"],
    ),
    Broken("python", "syntax", 3, ["x = 1", "y = 2", "z = (1 +* 2)", "x = 4"]),
    Broken(
        "python", "in-function", 4,
        ["def turn():", "    a = 1", "    b = 0", "    return a / b", "", "", "turn()"],
    ),
    Broken(
        "python", "in-library", 5,
        ["import helper", "", "", "def turn():", "    helper.boom()", "", "", "turn()"],
        {"helper.py": PY_LIB},
    ),
    Broken(
        "perl", "raised", 4,
        ["use strict;", "use warnings;", "my $x = 1;", "die 'boom';", "$x = 5;", "$x = 6;"],
    ),
    # two errors reported (the second, at line 4, follows from the first): the first is marked
    Broken("perl", "syntax", 3, ["use strict;", "my $x = 1;", "my $z = 3 +;", "print $z;"]),
    # a warning first (line 5), then the error that ends the run
    Broken(
        "perl", "in-function", 6,
        ["use strict;", "use warnings;", "sub turn {", "    my ($a, $b) = @_;",
         "    print 'a' . $b;", "    return $a / $b;", "}", "turn(1);"],
    ),
    Broken(
        "perl", "in-library", 6,
        [*PL_USE_HELPER, "sub turn {", "    Helper::boom();", "}", "turn();"],
        {"Helper.pm": PL_LIB},
    ),
    # a plain die in a library names only the library: no program line, and not the library's
    Broken(
        "perl", "dies-in-library", None,
        [*PL_USE_HELPER, "Helper::plain();"], {"Helper.pm": PL_LIB},
    ),
    Broken("ruby", "raised", 4, ["x = 1", "y = 2", "z = 3", "raise 'boom'", "x = 5", "x = 6"]),
    # two errors reported (Ruby before 3.4 goes on to line 4): the first is marked
    Broken("ruby", "syntax", 3, ["x = 1", "y = 2", "z = (1 + * 2)", "x = 4"]),
    Broken(
        "ruby", "in-function", 4,
        ["def turn", "  a = 1", "  b = nil", "  b.foo", "end", "", "turn"],
    ),
    Broken(
        "ruby", "in-library", 4,
        ["require_relative 'helper'", "", "def turn", "  Helper.boom", "end", "", "turn"],
        {"helper.rb": RB_LIB},
    ),
    Broken(
        "lua", "raised", 4,
        ["local x = 1", "local y = 2", "local z = 3", "error('boom')", "x = 5", "x = 6"],
    ),
    Broken("lua", "syntax", 3, ["local x = 1", "local y = 2", "local z = = 3", "x = 4"]),
    Broken(
        "lua", "in-function", 4,
        ["local function turn()", "  local a = 1", "  local t = nil", "  return t.x", "end", "",
         "turn()"],
    ),
    Broken(
        "lua", "in-library", 4,
        ["local helper = require('helper')", "", "local function turn()", "  helper.boom()", "end",
         "", "turn()"],
        {"helper.lua": LUA_LIB},
    ),
    Broken(
        "javascript", "raised", 4,
        ["const x = 1;", "const y = 2;", "const z = 3;", "throw new Error('boom');", "x;", "y;"],
    ),
    Broken(
        "javascript", "syntax", 3,
        ["const x = 1;", "const y = 2;", "const z = (1 + * 2);", "z;"],
    ),
    Broken(
        "javascript", "in-function", 4,
        ["function turn() {", "  const a = 1;", "  const b = null;", "  return b.x;", "}", "",
         "turn();"],
    ),
    Broken(
        "javascript", "in-library", 4,
        ["const helper = require('./helper');", "", "function turn() {", "  helper.boom();", "}",
         "", "turn();"],
        {"helper.js": JS_LIB},
    ),
    Broken(
        "tcl", "raised", 4,
        ["set x 1", "set y 2", "set z 3", "error boom", "set x 5", "set x 6"],
    ),
    Broken("tcl", "syntax", 3, ["set x 1", "set y 2", "set z {abc", "set x 4"]),
    # Tcl counts a proc's lines from the proc: the file's line is the call's, line 7
    Broken(
        "tcl", "in-function", 7,
        ["proc turn {} {", "    set a 1", "    no_such_command", "}", "", "", "turn"],
    ),
    Broken(
        "tcl", "in-library", 7,
        ["source [file join [file dirname [info script]] helper.tcl]", "", "proc turn {} {",
         "    boom", "}", "", "turn"],
        {"helper.tcl": TCL_LIB},
    ),
    *shell("bash"),
    *shell("sh"),
    # bash names the sourced file's line, which is not the program's (dash would name the
    # program with the library's line number: the shell client is a command, never sourced)
    Broken(
        "shell", "in-library", None,
        ['. "$(dirname "$0")/helper.sh"', "x=2", "", "x=4", "boom"], {"helper.sh": SH_LIB}, "bash",
    ),
]  # fmt: skip


def interpreter(case: Broken) -> str:
    language = LANGUAGES[case.language]
    found = shutil.which(case.interpreter, path=SYSTEM_PATH) if case.interpreter else None
    found = found or (None if case.interpreter else language.interpreter_path())
    if found is None:
        message = f"no {case.interpreter or language.label} here: {language.install_hint}"
        if in_ci():
            pytest.fail(message, pytrace=False)  # nothing is skipped in CI
        pytest.skip(message)
    return found


def run(case: Broken, folder: Path) -> list[str]:
    """The program's standard error, run as the launcher runs it: by its path."""
    language = LANGUAGES[case.language]
    program = folder / f"{NAME}{language.extension}"
    program.write_text(lines(*case.source))
    for name, text in case.libraries.items():
        (folder / name).write_text(text)
    env = {"PATH": SYSTEM_PATH, "LUA_PATH": f"{folder}/?.lua;;", **language.env}
    done = subprocess.run(
        [interpreter(case), *language.args, str(program)],
        cwd=folder, env=env, capture_output=True, text=True, timeout=30,
    )  # fmt: skip
    assert done.stderr, f"the program ran without an error: {done.stdout}"  # a shell goes on
    return done.stderr.splitlines()


@pytest.mark.parametrize("case", BROKEN, ids=str)
def test_it_marks_the_line_the_interpreter_reports(case, tmp_path):
    stderr = run(case, tmp_path)
    # the page knows the path in the run box, not this one: the file's name is what counts
    file = program_file(case.language, "/home/run")
    place = last_error_place(case.language, stderr, file)
    assert (place.line if place else None) == case.line, "\n".join(stderr)
    if place is not None:  # and that line of output links there on its own too
        assert place in [error_place(case.language, text, file) for text in stderr]


def test_a_long_path_that_lua_shortens_still_matches(tmp_path):
    folder = tmp_path / ("deep-" * 12)
    folder.mkdir()
    case = Broken("lua", "raised", 2, ["local x = 1", "error('boom')"])
    stderr = run(case, folder)
    assert "..." in stderr[0]
    assert last_error_place("lua", stderr, program_file("lua")) == ErrorPlace(2, None, "boom")


# -- each format's lines, as text -----------------------------------------------------------

P = ErrorPlace
LINES = [
    ("python", '  File "/x/line-follower.py", line 12, in <module>', P(12, None, "")),
    ("python", '  File "/x/line-follower.py", line 3', P(3, None, "")),  # a SyntaxError's
    ("python", '  File "/opt/robotide/clients/python/robot.py", line 63, in call', None),
    ("python", '  File "/usr/lib/python3.11/socket.py", line 836, in create_connection', None),
    ("python", '  File "<frozen importlib._bootstrap>", line 1204, in _gcd_import', None),
    ("perl", "boom at /x/line-follower.pl line 7.", P(7, None, "boom")),
    ("perl", 'syntax error at line-follower.pl line 4, near "my "',
     P(4, None, 'syntax error, near "my "')),
    ("perl", "no reply at /x/line-follower.pl line 7, <STDIN> line 2.", P(7, None, "no reply")),
    ("perl", "\tmain::turn() called at /x/line-follower.pl line 9", P(9, None, "")),
    ("perl", "lib failed at /opt/robotide/clients/perl/Robot.pm line 104.", None),
    ("perl", "Execution of /x/line-follower.pl aborted due to compilation errors.", None),
    ("ruby", "/x/line-follower.rb:5:in `turn': boom (RuntimeError)",
     P(5, None, "boom (RuntimeError)")),
    ("ruby", "/x/line-follower.rb:5:in 'Object#turn': boom (RuntimeError)",  # Ruby 3.4
     P(5, None, "boom (RuntimeError)")),
    ("ruby", "/x/line-follower.rb:3: syntax error, unexpected end-of-input",
     P(3, None, "syntax error, unexpected end-of-input")),
    ("ruby", "/usr/bin/ruby: /x/line-follower.rb:3: syntax errors found (SyntaxError)",
     P(3, None, "syntax errors found (SyntaxError)")),
    ("ruby", "\tfrom /x/line-follower.rb:9:in `<main>'", P(9, None, "")),
    ("ruby", "/usr/lib/ruby/3.1.0/socket.rb:1214:in `connect': refused (Errno::ECONNREFUSED)",
     None),
    ("ruby", "\tfrom /opt/robotide/clients/ruby/robot.rb:62:in `call'", None),
    ("lua", "lua5.4: /x/line-follower.lua:8: boom", P(8, None, "boom")),
    ("lua", "/usr/bin/lua5.4: line-follower.lua:8: attempt to index a nil value",
     P(8, None, "attempt to index a nil value")),
    ("lua", "\t/x/line-follower.lua:8: in main chunk", P(8, None, "")),
    ("lua", "\t/x/line-follower.lua:12: in function <.../line-follower.lua:3>", P(12, None, "")),
    ("lua", "lua5.4: ...folder/line-follower.lua:8: boom", P(8, None, "boom")),
    ("lua", "lua5.4: /opt/robotide/clients/lua/robot.lua:75: boom", None),
    ("lua", "\t[C]: in function 'error'", None),
    ("javascript", "/x/line-follower.js:4", P(4, None, "")),
    ("javascript", "    at Object.<anonymous> (/x/line-follower.js:4:7)", P(4, 7, "")),
    ("javascript", "    at /x/line-follower.js:9:3", P(9, 3, "")),
    ("javascript", "    at async turn (file:///x/line-follower.js:5:3)", P(5, 3, "")),
    ("javascript", "    at Robot._call (/opt/robotide/clients/javascript/robot/index.js:120:5)",
     None),
    ("javascript", "    at Module._compile (node:internal/modules/cjs/loader:1521:14)", None),
    ("tcl", '    (file "/x/line-follower.tcl" line 6)', P(6, None, "")),
    ("tcl", '    (procedure "turn" line 3)', None),
    ("tcl", '    ("foreach" body line 2)', None),
    ("tcl", '    (file "/opt/robotide/clients/tcl/robot.tcl" line 130)', None),
    ("shell", "/x/line-follower.sh: 5: foo: not found", P(5, None, "foo: not found")),
    ("shell", "/x/line-follower.sh: line 5: foo: command not found",
     P(5, None, "foo: command not found")),
    ("shell", "bash: line 5: foo: command not found", None),
    ("shell", "./helper.sh: line 3: foo: command not found", None),
    ("shell", "speed: 5: fast", None),
]  # fmt: skip

# Ordinary output, in any language: it never points at the program.
ORDINARY = [
    "moving forward, see line 5",
    "line-follower: line 5 reached",
    "at line-follower line 5",
    "heading: 90",
    "",
]


@pytest.mark.parametrize(("language", "text", "place"), LINES)
def test_a_line_of_each_format(language, text, place):
    assert error_place(language, text, program_file(language)) == place


@pytest.mark.parametrize("language", sorted(LANGUAGES))
@pytest.mark.parametrize("text", ORDINARY)
def test_ordinary_output_points_nowhere(language, text):
    assert error_place(language, text, program_file(language)) is None


def test_a_line_of_the_program_is_known_by_the_file_name_alone():
    text = '  File "/var/lib/robotide/runs/7/line-follower.py", line 3, in <module>'
    assert error_place("python", text, "line-follower.py") == P(3, None, "")
    assert error_place("python", text, "/home/run/line-follower.py") == P(3, None, "")
    assert error_place("python", text, "/home/run/other.py") is None


def test_python_marks_the_traceback_that_ended_the_run():
    lines = [
        "Traceback (most recent call last):",
        '  File "/x/line-follower.py", line 4, in <module>',
        "KeyError: 'heading'",
        "",
        "During handling of the above exception, another exception occurred:",
        "",
        "Traceback (most recent call last):",
        '  File "/x/line-follower.py", line 6, in <module>',
        '  File "/x/line-follower.py", line 2, in turn',
        '  File "/opt/robotide/clients/python/robot.py", line 85, in call',
        "robot.RobotError: no such sensor",
    ]
    assert last_error_place("python", lines, "line-follower.py") == P(2, None, "")


def test_perl_marks_the_error_after_its_warnings():
    lines = [
        "Use of uninitialized value $x in concatenation (.) or string at line-follower.pl line 4.",
        "Illegal division by zero at line-follower.pl line 5.",
    ]
    assert last_error_place("perl", lines, "line-follower.pl").line == 5
