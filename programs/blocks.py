"""Blocks programs: Blockly's JSON serialization of a workspace, run as the Python made here.

A blocks program's source is the JSON Blockly's `serialization.workspaces.save` gives (the
editor, robotide/static/robotide/blocks.js, saves exactly that); what runs is the Python
`to_python` makes of it, with the Python Robot API client. The generator lives on the server
so that the JSON is the one source of truth: a blocks program runs on every robot like any
other program, whichever browser saved it last.

    {"blocks": {"languageVersion": 0, "blocks": [<a stack's top block>, ...]},
     "variables": [{"name": "speed", "id": "..."}]}

    a block: {"type": .., "id": .., "x": .., "y": .., "fields": {NAME: value},
              "inputs": {NAME: {"block": {..}, "shadow": {..}}}, "next": {"block": {..}},
              "extraState": {..}}; a variable field is {"id": ..}

Nothing from the JSON reaches the Python as raw text: texts, topics and names become repr()
literals, numbers are parsed and written anew, operators and modes are looked up in tables,
and variables become identifiers made here (valid, no keyword, no builtin, none twice). The
result is compiled before it is returned. Whatever is wrong (not JSON, not a workspace, an
unknown block, a field outside its table) is a BlocksError, a ValueError whose message names
the block. Blocks that would make too much Python (see the caps below) are refused before any
code is made. The server and the agents never call this: programs.blocks_worker runs it in a
worker process with limits of its own.
"""

import builtins
import json
import keyword
import math
import re
import unicodedata

from django.utils.translation import gettext as _
from django.utils.translation import gettext_lazy

__all__ = [
    "BlocksError",
    "block_types",
    "header",
    "to_python",
    "to_python_mapped",
    "to_runnable_python",
]


class BlocksError(ValueError):
    """The JSON is not a blocks program robotide can run; the message says which block."""


def header() -> str:
    """The first line of the Python made of blocks, in the active language: one comment line
    whatever a translation holds."""
    words = _("Generated from a blocks program by robotide: edit the blocks, not this text.")
    return "# " + " ".join(words.split())


# Seconds per radian a turn block waits is timed at the speed the robot says it applies.
TURN_SPEED = 1.0  # rad/s

HELPERS = {
    "turn": f'''\
TURN_SPEED = {TURN_SPEED!r}  # rad/s


def turn(degrees):
    """Turn on the spot, to the left for positive degrees, timed at the speed applied."""
    applied = bot.drive(0.0, math.copysign(TURN_SPEED, degrees))["angular"]
    if applied:
        time.sleep(abs(math.radians(degrees) / applied))
    bot.stop()''',
    "count_with": '''\
def count_with(start, end, step):
    """Blockly's "count with": from start to end, both included, by step up or down."""
    step = abs(step) or 1
    if start <= end:
        while start <= end:
            yield start
            start += step
    else:
        while start >= end:
            yield start
            start -= step''',
}

# Python's operator precedence, as Blockly's Python generator orders it: a value whose order
# is not lower than where it goes is put in parentheses.
ATOMIC = 0
MEMBER = 2.1
CALL = 2.2
POWER = 3
UNARY = 4
MULTIPLICATIVE = 5
ADDITIVE = 6
RELATIONAL = 11
NOT = 12
AND = 13
OR = 14
NONE = 99

COMPARE = {"EQ": "==", "NEQ": "!=", "LT": "<", "LTE": "<=", "GT": ">", "GTE": ">="}
ARITHMETIC = {
    "ADD": ("+", ADDITIVE),
    "MINUS": ("-", ADDITIVE),
    "MULTIPLY": ("*", MULTIPLICATIVE),
    "DIVIDE": ("/", MULTIPLICATIVE),
    "POWER": ("**", POWER),
}
ROUND = {"ROUND": "round", "ROUNDUP": "math.ceil", "ROUNDDOWN": "math.floor"}

# A sensor's name, or a part of one: "range", "position.x", "velocity.angular".
SENSOR_NAME = re.compile(r"[A-Za-z_][A-Za-z0-9_]*(\.[A-Za-z0-9_]+)*")

# Names the program itself uses: a variable called so gets another name.
RESERVED = {"bot", "robot", "time", "math", "random", "TURN_SPEED", *HELPERS}
RESERVED |= set(dir(builtins)) | set(keyword.kwlist)

MAX_BLOCKS = 10_000
# What blocks make, capped on the JSON before any code is made (_measure): a block's mutator
# makes code for every branch or item it says it has, plugged in or not, so a 57-byte if block
# with 1000 else-ifs made 21 KB of Python. Caps of one block, then of the whole program.
MAX_ELSE_IFS = 100  # else-if branches of one if block
MAX_ITEMS = 100  # items of one block (a text join, a list)
MAX_BRANCHES = 2000  # else-if and else branches in all
MAX_ALL_ITEMS = 2000  # items in all
MAX_DEPTH = 50  # blocks plugged inside each other
MAX_VARIABLES = 1000
# The Python: no longer than a program may be (programs.models.MAX_SOURCE_BYTES), so that its
# copy as a Python program can be saved too.
MAX_CODE_BYTES = 512 * 1024
INDENT = "    "
EMPTY_TEXT = "''"
MAX_INTEGER = 10**18  # a JSON number larger than this is refused, not approximated


def to_python(source_json: str) -> str:
    """The Python a blocks program runs as; BlocksError (a ValueError) if it cannot be."""
    return to_python_mapped(source_json)[0]


def to_python_mapped(source_json: str) -> tuple[str, list[str | None]]:
    """The Python, and its source map: for each of its lines (the first at 0), the id of the
    block that made it, None for lines of no block (the header, helpers). A run's error names
    a line of the Python; the workbench marks the block this gives."""
    try:
        workspace = json.loads(source_json)
    except ValueError as exc:  # also a number of more digits than Python reads
        raise BlocksError(
            _("This blocks program is not valid JSON (%(why)s).") % {"why": exc}
        ) from None
    except RecursionError:
        raise BlocksError(_("This blocks program is nested too deeply.")) from None
    _measure(workspace)
    try:
        code, source_map = _Generator(workspace).program()
    except RecursionError:
        raise BlocksError(_("This blocks program is nested too deeply.")) from None
    if len(code.encode()) > MAX_CODE_BYTES:
        raise BlocksError(_too_long())
    try:
        compile(code, "<blocks>", "exec")
    except (SyntaxError, RecursionError) as exc:  # a MemoryError is the worker's to say
        # Python's own limits, e.g. more than 20 loops inside each other.
        raise BlocksError(
            _("This blocks program cannot run as Python: %(why)s.") % {"why": exc}
        ) from None
    return code, source_map


def to_runnable_python(source_json: str) -> str:
    """What a run of a blocks program writes and runs: its Python, or, if the blocks cannot
    run, a program that fails saying why, on stderr with exit status 1, as an interpreter
    does with a syntax error; so the run's log tells it like any other program's error."""
    try:
        return to_python(source_json)
    except BlocksError as exc:
        return failing(str(exc))


def failing(why: str) -> str:
    """A program that fails saying `why`."""
    return f"{header()}\nimport sys\n\nsys.exit({why!r})\n"


def block_types() -> set[str]:
    """The types of block the generator knows."""
    generator = _Generator({})
    return set(generator.statement) | set(generator.value)


def _measure(workspace) -> None:
    """Refuse, naming the block, blocks that would make too much Python: counted on the JSON,
    before any code is made. What is malformed is left to the generator to say."""
    if not isinstance(workspace, dict):
        return
    variables = workspace.get("variables")
    if isinstance(variables, list) and len(variables) > MAX_VARIABLES:
        raise BlocksError(
            _("This blocks program has more than %(count)s variables.") % {"count": MAX_VARIABLES}
        )
    top = workspace.get("blocks")
    # Depth first, in the generator's order, so the block named is the first one past a cap.
    stack = [(block, 1) for block in reversed(_list_or_none(top, "blocks") or ())]
    blocks = branches = items = 0
    while stack:
        block, depth = stack.pop()
        if not isinstance(block, dict):
            continue
        blocks += 1
        if blocks > MAX_BLOCKS:
            raise BlocksError(
                _("This blocks program has more than %(count)s blocks.") % {"count": MAX_BLOCKS}
            )
        if depth > MAX_DEPTH:
            raise BlocksError(
                _("%(block)s is nested too deeply: blocks may go %(count)s inside each other.")
                % {"block": _name_of(block), "count": MAX_DEPTH}
            )
        state = block.get("extraState")
        if isinstance(state, dict):
            else_ifs, count = _count(state, "elseIfCount"), _count(state, "itemCount")
            branches += else_ifs + bool(state.get("hasElse"))
            items += count
            _refuse_past(block, else_ifs, MAX_ELSE_IFS, ONE_BLOCKS_ELSE_IFS)
            _refuse_past(block, count, MAX_ITEMS, ONE_BLOCKS_ITEMS)
            _refuse_past(block, branches, MAX_BRANCHES, ALL_BRANCHES)
            _refuse_past(block, items, MAX_ALL_ITEMS, ALL_ITEMS)
        stack.append((_plugged(block.get("next")), depth))
        inputs = block.get("inputs")
        for connection in reversed(inputs.values()) if isinstance(inputs, dict) else ():
            stack.append((_plugged(connection), depth + 1))


def _list_or_none(container, key: str) -> list | None:
    value = container.get(key) if isinstance(container, dict) else None
    return value if isinstance(value, list) else None


def _plugged(connection):
    """The block the generator takes from a connection: the one plugged in, else its shadow."""
    if not isinstance(connection, dict):
        return None
    return connection.get("block") or connection.get("shadow")


def _count(state: dict, key: str) -> int:
    """A mutator's count; 0 for one that is no count (the generator says so where it reads it)."""
    value = state.get(key, 0)
    if not isinstance(value, int) or isinstance(value, bool) or value < 0:
        return 0
    return value


# What _measure says of the block past a cap.
ONE_BLOCKS_ELSE_IFS = gettext_lazy(
    "%(block)s has %(count)s else-if branches; an if block may have at most %(most)s."
)
ONE_BLOCKS_ITEMS = gettext_lazy("%(block)s has %(count)s items; a block may have at most %(most)s.")
ALL_BRANCHES = gettext_lazy(
    "%(block)s takes this program past %(most)s else-if and else branches in all."
)
ALL_ITEMS = gettext_lazy("%(block)s takes this program past %(most)s items in all.")


def _refuse_past(block: dict, count: int, most: int, message) -> None:
    if count > most:
        shown = count if count < 10**12 else f"{10**12:,}+"  # a 4000-digit count is not read
        raise BlocksError(str(message) % {"block": _name_of(block), "count": shown, "most": most})


def _too_long(block: dict | None = None) -> str:
    kb = MAX_CODE_BYTES // 1024
    if block is None:
        return _("This blocks program's Python would be longer than %(kb)s KB.") % {"kb": kb}
    return _(
        "%(block)s makes this program's Python longer than %(kb)s KB, the most a program may be."
    ) % {"block": _name_of(block), "kb": kb}


def _name_of(block: dict) -> str:
    """How an error names a block: its type and id."""
    block_id = block.get("id")
    kind = repr(str(block.get("type"))[:60])
    if block_id is None:
        return _("block %(type)s") % {"type": kind}
    return _("block %(type)s (id %(id)s)") % {"type": kind, "id": repr(str(block_id)[:40])}


class _Generator:
    def __init__(self, workspace):
        if not isinstance(workspace, dict):
            raise BlocksError(_("A blocks program is a JSON object with 'blocks' and 'variables'."))
        self.workspace = workspace
        self.used: set[str] = set(RESERVED)
        self.variables: dict[str, str] = {}  # variable id -> identifier
        self.by_name: dict[str, str] = {}  # variable name -> identifier
        self.suffixes: dict[str, int] = {}  # base -> the last number tried after it
        self.declared: list[str] = []
        self.helpers: set[str] = set()
        self.imports: set[str] = set()
        self.topics: list[str] = []  # the topics received from: subscribed at the start
        self.loops = 0  # loops around the block being made (break and continue need one)
        self.repeats = 0  # repeat blocks around it, each with its own counter
        self.counters: list[str] = []
        self.blocks = 0
        self.statement = {
            "controls_if": self._if,
            "controls_repeat_ext": self._repeat,
            "controls_repeat": self._repeat,
            "controls_whileUntil": self._while_until,
            "controls_for": self._for,
            "controls_flow_statements": self._flow,
            "variables_set": self._set,
            "math_change": self._change,
            "text_print": self._print,
            "robot_drive": self._drive,
            "robot_stop": lambda block: ["bot.stop()"],
            "robot_turn": self._turn,
            "robot_forward": self._forward,
            "robot_wait": self._wait,
            "robot_show": self._show,
            "robot_say": self._say,
            "robot_publish": self._publish,
            "robot_memory_set": self._memory_set,
        }
        self.value = {
            "logic_compare": self._compare,
            "logic_operation": self._operation,
            "logic_negate": self._negate,
            "logic_boolean": self._boolean,
            "logic_null": lambda block: ("None", ATOMIC),
            "math_number": self._number,
            "math_arithmetic": self._arithmetic,
            "math_random_int": self._random_int,
            "math_round": self._round,
            "text": self._text,
            "text_join": self._join,
            "variables_get": self._get,
            "robot_sensor": self._sensor,
            "robot_receive": self._receive,
            "robot_memory_get": self._memory_get,
        }

    # -- the program -----------------------------------------------------------------------

    def program(self) -> tuple[str, list[str | None]]:
        for variable in self._list(self.workspace, "variables", "the workspace"):
            if not isinstance(variable, dict) or not isinstance(variable.get("name"), str):
                raise BlocksError(_("Each of the workspace's variables needs a name."))
            self._variable(variable.get("id"), variable["name"])
        blocks = self.workspace.get("blocks", {})
        if not isinstance(blocks, dict):
            raise BlocksError(_("The workspace's 'blocks' must be an object with a 'blocks' list."))
        tops = self._list(blocks, "blocks", "the workspace")
        if not all(isinstance(block, dict) for block in tops):
            raise BlocksError(_("Each of the workspace's top blocks must be an object."))
        main = self.main_stack(tops)
        body = self._sequence(main) if main is not None else []  # capped as it is made

        lines = [header(), "import robot, time"]
        if self.imports:
            lines.append(f"import {', '.join(sorted(self.imports))}")
        lines += ["", "bot = robot.Robot()"]
        # Subscribed from the start: what is published meanwhile waits for the receive.
        lines += [f"bot.subscribe({topic!r})" for topic in self.topics]
        for helper in sorted(self.helpers):
            lines += ["", "", HELPERS[helper]]
        if self.helpers:
            lines.append("")
        if self.declared:  # every variable starts as 0, so "change by" works at once
            lines += ["", *(f"{name} = 0" for name in self.declared)]
        lines += ["", *body]
        source_map = [
            getattr(line, "block", None) for text in lines for line in _split_keeping_block(text)
        ]
        return "\n".join(lines) + "\n", source_map

    def main_stack(self, tops: list[dict]) -> dict | None:
        """The stack that is the program: the top one, as the blocks lie (Blockly's reading
        order), of those that can be a program's start; a value block on its own cannot.
        Every other top block is loose: not run, as the editor shows it (greyed out)."""
        for block in _in_reading_order(tops):
            kind = block.get("type")
            if not (isinstance(kind, str) and kind in self.value) or block.get("next") is not None:
                return block
        return None

    # -- walking blocks --------------------------------------------------------------------

    def _sequence(self, block) -> list[str]:
        """The lines of a stack of blocks, from `block` down its "next" chain."""
        lines: list[str] = []
        size = 0
        while block is not None:
            self._check(block)
            if _enabled(block):
                # A line a block inside this one made (a body) is already that block's.
                made = [_Line(line, block.get("id")) for line in self._statement(block)]
                size = _within_cap(size, made, block)
                lines += made
            block = self._connected(block.get("next"), block, "next")
        return lines

    def _statement(self, block: dict) -> list[str]:
        kind = block["type"]
        if kind in self.statement:
            return self.statement[kind](block)
        if kind in self.value:  # a value on its own: Blockly runs it, and so do we
            return [self.value[kind](block)[0]]
        raise BlocksError(
            _("Unknown %(block)s: robotide cannot run it.") % {"block": _name_of(block)}
        )

    def _body(self, block: dict, name: str, loop: bool = False) -> list[str]:
        """The indented lines of a statement input (`pass` if it holds nothing)."""
        self.loops += loop
        try:
            lines = self._sequence(self._input(block, name))
        finally:
            self.loops -= loop
        return [_Line(INDENT + line, line.block) for line in lines] or [INDENT + "pass"]

    def _code(self, block: dict, name: str, order: float, default: str, same: bool = False):
        """The code of the value input `name`, in parentheses where `order` needs them;
        `default` if nothing is plugged in. `same`: a value of the same order goes without
        them (the left side of -, /, the right side of **)."""
        inner = self._input(block, name)
        if inner is None or not _enabled(inner):
            return default
        self._check(inner)
        kind = inner["type"]
        if kind not in self.value:
            if kind in self.statement:
                raise BlocksError(
                    _("%(block)s is not a value: it cannot go in %(name)s.")
                    % {"block": _name_of(inner), "name": name}
                )
            raise BlocksError(
                _("Unknown %(block)s: robotide cannot run it.") % {"block": _name_of(inner)}
            )
        code, inner_order = self.value[kind](inner)
        if _needs_parentheses(order, inner_order, same):
            return f"({code})"
        return code

    def _input(self, block: dict, name: str) -> dict | None:
        inputs = block.get("inputs", {})
        if not isinstance(inputs, dict):
            raise BlocksError(
                _("%(block)s: its 'inputs' must be an object.") % {"block": _name_of(block)}
            )
        return self._connected(inputs.get(name), block, name)

    def _connected(self, connection, block: dict, name: str) -> dict | None:
        """The block in a connection: the one plugged in, else its shadow."""
        if connection is None:
            return None
        if not isinstance(connection, dict):
            raise BlocksError(
                _("%(block)s: its %(name)s must be an object.")
                % {"block": _name_of(block), "name": name}
            )
        inner = connection.get("block") or connection.get("shadow")
        if inner is not None and not isinstance(inner, dict):
            raise BlocksError(
                _("%(block)s: the block in its %(name)s must be an object.")
                % {"block": _name_of(block), "name": name}
            )
        return inner

    def _check(self, block) -> None:
        if not isinstance(block, dict) or not isinstance(block.get("type"), str):
            raise BlocksError(_("Every block must be an object with a 'type'."))
        self.blocks += 1
        if self.blocks > MAX_BLOCKS:
            raise BlocksError(
                _("This blocks program has more than %(count)s blocks.") % {"count": MAX_BLOCKS}
            )

    def _field(self, block: dict, name: str, default=None):
        fields = block.get("fields", {})
        if not isinstance(fields, dict):
            raise BlocksError(
                _("%(block)s: its 'fields' must be an object.") % {"block": _name_of(block)}
            )
        value = fields.get(name, default)
        if value is None:
            raise BlocksError(
                _("%(block)s has no %(name)s field.") % {"block": _name_of(block), "name": name}
            )
        return value

    def _choice(self, block: dict, name: str, table: dict):
        value = self._field(block, name)
        if not isinstance(value, str) or value not in table:
            raise BlocksError(
                _("%(block)s: %(name)s must be one of %(choices)s, not %(value)s.")
                % {
                    "block": _name_of(block),
                    "name": name,
                    "choices": ", ".join(table),
                    "value": repr(value)[:40],
                }
            )
        return table[value]

    def _text_field(self, block: dict, name: str) -> str:
        value = self._field(block, name, "")
        if not isinstance(value, str | int | float) or isinstance(value, bool):
            raise BlocksError(
                _("%(block)s: its %(name)s must be a text.")
                % {"block": _name_of(block), "name": name}
            )
        return str(value)

    @staticmethod
    def _list(container: dict, key: str, what: str) -> list:
        value = container.get(key, [])
        if not isinstance(value, list):
            raise BlocksError(
                _("The '%(key)s' of %(what)s must be a list.") % {"key": key, "what": what}
            )
        return value

    # -- variables -------------------------------------------------------------------------

    def _variable(self, variable_id, name: str) -> str:
        """The identifier of a variable, made on first sight: a valid Python name, not a
        keyword, builtin or a name of the program's own, none twice."""
        if name in self.by_name:
            identifier = self.by_name[name]
        else:
            base = _identifier(name)
            # From the last number tried: a thousand names made alike are not a million tries.
            n = self.suffixes.get(base, 1)
            identifier = base if n == 1 else f"{base}{n}"
            while identifier in self.used:
                n += 1
                identifier = f"{base}{n}"
            self.suffixes[base] = n
            self.used.add(identifier)
            self.by_name[name] = identifier
            self.declared.append(identifier)
        if variable_id is not None:
            self.variables.setdefault(str(variable_id), identifier)
        return identifier

    def _variable_field(self, block: dict, name: str = "VAR") -> str:
        field = self._field(block, name)
        if isinstance(field, dict):
            if field.get("id") is not None and str(field["id"]) in self.variables:
                return self.variables[str(field["id"])]
            if isinstance(field.get("name"), str):
                return self._variable(field.get("id"), field["name"])
            raise BlocksError(
                _("%(block)s uses a variable the workspace does not have.")
                % {"block": _name_of(block)}
            )
        if isinstance(field, str):  # older saves: the variable's name
            return self._variable(None, field)
        raise BlocksError(
            _("%(block)s: its %(name)s must name a variable.")
            % {"block": _name_of(block), "name": name}
        )

    def _counter(self) -> str:
        """The counter of a repeat block: count, and count2 for one inside it, ..."""
        if self.repeats == len(self.counters):
            name, n = "count", 1
            while name in self.used:
                n += 1
                name = f"count{n}"
            self.used.add(name)
            self.counters.append(name)
        return self.counters[self.repeats]

    # -- logic and loops -------------------------------------------------------------------

    def _if(self, block: dict) -> list[str]:
        state = block.get("extraState") or {}
        if not isinstance(state, dict):
            raise BlocksError(
                _("%(block)s: its extraState must be an object.") % {"block": _name_of(block)}
            )
        else_ifs = state.get("elseIfCount", 0)
        if not isinstance(else_ifs, int) or isinstance(else_ifs, bool):
            raise BlocksError(
                _("%(block)s: elseIfCount must be a whole number.") % {"block": _name_of(block)}
            )
        if not 0 <= else_ifs <= MAX_ELSE_IFS:
            raise BlocksError(
                _("%(block)s: elseIfCount must be 0 to %(count)s.")
                % {"block": _name_of(block), "count": MAX_ELSE_IFS}
            )
        lines: list[str] = []
        for n in range(else_ifs + 1):
            condition = self._code(block, f"IF{n}", NONE, "False")
            lines.append(f"{'if' if n == 0 else 'elif'} {condition}:")
            lines += self._body(block, f"DO{n}")
        if state.get("hasElse"):
            lines.append("else:")
            lines += self._body(block, "ELSE")
        return lines

    def _repeat(self, block: dict) -> list[str]:
        if block["type"] == "controls_repeat":  # the older block: a number field
            times = _number_literal(block, self._field(block, "TIMES"))[0]
        else:
            times = self._code(block, "TIMES", NONE, "0")
        if not _is_int_literal(times):
            times = f"int({times})"
        counter = self._counter()
        self.repeats += 1
        try:
            body = self._body(block, "DO", loop=True)
        finally:
            self.repeats -= 1
        return [f"for {counter} in range({times}):", *body]

    def _while_until(self, block: dict) -> list[str]:
        until = self._choice(block, "MODE", {"WHILE": False, "UNTIL": True})
        if until:
            condition = f"not {self._code(block, 'BOOL', UNARY, 'False')}"  # not (a < b)
        else:
            condition = self._code(block, "BOOL", NONE, "False")
        return [f"while {condition}:", *self._body(block, "DO", loop=True)]

    def _for(self, block: dict) -> list[str]:
        variable = self._variable_field(block)
        start = self._code(block, "FROM", NONE, "0")
        end = self._code(block, "TO", NONE, "0")
        step = self._code(block, "BY", NONE, "1")
        if all(map(_is_int_literal, (start, end, step))):
            first, last, by = int(start), int(end), abs(int(step)) or 1
            if first <= last:
                steps = f"{first}, {last + 1}" + (f", {by}" if by != 1 else "")
            else:
                steps = f"{first}, {last - 1}, {-by}"
            loop = f"for {variable} in range({steps}):"
        else:
            self.helpers.add("count_with")  # up or down is known only when it runs
            loop = f"for {variable} in count_with({start}, {end}, {step}):"
        return [loop, *self._body(block, "DO", loop=True)]

    def _flow(self, block: dict) -> list[str]:
        word = self._choice(block, "FLOW", {"BREAK": "break", "CONTINUE": "continue"})
        if not self.loops:
            raise BlocksError(
                _("%(block)s: '%(word)s' works only inside a loop.")
                % {"block": _name_of(block), "word": word}
            )
        return [word]

    def _compare(self, block: dict):
        operator = self._choice(block, "OP", COMPARE)
        a = self._code(block, "A", RELATIONAL, "0")
        b = self._code(block, "B", RELATIONAL, "0")
        return f"{a} {operator} {b}", RELATIONAL

    def _operation(self, block: dict):
        operator, order = self._choice(block, "OP", {"AND": ("and", AND), "OR": ("or", OR)})
        a = self._code(block, "A", order, "False", same=True)
        b = self._code(block, "B", order, "False", same=True)
        return f"{a} {operator} {b}", order

    def _negate(self, block: dict):
        return f"not {self._code(block, 'BOOL', UNARY, 'True')}", NOT

    def _boolean(self, block: dict):
        return self._choice(block, "BOOL", {"TRUE": "True", "FALSE": "False"}), ATOMIC

    # -- math and text ---------------------------------------------------------------------

    def _number(self, block: dict):
        code, order = _number_literal(block, self._field(block, "NUM"))
        if "math." in code:
            self.imports.add("math")
        return code, order

    def _arithmetic(self, block: dict):
        operator, order = self._choice(block, "OP", ARITHMETIC)
        a = self._code(block, "A", order, "0", same=operator != "**")
        b = self._code(block, "B", order, "0", same=operator == "**")
        return f"{a} {operator} {b}", order

    def _random_int(self, block: dict):
        self.imports.add("random")
        low = self._code(block, "FROM", NONE, "0")
        high = self._code(block, "TO", NONE, "0")
        if _is_int_literal(low) and _is_int_literal(high):
            low, high = sorted((low, high), key=int)
        else:
            low, high = f"int({low})", f"int({high})"
        return f"random.randint({low}, {high})", CALL

    def _round(self, block: dict):
        function = self._choice(block, "OP", ROUND)
        if function.startswith("math."):
            self.imports.add("math")
        return f"{function}({self._code(block, 'NUM', NONE, '0')})", CALL

    def _text(self, block: dict):
        return repr(self._text_field(block, "TEXT")), ATOMIC

    def _join(self, block: dict):
        state = block.get("extraState") or {}
        count = state.get("itemCount", 2) if isinstance(state, dict) else None
        if not isinstance(count, int) or isinstance(count, bool) or not 0 <= count <= MAX_ITEMS:
            raise BlocksError(
                _("%(block)s: itemCount must be a whole number to %(count)s.")
                % {"block": _name_of(block), "count": MAX_ITEMS}
            )
        parts = [self._as_text(block, f"ADD{n}", ADDITIVE) for n in range(count)]
        if not parts:
            return EMPTY_TEXT, ATOMIC
        if len(parts) == 1:
            return parts[0], CALL
        return " + ".join(parts), ADDITIVE

    def _as_text(self, block: dict, name: str, order: float) -> str:
        """A value input as a text: str() of it unless it is a text already."""
        inner = self._input(block, name)
        if inner is None or not _enabled(inner) or inner.get("type") in ("text", "text_join"):
            return self._code(block, name, order, EMPTY_TEXT)
        return f"str({self._code(block, name, NONE, EMPTY_TEXT)})"

    def _print(self, block: dict) -> list[str]:
        return [f"print({self._code(block, 'TEXT', NONE, EMPTY_TEXT)})"]

    # -- variables -------------------------------------------------------------------------

    def _get(self, block: dict):
        return self._variable_field(block), ATOMIC

    def _set(self, block: dict) -> list[str]:
        return [f"{self._variable_field(block)} = {self._code(block, 'VALUE', NONE, '0')}"]

    def _change(self, block: dict) -> list[str]:
        return [f"{self._variable_field(block)} += {self._code(block, 'DELTA', NONE, '0')}"]

    # -- the robot -------------------------------------------------------------------------

    def _drive(self, block: dict) -> list[str]:
        linear = self._code(block, "LINEAR", NONE, "0")
        angular = self._code(block, "ANGULAR", NONE, "0")
        return [f"bot.drive({linear}, {angular})"]

    def _turn(self, block: dict) -> list[str]:
        left = self._choice(block, "DIRECTION", {"LEFT": True, "RIGHT": False})
        self.helpers.add("turn")
        self.imports.add("math")
        if left:
            return [f"turn({self._code(block, 'DEGREES', NONE, '0')})"]
        return [f"turn(-{self._code(block, 'DEGREES', UNARY, '0')})"]

    def _forward(self, block: dict) -> list[str]:
        seconds = self._code(block, "SECONDS", NONE, "0")
        speed = self._code(block, "SPEED", NONE, "0")
        return [f"bot.drive({speed}, 0.0)", f"time.sleep({seconds})", "bot.stop()"]

    def _wait(self, block: dict) -> list[str]:
        return [f"time.sleep({self._code(block, 'SECONDS', NONE, '0')})"]

    def _sensor(self, block: dict):
        name = self._text_field(block, "SENSOR")
        if not SENSOR_NAME.fullmatch(name):
            raise BlocksError(
                _("%(block)s: %(name)s is not a sensor's name.")
                % {"block": _name_of(block), "name": repr(name[:40])}
            )
        reading, *parts = name.split(".")
        return f"bot.sensor({reading!r})" + "".join(f"[{part!r}]" for part in parts), MEMBER

    def _show(self, block: dict) -> list[str]:
        name = self._text_field(block, "NAME")
        return [f"bot.show({name!r}, {self._code(block, 'VALUE', NONE, '0')})"]

    def _say(self, block: dict) -> list[str]:
        return [f"bot.say({self._as_text(block, 'TEXT', NONE)})"]

    def _publish(self, block: dict) -> list[str]:
        topic = self._text_field(block, "TOPIC")
        return [f"bot.publish({topic!r}, {self._code(block, 'VALUE', NONE, 'None')})"]

    def _receive(self, block: dict):
        topic = self._text_field(block, "TOPIC")
        if topic not in self.topics:
            self.topics.append(topic)
        timeout = self._code(block, "TIMEOUT", NONE, "None")  # None: wait for ever
        return f"bot.receive({topic!r}, {timeout})", CALL

    def _memory_set(self, block: dict) -> list[str]:
        key = self._text_field(block, "KEY")
        return [f"bot.memory_set({key!r}, {self._code(block, 'VALUE', NONE, 'None')})"]

    def _memory_get(self, block: dict):
        return f"bot.memory_get({self._text_field(block, 'KEY')!r})", CALL


class _Line(str):
    """A line of Python and the id of the block it was made for (None: no block's)."""

    block: str | None

    def __new__(cls, text: str, block=None):
        if isinstance(text, _Line):  # made by a block inside: it stays that block's
            return text
        line = super().__new__(cls, text)
        line.block = None if block is None else str(block)
        return line


def _split_keeping_block(text: str) -> list:
    """The lines of `text` (a helper is one text of many lines), each with `text`'s block."""
    if "\n" not in text:
        return [text]
    block = getattr(text, "block", None)
    return [_Line(part, block) for part in text.split("\n")]


def _within_cap(size: int, lines: list[str], block: dict) -> int:
    """`size` (characters so far) with `lines` added; refused naming `block` past the cap.
    Each stack counts its own lines as they stand, so code is refused as soon as it grows
    past the cap, not once all of it is made."""
    size += sum(map(len, lines)) + len(lines)
    if size > MAX_CODE_BYTES:
        raise BlocksError(_too_long(block))
    return size


# Why the editor disables a loose block (Blockly's own reason for orphans). Which blocks are
# loose is decided here from where they lie, whatever the saved reasons say.
LOOSE = "ORPHANED_BLOCK"


def _enabled(block: dict) -> bool:
    """Blockly skips a disabled block (and what is plugged into it) when it makes code."""
    reasons = block.get("disabledReasons")
    if isinstance(reasons, list):
        reasons = [reason for reason in reasons if reason != LOOSE]
    return block.get("enabled", True) is not False and not reasons


def _in_reading_order(blocks: list) -> list:
    """Top blocks as Blockly orders them for code: top to bottom, a little tilted."""
    tilt = math.sin(math.radians(3))

    def position(block):
        if not isinstance(block, dict):
            return 0.0
        x, y = block.get("x", 0), block.get("y", 0)
        if not all(isinstance(v, int | float) and not isinstance(v, bool) for v in (x, y)):
            return 0.0
        return y + tilt * x

    return sorted(blocks, key=position)


def _needs_parentheses(outer: float, inner: float, same: bool) -> bool:
    if inner < outer or (inner == outer and (same or outer in (ATOMIC, NONE))):
        return False
    # Calls and members chain without them: bot.sensor('position')['x'], str(x).
    return not (outer in (MEMBER, CALL) and inner in (MEMBER, CALL))


def _number_literal(block: dict, value) -> tuple[str, float]:
    """A number field's value written anew as Python, and its order (a minus is unary)."""
    if isinstance(value, bool) or not isinstance(value, int | float | str):
        raise BlocksError(
            _("%(block)s: %(value)s is not a number.")
            % {"block": _name_of(block), "value": repr(value)[:40]}
        )
    if isinstance(value, int):
        if abs(value) > MAX_INTEGER:
            raise BlocksError(_("%(block)s: the number is too large.") % {"block": _name_of(block)})
        code = str(value)
    else:
        try:
            number = float(value)
        except ValueError:
            raise BlocksError(
                _("%(block)s: %(value)s is not a number.")
                % {"block": _name_of(block), "value": repr(value)[:40]}
            ) from None
        if math.isnan(number):
            raise BlocksError(
                _("%(block)s: NaN is not a number a program can use.") % {"block": _name_of(block)}
            )
        if math.isinf(number):  # Blockly's number fields allow Infinity
            return ("math.inf", MEMBER) if number > 0 else ("-math.inf", UNARY)
        code = str(int(number)) if number.is_integer() and abs(number) < 2**53 else repr(number)
    return code, UNARY if code.startswith("-") else ATOMIC


def _is_int_literal(code: str) -> bool:
    return re.fullmatch(r"-?\d+", code) is not None


def _identifier(name: str) -> str:
    """A Python identifier like `name`: "my speed" -> my_speed, "2nd" -> var_2nd."""
    text = unicodedata.normalize("NFKC", name)  # as Python reads identifiers
    text = "".join(c if ("_" + c).isidentifier() else "_" for c in text)
    text = re.sub(r"_+", "_", text).strip("_") or "var"
    if not text.isidentifier():
        text = f"var_{text}"
    return text
