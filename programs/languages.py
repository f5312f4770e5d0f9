"""The languages programs can be written in: one registry entry each.

An entry says how to find the interpreter, how the launcher puts the Robot API client on the
interpreter's search path, and what the editor and a new program start with. Nothing else in
robotide names a language.

A language whose source is not what runs (blocks: Blockly's JSON) has a compiler; the launcher
writes what it makes of the source (`Language.program_file`) and runs that. A source that
cannot compile becomes a program that fails saying why, as an interpreter fails on a syntax
error, so the run's log says it like any other program's error.
"""

import json
import shutil
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

from django.utils.translation import gettext
from django.utils.translation import gettext_lazy as _

from programs import blocks_worker
from runbox import SYSTEM_PATH

CLIENTS_DIR = Path(__file__).resolve().parent / "clients"


@dataclass(frozen=True)
class Language:
    name: str
    label: str  # for people: translated where shown
    extension: str
    interpreter: tuple[str, ...]  # candidates, first found wins
    args: tuple[str, ...] = ()
    editor_mode: str = ""
    install_hint: str = ""
    template: str = ""
    env: dict[str, str] = field(default_factory=dict)
    # environment variable -> where the interpreter finds the client, "{clients}" standing for
    # the clients folder; an existing value (PATH) is kept after it
    client_paths: dict[str, str] = field(default_factory=dict)
    # source -> the program that runs, in the interpreter's language (see above), written to
    # a file with `compiled_extension`
    compiler: Callable[[str], str] | None = None
    compiled_extension: str = ""
    # What its programs sleep and read the clock with, as tested at a sim's speed above 1x
    # (runbox.timescale, tests/clients/test_sim_speed.py): the Languages page lists them.
    clock: str = ""
    # Its debugger (programs/clients/PROTOCOL.md, "The debugger"): what goes between the
    # interpreter's args and the program file for a run under it; () if it has none.
    # `debugger_note` (the Languages page) says what it is, or for a language without one,
    # what of the language's own could serve later: no promise, no faking.
    debugger: tuple[str, ...] = ()
    debugger_note: str = ""

    @property
    def debuggable(self) -> bool:
        return bool(self.debugger)

    def interpreter_path(self) -> str | None:
        for candidate in self.interpreter:
            found = shutil.which(candidate, path=SYSTEM_PATH)
            if found:
                return found
        return None

    @property
    def available(self) -> bool:
        return self.interpreter_path() is not None

    def command(self, program_file: str) -> list[str]:
        path = self.interpreter_path()
        if path is None:
            raise LanguageUnavailable(self)
        return [path, *self.args, program_file]

    def debug_command(self, program_file: str) -> list[str]:
        """The command of a run under the debugger; ValueError if the language has none."""
        if not self.debugger:
            raise ValueError(f"{self.label} programs cannot run under the debugger")
        path = self.interpreter_path()
        if path is None:
            raise LanguageUnavailable(self)
        return [path, *self.args, *self.debugger, program_file]

    def program_file(self, filename: str, source: str) -> tuple[str, str]:
        """(name, text) of the file a run writes and runs: the source as saved, or what the
        compiler makes of it."""
        if self.compiler is None:
            return filename, source
        return str(Path(filename).with_suffix(self.compiled_extension)), self.compiler(source)

    def client_env(self, clients_dir: Path = CLIENTS_DIR) -> dict[str, str]:
        return {var: path.format(clients=clients_dir) for var, path in self.client_paths.items()}


class LanguageUnavailable(Exception):
    def __init__(self, language: Language):
        super().__init__(
            f"The {language.label} interpreter is not installed on this robot computer"
            f" ({language.install_hint})."
        )


PYTHON_TEMPLATE = """\
import robot

bot = robot.Robot()
print("hello robot, my heading is", bot.sensors()["heading"])
"""

SHELL_TEMPLATE = """\
#!/bin/sh
echo "hello robot, my heading is $(robot sensors heading)"
"""

PERL_TEMPLATE = """\
use strict;
use warnings;
use Robot;

my $bot = Robot->new;
print "hello robot, my heading is ", $bot->sensors->{heading}, "\\n";
"""

RUBY_TEMPLATE = """\
require 'robot'

bot = Robot.new
puts "hello robot, my heading is #{bot.sensors['heading']}"
"""

LUA_TEMPLATE = """\
local Robot = require('robot')

local bot = Robot.new()
print('hello robot, my heading is ' .. bot:sensors().heading)
"""

JAVASCRIPT_TEMPLATE = """\
const { Robot } = require('robot');

(async () => {
  const bot = new Robot();
  console.log('hello robot, my heading is', (await bot.sensors()).heading);
  bot.close();
})();
"""

TCL_TEMPLATE = """\
package require robot

puts "hello robot, my heading is [dict get [robot::sensors] heading]"
"""

# Blockly's JSON serialization of a workspace (see programs.blocks): one print block.
BLOCKS_TEMPLATE = json.dumps(
    {
        "blocks": {
            "languageVersion": 0,
            "blocks": [
                {
                    "type": "text_print",
                    "id": "hello",
                    "x": 40,
                    "y": 40,
                    "inputs": {
                        "TEXT": {
                            "block": {
                                "type": "text_join",
                                "id": "hello-join",
                                "extraState": {"itemCount": 2},
                                "inputs": {
                                    "ADD0": {
                                        "block": {
                                            "type": "text",
                                            "id": "hello-text",
                                            "fields": {"TEXT": "hello robot, my heading is "},
                                        }
                                    },
                                    "ADD1": {
                                        "block": {
                                            "type": "robot_sensor",
                                            "id": "hello-heading",
                                            "fields": {"SENSOR": "heading"},
                                        }
                                    },
                                },
                            }
                        }
                    },
                }
            ],
        }
    },
    indent=2,
)

LANGUAGES: dict[str, Language] = {
    lang.name: lang
    for lang in [
        Language(
            name="python",
            clock="time.sleep, time.monotonic, time.time",
            label="Python",
            extension=".py",
            interpreter=("python3",),
            args=("-u",),
            editor_mode="python",
            install_hint="apt-get install python3",
            template=PYTHON_TEMPLATE,
            env={"PYTHONUNBUFFERED": "1", "PYTHONDONTWRITEBYTECODE": "1"},
            client_paths={"PYTHONPATH": "{clients}/python"},
            debugger=("-m", "robot_debug"),  # clients/python/robot_debug.py: bdb
            debugger_note=_(
                "Debug on the workbench: breakpoints (conditional too), stepping, variables"
                " and watches, built on Python's own bdb."
            ),
        ),
        Language(
            name="blocks",
            clock="wait (time.sleep)",
            label=_("Blocks"),
            extension=".json",
            interpreter=("python3",),
            args=("-u",),
            install_hint="apt-get install python3",
            template=BLOCKS_TEMPLATE,
            env={"PYTHONUNBUFFERED": "1", "PYTHONDONTWRITEBYTECODE": "1"},
            client_paths={"PYTHONPATH": "{clients}/python"},
            compiler=blocks_worker.to_runnable_python,
            compiled_extension=".py",
            debugger=("-m", "robot_debug"),  # on the Python made of the blocks
            debugger_note=_(
                "Debug on the workbench, on the Python made of the blocks: the running block"
                " lit, breakpoints on blocks, stepping, variables."
            ),
        ),
        Language(
            name="shell",
            clock="sleep, date",
            label="Shell",
            extension=".sh",
            interpreter=("bash", "sh"),
            editor_mode="shell",
            install_hint="apt-get install bash",
            template=SHELL_TEMPLATE,
            client_paths={"PATH": "{clients}/shell"},
            debugger_note=_(
                "None in robotide yet. Later: bash's own traces (bash -x, set -x: each command"
                " as it runs) or bashdb, a debugger for bash scripts."
            ),
        ),
        Language(
            name="perl",
            clock="sleep, Time::HiRes",
            label="Perl",
            extension=".pl",
            interpreter=("perl",),
            editor_mode="perl",
            install_hint="apt-get install perl",
            template=PERL_TEMPLATE,
            client_paths={"PERL5LIB": "{clients}/perl"},
            debugger_note=_(
                "None in robotide yet. Later: Perl's built-in debugger, perl -d (perl5db.pl),"
                " which can also talk over a port (RemotePort in PERLDB_OPTS)."
            ),
        ),
        Language(
            name="ruby",
            clock="sleep, Process.clock_gettime",
            label="Ruby",
            extension=".rb",
            interpreter=("ruby",),
            editor_mode="ruby",
            install_hint="apt-get install ruby",
            template=RUBY_TEMPLATE,
            env={"RUBYOPT": "-W0"},
            client_paths={"RUBYLIB": "{clients}/ruby"},
            debugger_note=_(
                "None in robotide yet. Later: the debug gem (rdbg), bundled with Ruby 3.1 and"
                " newer, which can also be attached to over a socket."
            ),
        ),
        Language(
            name="lua",
            clock="socket.sleep, socket.gettime",
            label="Lua",
            extension=".lua",
            interpreter=("lua5.4", "lua"),
            editor_mode="lua",
            install_hint="apt-get install lua5.4 lua-socket",
            template=LUA_TEMPLATE,
            client_paths={"LUA_PATH": "{clients}/lua/?.lua;;"},
            debugger_note=_(
                "None in robotide yet. Later: the hooks of Lua's debug library (debug.sethook,"
                " called at each line), on which a debugger can be built."
            ),
        ),
        Language(
            name="javascript",
            clock="setTimeout, process.hrtime, Date.now (libuv)",
            label="JavaScript (Node.js)",
            extension=".js",
            interpreter=("node", "nodejs"),
            editor_mode="javascript",
            install_hint="apt-get install nodejs",
            template=JAVASCRIPT_TEMPLATE,
            client_paths={"NODE_PATH": "{clients}/javascript"},
            debugger_note=_(
                "None in robotide yet. Later: Node's inspector (node --inspect), which speaks"
                " the Chrome DevTools Protocol."
            ),
        ),
        Language(
            name="tcl",
            clock="after, clock",
            label="Tcl",
            extension=".tcl",
            interpreter=("tclsh", "tclsh8.6"),
            editor_mode="tcl",
            install_hint="apt-get install tcl tcllib",
            template=TCL_TEMPLATE,
            client_paths={"TCLLIBPATH": "{clients}/tcl"},
            debugger_note=_(
                "None in robotide yet, and Tcl has none built in. Later: its execution traces"
                " (trace add execution) could serve to build one."
            ),
        ),
    ]
}


def get_language(name: str) -> Language:
    try:
        return LANGUAGES[name]
    except KeyError:
        known = ", ".join(LANGUAGES)
        raise ValueError(
            gettext("Unknown language %(name)s; known languages: %(known)s.")
            % {"name": repr(name), "known": known}
        ) from None


def language_for_filename(filename: str) -> Language | None:
    suffix = Path(filename).suffix.lower()
    return next((lang for lang in LANGUAGES.values() if lang.extension == suffix), None)


def language_choices() -> list[tuple[str, str]]:
    return [(lang.name, lang.label) for lang in LANGUAGES.values()]


def language_options() -> list[tuple[str, str]]:
    """For a form: a language whose interpreter is missing says so (and what to install)."""
    missing = gettext("%(language)s (not installed: %(install)s)")
    return [
        (lang.name, lang.label if lang.available
         else missing % {"language": lang.label, "install": lang.install_hint})
        for lang in LANGUAGES.values()
    ]  # fmt: skip


def editor_modes() -> list[str]:
    """The editor's (CodeMirror's) modes the languages need, for the page to load."""
    return sorted({lang.editor_mode for lang in LANGUAGES.values() if lang.editor_mode})


def editor_mode_of_language() -> dict[str, str]:
    return {name: lang.editor_mode for name, lang in LANGUAGES.items()}


def availability() -> list[dict]:
    """Each language with where its interpreter is on this computer (None: not installed)."""
    return [{**vars(lang), "path": lang.interpreter_path()} for lang in LANGUAGES.values()]
